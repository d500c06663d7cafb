//! Stage 1 of Shang et al. 2019 (section 3):
//! world graph discovery.
//!
//! Each **round** of the loop:
//! 1. *collects trajectories*: random walks started from the agent's start
//!    state and from the current pivotal states, which the agent reaches by
//!    replaying the action path it recorded the first time it got there
//!    (paper section 3.2, "the agent records the paths it took"); and
//!    rollouts of the goal-conditioned policy `π_g`;
//! 2. *trains the latent model* (section 3.1) on the collected trajectories,
//!    both sources alike (see [`DiscoveryConfig::buffer`]);
//! 3. *updates the pivotal states* `V_p`: the top `pivotal_ratio` of the
//!    visited cells by prior mean;
//! 4. *trains `π_g`* with the curiosity bonus (section 3.2).
//!
//! The loop stops when the latent model's reconstruction accuracy has not
//! improved by `min_improvement` for `patience` rounds, or at `max_rounds`.
//! Then [`Discovery::build_graph`] connects `V_p` into the world graph
//! (section 3.3) with the planner, and `π_g` shortens its edge paths
//! ([`crate::edge_refinement`]).
//!
//! Everything runs on a [`BatchEnvironment`], so the loop is the same in
//! process and over the shared-memory pipeline. Each round starts by
//! resetting every environment and reseeding from `(seed, round)`, so a run
//! resumed from a checkpoint continues as the run that was interrupted would
//! have (its weights, pivotal states, recorded paths and history are saved
//! at the end of every round).

use std::collections::BTreeMap;
use std::path::Path;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use sim::{Layout, action, flags};

use crate::batch_env::{BatchEnvironment, EnvError};
use crate::checkpoint;
use crate::edge_refinement::{RefinementStats, refine_with_gcp};
use crate::error::LearnerError;
use crate::experience::{ChainShape, Experience};
use crate::gcp::{GcpConfig, GcpStats, GoalConditionedPolicy};
use crate::vae::{AgentPose, LatentConfig, LatentTrainer, Trajectory, TrajectoryBatch};

/// Settings of the discovery loop (CPU-sized defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiscoveryConfig {
    /// Seed of everything random in the loop.
    pub seed: u64,
    /// Most rounds (the budget).
    pub max_rounds: u32,
    /// Rounds without improvement of the reconstruction accuracy before stopping.
    pub patience: u32,
    /// Rounds before a plateau may stop the loop: `π_g` needs about 1,000
    /// updates before its goal episodes mean anything, and the accuracy
    /// plateaus early on random walks alone.
    pub min_rounds: u32,
    /// Smallest accuracy gain that counts as an improvement.
    pub min_improvement: f64,
    /// Random-walk steps per environment per round.
    pub walk_steps_per_round: u32,
    /// Length of one random walk (actions).
    pub walk_len: u32,
    /// Fraction of walks started from a pivotal state (once there are some).
    pub from_pivotal: f64,
    /// Latent-model updates per round.
    pub latent_steps_per_round: u32,
    /// Trajectories per latent-model update.
    pub latent_batch: usize,
    /// Most trajectories kept for training (the newest), split evenly
    /// between the two sources: walks (random walks and path replays) and
    /// `π_g`'s goal trajectories. Every batch draws from both halves alike
    /// (all from one while the other is empty), so neither source crowds
    /// the other out: once `π_g` succeeds it yields far more trajectories
    /// than the walks, and one first-in-first-out buffer forgot the walks.
    pub buffer: usize,
    /// `π_g` A2C iterations per round (0: random walks only).
    pub gcp_iters_per_round: u32,
    /// Fraction of visited cells that become pivotal states (paper: 0.2).
    pub pivotal_ratio: f64,
    /// How far `π_g`'s training goals lie, round by round.
    pub goal_curriculum: GoalCurriculum,
    /// Erase the loops of `π_g`'s recorded trajectories before the latent
    /// model sees them, as the walks' recorded paths are
    /// ([`LoopErasedRoute`]): a half-trained `π_g` reaches its goals with
    /// detours (turning back and forth, stepping into walls), and what is
    /// left is the way it found, the kind of trajectory whose actions the
    /// pivotal states should explain (section 3.1). Off by default.
    pub loop_erase_goal_trajectories: bool,
    /// Make the recorded path to each cell the shortest the agent knows:
    /// at the start of every round, a breadth-first search from the start
    /// pose over every transition it has observed (pose, action → pose, from
    /// the walks and `π_g`'s trajectories: its own experience, no map is
    /// consulted). Section 3.2: "the agent can straightforwardly document
    /// and reuse the paths from its initial position to states in `V_p`";
    /// a walk's own path, even with its loops erased, wanders. The replays
    /// along these paths are training data too, and a shortest turn-and-move
    /// path across rooms is the kind of trajectory whose actions the
    /// doorways explain (section 3.1, `learner/tests/pivotal_doorways.rs`).
    /// Off by default.
    pub shortest_known_paths: bool,
    /// Goal chains along the agent's known routes, the goal-directed
    /// trajectories the latent model finds pivotal states in
    /// ([`GoalChains`]).
    pub goal_chains: GoalChains,
    /// The latent model.
    pub latent: LatentConfig,
    /// The goal-conditioned policy.
    pub gcp: GcpConfig,
}

impl Default for DiscoveryConfig {
    fn default() -> Self {
        DiscoveryConfig {
            seed: 0,
            max_rounds: 30,
            patience: 4,
            min_rounds: 12,
            min_improvement: 0.005,
            walk_steps_per_round: 256,
            walk_len: 24,
            from_pivotal: 0.5,
            latent_steps_per_round: 40,
            latent_batch: 64,
            buffer: 4096,
            // π_g needs hundreds of A2C updates before it reaches goals
            // (docs/implementation_details.md, "Where stage 1 departs").
            gcp_iters_per_round: 100,
            pivotal_ratio: 0.2,
            goal_curriculum: GoalCurriculum::default(),
            // The three levers of issue 12's second pass stay off: none beat
            // the loop without them (docs/implementation_details.md, "Second
            // pass").
            loop_erase_goal_trajectories: false,
            shortest_known_paths: false,
            goal_chains: GoalChains::default(),
            latent: LatentConfig::default(),
            gcp: GcpConfig::default(),
        }
    }
}

