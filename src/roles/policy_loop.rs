//! What the learner process's policy loops share: which policy runs
//! ([`PolicyKind`]), what a loop did ([`Served`], with a training learner's
//! [`TrainSummary`]), the stream log every learner process appends to
//! ([`StreamLog`]), and what to do once the sim died
//! ([`after_sim_death`]). Both loops use them: the serving loop of
//! `random` and `actor-critic` (`learner`) and `train-gcp`'s
//! (`learner_train`); this module needs neither.

use std::io::Write;
use std::time::Duration;

use clap::ValueEnum;
use iceoryx2::prelude::ipc;
use learner::batch_env::{BatchEnvironment, EnvError};
use serde::Serialize;

use super::shm_env::{ShmEnv, StreamStats};
use super::{OnPeerDeath, RunCtx};

/// Which policy chooses the actions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
pub enum PolicyKind {
    /// Uniformly random actions (the benchmark's null policy).
    Random,
    /// The A2C-LSTM actor-critic's forward pass (CNN encoder + LSTM core).
    ActorCritic,
    /// Trains π_g (the goal-conditioned policy) by A2C on the stream, with
    /// checkpoints in `<run dir>/learner-train/` that a restarted learner
    /// resumes from; needs `--slices 1`.
    TrainGcp,
}

impl PolicyKind {
    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PolicyKind::Random => "random",
            PolicyKind::ActorCritic => "actor-critic",
            PolicyKind::TrainGcp => "train-gcp",
        }
    }
}

/// What a policy loop did (the report's figures).
pub struct Served {
    /// Policy name.
    pub policy: String,
    /// Batches answered.
    pub batches: u64,
    /// Episodes finished.
    pub episodes: u64,
    /// Sum of their returns.
    pub return_sum: f64,
    /// Routes received with status Ok.
    pub routes_ok: u64,
    /// Route requests sent.
    pub routes_requested: u64,
    /// Why the loop ended.
    pub stopped_by: String,
    /// With `train-gcp`: the training summary.
    pub training: Option<TrainSummary>,
}

/// `learner.stream.jsonl`: appended by every learner process of the run,
/// one line every 250 ms or so with its pid: what a soak test sums up even
/// for a killed learner.
pub struct StreamLog {
    file: std::fs::File,
    pid: u32,
}

impl StreamLog {
    /// Opens the run's log for appending (`dir`: the run directory).
    pub fn open(dir: &std::path::Path) -> std::io::Result<StreamLog> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join("learner.stream.jsonl"))?;
        Ok(StreamLog {
            file,
            pid: std::process::id(),
        })
    }

    /// Appends one line of `s`.
    pub fn write(&mut self, s: StreamStats) -> std::io::Result<()> {
        let line = serde_json::json!({ "pid": self.pid, "stream": s });
        writeln!(self.file, "{line}")
    }
}

/// What a training learner did, for `learner.report.json`.
#[derive(Debug, Serialize)]
pub struct TrainSummary {
    /// The iteration this process resumed from (0: a fresh π_g).
    pub resumed_from: u64,
    /// Iterations done at exit (all processes' kept work).
    pub iterations: u64,
    /// Environment steps at exit.
    pub env_steps: u64,
    /// Checkpoints this process wrote.
    pub checkpoints_written: u64,
    /// The last checkpointed iteration.
    pub last_checkpoint: u64,
    /// Rollouts this process dropped because the sim died or restarted.
    pub rollouts_dropped: u64,
}

/// After the sim died (`detail`): waits for a sim to rejoin when the run
/// says so (`--on-peer-death wait`). Returns why to stop, or `None` to go on.
pub fn after_sim_death(
    ctx: &RunCtx,
    env: &mut ShmEnv<ipc::Service>,
    detail: &str,
) -> anyhow::Result<Option<&'static str>> {
    eprintln!("learner: the sim is gone ({detail})");
    if ctx.on_peer_death == OnPeerDeath::Exit {
        return Ok(Some("sim died"));
    }
    eprintln!("learner: waiting for a sim to rejoin");
    match env.wait_for_peer(Duration::from_secs(3600)) {
        Ok(()) => {
            eprintln!("learner: a sim rejoined at batch {}", env.observe().seq);
            Ok(None)
        }
        Err(EnvError::Interrupted) => Ok(Some("stop request")),
        Err(e) => Err(e.into()),
    }
}
