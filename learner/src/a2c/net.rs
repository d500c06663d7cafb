//! The A2C-LSTM networks: a CNN encoder and an LSTM core (the *trunk*),
//! then heads (Shang et al. 2019, section 4.1: "A2C models both a value
//! function V(s_t) ... and a policy π"; the Manager, the Worker and `π_g`
//! are all A2C-LSTMs at different time scales). Encoder / core / heads are
//! split as Sample Factory does, so the Manager and the Worker reuse the
//! trunk under their own heads and `π_g` initialisation copies it
//! ([`crate::hrl::init`]).
//!
//! Encoder: 3×3 conv (stride 1) → ReLU → 3×3 conv (stride 2) → ReLU →
//! linear → ReLU. The first convolution runs either densely on one-hot
//! planes (the plain path, [`Trunk::features_dense`]) or as an
//! embedding-bag over the active cells ([`Trunk::features`], see
//! [`crate::a2c::input`]); both use the same weights.
//!
//! Variable names (`encoder.conv1`, `encoder.conv2`, `encoder.fc`,
//! `core.weight_ih_l0`, ...) are those of tch's `nn::conv2d`, `nn::linear`
//! and `nn::lstm`, created in the same order with the same initialisers, so
//! checkpoints of earlier versions load unchanged.

use serde::{Deserialize, Serialize};
use tch::nn::{self, Module};
use tch::{Device, Kind, Tensor};

use super::input::{BASE_CHANNELS, CellInput, FirstLayer, first_conv};

/// Sizes of an actor-critic (CPU-sized defaults).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ActorCriticConfig {
    /// Output channels of the two 3×3 convolutions (the second has stride 2).
    pub conv_channels: [i64; 2],
    /// Width of the encoder's output and of the LSTM core.
    pub hidden: i64,
    /// Actions of the policy head.
    pub num_actions: i64,
    /// Goal planes of the input: 0 (the A2C baseline), 1 (`π_g`, the
    /// Feudal Worker), 2 (the Wide-then-Narrow Worker: `g_w`, `g_n`).
    pub goal_planes: usize,
}

impl Default for ActorCriticConfig {
    fn default() -> Self {
        ActorCriticConfig {
            conv_channels: [16, 32],
            hidden: 128,
            num_actions: 3,
            goal_planes: 0,
        }
    }
}

impl ActorCriticConfig {
    /// Input channels.
    pub fn in_channels(&self) -> i64 {
        (BASE_CHANNELS + self.goal_planes) as i64
    }
}

/// LSTM state of a batch, `h` and `c` of shape `[B, hidden]`.
#[derive(Debug)]
pub struct LstmState {
    /// Hidden state.
    pub h: Tensor,
    /// Cell state.
    pub c: Tensor,
}

impl LstmState {
    /// Zero state for `batch` environments.
    pub fn zeros(batch: i64, hidden: i64) -> LstmState {
        LstmState {
            h: Tensor::zeros([batch, hidden], (Kind::Float, Device::Cpu)),
            c: Tensor::zeros([batch, hidden], (Kind::Float, Device::Cpu)),
        }
    }

    /// Zeroes the state of environments whose episode just ended
    /// (`done[i] = 1`): CleanRL's `(1 - done)` trick, written once.
    pub fn reset_done(&self, done: &Tensor) -> LstmState {
        let keep: Tensor = done
            .to_kind(Kind::Float)
            .neg()
            .g_add_scalar(1.0)
            .unsqueeze(1);
        LstmState {
            h: &self.h * &keep,
            c: &self.c * &keep,
        }
    }

    /// A copy detached from the autograd graph (truncated BPTT).
    pub fn detach(&self) -> LstmState {
        LstmState {
            h: self.h.detach(),
            c: self.c.detach(),
        }
    }

    /// The rows `index` (`[K]` int64) of the batch.
    pub fn select(&self, index: &Tensor) -> LstmState {
        LstmState {
            h: self.h.index_select(0, index),
            c: self.c.index_select(0, index),
        }
    }

    /// Writes `rows` into the rows `index` of this state.
    pub fn scatter(&mut self, index: &Tensor, rows: &LstmState) {
        self.h = self.h.index_copy(0, index, &rows.h);
        self.c = self.c.index_copy(0, index, &rows.c);
    }