impl DiscoveryConfig {
    /// True when the loop books the transitions it observes (the known
    /// routes are used).
    pub fn records_experience(&self) -> bool {
        self.shortest_known_paths || self.goal_chains.per_round > 0
    }

    /// Checks the values once, before anything is built.
    pub fn validate(&self) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: &str| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if self.max_rounds == 0 {
            return bad("max_rounds", "must be at least 1");
        }
        if self.walk_len == 0 || self.walk_steps_per_round < self.walk_len {
            return bad(
                "walk_len",
                "must be at least 1 and at most walk_steps_per_round",
            );
        }
        if !(0.0..=1.0).contains(&self.from_pivotal) {
            return bad("from_pivotal", "must be in [0, 1]");
        }
        if !(self.pivotal_ratio > 0.0 && self.pivotal_ratio <= 1.0) {
            return bad("pivotal_ratio", "must be in (0, 1]");
        }
        if self.latent_batch == 0 || self.buffer < self.latent_batch {
            return bad("latent_batch", "must be at least 1 and at most buffer");
        }
        self.goal_curriculum.validate(self.gcp.goal_walk_len)?;
        self.goal_chains.validate()?;
        self.latent.validate()?;
        self.gcp.validate()?;
        Ok(())
    }
}

/// Goal chains: trajectories that reach `legs` goals in turn, each along
/// a shortest route through the transitions the agent has observed, ties
/// broken at random ([`crate::experience`]). They stand for what a trained
/// `π_g` does (section 3.2), whose trajectories the latent model learns
/// from (section 3.1): on this machine's budget `π_g` reaches goals within
/// one room only, while a trajectory whose legs cross rooms is what the
/// doorways explain. The chains join the walks and `π_g`'s episodes as a
/// third source of the training buffer, and `batch_share` of every latent
/// batch is drawn from them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GoalChains {
    /// Chains drawn per round (0: none, the loop of the paper's sources
    /// alone).
    pub per_round: usize,
    /// Goals reached in turn by one chain.
    pub legs: usize,
    /// Fewest actions from one goal (or the chain's start) to the next
    /// along the shortest known route.
    pub min_actions: u32,
    /// Most actions from one goal to the next.
    pub max_actions: u32,
    /// Share of every latent-model batch drawn from the chains; the rest
    /// is split evenly between the walks and `π_g`'s episodes.
    pub batch_share: f64,
}

impl Default for GoalChains {
    fn default() -> Self {
        GoalChains {
            per_round: 512,
            legs: 1,
            min_actions: 8,
            // Beyond the farthest cell of any embedded maze: goals anywhere
            // at least `min_actions` away.
            max_actions: 1000,
            batch_share: 0.75,
        }
    }
}

impl GoalChains {
    /// The shape of one chain.
    pub fn shape(&self) -> ChainShape {
        ChainShape {
            legs: self.legs,
            min_actions: self.min_actions,
            max_actions: self.max_actions,
        }
    }

    fn validate(&self) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: &str| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if self.per_round > 0 && self.legs == 0 {
            return bad("goal_chains.legs", "must be at least 1");
        }
        if self.min_actions == 0 || self.max_actions < self.min_actions {
            return bad(
                "goal_chains.min_actions",
                "must be at least 1 and at most goal_chains.max_actions",
            );
        }
        if !(0.0..1.0).contains(&self.batch_share) {
            return bad("goal_chains.batch_share", "must be in [0, 1)");
        }
        Ok(())
    }
}

/// A curriculum on the distance of `π_g`'s training goals. The paper draws
/// goals at "the end points of random walks with reasonable length"
/// (section 3.2) and leaves the length open. Near goals are what `π_g`
/// learns first, far goals are what the latent model needs: a trajectory
/// whose legs cross rooms is explained by the doorways it passes, a short
/// one by its two ends alone (section 3.1). So goals start within
/// [`GcpConfig::goal_walk_len`] moves, and after each round in which `π_g`
/// reached at least `success_threshold` of its training goals the
/// distance grows by `step` moves, up to `max_moves` (`step = 0`, the
/// default, keeps it at `goal_walk_len`). The distance is part of the
/// checkpoint, so a resumed run goes on at the distance it reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GoalCurriculum {
    /// Moves added to the goal distance after a round that passed
    /// `success_threshold` (0: the distance stays at `goal_walk_len`).
    pub step: usize,
    /// Training success rate of a round (mean over its A2C iterations) at
    /// which the next round's goals lie `step` moves farther.
    pub success_threshold: f64,
    /// The farthest goal distance, in moves.
    pub max_moves: usize,
}

impl Default for GoalCurriculum {
    fn default() -> Self {
        GoalCurriculum {
            // Off (see `DiscoveryConfig::default`); `step = 2` turns it on.
            step: 0,
            success_threshold: 0.5,
            max_moves: 16,
        }
    }
}

impl GoalCurriculum {
    /// The distance of the round after one at `moves` whose training
    /// success rate was `success`.
    pub fn next(&self, moves: usize, success: f64) -> usize {
        if success >= self.success_threshold {
            (moves + self.step).min(self.max_moves.max(moves))
        } else {
            moves
        }
    }

    fn validate(&self, start: usize) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: String| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if !(self.success_threshold > 0.0 && self.success_threshold <= 1.0) {
            return bad(
                "goal_curriculum.success_threshold",
                format!("{} must be in (0, 1]", self.success_threshold),
            );
        }
        if self.step > 0 && self.max_moves < start {
            return bad(
                "goal_curriculum.max_moves",
                format!(
                    "{} must be at least gcp.goal_walk_len ({start})",
                    self.max_moves
                ),
            );
        }
        Ok(())
    }
}

