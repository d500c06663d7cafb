//! The lever of `π_g` that is not the paper's: the distance of its
//! training goals ([`GoalConditionedPolicy::set_goal_distance`]), which
//! the discovery loop's goal curriculum moves round by round
//! (`discovery::GoalCurriculum`). The paper draws goals at "the end points
//! of random walks with reasonable length" (section 3.2) and leaves the
//! length open. The other setting that departs from the paper,
//! [`super::GcpConfig::record_missed_legs`], is a flag of the goal
//! episodes (`goals.rs`).

use super::GoalConditionedPolicy;

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
