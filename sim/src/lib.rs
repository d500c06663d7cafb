//! # sim — the maze simulator of worldgraph
//!
//! A batched, allocation-free re-implementation of the MiniGrid mazes used by
//! Shang et al. 2019, *Learning World Graphs to Accelerate Hierarchical
//! Reinforcement Learning* (arXiv:1907.00664), section 5 (README.md, "The environment contract").
//!
//! - [`layout`]: ASCII layouts ([`Layout`]), their validation, and the three
//!   embedded mazes ([`Maze`]: small, medium, large, each with a Door-Key
//!   variant).
//! - [`object`]: the one-byte cell codes ([`Object`]) and MiniGrid's
//!   3-channel encoding.
//! - [`task`]: the four tasks and their rewards ([`Task`]).
//! - [`env`]: one environment ([`Env`]), MiniGrid's action rules, episode
//!   termination/truncation and the auto-reset mode.
//! - [`batch`]: [`BatchEnv`], N environments stepped in parallel into
//!   caller-provided buffers.
//! - [`render`]: ASCII and PNG pictures, and the small raster [`render::Canvas`]
//!   other crates draw on.
//!
//! ```
//! use sim::{BatchEnv, EnvConfig, Maze, Task};
//! let layout = Maze::Small.layout(false);
//! let cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
//! let mut batch = BatchEnv::new(layout, cfg, 8, 42, 1).unwrap();
//! let mut buf = batch.buffers();
//! batch.reset(buf.out());
//! batch.step(&[2; 8], buf.out());
//! assert!(buf.meta.iter().all(|m| (m.reward - -0.01).abs() < 1e-6 || m.reward > 0.0));
//! ```
#![forbid(unsafe_code)]

pub mod atomic_file;
pub mod batch;
pub mod env;
mod error;
pub mod layout;
pub mod object;
pub mod render;
pub mod rng;
pub mod task;

pub use atomic_file::write_atomic;
pub use batch::{BatchEnv, StepBuffers, StepOut};
pub use env::{AutoReset, BallSpawn, Env, EnvConfig, EnvState, action, env_seed, minigrid_encode};
pub use error::SimError;
pub use layout::{Layout, LayoutError, LayoutErrorKind, Maze, Pose};
pub use object::Object;
pub use rng::{ReplayRng, RngState};
pub use shm_schemas::{EnvMeta, flags};
pub use task::Task;
