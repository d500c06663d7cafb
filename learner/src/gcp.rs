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

use std::path::Path;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use shm_schemas::{EnvMeta, flags};
use sim::{AutoReset, BallSpawn, Env, EnvConfig, Layout, Object, Pose, Task};
use tch::nn::{self, OptimizerConfig};
use tch::{Device, Kind, Tensor};

use crate::a2c::input::{CellInput, GoalMarks, mask};
use crate::a2c::net::{ActorCritic, ActorCriticConfig, LstmState};
use crate::a2c::rollout::{GradPath, Rollout, bootstrap_truncated, bootstrap_values};
use crate::a2c::{A2cConfig, LossFigures, PhaseTimes};
use crate::batch_env::{BatchEnvironment, ObsView};
use crate::error::{ConfigError, LearnerError};
use crate::vae::{AgentPose, LatentModel, Trajectory, TrajectoryBatch};

/// Settings of `π_g`. The paper gives no values for `π_g` beyond "A2C" and
/// the step penalty of its tasks (appendix, "every action ... receives a
/// negative reward penalty −0.01"); the defaults are CPU-sized A2C values.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct GcpConfig {
    /// Steps per environment in one rollout, `T` (one update per rollout).
    pub rollout_len: usize,
    /// Moves of the random walk whose end point is the goal.
    pub goal_walk_len: usize,
    /// The goal's time limit in steps per walk move (see [`Self::goal_time_limit`]).
    pub goal_time_factor: usize,
    /// Discount `γ`.
    pub gamma: f64,
    /// GAE `λ`.
    pub gae_lambda: f64,
    /// Weight of the entropy bonus.
    pub entropy_coef: f64,
    /// Weight of the value loss.
    pub value_coef: f64,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Gradients are rescaled to at most this global L2 norm.
    pub grad_clip_norm: f64,
    /// Reward for standing on the goal.
    pub goal_reward: f32,
    /// Reward of every step (the paper's task penalty).
    pub step_penalty: f32,
    /// Weight of the curiosity bonus (the decoder's action reconstruction
    /// error, in nats, capped at [`CURIOSITY_CAP_NATS`]). Keep
    /// `curiosity_coef · CURIOSITY_CAP_NATS` below `|step_penalty|`: every
    /// step then still costs, so curiosity steers *which way* `π_g` goes,
    /// never *whether* it goes to its goal (a larger coefficient made a
    /// trained `π_g` wander: `docs/implementation_details.md`, "Where stage
    /// 1 departs from the paper").
    pub curiosity_coef: f64,
    /// Record for the latent model the goal episodes `π_g` missed as well
    /// (a chain's last leg when it timed out or the environment's episode
    /// ended; the default). Off: a chain is recorded up to its last reached
    /// goal, so `π_g`'s trajectories are navigation, not wandering (see
    /// [`GoalBook`]).
    pub record_missed_legs: bool,
    /// Output channels of the encoder's two convolutions.
    pub conv_channels: [i64; 2],
    /// Width of the encoder's output and of the LSTM core.
    pub hidden: i64,
}

impl Default for GcpConfig {
    fn default() -> Self {
        GcpConfig {
            rollout_len: 16,
            goal_walk_len: 6,
            goal_time_factor: 4,
            gamma: 0.95,
            gae_lambda: 0.95,
            entropy_coef: 0.01,
            value_coef: 0.5,
            learning_rate: 1e-3,
            grad_clip_norm: 0.5,
            goal_reward: 1.0,
            step_penalty: -0.01,
            curiosity_coef: 0.004,
            // Recording only up to the last reached goal did not make `V_p`
            // better (docs/implementation_details.md, "Earlier passes").
            record_missed_legs: true,
            conv_channels: [16, 32],
            hidden: 128,
        }
    }
}

impl GcpConfig {
    /// Steps a goal drawn by a walk of `walk_len` moves may take before it
    /// counts as failed: `goal_time_factor · walk_len`.
    pub fn goal_time_limit(&self, walk_len: usize) -> u32 {
        (self.goal_time_factor * walk_len.max(1)).min(u32::MAX as usize) as u32
    }

