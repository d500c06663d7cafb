//! `learner serve --policy train-gcp`: the learner trains `π_g` (the
//! goal-conditioned policy, section 3.2) on the shared-memory stream and
//! survives being killed.
//!
//! - **One slice.** A rollout steps the whole batch lock-step, so the sim
//!   must publish it as one slice (`--slices 1`); more is a configuration
//!   error ([`check_slices`]).
//! - **Checkpoints.** Every `--checkpoint-every` iterations, and at a clean
//!   stop, π_g's weights (`gcp.ot`) and a small state (`state.json`:
//!   iterations done, env steps, the run's maze, batch and configuration)
//!   are committed together into `<run dir>/learner-train/`
//!   ([`learner::checkpoint::commit`]: atomic, whole or not at all).
//! - **Resume.** A learner that starts finds the checkpoint and goes on
//!   from its iteration count; a checkpoint of another maze, batch size,
//!   task or configuration is refused, naming the field. As in discovery
//!   (`learner::discovery`), Adam's moments are not checkpointed: a
//!   resumed learner starts a fresh optimiser, and its goal samplers and
//!   action RNG are reseeded from the seed and the iteration count
//!   ([`GoalConditionedPolicy::start_round`]).
//! - **What a kill costs.** Every process appends one line per iteration to
//!   `<run dir>/learner-train.jsonl` (pid, time, iterations done, the last
//!   checkpointed iteration), plus a `start` line with the iteration it
//!   resumed from and a `stop` line, so the work a killed learner lost
//!   (iterations since its last checkpoint, and the rollout it was in) can
//!   be counted afterwards (`worldgraph soak --learner-trains`).
//! - **A sim that dies during a rollout**: the partial rollout is dropped
//!   (the next iteration's rollout starts afresh, goal episodes of moved
//!   agents restart), the learner waits for a sim to rejoin and goes on;
//!   the iteration count is unchanged. A sim restarted so quickly that the
//!   stream only shows its batches starting over ([`ShmEnv`] counts a sim
//!   restart) drops the rollout too ([`RestartGuard`]): no transition of
//!   it spans two simulators. Each dropped rollout is a `dropped` line.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use iceoryx2::prelude::ipc;
use learner::LearnerError;
use learner::batch_env::{BatchEnvironment, EnvError, ObsView};
use learner::gcp::{GcpConfig, GoalConditionedPolicy};
use serde::{Deserialize, Serialize};
use sim::Layout;

use super::RunCtx;
use super::policy_loop::{PolicyKind, Served, StreamLog, TrainSummary, after_sim_death};
use super::shm_env::ShmEnv;
use crate::latency::Latencies;

/// The checkpoint directory inside the run directory.
pub const CHECKPOINT_DIR: &str = "learner-train";
/// The training log inside the run directory (one JSON line per iteration).
pub const TRAIN_LOG: &str = "learner-train.jsonl";

/// Refuses `train-gcp` with more than one slice: a rollout steps the whole
/// batch lock-step.
pub fn check_slices(policy: PolicyKind, slices: usize) -> anyhow::Result<()> {
    anyhow::ensure!(
        policy != PolicyKind::TrainGcp || slices == 1,
        "--policy train-gcp trains on the whole batch lock-step: it needs --slices 1, \
         not {slices}"
    );
    Ok(())
}

/// `state.json` of a training checkpoint.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrainState {
    /// Training iterations (rollout + A2C update) the weights have had.
    pub iterations: u64,
    /// Environment steps (per environment) of those iterations.
    pub env_steps: u64,
    /// The maze's name.
    pub maze: String,
    /// The maze's size.
    pub grid: (usize, usize),
    /// Environments in the batch.
    pub envs: usize,
    /// The task.
    pub task: String,
    /// π_g's configuration.
    pub gcp: GcpConfig,
}

impl TrainState {
    fn fresh(layout: &Layout, envs: usize, task: &str) -> TrainState {
        TrainState {
            iterations: 0,
            env_steps: 0,
            maze: layout.name.clone(),
            grid: (layout.width, layout.height),
            envs,
            task: task.into(),
            gcp: GcpConfig::default(),
        }
    }

