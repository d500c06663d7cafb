//! One maze environment: MiniGrid's movement, pickup, drop and toggle rules
//! plus the task rewards of [`crate::task`].
//!
//! ## Actions (MiniGrid numbering)
//! 0 turn left, 1 turn right, 2 forward, 3 pickup, 4 drop, 5 toggle, 6 done.
//! - *forward* moves onto floor, open doors, the exit and lava (MiniGrid's
//!   `can_overlap`); in MultiGoal tasks it also moves onto a ball, which is
//!   collected. Walls, keys, closed and locked doors block it.
//! - *pickup* takes a key or ball in front when the hands are empty.
//! - *drop* puts the carried object on the empty floor in front.
//! - *toggle* opens a closed door, closes an open one, and unlocks (and
//!   opens) a locked one when the key is carried; the key is kept.
//! - *done* does nothing. Codes 7..=254 are treated as *done*.
//! - [`action::RESET`] (255) is not a MiniGrid action but a request from the
//!   learner: the environment starts a new episode now (flag `RESET`, reward
//!   0, no `DONE` flags). It travels in the action batch like any action, so
//!   both transports support it; discovery uses it to return to the start and
//!   replay recorded paths to pivotal states (section 3.2).
//!
//! ## Episode end and auto-reset
//! An episode **terminates** at the exit or on lava, and is **truncated** when
//! it reaches `max_steps` without terminating; the two are separate flags
//! ([`shm_schemas::flags`]). With [`AutoReset::SameStep`] (the default, as in
//! EnvPool and gymnasium's vector envs "same-step" mode) the step that ends
//! an episode returns the reward and flags of that step, the finished
//! episode's return, length and ball count in [`EnvMeta`], and **the first
//! observation of the next episode** (flag `RESET`); the finished episode's
//! final state stays readable: the pose the action led to in `EnvMeta`'s
//! `end_*` fields and the grid it ended on in the step's final cells
//! ([`Env::step`]), so consumers judge arrival on the last step and
//! bootstrap a truncated one from its final state. With [`AutoReset::Off`]
//! the environment stays on its final state until [`Env::reset`]; stepping
//! it again repeats the final flags with zero reward.
//!
//! ## Determinism
//! Every environment owns its RNG, seeded from `(seed, index)` by
//! [`env_seed`]; nothing else is random, so a batch gives the same result on
//! any number of threads.

use std::sync::Arc;

use rand::Rng;
use serde::{Deserialize, Serialize};
use shm_schemas::{EnvMeta, flags};

use crate::layout::{Layout, Pose};
use crate::object::Object;
use crate::rng::{ReplayRng, RngState};
use crate::task::{DEFAULT_BALLS, LAVA_PENALTY, STEP_PENALTY, Task};

/// Action codes, MiniGrid numbering.
pub mod action {
    /// Turn left.
    pub const LEFT: u8 = 0;
    /// Turn right.
    pub const RIGHT: u8 = 1;
    /// Move forward.
    pub const FORWARD: u8 = 2;
    /// Pick up the object in front.
    pub const PICKUP: u8 = 3;
    /// Drop the carried object in front.
    pub const DROP: u8 = 4;
    /// Open/close/unlock the door in front.
    pub const TOGGLE: u8 = 5;
    /// Do nothing.
    pub const DONE: u8 = 6;
    /// Start a new episode now (not a MiniGrid action; see the module docs).
    pub const RESET: u8 = 255;
    /// Names, indexed by code.
    pub const NAMES: [&str; 7] = [
        "left", "right", "forward", "pickup", "drop", "toggle", "done",
    ];
}

/// What happens when an episode ends; see the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AutoReset {
    /// The ending step returns the next episode's first observation.
    #[default]
    SameStep,
    /// The environment waits for an explicit [`Env::reset`].
    Off,
}

/// Where the balls of the MultiGoal tasks come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BallSpawn {
    /// This many balls at random free cells each episode (the paper: 5).
    Random(u8),
    /// Only the balls drawn in the layout.
    Layout,
}

/// Settings of one environment (shared by a batch).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvConfig {
    /// The task, which decides rewards and terminations.
    pub task: Task,
    /// Step limit; reaching it truncates the episode.
    pub max_steps: u32,
    /// Ball spawning of the MultiGoal tasks.
    pub balls: BallSpawn,
    /// Auto-reset mode.
    pub auto_reset: AutoReset,
}

