//! The A2C-LSTM actor-critic: CNN encoder → LSTM core → policy and value
//! heads (Shang et al. 2019, section 4.1: "A2C models both a value function
//! V(s_t) ... and a policy π"; the Manager, the Worker and `π_g` are all
//! A2C-LSTMs). Split encoder / core / heads as Sample Factory does.
//!
//! Input: the bird's-eye observation, one-hot encoded by [`encode_obs`] to
//! `[B, C, H, W]`: one channel per object kind, four for the agent (one per
//! facing), one for the carried key, and optionally one marking a goal cell
//! (for the goal-conditioned policy `π_g`, section 3.2).

use serde::{Deserialize, Serialize};
use tch::nn::{self, Module, RNN};
use tch::{Device, Kind, Tensor};

use crate::batch_env::ObsView;

/// Channels per object kind (`sim::object::NUM_OBJECTS`).
const OBJECT_CHANNELS: usize = sim::object::NUM_OBJECTS;
/// Object channels + 4 agent facings + 1 carried key.
pub const BASE_CHANNELS: usize = OBJECT_CHANNELS + 5;

/// Sizes of the actor-critic (CPU-sized defaults).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ActorCriticConfig {
    /// Output channels of the two 3×3 convolutions (the second has stride 2).
    pub conv_channels: [i64; 2],
    /// Width of the LSTM core.
    pub hidden: i64,
    /// Actions of the task.
    pub num_actions: i64,
    /// Whether a goal channel is part of the input (`π_g`).
    pub goal_channel: bool,
}

impl Default for ActorCriticConfig {
    fn default() -> Self {
        ActorCriticConfig {
            conv_channels: [16, 32],
            hidden: 128,
            num_actions: 3,
            goal_channel: false,
        }
    }
}

impl ActorCriticConfig {
    /// Input channels.
    pub fn in_channels(&self) -> i64 {
        (BASE_CHANNELS + usize::from(self.goal_channel)) as i64
    }
}

/// One-hot encodes a batch: `[B, C, H, W]` float32. `goals[i]`, when given,
/// marks environment `i`'s goal cell in the last channel.
pub fn encode_obs(obs: &ObsView<'_>, goals: Option<&[u32]>) -> Tensor {
    let (n, h, w) = (obs.num_envs(), obs.height, obs.width);
    let c = BASE_CHANNELS + usize::from(goals.is_some());
    let hw = h * w;
    let mut buf = vec![0f32; n * c * hw];
    for i in 0..n {
        let base = i * c * hw;
        for (j, &code) in obs.env_cells(i).iter().enumerate() {
            let k = (code as usize).min(OBJECT_CHANNELS - 1);
            buf[base + k * hw + j] = 1.0;
        }
        let m = &obs.meta[i];
        let agent = m.y as usize * w + m.x as usize;
        if agent < hw {
            buf[base + (OBJECT_CHANNELS + (m.dir as usize & 3)) * hw + agent] = 1.0;
        }
        if m.carrying == sim::Object::Key as u8 {
            buf[base + (OBJECT_CHANNELS + 4) * hw..base + (OBJECT_CHANNELS + 5) * hw].fill(1.0);
        }
        if let Some(g) = goals {
            let gc = g[i] as usize;
            if gc < hw {
                buf[base + BASE_CHANNELS * hw + gc] = 1.0;
            }
        }
    }
    Tensor::from_slice(&buf).view([n as i64, c as i64, h as i64, w as i64])
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
}

/// What the network outputs for one step.
#[derive(Debug)]
pub struct ActorCriticOutput {
    /// Action logits `[B, A]`.
    pub logits: Tensor,
    /// State values `[B]`.
    pub value: Tensor,
    /// The core's next state.
    pub state: LstmState,
    /// The encoder's features `[B, hidden]` (what `π_g` initialisation transfers).
    pub features: Tensor,
}

/// CNN encoder + LSTM core + policy/value heads.
#[derive(Debug)]
pub struct ActorCritic {
    encoder: nn::Sequential,
    core: nn::LSTM,
    policy: nn::Linear,
    value: nn::Linear,
    cfg: ActorCriticConfig,
}

impl ActorCritic {
    /// Builds the network under `p` for grids of `width × height`.
    pub fn new(p: &nn::Path, cfg: &ActorCriticConfig, width: usize, height: usize) -> ActorCritic {
        let [c1, c2] = cfg.conv_channels;
        let conv = |stride| nn::ConvConfig {
            stride,
            padding: 1,
            ..Default::default()
        };
        let (h2, w2) = ((height as i64 + 1) / 2, (width as i64 + 1) / 2);
        let enc = p / "encoder";
        let encoder = nn::seq()
            .add(nn::conv2d(
                &enc / "conv1",
                cfg.in_channels(),
                c1,
                3,
                conv(1),
            ))
            .add_fn(|x| x.relu())
            .add(nn::conv2d(&enc / "conv2", c1, c2, 3, conv(2)))
            .add_fn(|x| x.relu())
            .add_fn(|x| x.flatten(1, -1))
            .add(nn::linear(
                &enc / "fc",
                c2 * h2 * w2,
                cfg.hidden,
                Default::default(),
            ))
            .add_fn(|x| x.relu());
        let core = nn::lstm(p / "core", cfg.hidden, cfg.hidden, Default::default());
        let policy = nn::linear(
            p / "policy",
            cfg.hidden,
            cfg.num_actions,
            Default::default(),
        );
        let value = nn::linear(p / "value", cfg.hidden, 1, Default::default());
        ActorCritic {
            encoder,
            core,
            policy,
            value,
            cfg: cfg.clone(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ActorCriticConfig {
        &self.cfg
    }

    /// Zero core state for `batch` environments.
    pub fn zero_state(&self, batch: i64) -> LstmState {
        LstmState::zeros(batch, self.cfg.hidden)
    }

    /// One step: `obs` `[B, C, H, W]` → logits, value, next state.
    pub fn forward(&self, obs: &Tensor, state: &LstmState) -> ActorCriticOutput {
        let features = self.encoder.forward(obs);
        let nn::LSTMState((h, c)) = self.core.step(
            &features,
            &nn::LSTMState((state.h.unsqueeze(0), state.c.unsqueeze(0))),
        );
        let (h, c) = (h.squeeze_dim(0), c.squeeze_dim(0));
        ActorCriticOutput {
            logits: self.policy.forward(&h),
            value: self.value.forward(&h).squeeze_dim(-1),
            state: LstmState { h, c },
            features,
        }
    }
}
