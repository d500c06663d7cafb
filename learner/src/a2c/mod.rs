//! The one A2C core every learner of worldgraph trains with: `π_g`
//! (Shang et al. 2019, section 3.2), the A2C baseline, and the Manager and
//! Worker of the Feudal and Wide-then-Narrow agents (section 4).
//!
//! "A2C models both a value function V(s_t) by regressing over the
//! estimated t_max-step discounted returns ... and a policy π guided by
//! advantage-based policy gradient. The policy entropy is regularized to
//! encourage exploration" (section 4.1). Here:
//!
//! - [`input`]: the observation as the first convolution's input, densely
//!   (the plain path) or as embedding-bag indices (the fast path);
//! - [`net`]: the CNN + LSTM trunk and the policy/value heads;
//! - [`kernels`], [`gemm`], [`encoder`]: the trunk's encoder in kernels of
//!   the project's own (plain Rust over the `gemm` crate), forward and
//!   backward, and the rollout path that runs it around tch's graph;
//! - [`advantages`]: generalised advantage estimation with a discount per
//!   transition (`γ` for one env step, `γ^k` for a Manager interval of `k`
//!   steps);
//! - [`rollout`]: rollout storage `[T, B]` with the bootstrap values, and
//!   the update, by default through every step's autograd graph over the
//!   own encoder's features ([`encoder`]), else over the whole network in
//!   tch (with the gather-and-sum first layer); the alternative, acting
//!   under `no_grad` and recomputing the encoder for all `T·B`
//!   observations in one batched call before unrolling the LSTM over the
//!   stored features (CleanRL's PPO-LSTM layout), gives the same gradients
//!   and is kept for `worldgraph bench learner`;
//! - [`a2c_loss`]: `L = L_π + c_V · L_V − c_H · H` over weighted entries;
//! - [`learner`]: a network, its optimiser and its rollout, as the A2C
//!   baseline and the Worker train them.

pub mod encoder;
pub mod gemm;
mod grad_path;
pub mod input;
pub mod kernels;
pub mod learner;
pub mod lstm;
pub mod net;
pub mod optim;
pub mod rollout;
pub mod rust_net;
pub mod tensors;

use std::time::Instant;

use serde::{Deserialize, Serialize};
use tch::{Kind, Tensor};

use crate::error::ConfigError;

/// The A2C hyperparameters shared by every learner.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct A2cConfig {
    /// Discount `γ` per environment step.
    pub gamma: f64,
    /// GAE `λ`.
    pub gae_lambda: f64,
    /// Weight `c_H` of the entropy bonus.
    pub entropy_coef: f64,
    /// Weight `c_V` of the value loss.
    pub value_coef: f64,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Gradients are rescaled to at most this global L2 norm.
    pub grad_clip_norm: f64,
}

impl Default for A2cConfig {
    fn default() -> Self {
        A2cConfig {
            gamma: 0.99,
            gae_lambda: 0.95,
            entropy_coef: 0.01,
            value_coef: 0.5,
            learning_rate: 7e-4,
            grad_clip_norm: 0.5,
        }
    }
}

impl A2cConfig {
    /// Checks every field's range; `prefix` names the section in errors.
    pub fn validate(&self, prefix: &str) -> Result<(), ConfigError> {
        let field = |name: &str| {
            if prefix.is_empty() {
                name.to_string()
            } else {
                format!("{prefix}.{name}")
            }
        };
        for (name, v) in [("gamma", self.gamma), ("gae_lambda", self.gae_lambda)] {
            if !(0.0..=1.0).contains(&v) {
                return Err(ConfigError::new(
                    field(name),
                    format!("{v} is not in [0, 1]"),
                ));
            }
        }
        for (name, v) in [
            ("entropy_coef", self.entropy_coef),
            ("value_coef", self.value_coef),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ConfigError::new(
                    field(name),
                    format!("{v} must be finite and ≥ 0"),
                ));
            }
        }
        for (name, v) in [
            ("learning_rate", self.learning_rate),
            ("grad_clip_norm", self.grad_clip_norm),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(ConfigError::new(
                    field(name),
                    format!("{v} must be finite and > 0"),
                ));
            }
        }
        Ok(())
    }
}

