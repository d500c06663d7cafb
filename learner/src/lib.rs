//! # learner — models and algorithms (tch)
//!
//! Shang et al. 2019 (arXiv:1907.00664): the recurrent variational model that
//! discovers pivotal states (section 3.1, [`vae`]), the curiosity-driven
//! goal-conditioned policy `π_g` (section 3.2), and the stage-2 agents (A2C,
//! Feudal Manager/Worker with Wide-then-Narrow goals, section 4).
//!
//! [`vae::LatentModel`] reads padded batches of agent trajectories
//! ([`vae::TrajectoryBatch`]), learns a Beta prior per state, and ranks the
//! visited states by prior mean into the pivotal states `V_p`; its per-step
//! action reconstruction error is the curiosity bonus of `π_g`.

pub mod a2c;
pub mod batch_env;
pub mod checkpoint;
pub mod discovery;
pub mod edge_refinement;
pub mod error;
pub mod experience;
pub mod gcp;
pub mod hrl;
pub mod identity;
pub mod run;
pub mod seeding;
pub mod serving_policy;
pub mod vae;

pub use error::{ConfigError, LearnerError};
