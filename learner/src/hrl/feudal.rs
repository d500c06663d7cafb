//! The Feudal Manager (Shang et al. 2019, section 4.1; FeUdal Networks,
//! Vezhnevets et al. 2017, in the paper's fully observed form).
//!
//! "The Manager receives rewards from the environment and the Worker
//! receives rewards from the Manager by reaching its subgoals. The high and
//! low-level policy models are distinct and operate at different temporal
//! resolutions: the Manager only outputs a new subgoal if either Worker
//! completes its current one or the subgoal horizon `c` is exceeded." In a
//! fully observed maze "the Manager policy can emit a probability vector of
//! dimension `|S|`": a softmax over every valid cell, walls masked
//! ([`ManagerHead::Feudal`]). The Wide-then-Narrow Manager of section 4.2 is
//! the same Manager with the head of [`crate::hrl::wide_narrow`].
//!
//! ## The Manager's own time scale
//! A Manager *decision* is taken at the start of an episode and whenever
//! its interval ends; its reward is the task's rewards summed over the `k`
//! steps of the interval, and its transition is discounted by `γ^k`
//! ([`interval_transition`]). An interval that the episode's step limit
//! cut (truncation, not termination) bootstraps from the Manager's value of
//! the episode's final state ([`Manager::final_values`]). The Manager's
//! core steps once per decision.
//! Decisions are kept per environment ([`DecisionQueue`]); an interval
//! still running at the end of a rollout is trained in the next one: the
//! queue carries it over together with the core state before it, so every
//! decision is trained exactly once with the gradient of the step it was
//! taken in ([`Manager::loss`]).

use tch::nn::{self, Module};
use tch::{Kind, Tensor};

use super::wide_narrow::{WINDOW_CHANNELS, WideNarrowHead, Window};
use crate::a2c::encoder::with_gradients;
use crate::a2c::input::CellInput;
use crate::a2c::net::{LstmState, Trunk};
use crate::a2c::tensors::floats;
use crate::a2c::{A2cConfig, Categorical, LossFigures, PolicyTerms, a2c_loss, advantages};
use crate::batch_env::ObsView;

/// The reward and discount of one Manager transition: the task rewards of
/// the interval summed, `γ^k` over its `k` steps, 0 where the interval
/// ended the episode; an interval the step limit cut adds `γ^k · V(s_final)`
/// (`final_value`) to its reward instead of bootstrapping from the next
/// episode's start.
pub fn interval_transition(
    rewards: &[f32],
    gamma: f64,
    episode_ended: bool,
    final_value: Option<f32>,
) -> (f32, f32) {
    let sum: f32 = rewards.iter().sum();
    let gk = gamma.powi(rewards.len() as i32) as f32;
    match (episode_ended, final_value) {
        (true, Some(v)) => (sum + gk * v, 0.0),
        (true, None) => (sum, 0.0),
        (false, _) => (sum, gk),
    }
}

/// The Manager's trunk run outside tch's autograd (the
/// [`crate::a2c::rollout::GradPath::RustCore`] path): the update's forward
/// over the `K·B` decisions, and its backward from the gradients of the
/// hidden states. Implemented by the own kernels
/// (`manager_kernels::OwnManager`); [`Manager::loss_with`] takes it.
pub(super) trait OwnTrunk {
    /// The hidden and cell states after every row (`[K·B, hidden]` each) of
    /// `input`, from `init_h`, `init_c`, zeroed before row `i` where
    /// `reset[i]`.
    fn unroll(
        &mut self,
        input: &CellInput,
        init_h: &[f32],
        init_c: &[f32],
        reset: &[bool],
        b: usize,
    ) -> (Vec<f32>, Vec<f32>);
    /// The gradients of the trunk's weights (encoder, then core) from
    /// `dh`, the gradient of the loss in every hidden state of the last
    /// [`Self::unroll`].
    fn unroll_backward(&mut self, dh: &[f32], b: usize) -> Vec<Tensor>;
}

/// The Manager's goal head.
#[derive(Debug)]
pub enum ManagerHead {
    /// FN: one subgoal cell, a softmax over the grid with invalid cells
    /// masked.
    Feudal {
        /// Logits over the `H·W` cells.
        cells: nn::Linear,
        /// `[H·W]` valid subgoal cells.
        valid: Tensor,
    },
    /// WN: a wide goal from `V`, then a narrow goal in its window.
    WideNarrow(WideNarrowHead),
}