/// Figures of one round (the discovery curves).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundStats {
    /// Round index, from 0.
    pub round: u32,
    /// Environment steps taken in the round.
    pub env_steps: u64,
    /// Trajectories collected in the round (walks and `π_g` goal episodes).
    pub trajectories: usize,
    /// Reconstruction accuracy of the latent model on trajectories of this
    /// round held out of its training, drawn from both sources as the
    /// training batches are.
    pub reconstruction_accuracy: f64,
    /// Mean KL of the last update.
    pub kl: f64,
    /// Fraction of interior states kept by the posterior.
    pub kept_fraction: f64,
    /// `π_g` goal success rate during the round's training.
    pub gcp_success: f64,
    /// Mean curiosity bonus of `π_g`'s rollouts.
    pub gcp_curiosity: f64,
    /// The most moves away `π_g`'s training goals lay in the round
    /// ([`GoalCurriculum`]; 0 in histories written before it was kept).
    #[serde(default)]
    pub goal_distance: usize,
    /// `π_g` trajectories the round gave the latent model (chains up to
    /// their last reached goal, loops erased).
    #[serde(default)]
    pub goal_trajectories: usize,
    /// Goal chains along known routes the round gave the latent model
    /// ([`GoalChains`]; 0 in histories written before they existed).
    #[serde(default)]
    pub goal_chains: usize,
    /// Distinct cells visited so far.
    pub cells_visited: usize,
    /// Size of `V_p` after the round.
    pub pivotal_states: usize,
    /// Seconds the round took.
    pub seconds: f64,
}

/// A buffered trajectory as checkpointed: `(cell, direction, carried)`
/// for each state, then the actions.
type SavedTrajectory = (Vec<(u32, u8, u8)>, Vec<u8>);

/// What is checkpointed besides the weights.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct State {
    config: DiscoveryConfig,
    layout_name: String,
    rounds_done: u32,
    history: Vec<RoundStats>,
    visits: BTreeMap<u32, u64>,
    /// Shortest recorded action path from the start to each visited cell.
    paths: BTreeMap<u32, Vec<u8>>,
    pivotal: Vec<u32>,
    best_accuracy: f64,
    rounds_without_improvement: u32,
    /// The walks' half of the training buffer.
    buffer: Vec<SavedTrajectory>,
    /// `π_g`'s half of the training buffer.
    #[serde(default)]
    gcp_buffer: Vec<SavedTrajectory>,
    /// The latent model's Lagrange multipliers (eq. 3), which live outside
    /// its weights; `None` only in checkpoints written before they were kept.
    #[serde(default)]
    multipliers: Option<crate::vae::Multipliers>,
    /// The most moves away `π_g`'s training goals lie in the next round
    /// ([`GoalCurriculum`]); 0 in checkpoints written before it was kept
    /// (read as `gcp.goal_walk_len`).
    #[serde(default)]
    goal_distance: usize,
    /// Every transition observed so far, when the known routes are used
    /// ([`DiscoveryConfig::shortest_known_paths`], [`GoalChains`]).
    #[serde(default)]
    experience: Experience,
    /// The goal chains' third of the training buffer.
    #[serde(default)]
    chain_buffer: Vec<SavedTrajectory>,
}

/// The discovery loop's models and bookkeeping.
pub struct Discovery {
    layout: Layout,
    state: State,
    latent: LatentTrainer,
    gcp: GoalConditionedPolicy,
    /// Training trajectories of the walks (random walks, path replays).
    buffer: Vec<Trajectory>,
    /// Training trajectories of `π_g` (chained goal episodes).
    gcp_buffer: Vec<Trajectory>,
    /// Training trajectories along known routes ([`GoalChains`]).
    chain_buffer: Vec<Trajectory>,
}

impl std::fmt::Debug for Discovery {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Discovery")
            .field("rounds_done", &self.state.rounds_done)
            .finish_non_exhaustive()
    }
}

/// The pose the latent model reads from an observation record (the one
/// constructor every trajectory source uses, [`AgentPose::from_meta`]).
pub fn pose_of(m: &sim::EnvMeta, width: usize) -> AgentPose {
    AgentPose::from_meta(m, width)
}

enum Phase {
    NeedReset,
    Replay { path: Vec<u8>, next: usize },
    Walk { left: u32 },
}

struct Walker {
    phase: Phase,
    /// The way from the start to the agent's pose, loops erased.
    route: LoopErasedRoute,
    /// The action whose outcome the next observation shows (`None` after a
    /// reset).
    pending: Option<u8>,
    /// The walk started with a replay whose trajectory is not emitted yet.
    replayed: bool,
    states: Vec<AgentPose>,
    actions: Vec<u8>,
}

/// The actions since the last reset with every loop erased: whenever the
/// agent comes back to a pose (cell and facing) it had, the actions in
/// between are dropped. In a maze with deterministic dynamics the result
/// still leads from the start to the same pose, and it is never longer
/// than what was walked, so recorded paths approach the agent's shortest
/// known routes (its own experience: no map is consulted). Their replays
/// are goal-directed trajectories, which the latent model needs: uniformly
/// random actions are unpredictable between any kept states, so on them
/// alone it learns to keep none.
#[derive(Debug, Default)]
struct LoopErasedRoute {
    poses: Vec<AgentPose>,
    actions: Vec<u8>,
    index: std::collections::HashMap<AgentPose, usize>,
}

impl LoopErasedRoute {
    fn reset(&mut self, start: AgentPose) {
        self.poses.clear();
        self.actions.clear();
        self.index.clear();
        self.poses.push(start);
        self.index.insert(start, 0);
    }

    fn clear(&mut self) {
        self.poses.clear();
        self.actions.clear();
        self.index.clear();
    }

    /// `action` led to `pose`.
    fn push(&mut self, action: u8, pose: AgentPose) {
        if self.poses.is_empty() {
            return; // not started since the last episode end
        }
        if let Some(&i) = self.index.get(&pose) {
            for p in self.poses.drain(i + 1..) {
                self.index.remove(&p);
            }
            self.actions.truncate(i);
        } else {
            self.actions.push(action);
            self.poses.push(pose);
            self.index.insert(pose, self.poses.len() - 1);
        }
    }

