//! The controller: what the hierarchy carries from one step of the batch
//! to the next (Shang et al. 2019, sections 4.1–4.3).
//!
//! The Manager and the Worker act on time scales of their own (section
//! 4.1): per environment the controller holds the Worker's goals of the
//! current interval (`g_w`, `g_n`; [`WorkerGoal`]), whether the Manager
//! has to decide before the next step, the world graph traversal under way
//! (section 4.3; [`Traversal`]) and, while training, the Manager's
//! decisions not trained yet ([`DecisionQueue`]). Beside them: the core
//! states of the Worker, the Manager and `π_g` (steering traversals), and
//! the action RNG.
//!
//! Training keeps one controller across its iterations and validations; a
//! checkpoint saves it ([`Controller::save`]) beside the environments'
//! states, so a resumed run goes on mid-episode exactly where it stopped.
//! Evaluation runs on a controller of its own.

use std::path::Path;

use serde::{Deserialize, Serialize};
use sim::{ReplayRng, RngState};
use tch::Tensor;

use super::feudal::{DecisionQueue, Manager};
use super::traversal::Traversal;
use super::worker::WorkerGoal;
use crate::a2c::input::NO_GOAL;
use crate::a2c::net::{ActorCritic, LstmState};
use crate::checkpoint::checkpoint_error;
use crate::error::LearnerError;
use crate::gcp::GoalConditionedPolicy;

/// Training visits of each cell, by environment: the count-based
/// exploration bonus `β / √n` ([`super::config::AgentConfig::count_bonus`];
/// MiniGrid's `PositionBonus`). Empty until the first bonus is paid.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub(super) struct VisitCounts(Vec<Vec<u32>>);

impl VisitCounts {
    /// Counts a training visit of `cell` (of a grid of `cells`) in
    /// environment `e` of `envs` and returns the bonus `beta / √n`, `n` the
    /// visits so far, this one included. With `fade` > 0 the bonus is
    /// scaled by `max(0, 1 − t / fade)`, `t` the env steps trained so far
    /// over all `envs` environments (this environment's visits, all cells,
    /// times `envs`: every environment steps once per batch step), so it
    /// is gone after `fade` env steps
    /// ([`super::config::AgentConfig::count_bonus_fade`]).
    pub(super) fn bonus(
        &mut self,
        e: usize,
        envs: usize,
        cell: u32,
        cells: usize,
        beta: f32,
        fade: u64,
    ) -> f32 {
        if self.0.is_empty() {
            self.0 = vec![vec![0; cells]; envs];
        }
        let row = &mut self.0[e];
        row[cell as usize] += 1;
        let n = row[cell as usize];
        let scale = if fade == 0 {
            1.0
        } else {
            let trained = row.iter().map(|&v| u64::from(v)).sum::<u64>() * envs as u64;
            (1.0 - trained as f64 / fade as f64).max(0.0) as f32
        };
        scale * beta / (n as f32).sqrt()
    }

    /// No bonus has been paid yet.
    pub(super) fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Environments counted (0 before the first bonus).
    pub(super) fn envs(&self) -> usize {
        self.0.len()
    }
}

/// The potential `Φ` of the state an observation's record leads from: the
/// balls collected so far in its episode, 0 at the start of one (a record
/// that ended an episode is followed by the next one's start)
/// ([`super::config::AgentConfig::ball_shaping`]).
pub(super) fn balls_before(meta: &shm_schemas::EnvMeta) -> u8 {
    if meta.done() { 0 } else { meta.balls }
}

/// [`balls_before`] of every environment of a batch's records, or nothing
/// when `shaping` is off (no allocation on the steps that need none).
pub(super) fn balls_before_batch(meta: &[shm_schemas::EnvMeta], shaping: bool) -> Vec<u8> {
    if shaping {
        meta.iter().map(balls_before).collect()
    } else {
        Vec::new()
    }
}

/// The shaping term `γ Φ(s') − Φ(s)` of one step with `Φ = weight × balls`
/// (Ng, Harada & Russell 1999; [`super::config::AgentConfig::ball_shaping`]):
/// `before` the balls before the step ([`balls_before`]), `meta` the step's
/// record. A step the task ended leads to no state (`Φ(s') = 0`); a cut one
/// keeps its balls, as its value is bootstrapped.
pub(super) fn ball_shaping(
    weight: f32,
    gamma: f64,
    before: u8,
    meta: &shm_schemas::EnvMeta,
) -> f32 {
    let after = if meta.terminated() {
        0.0
    } else {
        f32::from(meta.balls)
    };
    weight * (gamma as f32 * after - f32::from(before))
}

/// The balls one step collected: `before` the balls before it
/// ([`balls_before`]), `meta` its record (a record that ended the episode
/// still counts the episode's balls).
pub(super) fn balls_collected(before: u8, meta: &shm_schemas::EnvMeta) -> u8 {
    meta.balls.saturating_sub(before)
}