/// One Manager decision and its interval.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Decision {
    /// The observation it was taken on (one observation).
    pub input: CellInput,
    /// FN: the subgoal cell; WN: the index of `g_w` in `V`.
    pub wide: i64,
    /// WN: the window slot of `g_n` (0 for FN).
    pub narrow: i64,
    /// WN: the local input `s_w(g_w)` and the valid slots of the window.
    pub local: Vec<f32>,
    /// WN: valid narrow slots.
    pub valid: Vec<bool>,
    /// `V(s)` when it was taken.
    pub value: f32,
    /// The core was reset before this decision (first of an episode).
    pub reset_before: bool,
    /// Task rewards of the interval so far.
    pub rewards: Vec<f32>,
    /// The interval is over.
    pub complete: bool,
    /// The interval ended the episode.
    pub episode_ended: bool,
    /// The Manager's value of the final state, where the episode's step
    /// limit ended the interval (truncation).
    pub final_value: Option<f32>,
}

/// One environment's decisions not yet trained, oldest first. (The
/// Manager's core state before the first of them is kept beside the
/// queues, one row per environment: the `init` of [`Manager::loss`].)
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct DecisionQueue {
    /// The decisions; the last one is the interval under way.
    pub decisions: Vec<Decision>,
}

/// The Manager's goal map: its subgoal encoder, a small fully convolutional
/// network from the observation planes to one logit per cell, added to the
/// goal head's logits (the paper's Manager emits "a masked probability
/// heatmask, assigning probability to valid goal states", and its "subgoal
/// encoder ... uses very similar CNN encoding with fewer channels";
/// section 4.1 and its comments). A cell's logit sees the `5×5` cells
/// around it, so "name the cell beside a ball" is a local pattern, learnt
/// from every decision, where the goal head's linear layer over the core
/// output must learn each ball-to-goal mapping separately. The last layer
/// starts at zero: an untrained map leaves the head's distribution as it
/// is.
///
/// For WN the map reaches both of the Manager's choices when it is given
/// the windows of `V` ([`GoalMap::with_windows`]): `π^n`'s logit of a window
/// cell gains the map's logit of that cell, and `π^ω`'s logit of a wide
/// goal gains the log-sum-exp of the map over its window, the log of the
/// mass its narrow goals would add. Without windows `π^ω` reads the map at
/// the candidates' own cells only and `π^n` not at all, so "a ball lies in
/// this window" reaches neither choice.
#[derive(Debug)]
pub struct GoalMap {
    conv1: nn::Conv2D,
    conv2: nn::Conv2D,
    /// WN: the cells of `V`, whose logits `π^ω` reads; FN: every cell.
    cells: Option<Tensor>,
    /// WN with windows: the cells of each candidate's window.
    windows: Option<WindowCells>,
}

/// The cells of every candidate's window, `[|V|, N·N]` (slots outside the
/// grid or on a wall are masked).
#[derive(Debug)]
struct WindowCells {
    /// Cell indices, 0 at masked slots.
    cells: Tensor,
    /// Which slots are valid narrow goals.
    valid: Tensor,
}

/// The goal map's logits for one batch of Manager decisions.
#[derive(Debug)]
pub struct GoalBias {
    /// Added to the goal head: FN's cells `[N, H·W]` or `π^ω`'s candidates
    /// `[N, |V|]`.
    pub wide: Tensor,
    /// WN with windows: the map at every candidate's window cells, `[N,
    /// |V|, N·N]`, for `π^n` ([`WideNarrowHead::narrow_bias`]).
    pub windows: Option<Tensor>,
}

impl GoalMap {
    /// A map under `p` over `in_channels` planes with `channels` hidden
    /// channels; `cells`: the cells whose logits the head reads (`None`:
    /// all, in cell order).
    pub fn new(p: &nn::Path, in_channels: i64, channels: i64, cells: Option<&[u32]>) -> GoalMap {
        let same = nn::ConvConfig {
            padding: 1,
            ..Default::default()
        };
        let zero = nn::ConvConfig {
            padding: 1,
            ws_init: nn::Init::Const(0.0),
            bs_init: nn::Init::Const(0.0),
            ..Default::default()
        };
        GoalMap {
            conv1: nn::conv2d(p / "conv1", in_channels, channels, 3, same),
            conv2: nn::conv2d(p / "conv2", channels, 1, 3, zero),
            cells: cells
                .map(|c| Tensor::from_slice(&c.iter().map(|&x| i64::from(x)).collect::<Vec<_>>())),
            windows: None,
        }
    }