    fn trajectory(&self) -> Trajectory {
        Trajectory {
            states: self.poses.clone(),
            actions: self.actions.clone(),
        }
    }
}

/// RNG stream of the final evaluation (far from any round's index).
const EVALUATION_STREAM: u64 = 0xE7A1_0000;

impl Discovery {
    /// A fresh discovery on `layout` with `num_envs` environments.
    pub fn new(
        cfg: DiscoveryConfig,
        layout: &Layout,
        num_envs: usize,
        num_actions: usize,
    ) -> Result<Discovery, LearnerError> {
        let mut cfg = cfg;
        cfg.latent.num_cells = (layout.width * layout.height) as i64;
        cfg.latent.num_actions = cfg.latent.num_actions.max(num_actions as i64);
        cfg.validate()?;
        let latent = LatentTrainer::new(&cfg.latent, tch::Device::Cpu, cfg.seed)?;
        let gcp = GoalConditionedPolicy::new(&cfg.gcp, layout, num_envs, num_actions, cfg.seed)?;
        let goal_distance = cfg.gcp.goal_walk_len;
        let state = State {
            config: cfg,
            layout_name: layout.name.clone(),
            rounds_done: 0,
            history: Vec::new(),
            visits: BTreeMap::new(),
            paths: BTreeMap::new(),
            pivotal: Vec::new(),
            best_accuracy: 0.0,
            rounds_without_improvement: 0,
            buffer: Vec::new(),
            gcp_buffer: Vec::new(),
            multipliers: None,
            goal_distance,
            experience: Experience::default(),
            chain_buffer: Vec::new(),
        };
        Ok(Discovery {
            layout: layout.clone(),
            state,
            latent,
            gcp,
            buffer: Vec::new(),
            gcp_buffer: Vec::new(),
            chain_buffer: Vec::new(),
        })
    }

    /// The configuration in force (with the maze's sizes filled in).
    pub fn config(&self) -> &DiscoveryConfig {
        &self.state.config
    }

    /// Rounds completed.
    pub fn rounds_done(&self) -> u32 {
        self.state.rounds_done
    }

    /// The curves so far.
    pub fn history(&self) -> &[RoundStats] {
        &self.state.history
    }

    /// The current pivotal states `V_p` (cell indices), most pivotal first.
    pub fn pivotal_states(&self) -> &[u32] {
        &self.state.pivotal
    }

    /// Cells visited so far, with visit counts.
    pub fn visits(&self) -> &BTreeMap<u32, u64> {
        &self.state.visits
    }

    /// The latent model.
    pub fn latent(&self) -> &LatentTrainer {
        &self.latent
    }

    /// The goal-conditioned policy.
    pub fn gcp(&mut self) -> &mut GoalConditionedPolicy {
        &mut self.gcp
    }

    /// `π_g`'s success rate on goals `goal_walk_len` random moves away,
    /// from freshly reset environments and RNGs seeded from the run's seed:
    /// the same figure whether or not the run was interrupted.
    pub fn evaluate_gcp(
        &mut self,
        env: &mut dyn BatchEnvironment,
        goal_walk_len: usize,
        steps: usize,
    ) -> Result<f64, LearnerError> {
        let n = env.num_envs();
        env.step(&vec![action::RESET; n])
            .map_err(LearnerError::from)?;
        self.gcp
            .start_round(sim::env_seed(self.state.config.seed, EVALUATION_STREAM))?;
        self.gcp.evaluate(env, goal_walk_len, steps)
    }

    /// True when the accuracy plateaued or the round budget is spent.
    pub fn finished(&self) -> bool {
        let c = &self.state.config;
        self.state.rounds_done >= c.max_rounds
            || (self.state.rounds_done >= c.min_rounds
                && self.state.rounds_without_improvement >= c.patience)
    }

    /// Prior mean of every cell index of the grid (walls included; 0 for
    /// cells never visited is *not* assumed: the prior is a function of the
    /// state alone).
    pub fn prior_means(&self) -> Vec<f32> {
        let cells: Vec<u32> = (0..(self.layout.width * self.layout.height) as u32).collect();
        self.latent.model().prior_mean(&cells)
    }

    /// This round's goal chains ([`GoalChains`]), drawn from the
    /// experience with an RNG of their own seeded from `(seed, round)`.
    fn goal_chains(&self, round: u32) -> Vec<Trajectory> {
        let c = &self.state.config.goal_chains;
        if c.per_round == 0 {
            return Vec::new();
        }
        let seed = sim::env_seed(self.state.config.seed, 0x200_0000 + u64::from(round));
        let mut rng = SmallRng::seed_from_u64(seed);
        let routes = self.state.experience.routes();
        (0..c.per_round)
            .filter_map(|_| routes.chain(c.shape(), &mut rng))
            .collect()
    }

    /// Replaces each recorded path by the shortest action sequence from
    /// `start` through the observed transitions, where that is shorter
    /// ([`DiscoveryConfig::shortest_known_paths`]). Breadth-first over
    /// poses, actions in ascending order, so the result is a function of
    /// the experience alone.
    fn shorten_paths(&mut self, start: AgentPose) {
        for (cell, path) in self.state.experience.shortest_paths_from(start) {
            let known = self.state.paths.get(&cell).map_or(usize::MAX, Vec::len);
            if path.len() < known {
                self.state.paths.insert(cell, path);
            }
        }
    }

