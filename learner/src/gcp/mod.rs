//! The curiosity-driven goal-conditioned policy `π_g = π(a_t | s_t, g)` of
//! Shang et al. 2019 (arXiv:1907.00664), section 3.2 ("Curiosity-Driven
//! Goal-Conditioned Agent").
//!
//! - **Goals.** "We train such an A2C-based goal-conditioned policy by
//!   sampling goals using the end points of random walks with reasonable
//!   length from a given starting state": every environment holds a goal
//!   cell 1 to [`GcpConfig::goal_walk_len`] moves from the agent's current
//!   cell by path distance in training, the end of a random walk of that
//!   many moves in evaluation ([`GoalSampler`]). A *goal episode* ends
//!   when the agent stands on the goal (reward [`GcpConfig::goal_reward`],
//!   a success), at the time limit [`GcpConfig::goal_time_limit`] (a
//!   failure) or when the environment's own episode ends; the next goal is
//!   drawn from wherever the agent then stands.
//! - **Curiosity.** "We leverage the readily available action reconstruction
//!   errors from the generative decoder as intrinsic reward signals": with a
//!   latent model at hand, each step's reward gains
//!   `curiosity_coef · min(−log p_θ(a_t | S, Z), CURIOSITY_CAP_NATS)`
//!   computed on the policy's own rollout
//!   ([`LatentModel::reconstruction_error`]), weighted so that a step's net
//!   reward stays negative ([`GcpConfig::curiosity_coef`]).
//! - **Learner.** A2C-LSTM ([`ActorCritic`] with the goal marked in an extra
//!   input channel), GAE advantages ([`crate::a2c::advantages`]), an entropy bonus,
//!   gradient-norm clipping and one Adam step per rollout.
//! - **Trajectories.** The finished goal episodes' `(s_t, a_t)` sequences
//!   are kept for the latent model ([`GoalConditionedPolicy::take_trajectories`]):
//!   `π_g`'s rollouts are one of the two trajectory sources of world graph
//!   discovery (section 3.1).
//!
//! The environments come through [`BatchEnvironment`], so `π_g` trains
//! in-process or over the shared-memory pipeline unchanged. Everything is
//! deterministic for a seed: the weights' initialisation
//! ([`crate::seeding::init_seeded`]),
//! and goals and actions drawn from the policy's own seeded RNGs.
//!
//! ## Files
//! - this one: `π_g` ([`GoalConditionedPolicy`]), its A2C update with the
//!   curiosity reward ([`GoalConditionedPolicy::train_iteration`]) and its
//!   evaluation;
//! - `goals.rs`: goal sampling ([`GoalSampler`]) and the goal episodes of
//!   a batch (their rewards, ends and recorded trajectories);
//! - `goal_distance.rs`: the distance of the training goals, which the
//!   discovery loop's goal curriculum (not the paper's) moves;
//! - `config.rs`: [`GcpConfig`] and its validation;
//! - `checkpointing.rs`: the weights, saved and loaded.

mod checkpointing;
mod config;
mod goal_distance;
mod goals;

use rand::SeedableRng;
use rand::rngs::SmallRng;
use serde::Serialize;
use sim::Layout;
use tch::nn::{self, OptimizerConfig};
use tch::{Device, Kind, Tensor};

pub use self::config::GcpConfig;
pub use self::goals::GoalSampler;
use self::goals::{GoalBook, agent_pose};
use crate::a2c::input::{CellInput, GoalMarks, mask};
use crate::a2c::net::{ActorCritic, LstmState};
use crate::a2c::rollout::{GradPath, Rollout, bootstrap_truncated, bootstrap_values};
use crate::a2c::{LossFigures, PhaseTimes};
use crate::batch_env::{BatchEnvironment, ObsView};
use crate::error::{ConfigError, LearnerError};
use crate::vae::{AgentPose, LatentModel, Trajectory, TrajectoryBatch};

/// What one training iteration (one rollout, one update) measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GcpStats {
    /// Fraction of the goal episodes finished in this rollout that reached
    /// their goal (0 when none finished).
    pub success_rate: f64,
    /// Goal episodes finished in this rollout (successes, time-outs and
    /// episodes cut by the environment).
    pub goals_finished: usize,
    /// Mean length in steps of the successful goal episodes (0 when none).
    pub mean_steps_to_goal: f64,
    /// `L_π` (see [`GoalConditionedPolicy::train_iteration`]).
    pub policy_loss: f64,
    /// `L_V`.
    pub value_loss: f64,
    /// Mean policy entropy per step, in nats.
    pub entropy: f64,
    /// Mean curiosity bonus per step (already weighted by the coefficient;
    /// 0 without a latent model).
    pub mean_curiosity: f64,
}

