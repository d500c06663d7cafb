//! An A2C-LSTM learner: one actor-critic network ([`ActorCritic`]), its
//! Adam optimiser and the `[T, B]` rollout it learns from (section 4.1:
//! "A2C models both a value function ... and a policy π guided by
//! advantage-based policy gradient").
//!
//! The flat A2C baseline ([`crate::hrl::baseline::A2cAgent`]) is one of
//! them; the Worker of the Feudal and Wide-then-Narrow agents is one with
//! goal planes on its input ([`crate::hrl::worker`]). Both act, bootstrap
//! and update through the methods here, so the two share the rollout
//! storage and the loss ([`Rollout::loss`]).

use tch::{Tensor, nn};

use super::input::{CellInput, GoalMarks, goal_planes};
use super::net::{ActorCritic, ActorCriticConfig, ActorCriticOutput, LstmState};
use super::optim::Adam;
use super::rollout::{GradPath, Rollout, bootstrap_truncated, bootstrap_values};
use super::{A2cConfig, LossFigures, PhaseTimes};
use crate::batch_env::ObsView;

/// A network, its optimiser and its training rollout (module docs).
#[derive(Debug)]
pub struct A2cLearner {
    width: usize,
    height: usize,
    /// The network's variables.
    pub vs: nn::VarStore,
    /// The actor-critic.
    pub net: ActorCritic,
    /// Its optimiser.
    pub opt: Adam,
    /// The rollout of the training iteration under way.
    pub rollout: Rollout,
}

impl A2cLearner {
    /// A fresh learner of the network `net_cfg` on a `width × height`
    /// grid, its optimiser's parameters named `name` and stepping at
    /// `learning_rate`, its rollout of `envs` environments on gradient
    /// path `grad_path`. The weights are drawn from libtorch's generator:
    /// build it under [`crate::seeding::init_seeded`].
    pub fn new(
        net_cfg: &ActorCriticConfig,
        width: usize,
        height: usize,
        name: &str,
        learning_rate: f64,
        grad_path: GradPath,
        envs: usize,
    ) -> A2cLearner {
        let vs = nn::VarStore::new(tch::Device::Cpu);
        let net = ActorCritic::new(&vs.root(), net_cfg, width, height);
        let opt = Adam::new(&[(name, &vs)], learning_rate);
        A2cLearner {
            width,
            height,
            vs,
            net,
            opt,
            rollout: Rollout::new(grad_path, envs),
        }
    }

    /// Rebuilds the (empty) rollout of `envs` environments with gradient
    /// path `path`.
    pub fn set_grad_path(&mut self, path: GradPath, envs: usize) {
        self.rollout = Rollout::new(path, envs);
    }

    /// One step of the network on `obs` (towards `goals`, if any) from
    /// `state`: recorded in the rollout when `train`, else without
    /// gradient.
    pub fn act(
        &mut self,
        obs: &ObsView<'_>,
        goals: Option<GoalMarks<'_>>,
        state: &LstmState,
        train: bool,
    ) -> ActorCriticOutput {
        if train {
            self.rollout.act(&self.net, obs, goals, state)
        } else {
            let input = self.input(obs, goals);
            tch::no_grad(|| self.net.step(&input, state))
        }
    }

    /// The network's input of `obs` with `goals` on its goal planes.
    pub fn input(&self, obs: &ObsView<'_>, goals: Option<GoalMarks<'_>>) -> CellInput {
        let mut input = CellInput::new(self.width, self.height, goal_planes(goals));
        input.push_obs(obs, goals);
        input
    }

    /// Adds `γ · V(s_final)` to the `rewards` of the environments `cut`,
    /// whose episodes the step limit cut (truncation is not termination),
    /// from their final states (towards `goals`).
    #[allow(clippy::too_many_arguments)]
    pub fn bootstrap_truncated(
        &self,
        rewards: &mut [f32],
        obs: &ObsView<'_>,
        goals: Option<GoalMarks<'_>>,
        state: &LstmState,
        cut: &[usize],
        gamma: f64,
    ) {
        bootstrap_truncated(rewards, &self.net, obs, goals, state, cut, gamma);
    }

    /// The rollout's bootstrap values `V(s_T)` at `obs` (towards `goals`).
    pub fn bootstrap(
        &mut self,
        obs: &ObsView<'_>,
        goals: Option<GoalMarks<'_>>,
        state: &LstmState,
    ) {
        self.rollout.bootstrap = bootstrap_values(&self.net, obs, goals, state);
    }

    /// The A2C update on the rollout; the time it took goes to `times`.
    pub fn update(&mut self, cfg: &A2cConfig, times: &mut PhaseTimes) -> LossFigures {
        let t0 = std::time::Instant::now();
        let (loss, figures) = self.rollout.loss(&self.net, cfg);
        let t1 = PhaseTimes::lap(&mut times.loss, t0);
        self.opt.backward_step(&loss, cfg.grad_clip_norm);
        PhaseTimes::lap(&mut times.backward, t1);
        figures
    }

    /// The network's weights named `<prefix>/<variable>`, sorted by name.
    pub fn weights(&self, prefix: &str) -> Vec<(String, Tensor)> {
        named_variables(prefix, &self.vs)
    }

    /// The optimiser's moments named `<prefix>-adam/...`.
    pub fn moments(&self, prefix: &str) -> Vec<(String, Tensor)> {
        self.opt
            .state()
            .into_iter()
            .map(|(k, t)| (format!("{prefix}-{k}"), t))
            .collect()
    }
}

/// The variables of `vs` named `<prefix>/<variable>`, sorted by name (a
/// checkpoint's tensor names).
pub fn named_variables(prefix: &str, vs: &nn::VarStore) -> Vec<(String, Tensor)> {
    let mut v: Vec<(String, Tensor)> = vs
        .variables()
        .into_iter()
        .map(|(k, t)| (format!("{prefix}/{k}"), t))
        .collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

/// Copies the tensors named `<prefix>/<variable>` of `loaded` (a
/// checkpoint's) into the variables of `vs`; an error names a tensor that
/// is missing or of another shape.
pub fn load_variables(
    prefix: &str,
    vs: &nn::VarStore,
    loaded: &[(String, Tensor)],
) -> Result<(), String> {
    tch::no_grad(|| {
        for (k, mut t) in vs.variables() {
            let key = format!("{prefix}/{k}");
            let src = loaded
                .iter()
                .find(|(n, _)| *n == key)
                .map(|(_, t)| t)
                .ok_or_else(|| format!("no tensor {key}"))?;
            if src.size() != t.size() {
                return Err(format!(
                    "{key} has shape {:?}, expected {:?}",
                    src.size(),
                    t.size()
                ));
            }
            t.copy_(src);
        }
        Ok(())
    })
}

/// The tensors of `loaded` named `<prefix>-<rest>`, as `<rest>` (an
/// optimiser's state saved by [`A2cLearner::moments`]).
pub fn moments_of(prefix: &str, loaded: &[(String, Tensor)]) -> Vec<(String, Tensor)> {
    let prefix = format!("{prefix}-");
    loaded
        .iter()
        .filter_map(|(k, t)| {
            k.strip_prefix(&prefix)
                .map(|s| (s.to_string(), t.shallow_clone()))
        })
        .collect()
}