    /// The map over the windows of `candidates` too (WN, type docs): `π^ω`
    /// reads each window's log-sum-exp, `π^n` each window cell.
    pub fn with_windows(mut self, window: &Window, candidates: &[u32]) -> GoalMap {
        let mut cells = Vec::with_capacity(candidates.len() * window.len());
        let mut valid = Vec::with_capacity(candidates.len() * window.len());
        for &centre in candidates {
            let ok = window.valid(centre);
            for (k, &v) in ok.iter().enumerate() {
                cells.push(window.cell(centre, k).map_or(0, i64::from));
                valid.push(v);
            }
        }
        let rows = candidates.len() as i64;
        self.windows = Some(WindowCells {
            cells: Tensor::from_slice(&cells).view([rows, -1]),
            valid: Tensor::from_slice(&valid).view([rows, -1]),
        });
        self
    }

    /// The two convolutions, the cells `π^ω` (or FN's head) reads and, with
    /// windows, every candidate's window cells and valid slots (`[|V|,
    /// N·N]` each): what [`super::manager_kernels`] runs.
    pub(super) fn parts(
        &self,
    ) -> (
        &nn::Conv2D,
        &nn::Conv2D,
        Option<&Tensor>,
        Option<[&Tensor; 2]>,
    ) {
        (
            &self.conv1,
            &self.conv2,
            self.cells.as_ref(),
            self.windows.as_ref().map(|w| [&w.cells, &w.valid]),
        )
    }

    /// The logits `[N, cells]` of the observations `input`.
    pub fn logits(&self, input: &CellInput) -> Tensor {
        self.logits_dense(&input.to_dense())
    }

    /// The logits `[N, cells]` of dense one-hot planes `[N, C, H, W]`.
    pub fn logits_dense(&self, planes: &Tensor) -> Tensor {
        self.bias_dense(planes).wide
    }

    /// The map's logits for the goal head of dense one-hot planes `[N, C,
    /// H, W]` (type docs).
    pub fn bias_dense(&self, planes: &Tensor) -> GoalBias {
        let map = planes
            .apply(&self.conv1)
            .relu()
            .apply(&self.conv2)
            .flatten(1, -1);
        if let Some(w) = &self.windows {
            let (n, rows) = (map.size()[0], w.cells.size()[0]);
            let at = map.index_select(1, &w.cells.view([-1])).view([n, rows, -1]);
            let masked = at.masked_fill(&w.valid.logical_not().unsqueeze(0), -1e9);
            return GoalBias {
                wide: masked.logsumexp([2], false),
                windows: Some(at),
            };
        }
        let wide = match &self.cells {
            Some(c) => map.index_select(1, c),
            None => map,
        };
        GoalBias {
            wide,
            windows: None,
        }
    }
}

/// One acting step of the [`Manager`] ([`Manager::act`]).
#[derive(Debug)]
pub struct ManagerStep {
    /// The core state after the step.
    pub state: LstmState,
    /// `V(s)` of each observation.
    pub values: Vec<f32>,
    /// The core outputs `h_t` (`[S, hidden]`) the goal head reads.
    pub h: Tensor,
}

/// The Manager's A2C loss over its decision queues ([`Manager::loss`]).
#[derive(Debug)]
pub struct ManagerLoss {
    /// The loss to back-propagate.
    pub loss: Tensor,
    /// Its figures.
    pub figures: LossFigures,
    /// Each environment's core state before its interval under way: the
    /// `init` of the next update.
    pub next_init: LstmState,
}

/// The Manager: a trunk without goal channel, a value head, a goal head
/// and, optionally, a [`GoalMap`].
#[derive(Debug)]
pub struct Manager {
    trunk: Trunk,
    value: nn::Linear,
    head: ManagerHead,
    hidden: i64,
    goal_map: Option<GoalMap>,
}