impl Default for EnvConfig {
    fn default() -> Self {
        EnvConfig {
            task: Task::MultiGoal,
            max_steps: 500,
            balls: BallSpawn::Random(DEFAULT_BALLS),
            auto_reset: AutoReset::SameStep,
        }
    }
}

impl EnvConfig {
    /// The usual configuration of a task on an embedded maze: random balls
    /// for MultiGoal tasks, none for Door-Key, and a step limit of twice the
    /// number of free cells.
    pub fn for_task(task: Task, layout: &Layout) -> EnvConfig {
        EnvConfig {
            task,
            max_steps: (2 * layout.free_cells().len()) as u32,
            balls: if task.is_multigoal() {
                BallSpawn::Random(DEFAULT_BALLS)
            } else {
                BallSpawn::Layout
            },
            auto_reset: AutoReset::SameStep,
        }
    }
}

/// Seed of environment `index` in a run with seed `seed` (SplitMix64 of the
/// pair), so each environment's stream is independent of the others and of
/// the thread that steps it.
pub fn env_seed(seed: u64, index: u64) -> u64 {
    fn splitmix(mut z: u64) -> u64 {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    splitmix(splitmix(seed) ^ index.wrapping_mul(0xD6E8_FEB8_6659_FD93))
}

/// The saved state of one environment ([`Env::snapshot`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvState {
    grid: Vec<u8>,
    pos: u32,
    dir: u8,
    carrying: u8,
    rng: RngState,
    t: u32,
    episode_return: f32,
    balls: u8,
    balls_spawned: u8,
    door_opened: bool,
    lava: u32,
    done_flags: u8,
}

/// Static data shared by all environments of a batch.
#[derive(Debug)]
pub(crate) struct Shared {
    pub layout: Layout,
    pub cfg: EnvConfig,
    /// Floor cells of the layout other than the start: where balls and lava spawn.
    pub spawnable: Vec<u32>,
    /// Index offset of one step in each direction.
    pub dir_offset: [isize; 4],
}

impl Shared {
    pub(crate) fn new(layout: Layout, cfg: EnvConfig) -> Arc<Shared> {
        let start = layout.cell_index(layout.start.x as usize, layout.start.y as usize) as u32;
        let spawnable = layout
            .free_cells()
            .into_iter()
            .filter(|&i| i != start && layout.cells[i as usize] == Object::Floor as u8)
            .collect();
        let w = layout.width as isize;
        Arc::new(Shared {
            layout,
            cfg,
            spawnable,
            dir_offset: [1, w, -1, -w],
        })
    }
}

const NOTHING: u8 = EnvMeta::CARRYING_NOTHING;
const NO_LAVA: u32 = u32::MAX;

/// One environment. Cheap to clone (the layout is shared).
#[derive(Debug, Clone)]
pub struct Env {
    shared: Arc<Shared>,
    grid: Vec<u8>,
    /// Agent cell index.
    pos: usize,
    dir: u8,
    carrying: u8,
    rng: ReplayRng,
    t: u32,
    episode_return: f32,
    balls: u8,
    balls_spawned: u8,
    door_opened: bool,
    lava: u32,
    done_flags: u8,
}

impl Env {
    /// A new environment, already reset, with its RNG seeded from `(seed, index)`.
    pub fn new(layout: Layout, cfg: EnvConfig, seed: u64, index: u64) -> Env {
        Self::with_shared(Shared::new(layout, cfg), seed, index)
    }

    pub(crate) fn with_shared(shared: Arc<Shared>, seed: u64, index: u64) -> Env {
        let cells = shared.layout.cells.len();
        let mut env = Env {
            shared,
            grid: vec![0; cells],
            pos: 0,
            dir: 0,
            carrying: NOTHING,
            rng: ReplayRng::seed_from_u64(env_seed(seed, index)),
            t: 0,
            episode_return: 0.0,
            balls: 0,
            balls_spawned: 0,
            door_opened: false,
            lava: NO_LAVA,
            done_flags: 0,
        };
        env.reset_state();
        env
    }

    /// The layout this environment was built from.
    pub fn layout(&self) -> &Layout {
        &self.shared.layout
    }

    /// The configuration.
    pub fn config(&self) -> &EnvConfig {
        &self.shared.cfg
    }

    /// Current cell codes, row-major.
    pub fn grid(&self) -> &[u8] {
        &self.grid
    }