/// The goal-conditioned policy `π_g`: an A2C-LSTM actor-critic with its own
/// weights and Adam optimiser, the goal episodes of the batch it trains on,
/// and the trajectories it collected for the latent model.
pub struct GoalConditionedPolicy {
    cfg: GcpConfig,
    vs: nn::VarStore,
    net: ActorCritic,
    opt: nn::Optimizer,
    num_envs: usize,
    width: usize,
    height: usize,
    /// Goals of training rollouts.
    sampler: GoalSampler,
    /// Goals of evaluations, drawn apart so evaluating leaves training's
    /// goal sequence unchanged.
    eval_sampler: GoalSampler,
    /// Draws the sampled actions.
    action_rng: SmallRng,
    book: GoalBook,
    /// LSTM state carried across rollouts (detached between updates).
    state: LstmState,
    /// The rollout being collected (its buffers are reused).
    rollout: Rollout,
    /// Object kinds of the maze `π_g` was trained on: their input planes
    /// carry trained weights, the others only their initial draw
    /// ([`Self::trained_kinds`]).
    trained_kinds: [bool; sim::object::NUM_OBJECTS],
}

impl std::fmt::Debug for GoalConditionedPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GoalConditionedPolicy")
            .field("cfg", &self.cfg)
            .field("num_envs", &self.num_envs)
            .field("grid", &(self.width, self.height))
            .field("pending_trajectories", &self.book.finished.len())
            .finish_non_exhaustive()
    }
}

/// The object kinds present in `layout` (floor and wall always).
fn kinds_of(layout: &Layout) -> [bool; sim::object::NUM_OBJECTS] {
    let mut kinds = [false; sim::object::NUM_OBJECTS];
    kinds[sim::Object::Floor as usize] = true;
    kinds[sim::Object::Wall as usize] = true;
    for &c in &layout.cells {
        if let Some(k) = kinds.get_mut(c as usize) {
            *k = true;
        }
    }
    kinds
}

/// Largest reconstruction error (nats) that counts as curiosity: twice the
/// error of a uniform guess among the three moves (`2 ln 3`).
pub const CURIOSITY_CAP_NATS: f64 = 2.2;

/// Seeds of the policy's RNGs, derived from the one seed.
const EVAL_SEED_SALT: u64 = 0x5EED_E7A1;
const ACTION_SEED_SALT: u64 = 0xAC7_1015;

impl GoalConditionedPolicy {
    /// A fresh `π_g` for `num_envs` environments of `layout` with
    /// `num_actions` actions; weights initialised from `seed`.
    pub fn new(
        cfg: &GcpConfig,
        layout: &Layout,
        num_envs: usize,
        num_actions: usize,
        seed: u64,
    ) -> Result<Self, LearnerError> {
        cfg.validate()?;
        if num_envs == 0 {
            return Err(ConfigError::new("num_envs", "must be at least 1").into());
        }
        if num_actions == 0 {
            return Err(ConfigError::new("num_actions", "must be at least 1").into());
        }
        let (vs, net) = crate::seeding::init_seeded(seed, || {
            let vs = nn::VarStore::new(Device::Cpu);
            let net = ActorCritic::new(
                &vs.root(),
                &cfg.network(num_actions),
                layout.width,
                layout.height,
            );
            (vs, net)
        });
        let opt = nn::Adam::default().build(&vs, cfg.learning_rate)?;
        let state = net.zero_state(num_envs as i64);
        Ok(GoalConditionedPolicy {
            cfg: cfg.clone(),
            vs,
            net,
            opt,
            num_envs,
            width: layout.width,
            height: layout.height,
            sampler: GoalSampler::new(layout, seed),
            eval_sampler: GoalSampler::new(layout, seed ^ EVAL_SEED_SALT),
            action_rng: SmallRng::seed_from_u64(seed ^ ACTION_SEED_SALT),
            book: GoalBook {
                record_missed_legs: cfg.record_missed_legs,
                ..GoalBook::new(
                    cfg.goal_walk_len,
                    cfg.goal_time_limit(cfg.goal_walk_len),
                    true,
                )
            },
            state,
            rollout: Rollout::new(cfg.grad_path, num_envs),
            trained_kinds: kinds_of(layout),
        })
    }

