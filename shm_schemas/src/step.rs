//! Per-environment step records, written by the simulator in place.

use iceoryx2::prelude::ZeroCopySend;

/// Bits of [`EnvMeta::flags`].
pub mod flags {
    /// The episode ended by the task's own rule (exit reached, lava, ...).
    pub const TERMINATED: u8 = 1 << 0;
    /// The episode ended by the step limit.
    pub const TRUNCATED: u8 = 1 << 1;
    /// The observation is the first of a new episode (auto-reset happened,
    /// or the environment was just reset).
    pub const RESET: u8 = 1 << 2;
    /// `TERMINATED | TRUNCATED`: [`super::EnvMeta::episode_return`] and
    /// [`super::EnvMeta::episode_len`] hold the finished episode's figures.
    pub const DONE: u8 = TERMINATED | TRUNCATED;
}

/// What one environment reports after one step: the reward of the action,
/// how the episode stands, and the agent's state in the observation.
///
/// Position `x` is the column from the left, `y` the row from the top;
/// `dir` is 0 right, 1 down, 2 left, 3 up; `carrying` is a cell code
/// (`sim::Object as u8`) or [`EnvMeta::CARRYING_NOTHING`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("wg.EnvMeta.v1")]
pub struct EnvMeta {
    /// Reward of the step that produced this record.
    pub reward: f32,
    /// Return of the episode so far, or of the finished one when `flags & DONE`.
    pub episode_return: f32,
    /// Steps taken in the episode so far, or of the finished one when `flags & DONE`.
    pub episode_len: u32,
    /// Agent column.
    pub x: u16,
    /// Agent row.
    pub y: u16,
    /// Agent facing: 0 right, 1 down, 2 left, 3 up.
    pub dir: u8,
    /// Carried object's cell code, or [`EnvMeta::CARRYING_NOTHING`].
    pub carrying: u8,
    /// Bits from [`flags`].
    pub flags: u8,
    /// Balls collected in the current (or just finished) episode.
    pub balls: u8,
}

impl EnvMeta {
    /// Value of [`EnvMeta::carrying`] when the agent's hands are empty.
    pub const CARRYING_NOTHING: u8 = 0xff;

    /// A record with every field zero and nothing carried.
    pub const EMPTY: EnvMeta = EnvMeta {
        reward: 0.0,
        episode_return: 0.0,
        episode_len: 0,
        x: 0,
        y: 0,
        dir: 0,
        carrying: Self::CARRYING_NOTHING,
        flags: 0,
        balls: 0,
    };

    /// True when this step ended the episode (terminated or truncated).
    pub fn done(&self) -> bool {
        self.flags & flags::DONE != 0
    }
    /// True when the task's own rule ended the episode.
    pub fn terminated(&self) -> bool {
        self.flags & flags::TERMINATED != 0
    }
    /// True when the step limit ended the episode.
    pub fn truncated(&self) -> bool {
        self.flags & flags::TRUNCATED != 0
    }
}

impl Default for EnvMeta {
    fn default() -> Self {
        Self::EMPTY
    }
}

const _: () = assert!(std::mem::size_of::<EnvMeta>() == 20);
const _: () = assert!(std::mem::align_of::<EnvMeta>() == 4);