    /// Current agent pose.
    pub fn pose(&self) -> Pose {
        let w = self.shared.layout.width;
        Pose {
            x: (self.pos % w) as u16,
            y: (self.pos / w) as u16,
            dir: self.dir,
        }
    }

    /// Cell index of the agent.
    pub fn cell(&self) -> usize {
        self.pos
    }

    /// What the agent carries.
    pub fn carrying(&self) -> Option<Object> {
        Object::from_code(self.carrying)
    }

    /// Steps taken in the current episode.
    pub fn steps(&self) -> u32 {
        self.t
    }

    /// Balls collected in the current episode.
    pub fn balls_collected(&self) -> u8 {
        self.balls
    }

    /// True when an episode ended and (with [`AutoReset::Off`]) no reset followed.
    pub fn is_done(&self) -> bool {
        self.done_flags != 0
    }

    /// Everything that decides this environment's future: the grid, the
    /// agent, the episode's figures and the RNG's state. A training run
    /// saves it with its checkpoint, so that it resumes mid-episode exactly
    /// where it stopped ([`Env::restore`]).
    pub fn snapshot(&self) -> EnvState {
        EnvState {
            grid: self.grid.clone(),
            pos: self.pos as u32,
            dir: self.dir,
            carrying: self.carrying,
            rng: self.rng.state(),
            t: self.t,
            episode_return: self.episode_return,
            balls: self.balls,
            balls_spawned: self.balls_spawned,
            door_opened: self.door_opened,
            lava: self.lava,
            done_flags: self.done_flags,
        }
    }

    /// Puts the environment back in `state` (from [`Env::snapshot`] of an
    /// environment on the same layout).
    pub fn restore(&mut self, state: &EnvState) -> Result<(), crate::SimError> {
        if state.grid.len() != self.grid.len() || state.pos as usize >= self.grid.len() {
            return Err(crate::SimError::Config(format!(
                "a saved environment of {} cells (agent at {}) does not fit this layout of {} cells",
                state.grid.len(),
                state.pos,
                self.grid.len()
            )));
        }
        self.grid.copy_from_slice(&state.grid);
        self.pos = state.pos as usize;
        self.dir = state.dir & 3;
        self.carrying = state.carrying;
        self.rng = ReplayRng::from_state(state.rng);
        self.t = state.t;
        self.episode_return = state.episode_return;
        self.balls = state.balls;
        self.balls_spawned = state.balls_spawned;
        self.door_opened = state.door_opened;
        self.lava = state.lava;
        self.done_flags = state.done_flags;
        Ok(())
    }

    /// Places the agent at `pose` (its cell must be one the agent can stand
    /// on) without changing anything else. Used to start walks from pivotal
    /// states (section 3.2: the agent returns to them by recorded paths;
    /// in simulation the shortcut is exact).
    pub fn teleport(&mut self, pose: Pose) {
        let w = self.shared.layout.width;
        let i = pose.y as usize * w + pose.x as usize;
        debug_assert!(Object::from_code(self.grid[i]).is_some_and(Object::can_overlap));
        self.pos = i;
        self.dir = pose.dir & 3;
        self.done_flags = 0;
    }

    /// Starts a new episode and writes its first observation.
    pub fn reset(&mut self, cells: &mut [u8], meta: &mut EnvMeta) {
        self.reset_state();
        *meta = EnvMeta {
            flags: flags::RESET,
            ..EnvMeta::EMPTY
        };
        self.write_agent(meta);
        meta.end_at_agent();
        cells.copy_from_slice(&self.grid);
    }

    fn reset_state(&mut self) {
        let shared = Arc::clone(&self.shared);
        let sh = &*shared;
        self.grid.copy_from_slice(&sh.layout.cells);
        self.pos = sh
            .layout
            .cell_index(sh.layout.start.x as usize, sh.layout.start.y as usize);
        self.dir = sh.layout.start.dir;
        self.carrying = NOTHING;
        self.t = 0;
        self.episode_return = 0.0;
        self.balls = 0;
        self.door_opened = false;
        self.lava = NO_LAVA;
        self.done_flags = 0;
        self.balls_spawned = self
            .grid
            .iter()
            .filter(|&&c| c == Object::Ball as u8)
            .count() as u8;
        if sh.cfg.task.is_multigoal()
            && let BallSpawn::Random(n) = sh.cfg.balls
        {
            for _ in 0..n.min(sh.spawnable.len() as u8) {
                if let Some(i) = self.random_floor_cell() {
                    self.grid[i] = Object::Ball as u8;
                    self.balls_spawned += 1;
                }
            }
        }
        if sh.cfg.task == Task::MultiGoalStochastic {
            self.move_lava();
        }
    }