/// One environment's hierarchical state.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct EnvCtl {
    /// The Manager decides a new goal before the next step (the episode
    /// started or the interval ended).
    pub(super) need_decision: bool,
    /// Reset the Manager's core before its next decision.
    pub(super) manager_reset: bool,
    /// The Worker's goals of the current interval.
    pub(super) goal: WorkerGoal,
    /// The world graph traversal under way.
    pub(super) traversal: Option<Traversal>,
}

impl EnvCtl {
    /// An environment at the start of an episode: no goal, a decision due.
    fn fresh() -> EnvCtl {
        EnvCtl {
            need_decision: true,
            manager_reset: true,
            goal: WorkerGoal::new(NO_GOAL, NO_GOAL, NO_GOAL),
            traversal: None,
        }
    }
}

/// The per-batch state of an agent: core states, goals, traversals, the
/// action RNG, and (training) the Manager's decision queues.
#[derive(Debug)]
pub(super) struct Controller {
    /// The Worker's core state.
    pub(super) worker_state: LstmState,
    /// The Manager's core state.
    pub(super) manager_state: LstmState,
    /// `π_g`'s core state while it steers traversals (with `π_g`).
    pub(super) steer_state: Option<LstmState>,
    /// Each environment's goals and traversal.
    pub(super) envs: Vec<EnvCtl>,
    /// Each environment's Manager decisions not trained yet.
    pub(super) queues: Vec<DecisionQueue>,
    /// The Manager's core state before the first decision of each queue.
    pub(super) manager_init: Option<LstmState>,
    /// Draws the Worker's, the Manager's and `π_g`'s actions.
    pub(super) rng: ReplayRng,
    /// Training visits of each cell, by environment (the count-based
    /// bonus).
    pub(super) visits: VisitCounts,
}

/// What of a [`Controller`] is not a tensor, as saved with a training
/// checkpoint ([`Controller::save`]).
#[derive(Debug, Serialize, Deserialize)]
struct ControllerRecord {
    envs: Vec<EnvCtl>,
    queues: Vec<DecisionQueue>,
    rng: RngState,
    /// Absent from the checkpoints of runs before the count-based bonus.
    #[serde(default, skip_serializing_if = "VisitCounts::is_empty")]
    visits: VisitCounts,
}

/// A training controller as a checkpoint saves it
/// (`HrlAgent::save_controller`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SavedController {
    /// Goals, traversals, the Manager's decision queues and the action
    /// RNG's state (JSON).
    pub record: Vec<u8>,
    /// The core states of the Worker, the Manager and `π_g` (a tensor
    /// file).
    pub tensors: Vec<u8>,
}

impl Controller {
    /// A controller of `n` environments at the start of their episodes:
    /// zero core states of `worker`, `manager` and `pi_g`, every
    /// environment waiting for a decision, the action RNG seeded by `seed`.
    pub(super) fn new(
        n: usize,
        seed: u64,
        worker: &ActorCritic,
        manager: &Manager,
        pi_g: Option<&GoalConditionedPolicy>,
    ) -> Controller {
        Controller {
            worker_state: worker.zero_state(n as i64),
            manager_state: manager.zero_state(n as i64),
            steer_state: pi_g.map(|g| g.network().zero_state(n as i64)),
            envs: vec![EnvCtl::fresh(); n],
            queues: (0..n)
                .map(|_| DecisionQueue {
                    decisions: Vec::new(),
                })
                .collect(),
            manager_init: Some(manager.zero_state(n as i64)),
            rng: ReplayRng::seed_from_u64(seed),
            visits: VisitCounts::default(),
        }
    }

    /// The Worker's goals, by environment.
    pub(super) fn goals(&self) -> impl Iterator<Item = &WorkerGoal> {
        self.envs.iter().map(|e| &e.goal)
    }

    /// The traversal under way in each environment.
    pub(super) fn traversals(&self) -> Vec<Option<&Traversal>> {
        self.envs.iter().map(|e| e.traversal.as_ref()).collect()
    }

    /// Books a task reward of environment `e`'s step for the Manager's
    /// interval under way.
    pub(super) fn book_manager_reward(&mut self, e: usize, reward: f32) {
        if let Some(q) = self.queues[e].decisions.last_mut() {
            q.rewards.push(reward);
        }
    }

    /// Ends environment `e`'s interval: the Manager decides before the next
    /// step (from a fresh core if `episode_ended`), and the traversal under
    /// way ends. With `train`, the interval's decision is complete; returns
    /// whether there was one.
    pub(super) fn end_interval(&mut self, e: usize, episode_ended: bool, train: bool) -> bool {
        let c = &mut self.envs[e];
        c.need_decision = true;
        c.traversal = None;
        if episode_ended {
            c.manager_reset = true;
        }
        match self.queues[e].decisions.last_mut() {
            Some(q) if train => {
                q.complete = true;
                q.episode_ended = episode_ended;
                true
            }
            _ => false,
        }
    }

