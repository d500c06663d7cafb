//! Stage 1 of Shang et al. 2019 (arXiv:1907.00664, section 3): world
//! graph discovery.
//!
//! Each **round** of the loop ([`Discovery::round`]):
//! 1. *collects trajectories*: random walks started from the agent's start
//!    state and from the current pivotal states, which the agent reaches by
//!    replaying the action path it recorded the first time it got there
//!    (section 3.2, "the agent records the paths it took"); and the goal
//!    episodes of the goal-conditioned policy `π_g`, collected while it
//!    trains (step 4);
//! 2. *trains the latent model* (section 3.1) on the collected trajectories,
//!    both sources alike (see [`DiscoveryConfig::buffer`]);
//! 3. *updates the pivotal states* `V_p`: the top `pivotal_ratio` of the
//!    visited cells by prior mean;
//! 4. *trains `π_g`* with the curiosity bonus of the latent model (section
//!    3.2), one A2C update per rollout of step 1.
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
//!
//! ## Files
//! - this one: the loop above ([`Discovery`], [`RoundStats`]);
//! - `walks.rs`: step 1's random walks and path replays;
//! - `buffer.rs`: the latent model's training buffer (held-out share,
//!   newest kept, batches mixed over the sources);
//! - `departures.rs`: what the optional research levers do, the settings that
//!   are not the paper's ([`GoalChains`], [`GoalCurriculum`],
//!   [`DiscoveryConfig::loop_erase_goal_trajectories`],
//!   [`DiscoveryConfig::shortest_known_paths`]);
//! - `config.rs`: every setting ([`DiscoveryConfig`], the levers' among
//!   them) and its validation;
//! - `checkpointing.rs`: save and resume (the checkpoint directory's
//!   `latent.ot`, `gcp.ot` and `state.json`);
//! - `config_diff.rs`: [`config_difference`], the field a resumed run's
//!   settings differ in.

mod buffer;
mod checkpointing;
mod config;
mod config_diff;
mod departures;
mod walks;

use std::collections::BTreeMap;

use rand::SeedableRng;
use rand::rngs::SmallRng;
use serde::{Deserialize, Serialize};
use sim::{Layout, action};

use self::buffer::{EVAL_PER_SOURCE, hold_out, mixed_batch, mixed_eval, push_newest};
use self::checkpointing::State;
pub use self::config::{DiscoveryConfig, GoalChains, GoalCurriculum};
pub use self::config_diff::config_difference;
pub use self::walks::pose_of;
use crate::batch_env::BatchEnvironment;
use crate::edge_refinement::{RefinementStats, refine_with_gcp};
use crate::error::LearnerError;
use crate::experience::Experience;
use crate::gcp::{GcpStats, GoalConditionedPolicy};
use crate::vae::{LatentTrainer, Trajectory, TrajectoryBatch};

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

    /// One round of the loop (steps 1–4 of the module docs).
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
        // How far π_g's training goals lie (a lever, `GoalCurriculum`:
        // `gcp.goal_walk_len` without one).
        let goal_distance = self.start_goal_distance();
        let n = env.num_envs();
        env.step(&vec![action::RESET; n])
            .map_err(LearnerError::from)?;

        // 1. Trajectories: random walks, then π_g rollouts, each one A2C
        // update of π_g (4.) with the curiosity of the latent model as the
        // previous round left it.
        self.shorten_known_paths(env); // a lever (departures.rs)
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
        }
        // The levers' share (departures.rs): the agent's experience books π_g's
        // transitions, their loops are erased when asked, and goal chains
        // along the routes the agent knows now join the sources.
        let goal_trajectories = self.goal_trajectories_for_latent(goal_trajectories);
        let goal_count = goal_trajectories.len();
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
        // The next round's goal distance (`GoalCurriculum`).
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

    /// True when the accuracy plateaued or the round budget is spent.
    pub fn finished(&self) -> bool {
        let c = &self.state.config;
        self.state.rounds_done >= c.max_rounds
            || (self.state.rounds_done >= c.min_rounds
                && self.state.rounds_without_improvement >= c.patience)
    }

    /// After the loop: the world graph over `V_p` (section 3.3), edges from
    /// random walks between pivotal states, weights = action counts, then
    /// each path refined by `π_g` where it reaches the next node faster
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

    /// Prior mean of every cell index of the grid (walls included; 0 for
    /// cells never visited is *not* assumed: the prior is a function of the
    /// state alone).
    pub fn prior_means(&self) -> Vec<f32> {
        let cells: Vec<u32> = (0..(self.layout.width * self.layout.height) as u32).collect();
        self.latent.model().prior_mean(&cells)
    }
}
