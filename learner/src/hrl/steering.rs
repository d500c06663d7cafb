//! `π_g` steering world-graph traversals in stochastic worlds, fine-tuned
//! while the agent trains (section 4.3: in MultiGoal-Stochastic "the
//! traversal is executed by `π_g`", which is "fine-tuned" on the task).
//!
//! Each edge of a steered traversal is a goal episode of `π_g` towards the
//! edge's end node (its waypoint, [`super::traversal::Traversal::waypoint`]).
//! While training, `π_g` samples its actions and every steered step joins
//! a rollout of its own: reward `goal_reward` when the step reaches the
//! waypoint, `step_penalty` otherwise; the goal episode ends at the
//! waypoint, at the edge's time limit, or when the traversal or the
//! environment's episode ends. After each training iteration of the agent,
//! `π_g` takes one A2C update of its own hyperparameters
//! ([`crate::gcp::GcpConfig::a2c`]) on the steps it steered. Environments
//! that were not steering at a step are in the rollout with weight 0.
//! Evaluation steers greedily with the fine-tuned weights.

use tch::Tensor;

use crate::a2c::input::{GoalMarks, NO_GOAL};
use crate::a2c::net::LstmState;
use crate::a2c::optim::Adam;
use crate::a2c::rollout::{GradPath, Rollout, bootstrap_values};
use crate::a2c::{A2cConfig, LossFigures};
use crate::batch_env::ObsView;
use crate::gcp::GoalConditionedPolicy;

/// The fine-tuning of `π_g` on the steps it steered.
#[derive(Debug)]
pub struct Steering {
    rollout: Rollout,
    opt: Adam,
    cfg: A2cConfig,
    goal_reward: f32,
    step_penalty: f32,
}

/// How one environment's steered step went (see [`Steering::book`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Leg {
    /// Not steering at this step.
    Idle,
    /// Steering, still heading for the waypoint.
    Going,
    /// Reached the waypoint.
    Reached,
    /// The goal episode ended without the waypoint (time limit, the
    /// traversal or the episode ended).
    Ended,
}

impl Steering {
    /// Fine-tuning of `gcp` for `num_envs` environments, its update on
    /// gradient path `path` (the agent's), with the Worker's goal reward and
    /// step penalty.
    pub fn new(
        gcp: &GoalConditionedPolicy,
        num_envs: usize,
        path: GradPath,
        goal_reward: f32,
        step_penalty: f32,
    ) -> Steering {
        let cfg = gcp.config().a2c();
        Steering {
            rollout: Rollout::new(path, num_envs),
            opt: Adam::new(&[("pi_g", gcp.var_store())], cfg.learning_rate),
            cfg,
            goal_reward,
            step_penalty,
        }
    }

    /// Starts the rollout of a training iteration from `state`.
    pub fn start(&mut self, state: &LstmState) {
        self.rollout.start(state);
    }

    /// One sampled step of `π_g` towards `goals` (`NO_GOAL` where not
    /// steering), recorded for the update: the logits and the next state.
    pub fn act(
        &mut self,
        gcp: &GoalConditionedPolicy,
        obs: &ObsView<'_>,
        goals: &[u32],
        state: &LstmState,
    ) -> (Tensor, LstmState) {
        let out = self
            .rollout
            .act(gcp.network(), obs, Some(GoalMarks::one(goals)), state);
        (out.logits, out.state)
    }

    /// Books the outcome of the step [`Self::act`] chose, one [`Leg`] per
    /// environment.
    pub fn book(&mut self, actions: &[u8], legs: &[Leg]) {
        let rewards: Vec<f32> = legs
            .iter()
            .map(|l| match l {
                Leg::Idle => 0.0,
                Leg::Reached => self.goal_reward,
                Leg::Going | Leg::Ended => self.step_penalty,
            })
            .collect();
        let dones: Vec<bool> = legs.iter().map(|l| *l != Leg::Going).collect();
        let weights: Vec<f32> = legs
            .iter()
            .map(|l| if *l == Leg::Idle { 0.0 } else { 1.0 })
            .collect();
        self.rollout.record(actions, &rewards, &dones, &weights);
    }

    /// The update after a training iteration, if `π_g` steered any step:
    /// bootstrapped at `obs` towards `goals` from `state`, then one clipped
    /// Adam step.
    pub fn update(
        &mut self,
        gcp: &GoalConditionedPolicy,
        obs: &ObsView<'_>,
        goals: &[u32],
        state: &LstmState,
    ) -> Option<LossFigures> {
        if self.rollout.steps() == 0 || !self.rollout.weights.iter().any(|&w| w > 0.0) {
            return None;
        }
        self.rollout.bootstrap = if goals.iter().all(|&g| g == NO_GOAL) {
            vec![0.0; goals.len()]
        } else {
            bootstrap_values(gcp.network(), obs, Some(GoalMarks::one(goals)), state)
        };
        let (loss, figures) = self.rollout.loss(gcp.network(), &self.cfg);
        self.opt.backward_step(&loss, self.cfg.grad_clip_norm);
        Some(figures)
    }

    /// The optimiser's moments, for a checkpoint.
    pub fn optimiser(&self) -> &Adam {
        &self.opt
    }

    /// The optimiser, to restore a checkpoint.
    pub fn optimiser_mut(&mut self) -> &mut Adam {
        &mut self.opt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_leg_outcomes_give_the_goal_episode_rewards() {
        let layout = sim::Maze::Small.layout(false);
        let gcp = GoalConditionedPolicy::new(&crate::gcp::GcpConfig::default(), &layout, 1, 3, 0)
            .unwrap();
        let mut s = Steering::new(&gcp, 4, GradPath::RustCore, 1.0, -0.01);
        s.start(&gcp.network().zero_state(4));
        s.book(
            &[0, 1, 2, 0],
            &[Leg::Idle, Leg::Going, Leg::Reached, Leg::Ended],
        );
        assert_eq!(s.rollout.rewards, vec![0.0, -0.01, 1.0, -0.01]);
        assert_eq!(s.rollout.dones, vec![1.0, 0.0, 1.0, 1.0]);
        assert_eq!(s.rollout.weights, vec![0.0, 1.0, 1.0, 1.0]);
    }
}
