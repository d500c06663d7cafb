//! The downstream tasks of the paper (section 5) and their rewards.
//!
//! Every action costs [`STEP_PENALTY`]. Then:
//! - **MultiGoal**: +1 per ball collected (balls are collected by stepping on
//!   them), +1 on reaching the exit, which ends the episode.
//! - **MultiGoal-Sparse**: no ball reward; on reaching the exit,
//!   `balls collected / balls spawned` (a single reward `r ≤ 1`).
//! - **MultiGoal-Stochastic**: MultiGoal plus a lava block re-spawned at a
//!   random free cell every step; stepping on it ends the episode with
//!   [`LAVA_PENALTY`].
//! - **Door-Key**: +1 when the locked door is opened with the key (once per
//!   episode), +1 on reaching the exit.

use serde::{Deserialize, Serialize};

/// Reward of every action.
pub const STEP_PENALTY: f32 = -0.01;
/// Reward of stepping on lava in MultiGoal-Stochastic.
pub const LAVA_PENALTY: f32 = -0.5;
/// Balls spawned per episode in the MultiGoal tasks.
pub const DEFAULT_BALLS: u8 = 5;

/// A downstream task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Task {
    /// Collect balls (+1 each) and leave by the exit (+1).
    MultiGoal,
    /// Collect balls; a single reward `balls/spawned` at the exit.
    MultiGoalSparse,
    /// MultiGoal with a lava block that moves every step (−0.5, ends the episode).
    MultiGoalStochastic,
    /// Pick up the key, open the locked door (+1), reach the exit (+1).
    DoorKey,
}

impl Task {
    /// All tasks.
    pub const ALL: [Task; 4] = [
        Task::MultiGoal,
        Task::MultiGoalSparse,
        Task::MultiGoalStochastic,
        Task::DoorKey,
    ];

    /// Command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Task::MultiGoal => "multigoal",
            Task::MultiGoalSparse => "multigoal-sparse",
            Task::MultiGoalStochastic => "multigoal-stochastic",
            Task::DoorKey => "doorkey",
        }
    }

    /// The paper's name: `MultiGoal`, `MultiGoal-Sparse`,
    /// `MultiGoal-Stochastic`, `Door-Key`.
    pub fn label(self) -> &'static str {
        match self {
            Task::MultiGoal => "MultiGoal",
            Task::MultiGoalSparse => "MultiGoal-Sparse",
            Task::MultiGoalStochastic => "MultiGoal-Stochastic",
            Task::DoorKey => "Door-Key",
        }
    }

    /// True for the three ball-collecting tasks.
    pub fn is_multigoal(self) -> bool {
        !matches!(self, Task::DoorKey)
    }

    /// Number of actions the task uses: MultiGoal tasks use left, right,
    /// forward; Door-Key adds pickup, drop and toggle (MiniGrid numbering).
    pub fn num_actions(self) -> usize {
        if self.is_multigoal() { 3 } else { 6 }
    }

    /// True when the Door-Key variant of a maze is the task's layout.
    pub fn uses_door_key_layout(self) -> bool {
        matches!(self, Task::DoorKey)
    }
}

impl std::str::FromStr for Task {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let k = s.to_ascii_lowercase().replace('_', "-");
        Task::ALL
            .into_iter()
            .find(|t| t.name() == k || (k == "door-key" && *t == Task::DoorKey))
            .ok_or_else(|| {
                format!("unknown task {s:?}: expected multigoal, multigoal-sparse, multigoal-stochastic or doorkey")
            })
    }
}

impl std::fmt::Display for Task {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