    /// Step 1: random walks from the start and from pivotal states.
    ///
    /// Each environment runs a small state machine: reset to the start;
    /// then either replay the recorded path to a random pivotal state or
    /// not; then `walk_len` uniformly random actions, recorded as a
    /// trajectory. Every step first records the outcome of the previous
    /// action (the observed pose), then picks the next action. The first
    /// time a cell is reached, or by a shorter path, the actions since the
    /// reset are recorded as the way back to it.
    fn collect_walks(
        &mut self,
        env: &mut dyn BatchEnvironment,
        rng: &mut SmallRng,
    ) -> Result<(Vec<Trajectory>, u64), EnvError> {
        let cfg = self.state.config.clone();
        let n = env.num_envs();
        let width = env.observe().width;
        let num_actions = env.num_actions() as u8;
        let mut walkers: Vec<Walker> = (0..n)
            .map(|_| Walker {
                phase: Phase::NeedReset,
                route: LoopErasedRoute::default(),
                pending: None,
                replayed: false,
                states: Vec::new(),
                actions: Vec::new(),
            })
            .collect();
        if cfg.shortest_known_paths {
            // Every environment was just reset: the agent is at the start.
            let start = pose_of(&env.observe().meta[0], width);
            self.shorten_paths(start);
        }
        let mut out = Vec::new();
        let mut actions = vec![0u8; n];
        let steps = cfg.walk_steps_per_round as u64;
        for _ in 0..steps {
            let obs = env.observe();
            for (i, w) in walkers.iter_mut().enumerate() {
                let m = obs.meta[i];
                let pose = pose_of(&m, width);
                // An ended episode auto-reset: the agent is back at the start
                // and the last action's outcome is lost.
                let ended = m.flags & flags::DONE != 0;
                if ended {
                    w.route.clear();
                    w.pending = None;
                    w.replayed = false;
                } else {
                    match w.pending.take() {
                        None => w.route.reset(pose),
                        Some(a) => {
                            if let Some(&before) = w.route.poses.last()
                                && cfg.records_experience()
                            {
                                self.state.experience.observe(before, a, pose);
                            }
                            w.route.push(a, pose);
                        }
                    }
                }
                let awaiting_outcome = !w.actions.is_empty() && w.states.len() == w.actions.len();
                if awaiting_outcome {
                    if ended {
                        w.actions.pop();
                    } else {
                        w.states.push(pose);
                    }
                }
                if ended || (awaiting_outcome && matches!(w.phase, Phase::Walk { left: 0 })) {
                    finish(w, &mut out);
                    w.phase = Phase::NeedReset;
                }
                if !ended {
                    *self.state.visits.entry(pose.cell).or_default() += 1;
                    let known = self
                        .state
                        .paths
                        .get(&pose.cell)
                        .map_or(usize::MAX, Vec::len);
                    if w.route.actions.len() < known && !w.route.poses.is_empty() {
                        self.state.paths.insert(pose.cell, w.route.actions.clone());
                    }
                }
                actions[i] = match &mut w.phase {
                    Phase::NeedReset => {
                        w.route.clear();
                        w.pending = None;
                        let pivot = (!self.state.pivotal.is_empty()
                            && rng.random_bool(cfg.from_pivotal))
                        .then(|| self.state.pivotal[rng.random_range(0..self.state.pivotal.len())]);
                        w.phase = match pivot.and_then(|p| self.state.paths.get(&p)) {
                            Some(path) if !path.is_empty() => {
                                w.replayed = true;
                                Phase::Replay {
                                    path: path.clone(),
                                    next: 0,
                                }
                            }
                            _ => Phase::Walk { left: cfg.walk_len },
                        };
                        action::RESET
                    }
                    Phase::Replay { path, next } => {
                        let a = path[*next];
                        *next += 1;
                        if *next == path.len() {
                            w.phase = Phase::Walk { left: cfg.walk_len };
                        }
                        w.pending = Some(a);
                        a
                    }
                    Phase::Walk { left } => {
                        if w.actions.is_empty() {
                            w.states.clear();
                            w.states.push(pose);
                        }
                        // The replay just ended here: its (loop-erased,
                        // goal-directed) trajectory is training data too.
                        if std::mem::take(&mut w.replayed) && w.route.actions.len() >= 2 {
                            out.push(w.route.trajectory());
                        }
                        let a = rng.random_range(0..num_actions);
                        w.actions.push(a);
                        w.pending = Some(a);
                        *left -= 1;
                        a
                    }
                };
            }
            env.step(&actions)?;
        }
        Ok((out, steps * n as u64))
    }