    /// A copy sharing no storage.
    pub fn copy(&self) -> LstmState {
        LstmState {
            h: self.h.copy(),
            c: self.c.copy(),
        }
    }
}

/// The LSTM core, one cell step at a time (`lstm_cell`), with the weights
/// `nn::lstm` would create.
#[derive(Debug)]
struct LstmCore {
    w_ih: Tensor,
    w_hh: Tensor,
    b_ih: Tensor,
    b_hh: Tensor,
}

impl LstmCore {
    fn new(p: &nn::Path, input: i64, hidden: i64) -> LstmCore {
        let gates = 4 * hidden;
        let init = nn::init::DEFAULT_KAIMING_UNIFORM;
        LstmCore {
            w_ih: p.var("weight_ih_l0", &[gates, input], init),
            w_hh: p.var("weight_hh_l0", &[gates, hidden], init),
            b_ih: p.var("bias_ih_l0", &[gates], nn::Init::Const(0.)),
            b_hh: p.var("bias_hh_l0", &[gates], nn::Init::Const(0.)),
        }
    }

    fn step(&self, x: &Tensor, state: &LstmState) -> LstmState {
        let (h, c) = x.lstm_cell(
            &[&state.h, &state.c],
            &self.w_ih,
            &self.w_hh,
            Some(&self.b_ih),
            Some(&self.b_hh),
        );
        LstmState { h, c }
    }
}

/// Encoder + LSTM core.
#[derive(Debug)]
pub struct Trunk {
    conv1: nn::Conv2D,
    conv2: nn::Conv2D,
    fc: nn::Linear,
    core: LstmCore,
    hidden: i64,
    in_channels: i64,
    width: usize,
    height: usize,
}

impl Trunk {
    /// A trunk under `p` (`p / "encoder"`, `p / "core"`) for `width ×
    /// height` grids with `in_channels` input planes.
    pub fn new(
        p: &nn::Path,
        in_channels: i64,
        conv_channels: [i64; 2],
        hidden: i64,
        width: usize,
        height: usize,
    ) -> Trunk {
        let [c1, c2] = conv_channels;
        let conv = |stride| nn::ConvConfig {
            stride,
            padding: 1,
            ..Default::default()
        };
        let (h2, w2) = ((height as i64 + 1) / 2, (width as i64 + 1) / 2);
        let enc = p / "encoder";
        let conv1 = nn::conv2d(&enc / "conv1", in_channels, c1, 3, conv(1));
        let conv2 = nn::conv2d(&enc / "conv2", c1, c2, 3, conv(2));
        let fc = nn::linear(&enc / "fc", c2 * h2 * w2, hidden, Default::default());
        let core = LstmCore::new(&(p / "core"), hidden, hidden);
        Trunk {
            conv1,
            conv2,
            fc,
            core,
            hidden,
            in_channels,
            width,
            height,
        }
    }

    /// The first convolution's kernel `[out, C, 3, 3]`.
    pub fn conv1_weight(&self) -> Tensor {
        self.conv1.ws.shallow_clone()
    }

    /// The encoder's parameters, in order: the first convolution's weight
    /// and bias, the second's, the linear layer's (what
    /// [`crate::a2c::encoder::RustEncoder`] runs).
    pub fn encoder_parameters(&self) -> [Tensor; 6] {
        let bias = |b: &Option<Tensor>| {
            b.as_ref()
                .expect("invariant: the encoder's layers have biases")
                .shallow_clone()
        };
        [
            self.conv1.ws.shallow_clone(),
            bias(&self.conv1.bs),
            self.conv2.ws.shallow_clone(),
            bias(&self.conv2.bs),
            self.fc.ws.shallow_clone(),
            bias(&self.fc.bs),
        ]
    }

    /// The core's parameters (`weight_ih`, `weight_hh`, `bias_ih`, `bias_hh`).
    pub fn core_parameters(&self) -> [Tensor; 4] {
        let c = &self.core;
        [&c.w_ih, &c.w_hh, &c.b_ih, &c.b_hh].map(Tensor::shallow_clone)
    }

    /// Output channels of the two convolutions.
    pub fn conv_channels(&self) -> [i64; 2] {
        [self.conv1.ws.size()[0], self.conv2.ws.size()[0]]
    }