    /// Records that `π_g` was trained on `maze` (a policy loaded for
    /// another layout of the same size: a discovery's `π_g` serving a
    /// Door-Key run of its maze).
    pub fn set_trained_on(&mut self, maze: &Layout) {
        self.trained_kinds = kinds_of(maze);
    }

    /// Which object kinds (indexed by code) the maze `π_g` was trained on
    /// holds: the input planes of the others were never non-zero in
    /// training, so their first-layer weights are still the initial random
    /// draw. Floor and wall always count.
    pub fn trained_kinds(&self) -> [bool; sim::object::NUM_OBJECTS] {
        self.trained_kinds
    }

    /// Starts a round of the discovery loop from the weights alone: goal
    /// samplers and the action RNG reseeded from `seed`, the LSTM state
    /// zeroed, open goal episodes dropped and a fresh Adam optimiser (its
    /// moments are not part of a checkpoint). A round is then a function of
    /// the checkpoint and `seed`, so a resumed run repeats an uninterrupted
    /// one exactly.
    pub fn start_round(&mut self, seed: u64) -> Result<(), LearnerError> {
        self.sampler.rng = SmallRng::seed_from_u64(seed);
        self.eval_sampler.rng = SmallRng::seed_from_u64(seed ^ EVAL_SEED_SALT);
        self.action_rng = SmallRng::seed_from_u64(seed ^ ACTION_SEED_SALT);
        self.state = self.net.zero_state(self.num_envs as i64);
        self.book.episodes.clear();
        self.book.finished.clear();
        self.opt = nn::Adam::default().build(&self.vs, self.cfg.learning_rate)?;
        Ok(())
    }

    /// The configuration.
    pub fn config(&self) -> &GcpConfig {
        &self.cfg
    }

    /// The network.
    pub fn network(&self) -> &ActorCritic {
        &self.net
    }

    /// The trajectories of the goal episodes finished since the last call,
    /// oldest first; each has at least one action.
    pub fn take_trajectories(&mut self) -> Vec<Trajectory> {
        std::mem::take(&mut self.book.finished)
    }

    /// The batch must be the one the policy was built for.
    fn check_shape(&self, obs: &ObsView<'_>) -> Result<(), LearnerError> {
        if obs.num_envs() != self.num_envs || obs.width != self.width || obs.height != self.height {
            return Err(LearnerError::ShapeMismatch {
                expected_envs: self.num_envs,
                expected_width: self.width,
                expected_height: self.height,
                envs: obs.num_envs(),
                width: obs.width,
                height: obs.height,
            });
        }
        Ok(())
    }

    /// One action per environment from `logits` `[B, A]`: sampled from
    /// `softmax(logits)` with the policy's RNG, or the argmax when `greedy`.
    fn choose_actions(&mut self, logits: &Tensor, greedy: bool) -> Vec<u8> {
        let probs = tch::no_grad(|| logits.softmax(-1, Kind::Float));
        crate::seeding::sample_categorical(&mut self.action_rng, &probs, greedy)
    }

    /// One greedy step of `π_g` on any batch of observations of this
    /// policy's grid (its size need not be the training batch's): the
    /// argmax action of every environment towards its goal cell, and the
    /// next LSTM state. Start from [`ActorCritic::zero_state`], as a goal
    /// episode does. Used to follow `π_g` along world-graph edges
    /// ([`crate::edge_refinement`]).
    pub fn greedy_step(
        &mut self,
        obs: &ObsView<'_>,
        goals: &[u32],
        state: &LstmState,
    ) -> Result<(Vec<u8>, LstmState), LearnerError> {
        if obs.width != self.width || obs.height != self.height || goals.len() != obs.num_envs() {
            return Err(LearnerError::ShapeMismatch {
                expected_envs: goals.len(),
                expected_width: self.width,
                expected_height: self.height,
                envs: obs.num_envs(),
                width: obs.width,
                height: obs.height,
            });
        }
        let mut input = CellInput::new(obs.width, obs.height, 1);
        input.push_obs(obs, Some(GoalMarks::one(goals)));
        let out = tch::no_grad(|| self.net.step(&input, state));
        let actions = self.choose_actions(&out.logits, true);
        Ok((actions, out.state))
    }