    /// The first field in which a checkpoint's state differs from this
    /// run (its progress aside): `maze is "small" in the checkpoint,
    /// "medium" now`.
    fn difference(&self, now: &TrainState) -> Option<String> {
        learner::identity::differences(self, now, &["iterations", "env_steps"])
            .into_iter()
            .next()
            .map(|d| {
                // The settings a user gives as flags are named as flags.
                let name = match d.path.as_str() {
                    "envs" | "task" => format!("--{}", d.path),
                    p if p.starts_with("gcp.") => format!("π_g's {}", &p[4..]),
                    p => p.to_string(),
                };
                format!("{name} is {} in the checkpoint, {} now", d.saved, d.now)
            })
    }
}

/// A π_g for this run, resumed from the checkpoint in `dir` when there is
/// one (refused when it belongs to another maze, batch, task or
/// configuration); with the state it resumed at.
pub fn open(
    dir: &Path,
    layout: &Layout,
    envs: usize,
    task: &str,
    num_actions: usize,
    seed: u64,
) -> anyhow::Result<(GoalConditionedPolicy, TrainState)> {
    let now = TrainState::fresh(layout, envs, task);
    let mut gcp = GoalConditionedPolicy::new(&now.gcp, layout, envs, num_actions, seed)?;
    learner::checkpoint::recover(dir)?;
    let path = dir.join("state.json");
    let state = match std::fs::read(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => now,
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
        Ok(bytes) => {
            let saved: TrainState = serde_json::from_slice(&bytes)
                .with_context(|| format!("{} is not a training state", path.display()))?;
            if let Some(d) = saved.difference(&now) {
                anyhow::bail!(
                    "{}: {d}; use another run directory or the same settings",
                    path.display()
                );
            }
            gcp.load(dir.join("gcp.ot"))?;
            saved
        }
    };
    // Fresh Adam, samplers reseeded from the iteration count (see the
    // module doc): a checkpoint is weights and counters only.
    gcp.start_round(sim::env_seed(seed, state.iterations))?;
    Ok((gcp, state))
}

/// The stream as π_g's rollout sees it: a step after which the sim turns
/// out to have restarted (its batches start over) fails, so the rollout
/// that began on the old sim is dropped rather than stitched onto the new
/// one.
struct RestartGuard<'a> {
    env: &'a mut ShmEnv<ipc::Service>,
    restarts: u64,
    restarted: bool,
}

impl BatchEnvironment for RestartGuard<'_> {
    fn num_envs(&self) -> usize {
        self.env.num_envs()
    }
    fn num_actions(&self) -> usize {
        self.env.num_actions()
    }
    fn observe(&self) -> ObsView<'_> {
        self.env.observe()
    }
    fn step(&mut self, actions: &[u8]) -> Result<(), EnvError> {
        self.env.step(actions)?;
        let restarts = self.env.stats().sim_restarts;
        if restarts != self.restarts {
            self.restarts = restarts;
            self.restarted = true;
            return Err(EnvError::PeerGone {
                peer: "sim",
                detail: "its batches started over (a restarted sim)".into(),
            });
        }
        Ok(())
    }
}

/// The training learner of one process.
pub struct Trainer {
    gcp: GoalConditionedPolicy,
    state: TrainState,
    dir: PathBuf,
    every: u64,
    log: std::fs::File,
    pid: u32,
    resumed_from: u64,
    last_checkpoint: u64,
    checkpoints_written: u64,
    rollouts_dropped: u64,
}

fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

impl Trainer {
    /// Opens (or resumes) the training of this run; `every` is the
    /// checkpoint interval in iterations (≥ 1).
    pub fn open(
        run_dir: &Path,
        layout: &Layout,
        envs: usize,
        task: &str,
        num_actions: usize,
        seed: u64,
        every: u64,
    ) -> anyhow::Result<Trainer> {
        anyhow::ensure!(every >= 1, "--checkpoint-every must be at least 1");
        let dir = run_dir.join(CHECKPOINT_DIR);
        let (gcp, state) = open(&dir, layout, envs, task, num_actions, seed)?;
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(run_dir.join(TRAIN_LOG))
            .with_context(|| format!("cannot open {}", run_dir.join(TRAIN_LOG).display()))?;
        let it = state.iterations;
        let mut t = Trainer {
            gcp,
            state,
            dir,
            every,
            log,
            pid: std::process::id(),
            resumed_from: it,
            last_checkpoint: it,
            checkpoints_written: 0,
            rollouts_dropped: 0,
        };
        t.log_line("start", None, false)?;
        Ok(t)
    }

