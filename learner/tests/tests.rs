//! Integration tests of the `learner` crate, built as one binary.

// tch trains a tiny network: libtorch links, autograd and Adam work.
mod tch_smoke;
// π_g learns to reach nearby goals; curiosity and trajectories are wired.
mod gcp_learns;
// The latent model ranks a four-room maze's doorways as pivotal states.
mod pivotal_doorways;
// Stage 2: the A2C baseline and WN with traversal and π_g init learn.
mod hrl_learns;
// π_g steering MultiGoal-Stochastic traversals is fine-tuned and checkpointed.
mod steering;
// WN: every free cell can be a narrow goal under V_p, V_rand and V_all.
mod window_coverage;