    /// One A2C update of `π_g` from a rollout of [`GcpConfig::rollout_len`]
    /// steps on `env` (section 3.2; A2C as in section 4.1).
    ///
    /// Per step `t` and environment `b`, with goal `g`:
    /// - reward `r_t = goal_reward · [s_{t+1} = g] + step_penalty +
    ///   curiosity_coef · (−log p_θ(a_t | S, Z))`, the last term only when
    ///   `curiosity` is given (the decoder's action reconstruction error on
    ///   the rollout, cut at the environment's episode ends);
    /// - `done_t = 1` when the goal episode ended (goal reached, time limit,
    ///   or the environment's episode ended); the LSTM state is reset there;
    /// - advantages `Â_t` and returns `R_t = Â_t + V(s_t)` by GAE
    ///   ([`crate::a2c::advantages`]) over `[T, B]`, bootstrapped with
    ///   `V(s_T)` `[B]`.
    ///
    /// Loss, every term a mean over `[T, B]`:
    /// `L = L_π + value_coef · L_V − entropy_coef · H`, with
    /// `L_π = −mean(Â_t · log π(a_t | s_t, g))`,
    /// `L_V = ½ · mean((R_t − V(s_t))²)`,
    /// `H = mean(−Σ_a π(a | s_t, g) · log π(a | s_t, g))`;
    /// the logits are `[T, B, A]`. Gradients are back-propagated through the
    /// rollout's LSTM steps, clipped to [`GcpConfig::grad_clip_norm`], and
    /// applied by one Adam step.
    pub fn train_iteration(
        &mut self,
        env: &mut dyn BatchEnvironment,
        curiosity: Option<&LatentModel>,
    ) -> Result<GcpStats, LearnerError> {
        let (steps, b) = (self.cfg.rollout_len, self.num_envs);
        {
            let obs = env.observe();
            self.check_shape(&obs)?;
            let restarted = self.book.sync(&mut self.sampler, &obs);
            self.state = self.state.reset_done(&mask(&restarted));
        }
        self.rollout.start(&self.state);
        // Poses s_0 … s_T: T + 1 rows, the last one the state after the
        // rollout, so every action that did not end an episode has its
        // successor state (for the curiosity's trajectories).
        let mut poses = Vec::with_capacity((steps + 1) * b);
        let mut env_ended = Vec::with_capacity(steps * b);
        let (mut finished, mut successes, mut success_steps) = (0usize, 0usize, 0u64);
        let weights = vec![1f32; b];
        for _ in 0..steps {
            let (out, chosen) = {
                let obs = env.observe();
                poses.extend(obs.meta.iter().map(|m| agent_pose(m, self.width)));
                let goals = self.book.goals();
                let out =
                    self.rollout
                        .act(&self.net, &obs, Some(GoalMarks::one(&goals)), &self.state);
                let chosen = self.choose_actions(&out.logits, false);
                (out, chosen)
            };
            let t0 = std::time::Instant::now();
            env.step(&chosen)?;
            PhaseTimes::lap(&mut self.rollout.times.step, t0);
            let obs = env.observe();
            let pursued = self.book.goals();
            let booked = self
                .book
                .advance(&mut self.sampler, &obs, &chosen, &self.cfg);
            let mut rewards: Vec<f32> = booked.iter().map(|s| s.reward).collect();
            let goal_done: Vec<bool> = booked.iter().map(|s| s.goal_done).collect();
            let cut: Vec<usize> = (0..b).filter(|&e| booked[e].cut).collect();
            if !cut.is_empty() {
                bootstrap_truncated(
                    &mut rewards,
                    &self.net,
                    &obs,
                    Some(GoalMarks::one(&pursued)),
                    &out.state,
                    &cut,
                    self.cfg.a2c().gamma,
                );
            }
            for s in &booked {
                env_ended.push(s.env_ended);
                if s.goal_done {
                    finished += 1;
                    if s.success {
                        successes += 1;
                        success_steps += u64::from(s.steps);
                    }
                }
            }
            self.rollout.record(&chosen, &rewards, &goal_done, &weights);
            self.state = out.state.reset_done(&mask(&goal_done));
        }
        {
            let obs = env.observe();
            poses.extend(obs.meta.iter().map(|m| agent_pose(m, self.width)));
            let goals = self.book.goals();
            self.rollout.bootstrap =
                bootstrap_values(&self.net, &obs, Some(GoalMarks::one(&goals)), &self.state);
        }

        let mut mean_curiosity = 0.0;
        if let Some(model) = curiosity {
            let actions: Vec<i64> = self.rollout.actions.clone();
            let bonus = curiosity_bonus(model, &poses, &actions, &env_ended, steps, b)?
                .clamp(0.0, CURIOSITY_CAP_NATS)
                * self.cfg.curiosity_coef;
            mean_curiosity = bonus.mean(Kind::Float).double_value(&[]);
            let bonus: Vec<f32> = Vec::try_from(bonus.flatten(0, -1))?;
            self.rollout.add_to_rewards(&bonus);
        }
        let LossFigures {
            policy_loss,
            value_loss,
            entropy,
            ..
        } = self
            .rollout
            .update(&self.net, &mut self.opt, &self.cfg.a2c());
        // Truncated BPTT: the next rollout starts from this state, detached.
        self.state = self.state.detach();

        Ok(GcpStats {
            success_rate: if finished == 0 {
                0.0
            } else {
                successes as f64 / finished as f64
            },
            goals_finished: finished,
            mean_steps_to_goal: if successes == 0 {
                0.0
            } else {
                success_steps as f64 / successes as f64
            },
            policy_loss,
            value_loss,
            entropy,
            mean_curiosity,
        })
    }

