//! The settings of `π_g` that are not the paper's, and their code:
//!
//! - the goal distance of a curriculum
//!   ([`GoalConditionedPolicy::set_goal_distance`], driven by the discovery
//!   loop's [`crate::discovery::GoalCurriculum`]);
//! - recording a chain of goal episodes only up to its last reached goal
//!   ([`super::GcpConfig::record_missed_legs`] off; on by default).

use super::GoalConditionedPolicy;
use super::goals::GoalEpisode;

impl GoalConditionedPolicy {
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
}

impl GoalEpisode {
    /// Cuts the recorded trajectory back to the last goal it reached: the
    /// missed leg goes ([`super::GcpConfig::record_missed_legs`] off).
    pub(super) fn drop_missed_leg(&mut self) {
        self.trajectory.actions.truncate(self.reached);
        self.trajectory.states.truncate(self.reached + 1);
    }
}