/// Where a learner's time goes, in seconds, accumulated over iterations
/// (read by `worldgraph bench learner`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PhaseTimes {
    /// Stepping the environments.
    pub step: f64,
    /// Encoding observations into network inputs.
    pub encode: f64,
    /// The acting forward passes.
    pub act: f64,
    /// The update's forward pass and loss (the recomputation, or the loss
    /// over kept graphs).
    pub loss: f64,
    /// Backward pass and optimiser step.
    pub backward: f64,
}

impl PhaseTimes {
    /// Sum of the phases.
    pub fn total(&self) -> f64 {
        self.step + self.encode + self.act + self.loss + self.backward
    }

    /// Adds the seconds since `since` to one phase, returns now.
    pub fn lap(slot: &mut f64, since: Instant) -> Instant {
        let now = Instant::now();
        *slot += (now - since).as_secs_f64();
        now
    }

    /// Adds another record.
    pub fn add(&mut self, o: &PhaseTimes) {
        self.step += o.step;
        self.encode += o.encode;
        self.act += o.act;
        self.loss += o.loss;
        self.backward += o.backward;
    }
}

/// Generalised advantage estimation (Schulman et al. 2016, eq. 16) over `K`
/// transitions of `B` sequences, entry `k·B + b`, with a discount per
/// transition:
///
/// ```text
/// delta_k = r_k + d_k · V_{k+1} − V_k
/// Â_k     = delta_k + d_k · λ · Â_{k+1}
/// R_k     = Â_k + V_k
/// ```
///
/// `d_k = γ^{steps_k} · (1 − done_k)`: `γ · (1 − done)` for one environment
/// step, `γ^k` for a Manager interval of `k` steps, 0 where the transition
/// ended the episode (so neither the next value nor the next advantage
/// flows back). `V_K = bootstrap[b]`. Returns `(Â, R)`.
pub fn advantages(
    rewards: &[f32],
    values: &[f32],
    discounts: &[f32],
    bootstrap: &[f32],
    lambda: f32,
) -> (Vec<f32>, Vec<f32>) {
    let b = bootstrap.len();
    let n = rewards.len();
    debug_assert!(b > 0 && n.is_multiple_of(b) && values.len() == n && discounts.len() == n);
    let steps = n / b;
    let mut adv = vec![0f32; n];
    let mut ret = vec![0f32; n];
    for (e, &boot) in bootstrap.iter().enumerate() {
        let mut next_value = boot;
        let mut next_adv = 0f32;
        for k in (0..steps).rev() {
            let i = k * b + e;
            let d = discounts[i];
            let delta = rewards[i] + d * next_value - values[i];
            next_adv = delta + d * lambda * next_adv;
            adv[i] = next_adv;
            ret[i] = next_adv + values[i];
            next_value = values[i];
        }
    }
    (adv, ret)
}

/// Logits of invalid choices (walls, cells outside a window): low enough
/// that their probability is exactly 0, finite so `p · log p` stays 0.
pub const MASKED_LOGIT: f64 = -1e9;

/// Log-probabilities and entropies of categorical policies.
#[derive(Debug)]
pub struct Categorical {
    /// `log π(·)` `[N, A]`.
    pub log_probs: Tensor,
}

impl Categorical {
    /// From logits `[N, A]`; where `valid` (`[N, A]` bool) is given, the
    /// invalid choices get probability 0.
    pub fn new(logits: &Tensor, valid: Option<&Tensor>) -> Categorical {
        let logits = match valid {
            Some(v) => logits.masked_fill(&v.logical_not(), MASKED_LOGIT),
            None => logits.shallow_clone(),
        };
        Categorical {
            log_probs: logits.log_softmax(-1, Kind::Float),
        }
    }

    /// `log π(a_n)` `[N]` of the taken choices `actions` (`[N]` int64).
    pub fn log_prob(&self, actions: &Tensor) -> Tensor {
        self.log_probs
            .gather(1, &actions.unsqueeze(-1), false)
            .squeeze_dim(-1)
    }