    /// The greedy (argmax) policy's success rate on goals drawn by walks of
    /// `goal_walk_len` moves, without training: every goal drawn during the
    /// first `steps` steps is followed to its end (success, time limit
    /// `goal_time_limit(goal_walk_len)`, or the environment's episode end,
    /// which counts as a failure), so slow goals are not under-counted.
    /// Goals come from a sampler of their own, so training's goals are
    /// unchanged; the environments are stepped, and the next training
    /// iteration starts fresh goal episodes from wherever they stand.
    /// Returns 0 when no goal episode finished.
    pub fn evaluate(
        &mut self,
        env: &mut dyn BatchEnvironment,
        goal_walk_len: usize,
        steps: usize,
    ) -> Result<f64, LearnerError> {
        let mut book = GoalBook::new(
            goal_walk_len.max(1),
            self.cfg.goal_time_limit(goal_walk_len),
            false,
        );
        {
            let obs = env.observe();
            self.check_shape(&obs)?;
            book.sync(&mut self.eval_sampler, &obs);
        }
        let mut state = self.net.zero_state(self.num_envs as i64);
        // Whether environment i's current goal was drawn within the first
        // `steps` steps (so it is counted).
        let mut counted = vec![steps > 0; self.num_envs];
        let (mut finished, mut successes) = (0usize, 0usize);
        let mut t = 0;
        while counted.iter().any(|&c| c) {
            let chosen = {
                let obs = env.observe();
                let (chosen, next) = self.greedy_step(&obs, &book.goals(), &state)?;
                state = next;
                chosen
            };
            env.step(&chosen)?;
            t += 1;
            let obs = env.observe();
            let booked = book.advance(&mut self.eval_sampler, &obs, &chosen, &self.cfg);
            for (i, s) in booked.iter().enumerate() {
                if s.goal_done {
                    if counted[i] {
                        finished += 1;
                        successes += usize::from(s.success);
                    }
                    counted[i] = t < steps;
                }
            }
            let goal_done: Vec<bool> = booked.iter().map(|s| s.goal_done).collect();
            state = state.reset_done(&mask(&goal_done));
        }
        Ok(if finished == 0 {
            0.0
        } else {
            successes as f64 / finished as f64
        })
    }

    /// Chooses how the update gets its gradients (`bench learner`'s baseline
    /// is [`GradPath::Tch`]); the result is the same either way.
    pub fn set_grad_path(&mut self, path: GradPath) {
        self.rollout = Rollout::new(path, self.num_envs);
    }

    /// Where training time went since the last [`Self::take_times`].
    pub fn take_times(&mut self) -> PhaseTimes {
        std::mem::take(&mut self.rollout.times)
    }
}