impl Manager {
    /// A Manager under `p` (`encoder`, `core`, `value`, `head/...`).
    pub fn new(
        p: &nn::Path,
        trunk: Trunk,
        head: impl FnOnce(&nn::Path, i64) -> ManagerHead,
    ) -> Manager {
        let hidden = trunk.hidden();
        let value = nn::linear(p / "value", hidden, 1, Default::default());
        let head = head(&(p / "head"), hidden);
        Manager {
            trunk,
            value,
            head,
            hidden,
            goal_map: None,
        }
    }

    /// The Manager with a goal map under `p / "goal_map"` (the cells of `V`
    /// for WN, every cell for FN); created after the rest, so the other
    /// weights are those of a Manager without one.
    /// For WN, `windows` extends the map over the windows of `V` to `π^n`
    /// ([`GoalMap::with_windows`]).
    pub fn with_goal_map(
        mut self,
        p: &nn::Path,
        channels: i64,
        cells: Option<&[u32]>,
        windows: Option<&Window>,
    ) -> Manager {
        let planes = self.trunk.in_channels();
        let map = GoalMap::new(&(p / "goal_map"), planes, channels, cells);
        self.goal_map = Some(match (windows, cells) {
            (Some(w), Some(v)) => map.with_windows(w, v),
            _ => map,
        });
        self
    }

    /// The goal map's logits of `input` (`None` without a map), with
    /// gradient unless under `no_grad`.
    pub fn goal_bias(&self, input: &CellInput) -> Option<GoalBias> {
        self.goal_map
            .as_ref()
            .map(|m| m.bias_dense(&input.to_dense()))
    }

    /// The FN head over a `width × height` grid with `valid` subgoal cells.
    pub fn feudal_head(p: &nn::Path, hidden: i64, valid: &[bool]) -> ManagerHead {
        ManagerHead::Feudal {
            cells: nn::linear(p / "cells", hidden, valid.len() as i64, Default::default()),
            valid: Tensor::from_slice(valid),
        }
    }

    /// The trunk.
    pub fn trunk(&self) -> &Trunk {
        &self.trunk
    }

    /// The goal head.
    pub fn head(&self) -> &ManagerHead {
        &self.head
    }

    /// Every weight outside the trunk: the value head's, the goal head's
    /// and the goal map's.
    pub(super) fn head_parameters(&self) -> Vec<Tensor> {
        let linear = |l: &nn::Linear| {
            std::iter::once(l.ws.shallow_clone())
                .chain(l.bs.as_ref().map(Tensor::shallow_clone))
                .collect::<Vec<_>>()
        };
        let conv = |c: &nn::Conv2D| {
            std::iter::once(c.ws.shallow_clone())
                .chain(c.bs.as_ref().map(Tensor::shallow_clone))
                .collect::<Vec<_>>()
        };
        let mut params = linear(&self.value);
        match &self.head {
            ManagerHead::Feudal { cells, .. } => params.extend(linear(cells)),
            ManagerHead::WideNarrow(head) => {
                head.layers()
                    .into_iter()
                    .for_each(|l| params.extend(linear(l)));
            }
        }
        if let Some(map) = &self.goal_map {
            let (conv1, conv2, _, _) = map.parts();
            params.extend(conv(conv1));
            params.extend(conv(conv2));
        }
        params
    }

    /// The value head.
    pub(super) fn value_head(&self) -> &nn::Linear {
        &self.value
    }

    /// The goal map, if the Manager has one.
    pub(super) fn goal_map(&self) -> Option<&GoalMap> {
        self.goal_map.as_ref()
    }

    /// Zero core state.
    pub fn zero_state(&self, batch: i64) -> LstmState {
        self.trunk.zero_state(batch)
    }

    /// One acting step (no gradient) on `input` (`S` observations) from
    /// `state` (`[S, hidden]`).
    pub fn act(&self, input: &CellInput, state: &LstmState) -> ManagerStep {
        tch::no_grad(|| {
            let next = self.trunk.step(&self.trunk.features(input), state);
            let v = self.value.forward(&next.h).squeeze_dim(-1);
            let h = next.h.shallow_clone();
            ManagerStep {
                state: next,
                values: floats(&v),
                h,
            }
        })
    }