    fn log_line(
        &mut self,
        event: &str,
        stats: Option<&learner::gcp::GcpStats>,
        checkpointed: bool,
    ) -> anyhow::Result<()> {
        let mut v = serde_json::json!({
            "pid": self.pid,
            "unix_ms": unix_ms(),
            "event": event,
            "iteration": self.state.iterations,
            "checkpoint": self.last_checkpoint,
            "checkpointed": checkpointed,
            "env_steps": self.state.env_steps,
        });
        if let Some(s) = stats {
            v["success_rate"] = s.success_rate.into();
            v["policy_loss"] = s.policy_loss.into();
            v["entropy"] = s.entropy.into();
        }
        writeln!(self.log, "{v}")?;
        Ok(())
    }

    fn checkpoint(&mut self) -> anyhow::Result<()> {
        let weights = learner::checkpoint::var_store_bytes(self.gcp.var_store())?;
        let state = serde_json::to_vec_pretty(&self.state)?;
        learner::checkpoint::commit(&self.dir, &[("gcp.ot", &weights), ("state.json", &state)])?;
        self.last_checkpoint = self.state.iterations;
        self.checkpoints_written += 1;
        Ok(())
    }

    /// Trains until stopped (a sim that dies is waited for, as the run's
    /// `--on-peer-death` says), checkpointing as configured and at the end.
    pub fn run(
        mut self,
        ctx: &RunCtx,
        env: &mut ShmEnv<ipc::Service>,
        stream_log: &mut StreamLog,
        lat: &mut Latencies,
    ) -> anyhow::Result<Served> {
        for h in ["iteration", "checkpoint"] {
            lat.register(h);
        }
        let steps = self.gcp.config().rollout_len as u64;
        let (mut batches, mut next_stream_line) = (0u64, Instant::now());
        let stopped_by = loop {
            if ctx.should_stop() {
                break "stop request";
            }
            let t0 = Instant::now();
            let mut guarded = RestartGuard {
                restarts: env.stats().sim_restarts,
                env,
                restarted: false,
            };
            let result = self.gcp.train_iteration(&mut guarded, None);
            let restarted = guarded.restarted;
            match result {
                Ok(stats) => {
                    lat.record("iteration", t0.elapsed().as_nanos() as u64);
                    // Trajectories are the latent model's input; nobody
                    // reads them here.
                    drop(self.gcp.take_trajectories());
                    batches += steps;
                    self.state.iterations += 1;
                    self.state.env_steps += steps;
                    let due = self.state.iterations.is_multiple_of(self.every);
                    if due {
                        let t1 = Instant::now();
                        self.checkpoint()?;
                        lat.record("checkpoint", t1.elapsed().as_nanos() as u64);
                    }
                    self.log_line("iteration", Some(&stats), due)?;
                }
                Err(LearnerError::Env(EnvError::Interrupted)) => break "stop request",
                Err(LearnerError::Env(EnvError::PeerGone { detail, .. })) => {
                    // The partial rollout is dropped: the next iteration's
                    // rollout starts afresh from the new sim's batch.
                    self.rollouts_dropped += 1;
                    self.log_line("dropped", None, false)?;
                    if restarted {
                        eprintln!("learner: the sim restarted during a rollout; rollout dropped");
                    } else if let Some(why) = after_sim_death(ctx, env, &detail)? {
                        break why;
                    }
                }
                Err(e) => return Err(e.into()),
            }
            if Instant::now() >= next_stream_line {
                next_stream_line = Instant::now() + Duration::from_millis(250);
                stream_log.write(env.stats())?;
                ctx.report_on_request(lat);
            }
        };
        let wrote = self.state.iterations > self.last_checkpoint;
        if wrote {
            self.checkpoint()?;
        }
        self.log_line("stop", None, wrote)?;
        eprintln!(
            "learner: π_g at iteration {} (resumed from {}), {} checkpoints written into {}",
            self.state.iterations,
            self.resumed_from,
            self.checkpoints_written,
            self.dir.display()
        );
        Ok(Served {
            policy: "train-gcp".into(),
            batches,
            episodes: 0,
            return_sum: 0.0,
            routes_ok: 0,
            routes_requested: 0,
            stopped_by: stopped_by.into(),
            training: Some(TrainSummary {
                resumed_from: self.resumed_from,
                iterations: self.state.iterations,
                env_steps: self.state.env_steps,
                checkpoints_written: self.checkpoints_written,
                last_checkpoint: self.last_checkpoint,
                rollouts_dropped: self.rollouts_dropped,
            }),
        })
    }
}
