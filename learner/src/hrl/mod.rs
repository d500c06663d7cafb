//! Stage 2 of Shang et al. 2019 (section 4): agents that solve the maze
//! tasks with the world graph of stage 1.
//!
//! The paper's parts, one module each:
//!
//! - [`baseline`]: the A2C-LSTM baseline (section 4.1), a flat agent of
//!   its own ([`A2cAgent`]);
//! - [`feudal`]: the Feudal Manager's network on its own time scale
//!   (section 4.1);
//! - [`wide_narrow`]: Wide-then-Narrow Manager instructions (section 4.2);
//! - `manager`: the Manager's side of an agent — network, optimiser, the
//!   candidates `V`, and its decisions `(g_w, g_n)` (sections 4.1–4.2);
//! - [`worker`]: the goal-conditioned Worker, its reward and its side of
//!   an agent (sections 4.1–4.2);
//! - [`traversal`]: world graph traversal and its execution (section 4.3);
//! - [`steering`]: `π_g` steering traversals in stochastic worlds, and its
//!   fine-tuning (section 4.3);
//! - [`init`]: initialisation from `π_g` (section 4.4).
//!
//! And the agent that puts them together:
//!
//! - [`config`]: the agent's settings and what it takes from stage 1;
//! - `agent`: [`HrlAgent`], its owners, how it is built, its checkpoints;
//! - `controller`: what the hierarchy carries from one step to the next
//!   (goals, traversals, core states, decision queues, the action RNG);
//! - `run`: a batch step, training iterations, evaluation;
//! - [`stats`]: what training and evaluation report.
//!
//! [`HrlAgent`] runs a hierarchy on a
//! [`BatchEnvironment`](crate::batch_env::BatchEnvironment): `FN` (Manager
//! over every valid cell) or `WN` (wide goals from `V_all`, `V_rand` or
//! `V_p`), each optionally initialised from `π_g`, WN optionally with
//! traversal; [`A2cAgent`] runs the flat baseline, and [`Agent`]
//! (`stage2`) is either, as a run trains it. Training is the A2C core's
//! ([`crate::a2c`]): the baseline and the Worker learn from `[T, B]`
//! rollouts ([`crate::a2c::learner::A2cLearner`]), the Manager from its
//! decision queues.
//!
//! A run starts its training stream once ([`HrlAgent::start_segment`]) and
//! carries it across validations; a checkpoint saves the controller
//! ([`HrlAgent::save_controller`]) beside the environments' states, so a
//! resumed run goes on exactly where it stopped.

mod agent;
pub mod baseline;
pub mod config;
mod controller;
pub mod feudal;
pub mod init;
mod iteration;
mod manager;
mod manager_kernels;
pub mod reports;
mod stage2;
pub mod steering;
pub mod traversal;
pub mod wide_narrow;
pub mod worker;

pub use agent::HrlAgent;
pub use baseline::A2cAgent;
pub use config::{
    AgentConfig, AgentKind, Candidates, DoorKeyActions, HandOver, ObjectActionInit, WorkerTaskEnd,
    WorldGraphInputs,
};
pub use controller::SavedController;
pub use reports::{EpisodeTrace, EvalResult, IterationStats, opened_a_door};
pub use stage2::Agent;

#[cfg(test)]
mod tests;