    /// The values of the final states of environments `envs`, whose
    /// episodes the last step truncated, from `state` (the Manager's core
    /// state after its last decision, `[B, hidden]`), without gradient.
    pub fn final_values(&self, obs: &ObsView<'_>, state: &LstmState, envs: &[usize]) -> Vec<f32> {
        let mut input = CellInput::new(obs.width, obs.height, 0);
        for &e in envs {
            input.push_final_env(obs, e, None);
        }
        let idx = Tensor::from_slice(&envs.iter().map(|&e| e as i64).collect::<Vec<_>>());
        self.act(&input, &state.select(&idx)).values
    }

    /// FN: the subgoal distribution of core outputs `h`, plus the goal
    /// map's logits `bias` (`[N, H·W]`) if the Manager has one.
    pub fn feudal_policy(&self, h: &Tensor, bias: Option<&Tensor>) -> Option<Categorical> {
        match &self.head {
            ManagerHead::Feudal { cells, valid } => {
                let n = h.size()[0];
                let mask = valid.view([1, -1]).expand([n, -1], false);
                let logits = cells.forward(h);
                let logits = match bias {
                    Some(b) => logits + b,
                    None => logits,
                };
                Some(Categorical::new(&logits, Some(&mask)))
            }
            ManagerHead::WideNarrow(_) => None,
        }
    }

    /// The A2C loss of the trainable decisions of `queues` (every complete
    /// one; the interval under way only bootstraps), unrolling the core over
    /// each environment's decisions from `init`.
    pub fn loss(
        &self,
        queues: &[DecisionQueue],
        init: &LstmState,
        cfg: &A2cConfig,
        gamma: f64,
    ) -> ManagerLoss {
        self.loss_with(queues, init, cfg, gamma, None)
    }

