//! # learner — models and algorithms (tch)
//!
//! Shang et al. 2019 (arXiv:1907.00664): the recurrent variational model that
//! discovers pivotal states (section 3.1), the curiosity-driven
//! goal-conditioned policy `π_g` (section 3.2), and the stage-2 agents (A2C,
//! Feudal Manager/Worker with Wide-then-Narrow goals, section 4).
#![deny(unsafe_code)]

pub mod vae;
pub mod actor_critic;
pub mod batch_env;
pub mod policy;
pub mod shm_env;