    /// `H = −Σ_a π(a) log π(a)` `[N]`.
    pub fn entropy(&self) -> Tensor {
        -(self.log_probs.exp() * &self.log_probs).sum_dim_intlist(-1, false, Kind::Float)
    }

    /// The probabilities `[N, A]`, without gradient.
    pub fn probs(&self) -> Tensor {
        tch::no_grad(|| self.log_probs.exp())
    }
}

/// The terms of one A2C loss, `[N]` each.
#[derive(Debug)]
pub struct PolicyTerms {
    /// `log π(a_n | s_n)` of the taken actions (for a Wide-then-Narrow
    /// Manager, `log π^w + log π^n`).
    pub log_prob: Tensor,
    /// The policy entropy (for Wide-then-Narrow, `H(π^w) + H(π^n(·|g_w))`).
    pub entropy: Tensor,
    /// `V(s_n)`.
    pub value: Tensor,
}

/// The figures of one loss.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct LossFigures {
    /// `L_π`.
    pub policy_loss: f64,
    /// `L_V`.
    pub value_loss: f64,
    /// Mean policy entropy, nats.
    pub entropy: f64,
    /// Entries that counted.
    pub entries: f64,
}

/// The A2C loss over weighted entries (`weights[n] = 0` leaves entry `n`
/// out; means are over the weights):
/// `L = L_π + c_V · L_V − c_H · H`, with
/// `L_π = −mean(Â · log π(a | s))`, `L_V = ½ · mean((R − V(s))²)`,
/// `H = mean(entropy)`.
pub fn a2c_loss(
    terms: &PolicyTerms,
    advantages: &[f32],
    returns: &[f32],
    weights: &[f32],
    cfg: &A2cConfig,
) -> (Tensor, LossFigures) {
    let adv = Tensor::from_slice(advantages);
    let ret = Tensor::from_slice(returns);
    let w = Tensor::from_slice(weights);
    let total: f64 = weights.iter().map(|&x| f64::from(x)).sum();
    let denom = total.max(1.0);
    let mean = |x: Tensor| (x * &w).sum(Kind::Float) / denom;
    let policy_loss = mean(-(adv * &terms.log_prob));
    let value_loss = mean((ret - &terms.value).square()) * 0.5;
    let entropy = mean(terms.entropy.shallow_clone());
    let loss = &policy_loss + &value_loss * cfg.value_coef - &entropy * cfg.entropy_coef;
    let figures = LossFigures {
        policy_loss: policy_loss.double_value(&[]),
        value_loss: value_loss.double_value(&[]),
        entropy: entropy.double_value(&[]),
        entries: total,
    };
    (loss, figures)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

    /// The textbook definition: `Â_t = Σ_{l≥0} (γλ)^l δ_{t+l}`, summed
    /// forward per sequence and cut at the first episode end.
    #[allow(clippy::needless_range_loop)] // indices as in the formula
    fn naive(
        rewards: &[Vec<f64>],
        values: &[Vec<f64>],
        dones: &[Vec<f64>],
        bootstrap: &[f64],
        gamma: f64,
        lambda: f64,
    ) -> Vec<Vec<f64>> {
        let (t_len, b_len) = (rewards.len(), bootstrap.len());
        let value_at = |t: usize, b: usize| {
            if t == t_len {
                bootstrap[b]
            } else {
                values[t][b]
            }
        };
        let mut out = vec![vec![0.0; b_len]; t_len];
        for b in 0..b_len {
            for t in 0..t_len {
                let mut sum = 0.0;
                let mut weight = 1.0;
                for l in t..t_len {
                    let alive = 1.0 - dones[l][b];
                    let delta = rewards[l][b] + gamma * value_at(l + 1, b) * alive - values[l][b];
                    sum += weight * delta;
                    if alive == 0.0 {
                        break;
                    }
                    weight *= gamma * lambda;
                }
                out[t][b] = sum;
            }
        }
        out
    }

    fn flat(rows: &[Vec<f64>]) -> Vec<f32> {
        rows.iter().flatten().map(|&x| x as f32).collect()
    }

    #[test]
    fn recursion_matches_the_naive_sum_of_discounted_td_errors() {
        let mut rng = SmallRng::seed_from_u64(3);
        let (t_len, b_len) = (11, 7);
        let mut grid = |f: &mut dyn FnMut(&mut SmallRng) -> f64| -> Vec<Vec<f64>> {
            (0..t_len)
                .map(|_| (0..b_len).map(|_| f(&mut rng)).collect())
                .collect()
        };
        let rewards = grid(&mut |r| r.random_range(-1.0..1.0));
        let values = grid(&mut |r| r.random_range(-2.0..2.0));
        let dones = grid(&mut |r| if r.random_bool(0.2) { 1.0 } else { 0.0 });
        let bootstrap: Vec<f64> = (0..b_len).map(|b| 0.5 - b as f64 * 0.1).collect();
        for (gamma, lambda) in [(0.99, 0.95), (0.9, 1.0), (0.5, 0.0)] {
            let expected = naive(&rewards, &values, &dones, &bootstrap, gamma, lambda);
            let discounts: Vec<f32> = flat(&dones)
                .iter()
                .map(|&d| (gamma * (1.0 - f64::from(d))) as f32)
                .collect();
            let boot: Vec<f32> = bootstrap.iter().map(|&x| x as f32).collect();
            let (adv, ret) = advantages(
                &flat(&rewards),
                &flat(&values),
                &discounts,
                &boot,
                lambda as f32,
            );
            for t in 0..t_len {
                for b in 0..b_len {
                    let i = t * b_len + b;
                    assert!(
                        (f64::from(adv[i]) - expected[t][b]).abs() < 1e-4,
                        "γ={gamma} λ={lambda} t={t} b={b}: {} vs {}",
                        adv[i],
                        expected[t][b]
                    );
                    assert!((f64::from(ret[i]) - expected[t][b] - values[t][b]).abs() < 1e-4);
                }
            }
        }
    }

    #[test]
    fn lambda_zero_is_the_one_step_td_error() {
        // γ = 0.5; the second transition ended its episode.
        let (adv, _) = advantages(
            &[1.0, 0.0, 2.0],
            &[0.5, 0.25, 1.0],
            &[0.5, 0.0, 0.5],
            &[4.0],
            0.0,
        );
        // 1 + 0.5·0.25 − 0.5; 0 − 0.25 (episode ended); 2 + 0.5·4 − 1.
        assert_eq!(adv, vec![0.625, -0.25, 3.0]);
    }

    #[test]
    fn an_interval_of_k_steps_discounts_by_gamma_to_the_k() {
        // One Manager transition of 3 steps, reward 1, then V = 2 at the
        // next decision: Â = 1 + 0.9³ · 2 − V.
        let g3 = 0.9f32.powi(3);
        let (adv, ret) = advantages(&[1.0], &[0.5], &[g3], &[2.0], 0.95);
        assert!((adv[0] - (1.0 + g3 * 2.0 - 0.5)).abs() < 1e-6);
        assert!((ret[0] - (1.0 + g3 * 2.0)).abs() < 1e-6);
    }

    #[test]
    fn masked_choices_have_zero_probability_and_finite_entropy() {
        let logits = Tensor::from_slice(&[1.0f32, 2.0, 3.0, 0.5, 0.5, 0.5]).view([2, 3]);
        let valid = Tensor::from_slice(&[true, false, true, true, true, false]).view([2, 3]);
        let pi = Categorical::new(&logits, Some(&valid));
        let p: Vec<f32> = Vec::try_from(pi.probs().flatten(0, -1)).expect("floats");
        assert_eq!(p[1], 0.0);
        assert_eq!(p[5], 0.0);
        let h: Vec<f32> = Vec::try_from(pi.entropy()).expect("floats");
        // Row 0: softmax over {1, 3}; row 1: uniform over two.
        let (a, b) = (1f32.exp(), 3f32.exp());
        let (pa, pb) = (a / (a + b), b / (a + b));
        assert!(
            (h[0] - -(pa * pa.ln() + pb * pb.ln())).abs() < 1e-5,
            "{h:?}"
        );
        assert!((h[1] - 2f32.ln()).abs() < 1e-5, "{h:?}");
    }
}