    /// The A2C hyperparameters of `π_g`'s update.
    pub fn a2c(&self) -> A2cConfig {
        A2cConfig {
            gamma: self.gamma,
            gae_lambda: self.gae_lambda,
            entropy_coef: self.entropy_coef,
            value_coef: self.value_coef,
            learning_rate: self.learning_rate,
            grad_clip_norm: self.grad_clip_norm,
        }
    }

    /// The actor-critic of `π_g`: goal channel on, `num_actions` outputs.
    pub fn network(&self, num_actions: usize) -> ActorCriticConfig {
        ActorCriticConfig {
            conv_channels: self.conv_channels,
            hidden: self.hidden,
            num_actions: num_actions as i64,
            goal_planes: 1,
        }
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.rollout_len == 0 {
            return Err(ConfigError::new("rollout_len", "must be at least 1"));
        }
        if self.goal_walk_len == 0 {
            return Err(ConfigError::new("goal_walk_len", "must be at least 1"));
        }
        if self.goal_time_factor == 0 {
            return Err(ConfigError::new("goal_time_factor", "must be at least 1"));
        }
        self.a2c().validate("")?;
        if !(self.curiosity_coef >= 0.0 && self.curiosity_coef.is_finite()) {
            return Err(ConfigError::new(
                "curiosity_coef",
                format!("{} must be finite and ≥ 0", self.curiosity_coef),
            ));
        }
        if !self.goal_reward.is_finite() || !self.step_penalty.is_finite() {
            return Err(ConfigError::new(
                "goal_reward",
                "goal_reward and step_penalty must be finite",
            ));
        }
        if self.conv_channels.iter().any(|&c| c < 1) {
            return Err(ConfigError::new(
                "conv_channels",
                format!("{:?} must be ≥ 1", self.conv_channels),
            ));
        }
        if self.hidden < 1 {
            return Err(ConfigError::new(
                "hidden",
                format!("{} must be ≥ 1", self.hidden),
            ));
        }
        Ok(())
    }
}

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

/// Draws goals (section 3.2: "sampling goals using the end points of random
/// walks with reasonable length from a given starting state"), two ways:
///
/// - [`GoalSampler::draw`]: the end cell of a random walk of `n` turn-or-
///   forward actions (mostly one to three moves away). Evaluation draws
///   these, so its figures stay comparable.
/// - [`GoalSampler::draw_by_distance`]: a cell drawn uniformly among those
///   whose shortest path from the agent's cell takes 1 to `n` moves (most
///   of them `n/2` or more away, as there are more cells there). Training
///   draws these: the walk ends were too near for `π_g`'s episodes to need
///   any state between their ends, and [`GoalBook`] chains them besides.
///
/// Both work on the layout's geometry: balls and keys count as lifted and
/// doors as open, since goals explore where the agent can go, not what it
/// may carry. A walk that would end the episode (exit, lava) or ends on its
/// own start cell is redrawn; path distances never pass through or end on
/// such cells.
#[derive(Debug)]
pub struct GoalSampler {
    walker: Env,
    width: usize,
    /// Cells a goal may lie on or a path may pass through.
    open: Vec<bool>,
    rng: SmallRng,
    /// Breadth-first search scratch: distances from the last start.
    distance: Vec<u32>,
    queue: std::collections::VecDeque<usize>,
}

impl GoalSampler {
    /// Redraws before a walk that keeps returning to its start is accepted
    /// as it is (only in a layout where the agent cannot move).
    const MAX_DRAWS: usize = 64;
    /// The actions a walk draws from.
    const MOVES: [u8; 3] = [sim::action::LEFT, sim::action::RIGHT, sim::action::FORWARD];

