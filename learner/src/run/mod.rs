//! Runs: the paper's experimental protocol as a library, so that the
//! commands are argument parsing and printing.
//!
//! - [`config`]: a training run's settings (`config.toml`), `--config` and
//!   `--set`, the budget it trains, and its identity.
//! - [`crate::identity`] (beside this module, as the discovery loop's
//!   checkpoint uses it too): the one comparison of a saved run record
//!   with this run's.
//! - [`dir`]: a run directory: what kind of run it holds, its lock, its
//!   record of invocations.
//! - [`artefact`]: the discovery run as stage 1's artefact, and the
//!   hand-off from stage 1 to stage 2 (graph over the candidate set, `π_g`,
//!   the agent built on them).
//! - [`protocol`]: section 5's protocol: seed streams, segments,
//!   checkpoints, the best checkpoint and the test summary.
//! - [`train_run`]: a training run as a value: opened (new or resumed),
//!   trained, tested.
//! - [`discovery_run`]: a discovery run as a value: opened (new, resumed
//!   or continued), run round by round, its world graph written.

pub mod artefact;
pub mod config;
pub mod dir;
pub mod discovery_run;
pub mod protocol;
pub mod train_run;