    /// Width of the features and of the core.
    pub fn hidden(&self) -> i64 {
        self.hidden
    }

    /// Input planes.
    pub fn in_channels(&self) -> i64 {
        self.in_channels
    }

    /// Grid `(width, height)`.
    pub fn grid(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Zero core state for `batch` environments.
    pub fn zero_state(&self, batch: i64) -> LstmState {
        LstmState::zeros(batch, self.hidden)
    }

    fn after_conv1(&self, y: Tensor) -> Tensor {
        self.conv2
            .forward(&y.relu())
            .relu()
            .flatten(1, -1)
            .apply(&self.fc)
            .relu()
    }

    /// Encoder features `[N, hidden]` of a [`CellInput`] (the fast path).
    pub fn features(&self, input: &CellInput) -> Tensor {
        self.after_conv1(first_conv(
            input,
            &self.conv1.ws,
            self.conv1.bs.as_ref(),
            FirstLayer::Gather,
        ))
    }

    /// Encoder features `[N, hidden]` of dense one-hot planes `[N, C, H, W]`
    /// (the plain path).
    pub fn features_dense(&self, x: &Tensor) -> Tensor {
        self.after_conv1(self.conv1.forward(x))
    }

    /// One core step.
    pub fn step(&self, features: &Tensor, state: &LstmState) -> LstmState {
        self.core.step(features, state)
    }

    /// The core over a sequence: `features` `[K, B, hidden]`, the state
    /// reset before step `k` where `reset_before[k, b] = 1` (`[K, B]`
    /// float). Returns the hidden states `[K, B, hidden]` and the state
    /// after the last step.
    pub fn unroll(
        &self,
        features: &Tensor,
        init: &LstmState,
        reset_before: &Tensor,
    ) -> (Tensor, LstmState) {
        let (hs, cs) = self.unroll_states(features, init, reset_before);
        let last = hs.size()[0] - 1;
        let state = LstmState {
            h: hs.get(last),
            c: cs.get(last),
        };
        (hs, state)
    }

    /// [`Self::unroll`] with the cell states too: `(h, c)`, `[K, B, hidden]`
    /// each, the state after every step.
    pub fn unroll_states(
        &self,
        features: &Tensor,
        init: &LstmState,
        reset_before: &Tensor,
    ) -> (Tensor, Tensor) {
        let steps = features.size()[0];
        let mut state = LstmState {
            h: init.h.shallow_clone(),
            c: init.c.shallow_clone(),
        };
        let mut hs = Vec::with_capacity(steps as usize);
        let mut cs = Vec::with_capacity(steps as usize);
        for k in 0..steps {
            state = self
                .core
                .step(&features.get(k), &state.reset_done(&reset_before.get(k)));
            hs.push(state.h.shallow_clone());
            cs.push(state.c.shallow_clone());
        }
        (Tensor::stack(&hs, 0), Tensor::stack(&cs, 0))
    }
}

/// What an actor-critic outputs for one step.
#[derive(Debug)]
pub struct ActorCriticOutput {
    /// Action logits `[B, A]`.
    pub logits: Tensor,
    /// State values `[B]`.
    pub value: Tensor,
    /// The core's next state.
    pub state: LstmState,
}

/// A trunk with a policy head over a fixed action set and a value head:
/// `π_g`, the A2C baseline and the Worker.
#[derive(Debug)]
pub struct ActorCritic {
    trunk: Trunk,
    policy: nn::Linear,
    value: nn::Linear,
    cfg: ActorCriticConfig,
}

impl ActorCritic {
    /// Builds the network under `p` for grids of `width × height`.
    pub fn new(p: &nn::Path, cfg: &ActorCriticConfig, width: usize, height: usize) -> ActorCritic {
        let trunk = Trunk::new(
            p,
            cfg.in_channels(),
            cfg.conv_channels,
            cfg.hidden,
            width,
            height,
        );
        let policy = nn::linear(
            p / "policy",
            cfg.hidden,
            cfg.num_actions,
            Default::default(),
        );
        let value = nn::linear(p / "value", cfg.hidden, 1, Default::default());
        ActorCritic {
            trunk,
            policy,
            value,
            cfg: cfg.clone(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ActorCriticConfig {
        &self.cfg
    }

    /// The encoder and core.
    pub fn trunk(&self) -> &Trunk {
        &self.trunk
    }

    /// Zero core state for `batch` environments.
    pub fn zero_state(&self, batch: i64) -> LstmState {
        self.trunk.zero_state(batch)
    }

    /// Policy logits `[.., A]` and values `[..]` of core outputs `[.., hidden]`.
    pub fn heads(&self, h: &Tensor) -> (Tensor, Tensor) {
        (
            self.policy.forward(h),
            self.value.forward(h).squeeze_dim(-1),
        )
    }

    /// One step on a [`CellInput`] of `B` observations (the fast path).
    pub fn step(&self, input: &CellInput, state: &LstmState) -> ActorCriticOutput {
        let state = self.trunk.step(&self.trunk.features(input), state);
        let (logits, value) = self.heads(&state.h);
        ActorCriticOutput {
            logits,
            value,
            state,
        }
    }

    /// One step from encoder features `[B, hidden]`: the core and the heads
    /// (the encoder ran elsewhere, [`crate::a2c::encoder::RustEncoder`]).
    pub fn step_features(&self, features: &Tensor, state: &LstmState) -> ActorCriticOutput {
        let state = self.trunk.step(features, state);
        let (logits, value) = self.heads(&state.h);
        ActorCriticOutput {
            logits,
            value,
            state,
        }
    }

    /// The heads' parameters (policy weight and bias, value weight and bias).
    pub fn head_parameters(&self) -> [Tensor; 4] {
        let bias = |b: &Option<Tensor>| {
            b.as_ref()
                .expect("invariant: the heads have biases")
                .shallow_clone()
        };
        [
            self.policy.ws.shallow_clone(),
            bias(&self.policy.bs),
            self.value.ws.shallow_clone(),
            bias(&self.value.bs),
        ]
    }

    /// One step on dense one-hot planes `[B, C, H, W]` (the plain path).
    pub fn forward(&self, obs: &Tensor, state: &LstmState) -> ActorCriticOutput {
        let state = self.trunk.step(&self.trunk.features_dense(obs), state);
        let (logits, value) = self.heads(&state.h);
        ActorCriticOutput {
            logits,
            value,
            state,
        }
    }
}

/// Multiply-adds of one trunk forward pass per observation, by layer:
/// `(first convolution dense, rest)`; with `bag` (mean table rows per
/// output position) the first convolution's fast-path additions instead.
pub fn trunk_macs(trunk: &Trunk, bag: Option<f64>) -> (f64, f64) {
    let (w, h) = trunk.grid();
    let hw = (w * h) as f64;
    let [c1, c2] = [
        trunk.conv1.ws.size()[0] as f64,
        trunk.conv2.ws.size()[0] as f64,
    ];
    let cin = trunk.in_channels as f64;
    let hw2 = (w.div_ceil(2) * h.div_ceil(2)) as f64;
    let hidden = trunk.hidden as f64;
    let conv1 = match bag {
        Some(b) => hw * c1 * b / 2.0,
        None => hw * c1 * cin * 9.0,
    };
    let conv2 = hw2 * c2 * c1 * 9.0;
    let fc = c2 * hw2 * hidden;
    let lstm = 4.0 * hidden * 2.0 * hidden;
    (conv1, conv2 + fc + lstm)
}

/// Model FLOPs per env-step of an every-step learner with `heads` outputs
/// (policy + value): one forward with its backward (twice the forward,
/// except the first convolution, which needs no input gradient). Table rows
/// of the gather-and-sum first layer count one FLOP each (an addition), a
/// multiply-add two. The same on both gradient paths: they compute the same
/// values.
pub fn flops_per_env_step(trunk: &Trunk, num_actions: i64) -> f64 {
    let heads = trunk.hidden as f64 * (num_actions as f64 + 1.0);
    // Ten table rows per position (nine taps, and the agent's, goals' and
    // key's few).
    let (c1, rest) = trunk_macs(trunk, Some(10.0));
    let fwd = 2.0 * (c1 + rest + heads);
    fwd + 2.0 * c1 + 4.0 * (rest + heads)
}