    /// A sampler over `layout`'s geometry with its own RNG.
    pub fn new(layout: &Layout, seed: u64) -> GoalSampler {
        let mut geometry = layout.clone();
        for cell in &mut geometry.cells {
            *cell = match Object::from_code(*cell) {
                Some(Object::Ball | Object::Key) => Object::Floor as u8,
                Some(Object::DoorClosed | Object::DoorLocked) => Object::DoorOpen as u8,
                _ => *cell,
            };
        }
        let open = geometry
            .cells
            .iter()
            .map(|&c| {
                !matches!(
                    Object::from_code(c),
                    Some(Object::Wall | Object::Exit | Object::Lava) | None
                )
            })
            .collect();
        let cfg = EnvConfig {
            task: Task::MultiGoal,
            max_steps: u32::MAX,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::Off,
        };
        GoalSampler {
            walker: Env::new(geometry, cfg, seed, 0),
            width: layout.width,
            open,
            rng: SmallRng::seed_from_u64(seed),
            distance: vec![u32::MAX; layout.cells.len()],
            queue: std::collections::VecDeque::new(),
        }
    }

    /// The end cell of a random walk of `walk_len` moves from `from`, never
    /// `from`'s own cell (unless no walk leaves it).
    pub fn draw(&mut self, from: Pose, walk_len: usize) -> u32 {
        let start = from.y as usize * self.width + from.x as usize;
        let mut end = start;
        for _ in 0..Self::MAX_DRAWS {
            // A fresh copy per walk: nothing of an earlier walk carries over.
            let mut walk = self.walker.clone();
            walk.teleport(from);
            let mut ended = false;
            for _ in 0..walk_len {
                let action = Self::MOVES[self.rng.random_range(0..Self::MOVES.len())];
                if walk.step_meta(action).done() {
                    ended = true;
                    break;
                }
            }
            if !ended {
                end = walk.cell();
                if end != start {
                    break;
                }
            }
        }
        end as u32
    }

    /// A goal cell 1 to `walk_len` moves from `from` by path distance,
    /// never `from`'s own cell unless the agent cannot move.
    pub fn draw_by_distance(&mut self, from: Pose, walk_len: usize) -> u32 {
        let (w, n) = (self.width, self.open.len());
        let start = from.y as usize * w + from.x as usize;
        self.distance.fill(u32::MAX);
        self.distance[start] = 0;
        self.queue.clear();
        self.queue.push_back(start);
        let far = walk_len.max(1) as u32;
        while let Some(i) = self.queue.pop_front() {
            let d = self.distance[i];
            if d == far {
                continue;
            }
            let (x, y) = (i % w, i / w);
            let next = [
                (x + 1 < w).then(|| i + 1),
                (x > 0).then(|| i - 1),
                (i + w < n).then(|| i + w),
                (y > 0).then(|| i - w),
            ];
            for j in next.into_iter().flatten() {
                if self.open[j] && self.distance[j] == u32::MAX {
                    self.distance[j] = d + 1;
                    self.queue.push_back(j);
                }
            }
        }
        let candidates: Vec<usize> = (0..n)
            .filter(|&i| self.distance[i] != u32::MAX && self.distance[i] >= 1)
            .collect();
        if candidates.is_empty() {
            return start as u32;
        }
        candidates[self.rng.random_range(0..candidates.len())] as u32
    }
}

/// One environment's current goal episode.
#[derive(Debug)]
struct GoalEpisode {
    /// The goal cell `g`.
    goal: u32,
    /// Steps taken towards it.
    steps: u32,
    /// Goals reached before this one within `trajectory`.
    legs: usize,
    /// Actions of `trajectory` up to the last goal it reached (0 before
    /// the first): where the recorded trajectory ends when this leg fails.
    reached: usize,
    /// `(s_t, a_t)` since the chain's first goal was drawn; `states` ends
    /// with the pose the agent stands on now.
    trajectory: Trajectory,
}

