//! Adam (Kingma & Ba 2015, Algorithm 1) with global-norm gradient clipping,
//! over named tensors whose moments can be saved with a checkpoint.
//!
//! The stage 2 agents train in segments and resume from a checkpoint
//! exactly as if never stopped; libtorch's optimiser keeps its moments out
//! of reach, so the core owns them: for every parameter `θ` with gradient
//! `g` (after clipping the global norm to `max_norm`),
//! `m ← β₁ m + (1 − β₁) g`, `v ← β₂ v + (1 − β₂) g²`,
//! `θ ← θ − lr · (m / (1 − β₁ᵗ)) / (√(v / (1 − β₂ᵗ)) + ε)`.

use tch::{Kind, Tensor, nn};

/// `β₁`, `β₂` and `ε` of tch's (and PyTorch's) Adam defaults.
const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPS: f64 = 1e-8;

/// Adam over the trainable variables of one or more var stores.
#[derive(Debug)]
pub struct Adam {
    names: Vec<String>,
    params: Vec<Tensor>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    t: i64,
    lr: f64,
}

impl Adam {
    /// Adam over `stores` (each `(prefix, store)`; names are `prefix/name`)
    /// with learning rate `lr`.
    pub fn new(stores: &[(&str, &nn::VarStore)], lr: f64) -> Adam {
        let mut named: Vec<(String, Tensor)> = Vec::new();
        for (prefix, vs) in stores {
            let mut vars: Vec<(String, Tensor)> = vs
                .variables()
                .into_iter()
                .filter(|(_, t)| t.requires_grad())
                .map(|(k, t)| (format!("{prefix}/{k}"), t))
                .collect();
            vars.sort_by(|a, b| a.0.cmp(&b.0));
            named.extend(vars);
        }
        let m = named.iter().map(|(_, p)| p.zeros_like()).collect();
        let v = named.iter().map(|(_, p)| p.zeros_like()).collect();
        let (names, params) = named.into_iter().unzip();
        Adam {
            names,
            params,
            m,
            v,
            t: 0,
            lr,
        }
    }

    /// Updates taken.
    pub fn steps(&self) -> i64 {
        self.t
    }

    /// Zeroes the gradients, back-propagates `loss`, clips the global
    /// gradient norm to `max_norm` and takes one step. Returns the norm
    /// before clipping.
    pub fn backward_step(&mut self, loss: &Tensor, max_norm: f64) -> f64 {
        for p in &self.params {
            let mut g = p.grad();
            if g.defined() {
                let _ = g.zero_();
            }
        }
        loss.backward();
        tch::no_grad(|| {
            let grads: Vec<Tensor> = self
                .params
                .iter()
                .map(|p| {
                    let g = p.grad();
                    if g.defined() { g } else { p.zeros_like() }
                })
                .collect();
            let norm = grads
                .iter()
                .map(|g| g.square().sum(Kind::Float))
                .fold(
                    Tensor::zeros([], (Kind::Float, tch::Device::Cpu)),
                    |a, b| a + b,
                )
                .sqrt()
                .double_value(&[]);
            let scale = if norm > max_norm {
                max_norm / (norm + 1e-6)
            } else {
                1.0
            };
            self.t += 1;
            let c1 = 1.0 - BETA1.powi(self.t as i32);
            let c2 = 1.0 - BETA2.powi(self.t as i32);
            for (k, g) in grads.iter().enumerate() {
                let g = g * scale;
                self.m[k] = &self.m[k] * BETA1 + &g * (1.0 - BETA1);
                self.v[k] = &self.v[k] * BETA2 + g.square() * (1.0 - BETA2);
                let step = (&self.m[k] / c1) / ((&self.v[k] / c2).sqrt() + EPS) * self.lr;
                let mut p = self.params[k].shallow_clone();
                let _ = p.g_sub_(&step);
            }
            norm
        })
    }

    /// The moments and the step count as named tensors (for a checkpoint).
    pub fn state(&self) -> Vec<(String, Tensor)> {
        let mut out = vec![("adam/t".to_string(), Tensor::from(self.t))];
        for (k, name) in self.names.iter().enumerate() {
            out.push((format!("adam/m/{name}"), self.m[k].shallow_clone()));
            out.push((format!("adam/v/{name}"), self.v[k].shallow_clone()));
        }
        out
    }

    /// Restores [`Self::state`]; `Err` names what is missing or misshapen.
    pub fn load_state(&mut self, named: &[(String, Tensor)]) -> Result<(), String> {
        let find = |key: &str| named.iter().find(|(k, _)| k == key).map(|(_, t)| t);
        self.t = find("adam/t").ok_or("no adam/t")?.int64_value(&[]);
        for (k, name) in self.names.iter().enumerate() {
            for (slot, which) in [(&mut self.m[k], "m"), (&mut self.v[k], "v")] {
                let key = format!("adam/{which}/{name}");
                let t = find(&key).ok_or_else(|| format!("no {key}"))?;
                if t.size() != slot.size() {
                    return Err(format!(
                        "{key} has shape {:?}, expected {:?}",
                        t.size(),
                        slot.size()
                    ));
                }
                *slot = t.copy();
            }
        }
        Ok(())
    }
}
