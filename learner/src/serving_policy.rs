//! Policies the learner process can run on a [`BatchEnvironment`]'s
//! observations: the uniform-random null policy (the pipeline benchmark's
//! baseline workload) and the A2C-LSTM actor-critic's forward pass.
//!
//! [`BatchEnvironment`]: crate::batch_env::BatchEnvironment

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use tch::{Kind, nn};

use crate::a2c::input::CellInput;
use crate::a2c::net::{ActorCritic, ActorCriticConfig, LstmState};
use crate::batch_env::ObsView;

/// Chooses one action per environment.
pub trait Policy {
    /// Short name for reports.
    fn name(&self) -> &'static str;
    /// Writes `actions[i]` for every environment of `obs`.
    fn act(&mut self, obs: &ObsView<'_>, actions: &mut [u8]);
}

/// Uniformly random actions: the null policy.
#[derive(Debug)]
pub struct RandomPolicy {
    rng: SmallRng,
    num_actions: u8,
}

impl RandomPolicy {
    /// Actions in `0..num_actions`, seeded.
    pub fn new(num_actions: usize, seed: u64) -> RandomPolicy {
        RandomPolicy {
            rng: SmallRng::seed_from_u64(seed),
            num_actions: num_actions.clamp(1, 255) as u8,
        }
    }
}

impl Policy for RandomPolicy {
    fn name(&self) -> &'static str {
        "random"
    }
    fn act(&mut self, _obs: &ObsView<'_>, actions: &mut [u8]) {
        for a in actions.iter_mut() {
            *a = self.rng.random_range(0..self.num_actions);
        }
    }
}

/// The actor-critic's forward pass, sampling from its policy. Weights are
/// freshly initialised (seeded) unless loaded; the LSTM state is carried
/// across steps and reset where an episode ended.
#[derive(Debug)]
pub struct ActorCriticPolicy {
    _vs: nn::VarStore,
    net: ActorCritic,
    state: LstmState,
    /// Draws the sampled actions (see [`crate::seeding`]).
    rng: SmallRng,
}

impl ActorCriticPolicy {
    /// A network for `num_envs` environments on `width × height` grids.
    pub fn new(
        cfg: &ActorCriticConfig,
        num_envs: usize,
        width: usize,
        height: usize,
        seed: u64,
    ) -> ActorCriticPolicy {
        let (vs, net) = crate::seeding::init_seeded(seed, || {
            let vs = nn::VarStore::new(tch::Device::Cpu);
            let net = ActorCritic::new(&vs.root(), cfg, width, height);
            (vs, net)
        });
        let state = net.zero_state(num_envs as i64);
        ActorCriticPolicy {
            _vs: vs,
            net,
            state,
            rng: SmallRng::seed_from_u64(seed),
        }
    }
}

impl Policy for ActorCriticPolicy {
    fn name(&self) -> &'static str {
        "actor-critic"
    }
    fn act(&mut self, obs: &ObsView<'_>, actions: &mut [u8]) {
        tch::no_grad(|| {
            let done: Vec<f32> = obs
                .meta
                .iter()
                .map(|m| f32::from(u8::from(m.done())))
                .collect();
            let state = self.state.reset_done(&tch::Tensor::from_slice(&done));
            let mut input = CellInput::new(obs.width, obs.height, 0);
            input.push_obs(obs, None);
            let out = self.net.step(&input, &state);
            let probs = out.logits.softmax(-1, Kind::Float);
            let sampled = crate::seeding::sample_categorical(&mut self.rng, &probs, false);
            for (a, s) in actions.iter_mut().zip(sampled) {
                *a = s;
            }
            self.state = out.state;
        });
    }
}
