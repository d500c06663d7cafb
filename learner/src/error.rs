//! Errors of the `learner` crate.

use thiserror::Error;

/// A configuration value out of its valid range, found by a `validate()`.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
#[error("invalid config `{field}`: {reason}")]
pub struct ConfigError {
    /// The offending field, as spelled in the config file (`section.field`
    /// inside a section).
    pub field: std::borrow::Cow<'static, str>,
    /// What is wrong with its value.
    pub reason: String,
}

impl ConfigError {
    /// An error for `field` with a human-readable `reason`.
    pub fn new(
        field: impl Into<std::borrow::Cow<'static, str>>,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// Errors returned by the models and algorithms of this crate.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum LearnerError {
    /// A configuration failed validation.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A batch needs at least one trajectory.
    #[error("a trajectory batch needs at least one trajectory")]
    EmptyBatch,
    /// A trajectory of the latent model needs its two boundary states.
    #[error("trajectory {index} has {states} states; at least 2 are needed (z_0 = z_T = 1)")]
    TrajectoryTooShort {
        /// Position of the trajectory in the batch.
        index: usize,
        /// Its number of states.
        states: usize,
    },
    /// `τ = {(s_t, a_t)}_{t=0..T}` has one action fewer than states.
    #[error("trajectory {index} has {states} states but {actions} actions (expected {})", states.saturating_sub(1))]
    ActionCountMismatch {
        /// Position of the trajectory in the batch.
        index: usize,
        /// Its number of states.
        states: usize,
        /// Its number of actions.
        actions: usize,
    },
    /// A state or action field outside the range the model was built for.
    #[error("{what} {value} out of range: the model was built for {limit} values")]
    OutOfRange {
        /// Which field (`cell`, `direction`, `carried`, `action`).
        what: &'static str,
        /// The offending value.
        value: i64,
        /// The number of values the model embeds.
        limit: i64,
    },
    /// An error from libtorch.
    #[error(transparent)]
    Torch(#[from] tch::TchError),
    /// The batch environment failed (transport, dead peer, interruption).
    #[error(transparent)]
    Env(#[from] crate::batch_env::EnvError),
    /// A checkpoint or model file could not be written or read back.
    #[error("checkpoint {path}: {message}")]
    Checkpoint {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// Building the world graph failed.
    #[error(transparent)]
    Planner(#[from] planner::PlannerError),
    /// The environment batch is not the one a policy was built for.
    #[error(
        "the policy was built for {expected_envs} environments on a {expected_width}×{expected_height} grid; got {envs} on {width}×{height}"
    )]
    ShapeMismatch {
        /// Environments the policy was built for.
        expected_envs: usize,
        /// Grid columns it was built for.
        expected_width: usize,
        /// Grid rows it was built for.
        expected_height: usize,
        /// Environments of the batch.
        envs: usize,
        /// Grid columns of the batch.
        width: usize,
        /// Grid rows of the batch.
        height: usize,
    },
}