    /// One round of the loop (steps 1–4).
    pub fn round(&mut self, env: &mut dyn BatchEnvironment) -> Result<RoundStats, LearnerError> {
        let t0 = std::time::Instant::now();
        let cfg = self.state.config.clone();
        let round = self.state.rounds_done;
        let mut rng = SmallRng::seed_from_u64(sim::env_seed(cfg.seed, 0x100_0000 + round as u64));
        // Everything random in a round is seeded from (seed, round), and the
        // optimisers start afresh: a round depends on the checkpoint only.
        let round_seed = sim::env_seed(cfg.seed, round as u64);
        self.latent.model_mut().reseed_noise(round_seed);
        self.latent.reset_optimizer()?;
        self.gcp.start_round(round_seed)?;
        let goal_distance = match self.state.goal_distance {
            0 => cfg.gcp.goal_walk_len,
            d => d,
        };
        self.gcp.set_goal_distance(goal_distance);
        let n = env.num_envs();
        env.step(&vec![action::RESET; n])
            .map_err(LearnerError::from)?;

        // 1. Trajectories: random walks, then π_g rollouts.
        let (walks, mut env_steps) = self.collect_walks(env, &mut rng)?;
        let mut gcp_stats: Vec<GcpStats> = Vec::new();
        for _ in 0..cfg.gcp_iters_per_round {
            let curiosity = (round > 0).then(|| self.latent.model());
            gcp_stats.push(self.gcp.train_iteration(env, curiosity)?);
            env_steps += (cfg.gcp.rollout_len * n) as u64;
        }
        let goal_trajectories: Vec<Trajectory> = self
            .gcp
            .take_trajectories()
            .into_iter()
            .filter(|t| !t.actions.is_empty())
            .collect();
        for t in &goal_trajectories {
            for s in &t.states {
                *self.state.visits.entry(s.cell).or_default() += 1;
            }
            if cfg.records_experience() {
                self.state.experience.observe_trajectory(t);
            }
        }
        let goal_trajectories: Vec<Trajectory> = if cfg.loop_erase_goal_trajectories {
            goal_trajectories
                .iter()
                .map(loop_erased)
                .filter(|t| !t.actions.is_empty())
                .collect()
        } else {
            goal_trajectories
        };
        let goal_count = goal_trajectories.len();
        // Goal chains along the routes the agent knows now.
        let chains = self.goal_chains(round);
        let chain_count = chains.len();
        let collected = walks.len() + goal_count + chain_count;

        // 2. The latent model, on the newest `buffer` trajectories of the
        // sources. A share of this round's trajectories of each source is
        // held out for the accuracy, and joins the buffer afterwards.
        let (walk_eval, walk_train) = hold_out(walks, EVAL_PER_SOURCE);
        let (goal_eval, goal_train) = hold_out(goal_trajectories, EVAL_PER_SOURCE);
        let (chain_eval, chain_train) = hold_out(chains, EVAL_PER_SOURCE);
        let half = cfg.buffer.div_ceil(2);
        push_newest(&mut self.buffer, walk_train, half);
        push_newest(&mut self.gcp_buffer, goal_train, half);
        push_newest(&mut self.chain_buffer, chain_train, half);
        let mut last = None;
        let rest = (1.0 - cfg.goal_chains.batch_share) / 2.0;
        if !(self.buffer.is_empty() && self.gcp_buffer.is_empty() && self.chain_buffer.is_empty()) {
            for _ in 0..cfg.latent_steps_per_round {
                let sources = [
                    (self.buffer.as_slice(), rest),
                    (self.gcp_buffer.as_slice(), rest),
                    (self.chain_buffer.as_slice(), cfg.goal_chains.batch_share),
                ];
                let batch = mixed_batch(&sources, cfg.latent_batch, &mut rng);
                let tb = TrajectoryBatch::new(
                    &batch,
                    &self.latent.model().config().clone(),
                    tch::Device::Cpu,
                )?;
                last = Some(self.latent.train_step(&tb));
            }
        }
        let eval_set = mixed_eval(&[&walk_eval, &goal_eval, &chain_eval]);
        let eval = if eval_set.is_empty() {
            None
        } else {
            let tb = TrajectoryBatch::new(
                &eval_set,
                &self.latent.model().config().clone(),
                tch::Device::Cpu,
            )?;
            Some(self.latent.model().evaluate(&tb))
        };
        let accuracy = eval.as_ref().map_or(0.0, |e| e.reconstruction_accuracy);
        push_newest(&mut self.buffer, walk_eval, half);
        push_newest(&mut self.gcp_buffer, goal_eval, half);
        push_newest(&mut self.chain_buffer, chain_eval, half);

        // 3. V_p: the top `pivotal_ratio` of the visited cells by prior mean.
        let visited: Vec<u32> = self.state.visits.keys().copied().collect();
        self.state.pivotal = self
            .latent
            .model()
            .pivotal_states(&visited, cfg.pivotal_ratio);

        // Plateau bookkeeping.
        if accuracy > self.state.best_accuracy + cfg.min_improvement {
            self.state.best_accuracy = accuracy;
            self.state.rounds_without_improvement = 0;
        } else {
            self.state.rounds_without_improvement += 1;
        }
        let mean = |f: fn(&GcpStats) -> f64| {
            if gcp_stats.is_empty() {
                0.0
            } else {
                gcp_stats.iter().map(f).sum::<f64>() / gcp_stats.len() as f64
            }
        };
        let gcp_success = mean(|s| s.success_rate);
        self.state.goal_distance = cfg.goal_curriculum.next(goal_distance, gcp_success);
        let stats = RoundStats {
            round,
            env_steps,
            trajectories: collected,
            reconstruction_accuracy: accuracy,
            kl: last.as_ref().map_or(0.0, |s| s.kl),
            kept_fraction: eval.as_ref().map_or(0.0, |e| e.kept_fraction),
            gcp_success,
            gcp_curiosity: mean(|s| s.mean_curiosity),
            goal_distance,
            goal_trajectories: goal_count,
            goal_chains: chain_count,
            cells_visited: self.state.visits.len(),
            pivotal_states: self.state.pivotal.len(),
            seconds: t0.elapsed().as_secs_f64(),
        };
        self.state.history.push(stats.clone());
        self.state.rounds_done += 1;
        Ok(stats)
    }

    /// Saves the loop's state into `dir` as one commit
    /// ([`crate::checkpoint::commit`]): the weights are serialised in
    /// memory, and `latent.ot`, `gcp.ot` and `state.json` replace the
    /// previous checkpoint together or not at all. A failed write (a full
    /// disk) is an error naming the file and the cause, and leaves the
    /// previous checkpoint intact.
    pub fn save(&mut self, dir: &Path) -> Result<(), LearnerError> {
        let latent = checkpoint::var_store_bytes(self.latent.var_store())?;
        let gcp = checkpoint::var_store_bytes(self.gcp.var_store())?;
        self.state.buffer = self.buffer.iter().map(saved).collect();
        self.state.gcp_buffer = self.gcp_buffer.iter().map(saved).collect();
        self.state.chain_buffer = self.chain_buffer.iter().map(saved).collect();
        self.state.multipliers = Some(*self.latent.model().multipliers());
        let json = serde_json::to_vec(&self.state).map_err(|e| ckpt(dir, e));
        self.state.buffer.clear();
        self.state.gcp_buffer.clear();
        self.state.chain_buffer.clear();
        checkpoint::commit(
            dir,
            &[
                ("latent.ot", &latent),
                ("gcp.ot", &gcp),
                ("state.json", &json?),
            ],
        )
    }