/// What one step meant for one environment's goal episode.
#[derive(Debug, Clone, Copy, Default)]
struct GoalStep {
    /// Goal reward plus step penalty (no curiosity).
    reward: f32,
    /// The goal episode ended with this step.
    goal_done: bool,
    /// The environment's own episode ended (or was reset) with this step.
    env_ended: bool,
    /// The agent stands on the goal.
    success: bool,
    /// Length of the goal episode that ended.
    steps: u32,
    /// The environment's step limit cut the goal episode (no goal reached,
    /// its own time limit not up): its target bootstraps from the final
    /// state's value.
    cut: bool,
}

/// The goal episodes of a batch of environments.
///
/// When recording, the goal episodes of one environment are **chained**:
/// a reached goal is followed by the next from where the agent stands,
/// and the trajectory goes on until [`GoalBook::LEGS`] goals were reached
/// or one was missed. A trajectory then crosses rooms, and the states
/// between its ends (the doorways it passes, where one leg turns into the
/// next) carry the information the latent model is meant to find; a
/// single leg's actions follow from its two ends alone. The A2C episodes
/// (rewards, done flags, LSTM resets) are the single goals either way.
///
/// With [`GcpConfig::record_missed_legs`] off, a chain that ends with a
/// missed goal is recorded up to the last goal it reached, and not at all
/// if it reached none: a missed leg is `π_g` wandering, which is what the
/// random walks already give, while the latent model is meant to see
/// `π_g`'s navigation "between close-by states" (section 3.2).
#[derive(Debug)]
struct GoalBook {
    walk_len: usize,
    time_limit: u32,
    episodes: Vec<GoalEpisode>,
    /// Trajectories of finished goal episodes (kept only when recording).
    finished: Vec<Trajectory>,
    record: bool,
    /// Record a chain's missed last leg too ([`GcpConfig::record_missed_legs`]).
    record_missed_legs: bool,
}

fn pose_of(meta: &EnvMeta) -> Pose {
    Pose {
        x: meta.x,
        y: meta.y,
        dir: meta.dir,
    }
}

/// The pose of an observation record, as every trajectory source encodes
/// it ([`AgentPose::from_meta`]).
fn agent_pose(meta: &EnvMeta, width: usize) -> AgentPose {
    AgentPose::from_meta(meta, width)
}

impl GoalBook {
    /// Goals chained into one recorded trajectory.
    const LEGS: usize = 3;

    fn new(walk_len: usize, time_limit: u32, record: bool) -> GoalBook {
        GoalBook {
            walk_len,
            time_limit,
            episodes: Vec::new(),
            finished: Vec::new(),
            record,
            // `GcpConfig::record_missed_legs`'s default: whole chains.
            record_missed_legs: true,
        }
    }

    fn fresh_episode(
        &self,
        sampler: &mut GoalSampler,
        meta: &EnvMeta,
        width: usize,
    ) -> GoalEpisode {
        // Training (recording) goals by path distance, evaluation goals
        // as random-walk ends ([`GoalSampler`]).
        let goal = if self.record {
            sampler.draw_by_distance(pose_of(meta), self.walk_len)
        } else {
            sampler.draw(pose_of(meta), self.walk_len)
        };
        GoalEpisode {
            goal,
            steps: 0,
            legs: 0,
            reached: 0,
            trajectory: Trajectory {
                states: vec![agent_pose(meta, width)],
                actions: Vec::new(),
            },
        }
    }

    /// Makes every environment's goal episode continue from where its agent
    /// stands: draws the first goals, and restarts an episode whose agent
    /// moved since the last step (the environment was stepped by someone
    /// else, e.g. evaluation or path replay in discovery). Returns which
    /// environments restarted (their LSTM state must be reset).
    fn sync(&mut self, sampler: &mut GoalSampler, obs: &ObsView<'_>) -> Vec<bool> {
        let width = obs.width;
        if self.episodes.len() != obs.num_envs() {
            self.episodes = obs
                .meta
                .iter()
                .map(|m| self.fresh_episode(sampler, m, width))
                .collect();
            return vec![true; obs.num_envs()];
        }
        let mut restarted = vec![false; obs.num_envs()];
        for (i, meta) in obs.meta.iter().enumerate() {
            let here = agent_pose(meta, width);
            if self.episodes[i].trajectory.states.last() != Some(&here) {
                self.episodes[i] = self.fresh_episode(sampler, meta, width);
                restarted[i] = true;
            }
        }
        restarted
    }