    /// Cuts the core states' graphs at the end of a training iteration.
    pub(super) fn detach(&mut self) {
        self.worker_state = self.worker_state.detach();
        self.manager_state = self.manager_state.detach();
        if let Some(s) = self.steer_state.as_mut() {
            *s = s.detach();
        }
    }

    /// The controller as a record and a tensor file.
    pub(super) fn save(&self) -> Result<SavedController, LearnerError> {
        let record = ControllerRecord {
            envs: self.envs.clone(),
            queues: self.queues.clone(),
            rng: self.rng.state(),
            visits: self.visits.clone(),
        };
        let json = serde_json::to_vec(&record).map_err(|e| checkpoint_error("controller", e))?;
        let tensors = save_core_states(&[
            ("worker", Some(&self.worker_state)),
            ("manager", Some(&self.manager_state)),
            ("steer", self.steer_state.as_ref()),
            ("manager_init", self.manager_init.as_ref()),
        ])?;
        Ok(SavedController {
            record: json,
            tensors,
        })
    }

    /// Replaces this controller (of an agent built for `envs`
    /// environments) by [`Self::save`]'s record and tensors of a controller
    /// of the same agent; `source` names them in errors. `π_g`'s core state
    /// stays as it is where the record has none.
    pub(super) fn restore(
        &mut self,
        json: &[u8],
        tensors: &[u8],
        source: &Path,
        envs: usize,
    ) -> Result<(), LearnerError> {
        let bad = |message: String| checkpoint_error(source, message);
        let record: ControllerRecord =
            serde_json::from_slice(json).map_err(|e| bad(e.to_string()))?;
        if record.envs.len() != envs
            || record.queues.len() != envs
            || !(record.visits.is_empty() || record.visits.envs() == envs)
        {
            return Err(bad(format!(
                "a controller of {} environments, the agent has {}",
                record.envs.len(),
                envs
            )));
        }
        let loaded = CoreStates::load(tensors).map_err(bad)?;
        let state = |name: &str| loaded.get(name).map_err(bad);
        let worker = state("worker")?.ok_or_else(|| bad("no Worker core state".into()))?;
        let (manager, steer, manager_init) =
            (state("manager")?, state("steer")?, state("manager_init")?);
        let manager = manager
            .filter(|_| worker.h.size() == self.worker_state.h.size())
            .ok_or_else(|| bad("the controller is of another agent".into()))?;
        *self = Controller {
            worker_state: worker,
            manager_state: manager,
            steer_state: steer.or_else(|| self.steer_state.take()),
            envs: record.envs,
            queues: record.queues,
            manager_init,
            rng: ReplayRng::from_state(record.rng),
            visits: record.visits,
        };
        Ok(())
    }
}

/// Core states `(name, state)` as a tensor file (`<name>/h`, `<name>/c`);
/// the absent ones are left out.
pub(super) fn save_core_states(
    states: &[(&str, Option<&LstmState>)],
) -> Result<Vec<u8>, LearnerError> {
    let mut named: Vec<(String, &Tensor)> = Vec::new();
    for (name, s) in states {
        if let Some(s) = s {
            named.push((format!("{name}/h"), &s.h));
            named.push((format!("{name}/c"), &s.c));
        }
    }
    let refs: Vec<(&str, &Tensor)> = named.iter().map(|(k, t)| (k.as_str(), *t)).collect();
    let mut tensors = Vec::new();
    Tensor::save_multi_to_stream(&refs, &mut tensors)?;
    Ok(tensors)
}

/// The core states of a tensor file of [`save_core_states`].
pub(super) struct CoreStates(Vec<(String, Tensor)>);

impl CoreStates {
    /// Reads `tensors`; an error says why it could not.
    pub(super) fn load(tensors: &[u8]) -> Result<CoreStates, String> {
        Tensor::load_multi_from_stream(std::io::Cursor::new(tensors))
            .map(CoreStates)
            .map_err(|e| e.to_string())
    }

    /// The state saved as `name`, if any; half a state is an error.
    pub(super) fn get(&self, name: &str) -> Result<Option<LstmState>, String> {
        let find = |k: String| self.0.iter().find(|(n, _)| *n == k).map(|(_, t)| t.copy());
        match (find(format!("{name}/h")), find(format!("{name}/c"))) {
            (Some(h), Some(c)) => Ok(Some(LstmState { h, c })),
            (None, None) => Ok(None),
            _ => Err(format!("half a core state {name}")),
        }
    }
}
