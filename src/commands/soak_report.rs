//! What `worldgraph soak` reports ([`SoakReport`]): its figures, each
//! kill and what followed ([`Recovery`]), and with `--learner-trains` what
//! the kills cost the training ([`TrainingReport`], [`KillCost`]). The
//! soak (`soak`) fills them in, its training analysis (`soak_training`)
//! the training's part; they live here so that neither of the two needs
//! the other for them.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::pipeline::Role;

/// One kill and what followed.
#[derive(Debug, Serialize)]
pub struct Recovery {
    /// Seconds into the soak.
    pub at_s: f64,
    /// The process killed.
    pub role: Role,
    /// Its pid.
    pub pid: Option<u32>,
    /// Seconds from the kill until batches flowed again (None: not within the limit).
    pub recovered_after_s: Option<f64>,
    /// With --learner-trains: what the kill cost the training.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub training: Option<KillCost>,
}

/// The soak report.
#[derive(Debug, Serialize)]
pub struct SoakReport {
    /// Minutes run.
    pub minutes: f64,
    /// Seconds from the start until the pipeline flowed (the sim published
    /// and, with --learner-trains, the learner finished an iteration); the
    /// kill clock starts then. None: it never did, and the soak fails.
    pub flowed_after_s: Option<f64>,
    /// Batches published by all sim processes.
    pub batches: u64,
    /// Batches lost (learner streams).
    pub lost: u64,
    /// Batches reordered (learner streams).
    pub reordered: u64,
    /// Times a learner saw the sim start over.
    pub sim_restarts_seen: u64,
    /// Kills and recoveries.
    pub recoveries: Vec<Recovery>,
    /// Largest resident-set growth per role (KiB), over processes that lived ≥ 60 s.
    pub rss_growth_kib: BTreeMap<String, i64>,
    /// Largest resident set per role (KiB).
    pub rss_max_kib: BTreeMap<String, u64>,
    /// Per soak minute: the median of the sims' 250 ms round-trip p99s (µs).
    pub roundtrip_p99_us_per_minute: Vec<f64>,
    /// Per soak minute: the worst 250 ms round-trip p99 (µs).
    pub roundtrip_p99_us_worst_interval_per_minute: Vec<f64>,
    /// The run's shared-memory files left after teardown.
    pub shm_left_behind: Vec<String>,
    /// With --learner-trains: iterations, checkpoints, what kills cost.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub training: Option<TrainingReport>,
    /// Everything held.
    pub ok: bool,
}

/// What one kill cost the training.
#[derive(Debug, Serialize)]
pub struct KillCost {
    /// Learner kills: iterations done since its last checkpoint (None when
    /// no successor started within the soak).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations_lost: Option<u64>,
    /// The longest time (s) without an iteration finishing in the pause
    /// window after the kill (`soak_training::PAUSE_WINDOW_S`; None: no
    /// iteration after it).
    pub pause_s: Option<f64>,
}

/// The soak's training section.
#[derive(Debug, Serialize)]
pub struct TrainingReport {
    /// Checkpoint interval (iterations).
    pub checkpoint_every: u64,
    /// Learner processes that trained.
    pub learner_processes: usize,
    /// Iterations finished by all learner processes, lost ones included.
    pub iterations_run: u64,
    /// Iterations in the final checkpoint (the work kept).
    pub iterations_kept: u64,
    /// Iterations lost to learner kills, in all.
    pub iterations_lost: u64,
    /// Checkpoints written by all learner processes.
    pub checkpoints_written: u64,
    /// Rollouts dropped because the sim died or restarted during them.
    pub rollouts_dropped: u64,
    /// Median seconds between two iterations of one process.
    pub median_iteration_s: f64,
    /// Why the final checkpoint could not be loaded (None: it loads).
    pub final_checkpoint_error: Option<String>,
}