    /// The goal cells, one per environment.
    fn goals(&self) -> Vec<u32> {
        self.episodes.iter().map(|e| e.goal).collect()
    }

    /// Books the step that took `actions` and produced `obs`: rewards,
    /// goal-episode ends, trajectories, and new goals where one ended.
    fn advance(
        &mut self,
        sampler: &mut GoalSampler,
        obs: &ObsView<'_>,
        actions: &[u8],
        cfg: &GcpConfig,
    ) -> Vec<GoalStep> {
        let width = obs.width;
        let mut out = Vec::with_capacity(self.episodes.len());
        for (i, meta) in obs.meta.iter().enumerate() {
            let env_ended = meta.done() || meta.flags & flags::RESET != 0;
            let here = agent_pose(meta, width);
            let episode = &mut self.episodes[i];
            episode.steps += 1;
            // After an episode end the observation is the next episode's
            // first; arrival is judged on the cell the action led to (the
            // finished episode's final cell). An explicit reset took no
            // action towards the goal.
            let success = if meta.done() {
                meta.end_cell(width) as u32 == episode.goal
            } else {
                !env_ended && here.cell == episode.goal
            };
            if !env_ended {
                episode.trajectory.actions.push(actions[i]);
                episode.trajectory.states.push(here);
            }
            let timed_out = episode.steps >= self.time_limit;
            let goal_done = success || env_ended || timed_out;
            let reward = cfg.step_penalty + if success { cfg.goal_reward } else { 0.0 };
            out.push(GoalStep {
                reward,
                goal_done,
                env_ended,
                success,
                steps: episode.steps,
                cut: meta.truncated() && !success && !timed_out,
            });
            if goal_done {
                let legs = episode.legs + 1;
                let chained = self.record && success && legs < Self::LEGS;
                // The chain goes on: the next goal's steps extend this
                // trajectory.
                let kept = chained.then(|| std::mem::take(&mut episode.trajectory));
                let mut next = self.fresh_episode(sampler, meta, width);
                if let Some(trajectory) = kept {
                    next.legs = legs;
                    next.reached = trajectory.actions.len();
                    next.trajectory = trajectory;
                }
                let mut done = std::mem::replace(&mut self.episodes[i], next);
                if self.record && !chained {
                    if !success && !self.record_missed_legs {
                        // Up to the last goal reached: the missed leg goes.
                        done.trajectory.actions.truncate(done.reached);
                        done.trajectory.states.truncate(done.reached + 1);
                    }
                    if !done.trajectory.actions.is_empty() {
                        self.finished.push(done.trajectory);
                    }
                }
            }
        }
        out
    }
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
            rollout: Rollout::new(
                GradPath::default(),
                num_envs,
                layout.width,
                layout.height,
                1,
            ),
        })
    }

    /// Chooses how the update gets its gradients (the benchmark's plain
    /// path is [`GradPath::PerStep`]); the result is the same either way.
    pub fn set_grad_path(&mut self, path: GradPath) {
        self.rollout = Rollout::new(path, self.num_envs, self.width, self.height, 1);
    }

    /// Where training time went since the last [`Self::take_times`].
    pub fn take_times(&mut self) -> PhaseTimes {
        std::mem::take(&mut self.rollout.times)
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

    /// Training goals from now on lie 1 to `moves` moves away by path
    /// distance, with the time limit `goal_time_limit(moves)`: the step of
    /// a goal-distance curriculum ([`crate::discovery::GoalCurriculum`]).
    /// Open goal episodes keep the goals they have. Evaluation is
    /// unaffected (it names its own distance).
    pub fn set_goal_distance(&mut self, moves: usize) {
        let moves = moves.max(1);
        self.book.walk_len = moves;
        self.book.time_limit = self.cfg.goal_time_limit(moves);
    }

    /// The most moves away a training goal may currently lie
    /// ([`Self::set_goal_distance`]; `goal_walk_len` until it is called).
    pub fn goal_distance(&self) -> usize {
        self.book.walk_len
    }

    /// The configuration.
    pub fn config(&self) -> &GcpConfig {
        &self.cfg
    }

    /// The network.
    pub fn network(&self) -> &ActorCritic {
        &self.net
    }

    /// The weights (the Manager's and Worker's encoders start from them,
    /// section 4).
    pub fn var_store(&self) -> &nn::VarStore {
        &self.vs
    }

    /// Saves the weights, serialised in memory and written atomically
    /// ([`crate::checkpoint`]): a full disk is an error naming the file,
    /// never an abort or a torn file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LearnerError> {
        crate::checkpoint::save_var_store_file(&self.vs, path.as_ref())
    }

    /// Loads weights saved by [`Self::save`] from a policy of the same
    /// configuration.
    pub fn load(&mut self, path: impl AsRef<Path>) -> Result<(), LearnerError> {
        crate::checkpoint::load_var_store_file(&mut self.vs, path.as_ref())
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
    use super::*;
    use crate::batch_env::InProcess;

    const ROOM: &str = "#######\n#.....#\n#.....#\n#..>..#\n#.....#\n#....E#\n#######\n";

    fn room() -> Layout {
        Layout::parse("room", ROOM).expect("valid layout")
    }

    #[test]
    fn default_config_is_valid_and_rejects_unknown_fields() {
        let cfg = GcpConfig::default();
        assert_eq!(cfg.validate(), Ok(()));
        assert_eq!(cfg.goal_time_limit(6), 24);
        let parsed: GcpConfig =
            serde_json::from_str(r#"{"goal_walk_len": 3}"#).expect("partial config parses");
        assert_eq!(
            parsed,
            GcpConfig {
                goal_walk_len: 3,
                ..GcpConfig::default()
            }
        );
        assert!(serde_json::from_str::<GcpConfig>(r#"{"goal_walk": 3}"#).is_err());
        for bad in [
            GcpConfig {
                rollout_len: 0,
                ..GcpConfig::default()
            },
            GcpConfig {
                gamma: 1.5,
                ..GcpConfig::default()
            },
            GcpConfig {
                learning_rate: 0.0,
                ..GcpConfig::default()
            },
            GcpConfig {
                curiosity_coef: -1.0,
                ..GcpConfig::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn goals_are_walk_ends_away_from_the_agent_within_reach() {
        let layout = room();
        let mut sampler = GoalSampler::new(&layout, 9);
        let from = Pose { x: 1, y: 1, dir: 0 };
        for (walk_len, by_distance) in (1..=6).flat_map(|n| [(n, false), (n, true)]) {
            let mut farthest = 0;
            for _ in 0..200 {
                let goal = if by_distance {
                    sampler.draw_by_distance(from, walk_len) as usize
                } else {
                    sampler.draw(from, walk_len) as usize
                };
                let (x, y) = (goal % layout.width, goal / layout.width);
                assert_ne!((x, y), (1, 1), "a goal is never the agent's own cell");
                assert_ne!(layout.cells[goal], Object::Wall as u8);
                assert_ne!(
                    layout.cells[goal],
                    Object::Exit as u8,
                    "walks that end the episode are redrawn"
                );
                // At most one cell per forward move (in this open room the
                // path distance is the Manhattan distance).
                assert!(
                    x - 1 + y - 1 <= walk_len,
                    "walk of {walk_len} reached ({x}, {y})"
                );
                farthest = farthest.max(x - 1 + y - 1);
            }
            if by_distance {
                // The room's far corner is 8 moves away: goals reach `walk_len`.
                assert_eq!(farthest, walk_len, "by distance, walk of {walk_len}");
            }
        }
        // Same seed, same goals.
        let draws = |seed| {
            let mut s = GoalSampler::new(&layout, seed);
            (0..20).map(|_| s.draw(from, 4)).collect::<Vec<_>>()
        };
        assert_eq!(draws(3), draws(3));
    }

    /// The observation of one environment of [`room`] whose agent stands
    /// on `cell` facing right, handed to `f`.
    fn with_obs<R>(cell: u32, f: impl FnOnce(&ObsView<'_>) -> R) -> R {
        let layout = room();
        let w = layout.width as u32;
        let meta = [EnvMeta {
            x: (cell % w) as u16,
            y: (cell / w) as u16,
            carrying: EnvMeta::CARRYING_NOTHING,
            ..EnvMeta::EMPTY
        }];
        let cells = vec![0u8; layout.cells.len()];
        f(&ObsView {
            seq: 0,
            cells: &cells,
            final_cells: &[],
            meta: &meta,
            width: layout.width,
            height: layout.height,
        })
    }

    /// Books a forward step after which the agent stands on `cell`.
    fn book_step(book: &mut GoalBook, sampler: &mut GoalSampler, cell: u32) -> GoalStep {
        with_obs(cell, |obs| {
            book.advance(sampler, obs, &[sim::action::FORWARD], &GcpConfig::default())[0]
        })
    }

    /// Records what a chain that reaches one goal, then misses the next,
    /// leaves for the latent model: (start cell, first goal, recorded).
    fn chain_with_a_missed_leg(record_missed_legs: bool) -> (u32, u32, Vec<Trajectory>) {
        let layout = room();
        let mut sampler = GoalSampler::new(&layout, 5);
        let mut book = GoalBook {
            record_missed_legs,
            ..GoalBook::new(3, 4, true)
        };
        let start = 3 * layout.width as u32 + 3;
        with_obs(start, |obs| book.sync(&mut sampler, obs));
        let first = book.goals()[0];
        assert_ne!(first, start);
        assert!(book_step(&mut book, &mut sampler, first).success);
        assert!(
            book.finished.is_empty(),
            "the chain goes on after a reached goal"
        );
        // The second goal is never reached: the agent stays on the first
        // goal's cell (a goal is never the agent's own cell) until the
        // time limit of 4 steps.
        for t in 0..4 {
            let step = book_step(&mut book, &mut sampler, first);
            assert_eq!(step.goal_done, t == 3);
            assert!(!step.success);
        }
        (start, first, std::mem::take(&mut book.finished))
    }

    #[test]
    fn a_chain_is_recorded_up_to_its_last_reached_goal() {
        let (start, first, recorded) = chain_with_a_missed_leg(false);
        assert_eq!(recorded.len(), 1);
        let cells: Vec<u32> = recorded[0].states.iter().map(|s| s.cell).collect();
        assert_eq!(cells, vec![start, first]);
        assert_eq!(recorded[0].actions, vec![sim::action::FORWARD]);

        // With the missed legs kept, the four steps towards the second goal
        // are part of it.
        let (_, _, recorded) = chain_with_a_missed_leg(true);
        assert_eq!(recorded.len(), 1);
        assert_eq!(recorded[0].actions.len(), 5);
        assert_eq!(recorded[0].states.len(), 6);
    }

    #[test]
    fn a_chain_that_reaches_no_goal_is_not_recorded() {
        let layout = room();
        let mut sampler = GoalSampler::new(&layout, 8);
        let mut book = GoalBook {
            record_missed_legs: false,
            ..GoalBook::new(3, 2, true)
        };
        let start = 2 * layout.width as u32 + 2;
        with_obs(start, |obs| book.sync(&mut sampler, obs));
        assert!(!book_step(&mut book, &mut sampler, start).goal_done);
        assert!(book_step(&mut book, &mut sampler, start).goal_done);
        assert!(book.finished.is_empty());
    }

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