    /// Resumes from a checkpoint in `dir` if there is one for this
    /// configuration and layout; returns whether it did. A larger budget
    /// (`max_rounds`, `patience`) is a continuation: the new one applies.
    /// Any other difference is refused, naming the field.
    pub fn resume(&mut self, dir: &Path) -> Result<bool, LearnerError> {
        checkpoint::recover(dir)?;
        let path = dir.join("state.json");
        let Ok(bytes) = std::fs::read(&path) else {
            return Ok(false);
        };
        let state: State = serde_json::from_slice(&bytes).map_err(|e| ckpt(&path, e))?;
        if state.layout_name != self.layout.name {
            return Err(ckpt(
                &path,
                format!(
                    "belongs to maze {:?}, this run uses {:?}; use another run directory",
                    state.layout_name, self.layout.name
                ),
            ));
        }
        if let Some(field) = config_difference(&state.config, &self.state.config) {
            return Err(ckpt(
                &path,
                format!("{field}; use another run directory or the same configuration"),
            ));
        }
        let latent = dir.join("latent.ot");
        checkpoint::load_var_store_file(self.latent.var_store_mut(), &latent)?;
        self.gcp.load(dir.join("gcp.ot"))?;
        if let Some(m) = state.multipliers {
            self.latent.model_mut().set_multipliers(m);
        }
        self.buffer = state.buffer.iter().map(restored).collect();
        self.gcp_buffer = state.gcp_buffer.iter().map(restored).collect();
        self.chain_buffer = state.chain_buffer.iter().map(restored).collect();
        self.state = State {
            buffer: Vec::new(),
            config: self.state.config.clone(),
            gcp_buffer: Vec::new(),
            chain_buffer: Vec::new(),
            ..state
        };
        Ok(true)
    }

    /// Step 6: the world graph over `V_p` (section 3.3): edges from random
    /// walks between pivotal states, weights = action counts, then each
    /// path refined by `π_g` where it reaches the next node faster
    /// ([`Self::refine_graph`]).
    pub fn build_graph(
        &mut self,
        task: sim::Task,
    ) -> Result<(planner::WorldGraph, RefinementStats), LearnerError> {
        let nodes = planner::pivotal::nodes_from_cells(&self.layout, &self.state.pivotal);
        let mut graph = planner::WorldGraph::build(&self.layout, &self.graph_config(task), &nodes)?;
        let stats = self.refine_graph(&mut graph)?;
        Ok((graph, stats))
    }

    /// The planner settings of [`Self::build_graph`]: the pivotal states as
    /// the nodes, the run's seed for the walks, and the walks' paths kept
    /// as found (`shorten` off): shortening is `π_g`'s job here. A planner
    /// process given the same nodes and settings builds the same graph.
    pub fn graph_config(&self, task: sim::Task) -> planner::PlannerConfig {
        planner::PlannerConfig {
            candidates: planner::CandidateSet::Given,
            seed: self.state.config.seed,
            task,
            shorten: false,
            ..planner::PlannerConfig::default()
        }
    }

    /// Refines the edge paths of `graph` by following `π_g` along them
    /// ([`crate::edge_refinement`]).
    pub fn refine_graph(
        &mut self,
        graph: &mut planner::WorldGraph,
    ) -> Result<RefinementStats, LearnerError> {
        refine_with_gcp(graph, &mut self.gcp)
    }
}

/// `t` with its loops erased ([`LoopErasedRoute`]): same first and last
/// pose, every pose at most once.
fn loop_erased(t: &Trajectory) -> Trajectory {
    let mut route = LoopErasedRoute::default();
    let Some(&start) = t.states.first() else {
        return t.clone();
    };
    route.reset(start);
    for (&a, &pose) in t.actions.iter().zip(&t.states[1..]) {
        route.push(a, pose);
    }
    route.trajectory()
}

fn finish(w: &mut Walker, out: &mut Vec<Trajectory>) {
    if !w.actions.is_empty() && w.states.len() == w.actions.len() + 1 {
        out.push(Trajectory {
            states: std::mem::take(&mut w.states),
            actions: std::mem::take(&mut w.actions),
        });
    }
    w.states.clear();
    w.actions.clear();
}

/// Trajectories of each source held out of a round's training to measure
/// the reconstruction accuracy.
const EVAL_PER_SOURCE: usize = 128;

/// Splits `all` into (every `k`-th, up to `n`; the rest), keeping order:
/// the held-out share is spread over the round.
fn hold_out(all: Vec<Trajectory>, n: usize) -> (Vec<Trajectory>, Vec<Trajectory>) {
    // Hold out at most a quarter, so a short round still trains.
    let n = n.min(all.len() / 4);
    let k = all.len().checked_div(n).unwrap_or(usize::MAX);
    let (mut held, mut rest) = (Vec::new(), Vec::new());
    for (i, t) in all.into_iter().enumerate() {
        if held.len() < n && i % k == 0 {
            held.push(t);
        } else {
            rest.push(t);
        }
    }
    (held, rest)
}

/// Appends `fresh` to `buffer`, then drops the oldest beyond `cap`.
fn push_newest(buffer: &mut Vec<Trajectory>, fresh: Vec<Trajectory>, cap: usize) {
    buffer.extend(fresh);
    if buffer.len() > cap {
        let excess = buffer.len() - cap;
        buffer.drain(..excess);
    }
}

/// `size` trajectories, each source's share (renormalised over the sources
/// that hold any) drawn uniformly from it. The sources take turns by
/// largest shortfall, ties to the first, so two equal shares alternate.
/// At least one source must hold a trajectory.
fn mixed_batch(
    sources: &[(&[Trajectory], f64)],
    size: usize,
    rng: &mut SmallRng,
) -> Vec<Trajectory> {
    let total: f64 = sources
        .iter()
        .filter(|(s, _)| !s.is_empty())
        .map(|&(_, w)| w)
        .sum();
    let share = |(s, w): &(&[Trajectory], f64)| if s.is_empty() { 0.0 } else { w / total };
    let mut drawn = vec![0usize; sources.len()];
    (0..size)
        .map(|k| {
            let mut pick = None;
            let mut most = f64::NEG_INFINITY;
            for (i, src) in sources.iter().enumerate() {
                let shortfall = share(src) * (k + 1) as f64 - drawn[i] as f64;
                if share(src) > 0.0 && shortfall > most {
                    (pick, most) = (Some(i), shortfall);
                }
            }
            let i = pick.expect("invariant: some source holds a trajectory");
            drawn[i] += 1;
            let from = sources[i].0;
            from[rng.random_range(0..from.len())].clone()
        })
        .collect()
}

