//! What running a stage 2 agent reports: a training iteration's figures
//! ([`IterationStats`]), an evaluation's scores ([`EvalResult`]) and one
//! evaluation episode for the picture of the paper's Figure 1
//! ([`EpisodeTrace`]); and the counts a batch step adds to
//! ([`StepCounts`], [`Decisions`]).

use serde::{Deserialize, Serialize};

use crate::a2c::LossFigures;

/// What one iteration measured.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct IterationStats {
    /// Env steps of the iteration.
    pub env_steps: u64,
    /// Episodes that ended.
    pub episodes: usize,
    /// Mean return of those episodes (0 when none).
    pub mean_return: f64,
    /// The Worker's (or the baseline's) loss.
    pub worker: LossFigures,
    /// The Manager's loss (zeros for A2C).
    pub manager: LossFigures,
    /// Manager intervals that ended (FN, WN).
    pub intervals: usize,
    /// Share of those in which the Worker reached `g_n`.
    pub goals_reached: f64,
    /// Share of env steps taken by graph traversal.
    pub traversal_share: f64,
    /// Share of the episodes that ended by reaching the exit.
    pub exit_share: f64,
    /// Manager decisions made (FN, WN).
    pub decisions: usize,
    /// Share of those whose narrow goal `g_n` is the exit.
    pub exit_goal_share: f64,
    /// Share of those whose narrow goal `g_n` held a ball when named.
    pub ball_goal_share: f64,
}

/// The result of an evaluation: one episode per environment.
#[derive(Debug, Clone, Serialize)]
pub struct EvalResult {
    /// Mean return (MultiGoal tasks) or success rate (Door-Key).
    pub score: f64,
    /// Mean episode return.
    pub mean_return: f64,
    /// Share of episodes that reached the exit.
    pub success_rate: f64,
    /// Episode returns, by environment.
    pub returns: Vec<f32>,
    /// Episode lengths.
    pub lengths: Vec<u32>,
    /// Share of steps taken by traversal.
    pub traversal_share: f64,
}

/// One evaluation episode, for the picture of the paper's Figure 1.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct EpisodeTrace {
    /// The agent's cell before the first step and after each (after the
    /// last, the cell the episode ended on).
    pub cells: Vec<u32>,
    /// Whether each step was taken by traversal.
    pub traversed: Vec<bool>,
    /// Manager decisions: `(step, g_w, g_n)`.
    pub goals: Vec<(u32, u32, u32)>,
    /// The episode's return.
    pub episode_return: f32,
    /// The grid the episode started on (row-major object codes, as
    /// `sim::Object`): its balls, key, doors, exit.
    #[serde(default)]
    pub start_cells: Vec<u8>,
    /// The grid the episode ended on (the step record's final cells of the
    /// step that ended it): a ball of `start_cells` missing here was
    /// collected. Empty when the transport carries no final cells.
    #[serde(default)]
    pub end_cells: Vec<u8>,
}

/// Counts of one rollout or evaluation.
#[derive(Debug, Default)]
pub(super) struct StepCounts {
    /// Environment steps.
    pub(super) steps: u64,
    /// Episodes that ended.
    pub(super) episodes: usize,
    /// The sum of their returns.
    pub(super) returns: f64,
    /// Those that ended on the exit.
    pub(super) successes: usize,
    /// Manager intervals that ended.
    pub(super) intervals: usize,
    /// Intervals in which `g_n` was reached.
    pub(super) reached: usize,
    /// Steps taken by world graph traversal.
    pub(super) traversal_steps: u64,
    /// Manager decisions.
    pub(super) decisions: usize,
    /// Decisions whose `g_n` was the exit.
    pub(super) exit_goals: usize,
    /// Decisions whose `g_n` held a ball.
    pub(super) ball_goals: usize,
}

impl StepCounts {
    /// Adds the decisions of one call of the Manager.
    pub(super) fn add(&mut self, d: Decisions) {
        self.decisions += d.count;
        self.exit_goals += d.exit_goals;
        self.ball_goals += d.ball_goals;
    }
}

/// The Manager's decisions of one call of
/// [`ManagerSide::decide`](super::manager::ManagerSide::decide).
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Decisions {
    /// Decisions made.
    pub(super) count: usize,
    /// Decisions whose narrow goal `g_n` is an exit cell.
    pub(super) exit_goals: usize,
    /// Decisions whose narrow goal `g_n` holds a ball.
    pub(super) ball_goals: usize,
}