    /// A random spawnable cell that is floor now and not under the agent.
    /// Rejection sampling: spawnable cells are mostly floor, so this takes a
    /// couple of draws; the bound only guards degenerate layouts.
    fn random_floor_cell(&mut self) -> Option<usize> {
        let sp = &self.shared.spawnable;
        if sp.is_empty() {
            return None;
        }
        for _ in 0..64 {
            let i = sp[self.rng.random_range(0..sp.len())] as usize;
            if i != self.pos && self.grid[i] == Object::Floor as u8 {
                return Some(i);
            }
        }
        None
    }

    /// MultiGoal-Stochastic: the lava block moves to a random free cell.
    fn move_lava(&mut self) {
        if self.lava != NO_LAVA && self.grid[self.lava as usize] == Object::Lava as u8 {
            self.grid[self.lava as usize] = Object::Floor as u8;
        }
        self.lava = match self.random_floor_cell() {
            Some(i) => {
                self.grid[i] = Object::Lava as u8;
                i as u32
            }
            None => NO_LAVA,
        };
    }

    /// Applies one action; returns `(reward, terminated)`.
    #[inline]
    fn act(&mut self, action: u8) -> (f32, bool) {
        let task = self.shared.cfg.task;
        let mut reward = STEP_PENALTY;
        let mut terminated = false;
        let front = (self.pos as isize + self.shared.dir_offset[self.dir as usize]) as usize;
        match action {
            action::LEFT => self.dir = (self.dir + 3) & 3,
            action::RIGHT => self.dir = (self.dir + 1) & 3,
            action::FORWARD => {
                const FLOOR: u8 = Object::Floor as u8;
                const OPEN: u8 = Object::DoorOpen as u8;
                const BALL: u8 = Object::Ball as u8;
                const EXIT: u8 = Object::Exit as u8;
                const LAVA: u8 = Object::Lava as u8;
                match self.grid[front] {
                    FLOOR | OPEN => self.pos = front,
                    BALL if task.is_multigoal() => {
                        self.pos = front;
                        self.grid[front] = FLOOR;
                        self.balls += 1;
                        if task != Task::MultiGoalSparse {
                            reward += 1.0;
                        }
                    }
                    EXIT => {
                        self.pos = front;
                        terminated = true;
                        reward += match task {
                            Task::MultiGoalSparse => {
                                if self.balls_spawned == 0 {
                                    0.0
                                } else {
                                    self.balls as f32 / self.balls_spawned as f32
                                }
                            }
                            _ => 1.0,
                        };
                    }
                    LAVA => {
                        self.pos = front;
                        terminated = true;
                        reward += LAVA_PENALTY;
                    }
                    _ => {}
                }
            }
            action::PICKUP => {
                let c = self.grid[front];
                if self.carrying == NOTHING && (c == Object::Key as u8 || c == Object::Ball as u8) {
                    self.carrying = c;
                    self.grid[front] = Object::Floor as u8;
                }
            }
            action::DROP if self.carrying != NOTHING && self.grid[front] == Object::Floor as u8 => {
                self.grid[front] = self.carrying;
                self.carrying = NOTHING;
            }
            action::TOGGLE => match Object::from_code(self.grid[front]) {
                Some(Object::DoorLocked) if self.carrying == Object::Key as u8 => {
                    self.grid[front] = Object::DoorOpen as u8;
                    if task == Task::DoorKey && !self.door_opened {
                        self.door_opened = true;
                        reward += 1.0;
                    }
                }
                Some(Object::DoorClosed) => self.grid[front] = Object::DoorOpen as u8,
                Some(Object::DoorOpen) => self.grid[front] = Object::DoorClosed as u8,
                _ => {}
            },
            _ => {}
        }
        if task == Task::MultiGoalStochastic && !terminated {
            self.move_lava();
        }
        (reward, terminated)
    }

    /// Takes one action and writes the next observation: the grid into
    /// `cells` (`width × height` bytes) and the rest into `meta`; when the
    /// step ends the episode, the grid it ended on goes into `final_cells`
    /// (untouched otherwise). Allocates nothing. See the module docs for
    /// what an ending step returns.
    #[inline]
    pub fn step(
        &mut self,
        action: u8,
        cells: &mut [u8],
        final_cells: &mut [u8],
        meta: &mut EnvMeta,
    ) {
        self.advance(action, meta, Some(final_cells));
        cells.copy_from_slice(&self.grid);
    }