/// The held-out trajectories in the training mix: as many of each source
/// that has any (the smallest count).
fn mixed_eval(sources: &[&[Trajectory]]) -> Vec<Trajectory> {
    let n = sources
        .iter()
        .map(|s| s.len())
        .filter(|&n| n > 0)
        .min()
        .unwrap_or(0);
    sources
        .iter()
        .flat_map(|s| s.iter().take(n))
        .cloned()
        .collect()
}

fn saved(t: &Trajectory) -> SavedTrajectory {
    (
        t.states
            .iter()
            .map(|s| (s.cell, s.direction, s.carried))
            .collect(),
        t.actions.clone(),
    )
}

fn restored((states, actions): &SavedTrajectory) -> Trajectory {
    Trajectory {
        states: states
            .iter()
            .map(|&(cell, direction, carried)| AgentPose {
                cell,
                direction,
                carried,
            })
            .collect(),
        actions: actions.clone(),
    }
}

fn ckpt(path: &Path, e: impl std::fmt::Display) -> LearnerError {
    LearnerError::Checkpoint {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// The first field (dotted path) in which a checkpoint's configuration
/// `saved` differs from this run's `now`, budget fields (`max_rounds`,
/// `patience`) aside: "config field gcp.lr is 0.001 in the checkpoint, 0.002 now".
pub fn config_difference(saved: &DiscoveryConfig, now: &DiscoveryConfig) -> Option<String> {
    fn walk(path: &str, a: &serde_json::Value, b: &serde_json::Value) -> Option<String> {
        match (a, b) {
            (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
                keys.sort();
                keys.dedup();
                keys.into_iter().find_map(|k| {
                    let sub = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    if path.is_empty() && (k == "max_rounds" || k == "patience") {
                        return None;
                    }
                    let null = serde_json::Value::Null;
                    walk(&sub, x.get(k).unwrap_or(&null), y.get(k).unwrap_or(&null))
                })
            }
            _ if a == b => None,
            _ => Some(format!(
                "config field {path} is {a} in the checkpoint, {b} now"
            )),
        }
    }
    let (a, b) = (
        serde_json::to_value(saved).ok()?,
        serde_json::to_value(now).ok()?,
    );
    walk("", &a, &b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experience::test_support::{pose, walked};

    #[test]
    fn loop_erasure_keeps_the_ends_and_drops_the_detours() {
        use sim::action::{FORWARD, LEFT, RIGHT};
        // Forward, a turn left and back (a loop on the pose), into a wall
        // (no move: a loop of one step), forward again.
        let t = Trajectory {
            states: vec![
                pose(1, 0),
                pose(2, 0),
                pose(2, 3),
                pose(2, 0),
                pose(2, 0),
                pose(3, 0),
            ],
            actions: vec![FORWARD, LEFT, RIGHT, FORWARD, FORWARD],
        };
        let erased = loop_erased(&t);
        assert_eq!(erased.states, vec![pose(1, 0), pose(2, 0), pose(3, 0)]);
        assert_eq!(erased.actions, vec![FORWARD, FORWARD]);
        // A trajectory without loops is left as it is.
        assert_eq!(loop_erased(&erased), erased);
    }

    #[test]
    fn recorded_paths_become_the_shortest_through_observed_transitions() {
        use sim::action::{FORWARD, LEFT, RIGHT};
        let layout = Layout::parse("room", "#####\n#>..#\n#..E#\n#####\n").expect("layout");
        let mut d = Discovery::new(DiscoveryConfig::default(), &layout, 1, 3).expect("discovery");
        // The room of `walked`: the top row, and a detour below.
        d.state.experience = walked();
        let walked = vec![FORWARD, LEFT, RIGHT, FORWARD, RIGHT, RIGHT, LEFT, FORWARD];
        d.state.paths.insert(13, walked);
        d.state.paths.insert(11, vec![FORWARD; 9]);
        d.state.paths.insert(7, vec![FORWARD]);
        d.shorten_paths(pose(6, 0));
        assert_eq!(d.state.paths[&13], vec![FORWARD, FORWARD, RIGHT, FORWARD]);
        assert_eq!(d.state.paths[&11], vec![RIGHT, FORWARD]);
        assert_eq!(d.state.paths[&8], vec![FORWARD, FORWARD]);
        // A recorded path as short as the known one is kept.
        assert_eq!(d.state.paths[&7], vec![FORWARD]);
    }

    #[test]
    fn the_goal_distance_grows_with_success_up_to_its_cap() {
        let c = GoalCurriculum {
            step: 2,
            success_threshold: 0.5,
            max_moves: 9,
        };
        assert_eq!(c.next(6, 0.49), 6);
        assert_eq!(c.next(6, 0.5), 8);
        assert_eq!(c.next(8, 0.9), 9);
        assert_eq!(c.next(9, 1.0), 9);
        let off = GoalCurriculum { step: 0, ..c };
        assert_eq!(off.next(6, 1.0), 6);
    }

    #[test]
    fn curriculum_settings_are_checked() {
        let mut cfg = DiscoveryConfig::default();
        assert!(cfg.validate().is_ok());
        cfg.goal_curriculum.success_threshold = 0.0;
        assert!(cfg.validate().is_err());
        cfg.goal_curriculum.success_threshold = 0.5;
        cfg.goal_curriculum.step = 2;
        cfg.goal_curriculum.max_moves = cfg.gcp.goal_walk_len - 1;
        let err = cfg.validate().expect_err("max_moves below the start");
        assert!(
            err.to_string().contains("goal_curriculum.max_moves"),
            "{err}"
        );
        cfg.goal_curriculum.step = 0;
        assert!(cfg.validate().is_ok(), "no curriculum, no cap to check");
    }
}