    /// [`Self::loss`], the trunk run by the own kernels when `own` is given
    /// (the [`crate::a2c::rollout::GradPath::RustCore`] path): its forward
    /// and backward outside tch's autograd, the heads, the goal map and the
    /// loss in tch; the returned loss hands the trunk's gradients to the
    /// optimiser ([`with_gradients`]).
    pub(super) fn loss_with(
        &self,
        queues: &[DecisionQueue],
        init: &LstmState,
        cfg: &A2cConfig,
        gamma: f64,
        mut own: Option<&mut dyn OwnTrunk>,
    ) -> ManagerLoss {
        let b = queues.len();
        let k_max = queues
            .iter()
            .map(|q| q.decisions.len())
            .max()
            .unwrap_or(0)
            .max(1);
        let template = &queues
            .iter()
            .find_map(|q| q.decisions.first())
            .expect("invariant: every environment has an interval under way")
            .input;
        let mut input = CellInput::new(template_grid(template).0, template_grid(template).1, 0);
        let n = k_max * b;
        let (mut reset, mut rewards, mut discounts, mut values, mut weights) = (
            vec![0f32; n],
            vec![0f32; n],
            vec![0f32; n],
            vec![0f32; n],
            vec![0f32; n],
        );
        let (mut wide, mut narrow) = (vec![0i64; n], vec![0i64; n]);
        let window = match &self.head {
            ManagerHead::WideNarrow(h) => h.window_len(),
            ManagerHead::Feudal { .. } => 0,
        };
        let mut local = vec![0f32; n * window * WINDOW_CHANNELS];
        let mut valid = vec![true; n * window];
        for k in 0..k_max {
            for (e, q) in queues.iter().enumerate() {
                let i = k * b + e;
                let d = q
                    .decisions
                    .get(k)
                    .unwrap_or_else(|| q.decisions.last().expect("non-empty"));
                input.extend_one(&d.input, 0);
                if k >= q.decisions.len() {
                    continue;
                }
                reset[i] = f32::from(u8::from(d.reset_before));
                values[i] = d.value;
                wide[i] = d.wide;
                narrow[i] = d.narrow;
                if window > 0 {
                    local[i * window * WINDOW_CHANNELS..(i + 1) * window * WINDOW_CHANNELS]
                        .copy_from_slice(&d.local);
                    valid[i * window..(i + 1) * window].copy_from_slice(&d.valid);
                }
                if d.complete {
                    let (r, disc) =
                        interval_transition(&d.rewards, gamma, d.episode_ended, d.final_value);
                    rewards[i] = r;
                    discounts[i] = disc;
                    weights[i] = 1.0;
                } else {
                    // The interval under way only bootstraps: its value is
                    // the next value of the last complete decision, and
                    // its own TD error must be 0 so that no advantage
                    // flows back through λ (reward V, discount 0).
                    rewards[i] = d.value;
                }
            }
        }
        let (k, bb) = (k_max as i64, b as i64);
        let (hs, cs, h) = match own.as_deref_mut() {
            Some(own) => {
                let resets: Vec<bool> = reset.iter().map(|&r| r > 0.5).collect();
                let (hs, cs) = own.unroll(&input, &floats(&init.h), &floats(&init.c), &resets, b);
                let shape = [k, bb, self.hidden];
                let h = Tensor::from_slice(&hs)
                    .view([k * bb, self.hidden])
                    .set_requires_grad(true);
                (
                    h.detach().view(shape),
                    Tensor::from_slice(&cs).view(shape),
                    h,
                )
            }
            None => {
                let features = self.trunk.features(&input).view([k, bb, -1]);
                let (hs, cs) = self.trunk.unroll_states(
                    &features,
                    init,
                    &Tensor::from_slice(&reset).view([k, bb]),
                );
                let h = hs.view([k * bb, self.hidden]);
                (hs, cs, h)
            }
        };
        let value = self.value.forward(&h).squeeze_dim(-1);
        let bias = self.goal_bias(&input);
        let (log_prob, entropy) = match &self.head {
            ManagerHead::Feudal { .. } => {
                let pi = self
                    .feudal_policy(&h, bias.as_ref().map(|b| &b.wide))
                    .expect("feudal head");
                (pi.log_prob(&Tensor::from_slice(&wide)), pi.entropy())
            }
            ManagerHead::WideNarrow(head) => head.terms(
                &h,
                bias.as_ref().map(|b| &b.wide),
                bias.as_ref().and_then(|b| b.windows.as_ref()),
                &Tensor::from_slice(&local).view([k * bb, -1]),
                &Tensor::from_slice(&valid).view([k * bb, -1]),
                &Tensor::from_slice(&wide),
                &Tensor::from_slice(&narrow),
            ),
        };
        let (adv, ret) = advantages(
            &rewards,
            &values,
            &discounts,
            &vec![0f32; b],
            cfg.gae_lambda as f32,
        );
        let terms = PolicyTerms {
            log_prob,
            entropy,
            value: value.to_kind(Kind::Float),
        };
        let (loss, figures) = a2c_loss(&terms, &adv, &ret, &weights, cfg);
        let loss = match own {
            Some(own) if figures.entries > 0.0 => {
                // One backward through tch's part (heads, goal map) to `h`
                // and to its own weights; the trunk's gradients from `h`'s.
                let rest: Vec<Tensor> = self
                    .head_parameters()
                    .into_iter()
                    .filter(Tensor::requires_grad)
                    .collect();
                let inputs: Vec<&Tensor> = std::iter::once(&h).chain(&rest).collect();
                let grads = Tensor::run_backward(&[&loss], &inputs, false, false);
                let dh = if grads[0].defined() {
                    floats(&grads[0])
                } else {
                    vec![0f32; (k * bb * self.hidden) as usize]
                };
                let params: Vec<Tensor> = self
                    .trunk
                    .encoder_parameters()
                    .into_iter()
                    .chain(self.trunk.core_parameters())
                    .chain(rest)
                    .collect();
                let grads: Vec<Tensor> = own
                    .unroll_backward(&dh, b)
                    .into_iter()
                    .chain(grads[1..].iter().map(Tensor::shallow_clone))
                    .collect();
                with_gradients(&loss, &params, &grads)
            }
            _ => loss,
        };
        // The state before each environment's interval under way.
        let mut next_h = Vec::with_capacity(b);
        let mut next_c = Vec::with_capacity(b);
        for (e, q) in queues.iter().enumerate() {
            let len = q.decisions.len();
            if len >= 2 {
                next_h.push(hs.get((len - 2) as i64).get(e as i64).detach());
                next_c.push(cs.get((len - 2) as i64).get(e as i64).detach());
            } else {
                next_h.push(init.h.get(e as i64).detach());
                next_c.push(init.c.get(e as i64).detach());
            }
        }
        let next = LstmState {
            h: Tensor::stack(&next_h, 0),
            c: Tensor::stack(&next_c, 0),
        };
        ManagerLoss {
            loss,
            figures,
            next_init: next,
        }
    }
}