    /// Writes the current observation (grid and agent) without stepping:
    /// after [`Env::teleport`], the first observation of a rollout that
    /// starts at a chosen pose. The step fields of `meta` (reward, flags,
    /// episode figures) are cleared.
    pub fn observe(&self, cells: &mut [u8], meta: &mut EnvMeta) {
        *meta = EnvMeta::EMPTY;
        self.write_agent(meta);
        meta.end_at_agent();
        cells.copy_from_slice(&self.grid);
    }

    /// Takes one action and returns the step record without copying the
    /// grid out (read it with [`Env::grid`]). For traces and walks.
    pub fn step_meta(&mut self, action: u8) -> EnvMeta {
        let mut meta = EnvMeta::EMPTY;
        self.advance(action, &mut meta, None);
        meta
    }

    /// Everything of a step but the observation's grid copy: the final
    /// grid goes into `final_cells` when the step ends the episode.
    #[inline]
    fn advance(&mut self, action: u8, meta: &mut EnvMeta, final_cells: Option<&mut [u8]>) {
        if action == action::RESET {
            self.reset_state();
            *meta = EnvMeta {
                flags: flags::RESET,
                ..EnvMeta::EMPTY
            };
            self.write_agent(meta);
            meta.end_at_agent();
            return;
        }
        if self.done_flags != 0 {
            // AutoReset::Off and the episode is over: nothing moves.
            meta.reward = 0.0;
            meta.flags = self.done_flags;
            self.write_agent(meta);
            meta.end_at_agent();
            if let Some(f) = final_cells {
                f.copy_from_slice(&self.grid);
            }
            return;
        }
        let (reward, terminated) = self.act(action);
        self.t += 1;
        self.episode_return += reward;
        let truncated = !terminated && self.t >= self.shared.cfg.max_steps;
        meta.reward = reward;
        meta.episode_return = self.episode_return;
        meta.episode_len = self.t;
        meta.balls = self.balls;
        let mut f = 0;
        if terminated {
            f |= flags::TERMINATED;
        }
        if truncated {
            f |= flags::TRUNCATED;
        }
        // The pose the action led to, before any auto-reset.
        self.write_agent(meta);
        meta.end_at_agent();
        if f != 0 {
            if let Some(out) = final_cells {
                out.copy_from_slice(&self.grid);
            }
            match self.shared.cfg.auto_reset {
                AutoReset::SameStep => {
                    self.reset_state();
                    f |= flags::RESET;
                    // The observation is the next episode's first.
                    self.write_agent(meta);
                }
                AutoReset::Off => self.done_flags = f,
            }
        }
        meta.flags = f;
    }

    #[inline]
    fn write_agent(&self, meta: &mut EnvMeta) {
        let w = self.shared.layout.width;
        meta.x = (self.pos % w) as u16;
        meta.y = (self.pos / w) as u16;
        meta.dir = self.dir;
        meta.carrying = self.carrying;
    }

    /// Every door: `(x, y, state)`.
    pub fn doors(&self) -> Vec<(u16, u16, Object)> {
        let w = self.shared.layout.width;
        self.grid
            .iter()
            .enumerate()
            .filter_map(|(i, &c)| {
                let o = Object::from_code(c)?;
                o.is_door().then_some(((i % w) as u16, (i / w) as u16, o))
            })
            .collect()
    }

    /// Current observation as MiniGrid's `H × W × 3` (object, colour, state)
    /// encoding, agent included (`agent`, red, direction), row-major.
    pub fn minigrid_obs(&self) -> Vec<[u8; 3]> {
        minigrid_encode(&self.grid, self.pos, self.dir)
    }
}

/// MiniGrid's 3-channel encoding of a grid of cell codes with the agent at
/// cell `agent` facing `dir`: one `(object, colour, state)` triple per cell.
pub fn minigrid_encode(cells: &[u8], agent: usize, dir: u8) -> Vec<[u8; 3]> {
    cells
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            if i == agent {
                [
                    crate::object::minigrid_idx::AGENT,
                    crate::object::minigrid_color::RED,
                    dir,
                ]
            } else {
                Object::from_code(c).map_or([0, 0, 0], Object::minigrid)
            }
        })
        .collect()
}