/// The curiosity bonus of a rollout (section 3.2): the latent model's
/// per-step action reconstruction error `−log p_θ(a_t | S, Z)`, `[T, B]`.
///
/// Environment `b`'s rollout is cut at its episode ends into trajectories
/// `s_{t0} … s_{t1}` (the action that ended an episode has no observed
/// successor and gets no bonus); each trajectory's errors are written back at
/// its steps.
///
/// - `poses`: `[(T + 1) · B]`, `s_t` of environment `b` at `t · B + b`;
/// - `actions`, `env_ended`: `[T · B]`.
fn curiosity_bonus(
    model: &LatentModel,
    poses: &[AgentPose],
    actions: &[i64],
    env_ended: &[bool],
    steps: usize,
    b: usize,
) -> Result<Tensor, LearnerError> {
    // (environment, first step) of each trajectory, in batch order.
    let mut origins = Vec::new();
    let mut trajectories = Vec::new();
    for env in 0..b {
        let mut start = 0;
        for t in 0..=steps {
            let cut = t == steps || env_ended[t * b + env];
            if !cut {
                continue;
            }
            if t > start {
                trajectories.push(Trajectory {
                    states: (start..=t).map(|k| poses[k * b + env]).collect(),
                    actions: (start..t).map(|k| actions[k * b + env] as u8).collect(),
                });
                origins.push((env, start));
            }
            start = t + 1;
        }
    }
    let mut bonus = vec![0f32; steps * b];
    if !trajectories.is_empty() {
        let batch = TrajectoryBatch::new(&trajectories, model.config(), Device::Cpu)?;
        let errors = model
            .reconstruction_error(&batch)
            .to_device(Device::Cpu)
            .to_kind(Kind::Float);
        let max_len = errors.size()[0] as usize;
        let errors: Vec<f32> = Vec::try_from(errors.flatten(0, -1))?;
        let n = trajectories.len();
        for (k, (tau, &(env, start))) in trajectories.iter().zip(&origins).enumerate() {
            for j in 0..tau.actions.len() {
                debug_assert!(j < max_len);
                bonus[(start + j) * b + env] = errors[j * n + k];
            }
        }
    }
    Ok(Tensor::from_slice(&bonus).view([steps as i64, b as i64]))
}

#[cfg(test)]
mod tests {
    use sim::{BallSpawn, EnvConfig, Task};

    use super::goals::tests::room;
    use super::*;
    use crate::batch_env::InProcess;

    #[test]
    fn training_is_deterministic_for_a_seed_and_weights_round_trip() -> Result<(), LearnerError> {
        let layout = room();
        let env_cfg = EnvConfig {
            balls: BallSpawn::Layout,
            ..EnvConfig::for_task(Task::MultiGoal, &layout)
        };
        let cfg = GcpConfig {
            rollout_len: 4,
            hidden: 16,
            conv_channels: [4, 8],
            ..GcpConfig::default()
        };
        let run =
            || -> Result<(Vec<GcpStats>, Vec<Trajectory>, GoalConditionedPolicy), LearnerError> {
                let mut env = InProcess::new(layout.clone(), env_cfg, 4, 11, 1)?;
                let mut gcp = GoalConditionedPolicy::new(&cfg, &layout, 4, 3, 11)?;
                let stats = (0..5)
                    .map(|_| gcp.train_iteration(&mut env, None))
                    .collect::<Result<Vec<_>, _>>()?;
                let trajectories = gcp.take_trajectories();
                Ok((stats, trajectories, gcp))
            };
        let (stats_a, taus_a, gcp_a) = run()?;
        let (stats_b, taus_b, mut gcp_b) = run()?;
        assert_eq!(stats_a, stats_b);
        assert_eq!(taus_a, taus_b);

        let path = std::env::temp_dir().join(format!("gcp-roundtrip-{}.ot", std::process::id()));
        gcp_a.save(&path)?;
        let mut fresh = GoalConditionedPolicy::new(&cfg, &layout, 4, 3, 99)?;
        fresh.load(&path)?;
        let _ = std::fs::remove_file(&path);
        let weights = |p: &GoalConditionedPolicy| {
            let mut v: Vec<(String, Tensor)> = p.var_store().variables().into_iter().collect();
            v.sort_by(|a, b| a.0.cmp(&b.0));
            v
        };
        for ((name, a), (_, b)) in weights(&gcp_a).iter().zip(weights(&fresh).iter()) {
            assert!(a.equal(b), "{name} differs after load");
        }
        // A batch of another size is refused.
        let mut wrong = InProcess::new(layout.clone(), env_cfg, 3, 11, 1)?;
        assert!(gcp_b.train_iteration(&mut wrong, None).is_err());
        Ok(())
    }
}