fn template_grid(input: &CellInput) -> (usize, usize) {
    input.grid()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::a2c::input::BASE_CHANNELS;
    use tch::nn::OptimizerConfig;
    use tch::{Device, Kind};

    /// Planes of a `w × h` grid of floor with a ball at `(x, y)`.
    fn ball_at(w: i64, h: i64, x: i64, y: i64) -> Tensor {
        let planes = Tensor::zeros([1, BASE_CHANNELS as i64, h, w], (Kind::Float, Device::Cpu));
        let _ = planes.get(0).get(sim::Object::Floor as i64).fill_(1.0);
        let _ = planes
            .get(0)
            .get(sim::Object::Floor as i64)
            .get(y)
            .get(x)
            .fill_(0.0);
        let _ = planes
            .get(0)
            .get(sim::Object::Ball as i64)
            .get(y)
            .get(x)
            .fill_(1.0);
        planes
    }

    /// A goal map (seeded by `seed`) trained for `iters` Adam steps to name
    /// the cell of a ball at `(x, y)` of a `w × h` grid of floor.
    fn map_trained_on_a_ball(
        seed: u64,
        w: i64,
        h: i64,
        (x, y): (i64, i64),
        iters: usize,
    ) -> GoalMap {
        let vs = nn::VarStore::new(Device::Cpu);
        let map = crate::seeding::init_seeded(seed, || {
            GoalMap::new(&vs.root(), BASE_CHANNELS as i64, 8, None)
        });
        let mut opt = nn::Adam::default().build(&vs, 1e-2).unwrap();
        for _ in 0..iters {
            let logp = map
                .logits_dense(&ball_at(w, h, x, y))
                .log_softmax(-1, Kind::Float);
            opt.backward_step(&(-logp.get(0).get(y * w + x)));
        }
        map
    }

    #[test]
    fn an_untrained_goal_map_leaves_the_goal_head_as_it_is() {
        let vs = nn::VarStore::new(Device::Cpu);
        let map = crate::seeding::init_seeded(1, || {
            GoalMap::new(&vs.root(), BASE_CHANNELS as i64, 8, Some(&[3, 10, 24]))
        });
        let logits = map.logits_dense(&ball_at(7, 7, 3, 3));
        assert_eq!(logits.size(), [1, 3]);
        assert_eq!(logits.abs().max().double_value(&[]), 0.0);
    }

    /// `π^ω` reads the map at the candidates' cells (`y · width + x`): a
    /// ball at `(5, 2)` of a 7-wide grid, trained as in the test below,
    /// scores highest at candidate cell 19 among candidates elsewhere.
    #[test]
    fn the_candidates_read_the_map_at_their_own_cells() {
        let (w, h) = (7, 6);
        let mut map = map_trained_on_a_ball(4, w, h, (5, 2), 40);
        let cells = [3u32, 19, 30, 40];
        let planes = ball_at(w, h, 5, 2);
        let all = map.logits_dense(&planes);
        map.cells = Some(Tensor::from_slice(&cells.map(i64::from)));
        let some = map.logits_dense(&planes);
        for (k, &c) in cells.iter().enumerate() {
            assert_eq!(
                some.get(0).get(k as i64).double_value(&[]),
                all.get(0).get(i64::from(c)).double_value(&[])
            );
        }
        assert_eq!(some.get(0).argmax(0, false).int64_value(&[]), 1);
    }

    /// What makes the map the Manager's lever: being paid for naming the
    /// ball's cell with the ball in one place teaches it to name the ball's
    /// cell wherever the ball lies, which a head over the core's output
    /// has to learn place by place.
    #[test]
    fn naming_a_ball_learnt_in_one_place_transfers_to_another() {
        let (w, h) = (9, 9);
        let map = map_trained_on_a_ball(3, w, h, (2, 2), 60);
        let cell = |x: i64, y: i64| y * w + x;
        let p = map
            .logits_dense(&ball_at(w, h, 6, 5))
            .softmax(-1, Kind::Float)
            .get(0)
            .get(cell(6, 5))
            .double_value(&[]);
        assert!(
            p > 10.0 / (w * h) as f64,
            "the ball's cell elsewhere has probability {p}, uniform {}",
            1.0 / (w * h) as f64
        );
    }

    /// With the windows of `V`, a ball near a wide goal (not on it) draws
    /// `π^ω` to that goal and `π^n` to the ball's slot: the map trained to
    /// name a ball at one place, then a ball elsewhere, in the window of
    /// one candidate of three.
    #[test]
    fn the_map_over_windows_points_both_choices_at_a_ball_beside_a_wide_goal() {
        let (w, h) = (13i64, 13i64);
        let layout = sim::Layout::parse(
            "open",
            &(0..h)
                .map(|y| {
                    (0..w)
                        .map(|x| match (x, y) {
                            (0, _) | (_, 0) => '#',
                            _ if x == w - 1 || y == h - 1 => '#',
                            (1, 1) => '>',
                            (1, 11) => 'E',
                            _ => '.',
                        })
                        .collect::<String>()
                })
                .collect::<Vec<_>>()
                .join("\n"),
        )
        .expect("an open room");
        let window = Window::new(5, &layout);
        let cell = |x: i64, y: i64| (y * w + x) as u32;
        let candidates = [cell(3, 3), cell(9, 8), cell(3, 9)];
        let map = map_trained_on_a_ball(3, w, h, (2, 2), 60).with_windows(&window, &candidates);
        // The ball two cells right and one down of the second candidate.
        let bias = map.bias_dense(&ball_at(w, h, 11, 9));
        assert_eq!(bias.wide.size(), [1, 3]);
        assert_eq!(bias.wide.get(0).argmax(0, false).int64_value(&[]), 1);
        let windows = bias.windows.expect("windows");
        let narrow = WideNarrowHead::narrow_bias(&windows, &Tensor::from_slice(&[1i64]));
        let ball_slot = window
            .slot_of(candidates[1], cell(11, 9))
            .expect("in the window");
        assert_eq!(
            narrow.get(0).argmax(0, false).int64_value(&[]),
            ball_slot as i64
        );
        // π^ω's logit is the log-sum-exp of π^n's over the valid slots.
        let valid = window.valid(candidates[1]);
        let lse = (0..window.len())
            .filter(|&k| valid[k])
            .map(|k| narrow.get(0).get(k as i64).double_value(&[]).exp())
            .sum::<f64>()
            .ln();
        assert!((bias.wide.get(0).get(1).double_value(&[]) - lse).abs() < 1e-4);
    }

    #[test]
    fn interval_returns_equal_the_closed_form() {
        // A hand-made interval of 4 steps: three step penalties and a ball.
        let rewards = [-0.01f32, -0.01, 0.99, -0.01];
        let (r, d) = interval_transition(&rewards, 0.9, false, None);
        assert!((r - 0.96).abs() < 1e-6);
        assert!((d - 0.9f32.powi(4)).abs() < 1e-7);
        // The Manager's advantage over two intervals: Â_0 = r_0 + γ^4 V_1 −
        // V_0 + γ^4 λ (r_1 + γ^2 · 0 − V_1) with the second ending the
        // episode after 2 steps.
        let (r1, d1) = interval_transition(&[0.5, 1.0], 0.9, true, None);
        assert_eq!(d1, 0.0);
        let (v0, v1, lambda) = (0.3f32, 0.7f32, 0.95f32);
        let (adv, ret) = advantages(&[r, r1], &[v0, v1], &[d, d1], &[0.0], lambda);
        let a1 = r1 - v1;
        let a0 = r + d * v1 - v0 + d * lambda * a1;
        assert!((adv[1] - a1).abs() < 1e-6);
        assert!((adv[0] - a0).abs() < 1e-6);
        assert!((ret[0] - (a0 + v0)).abs() < 1e-6);
        // Cut by the step limit after 2 steps: the final state's value
        // goes on, discounted by γ².
        let (r2, d2) = interval_transition(&[0.5, 1.0], 0.9, true, Some(2.0));
        assert!((r2 - (1.5 + 0.81 * 2.0)).abs() < 1e-6);
        assert_eq!(d2, 0.0);
    }
}
