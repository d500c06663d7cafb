//! `experiment GRID --cell INDEX`: one cell of the grid, run to its end
//! and recorded. The local runner starts one such process per run and a
//! SLURM array task `exec`s one, so a cell's run directory, log and summary
//! come from this code whichever runner started it.
//!
//! While it runs, and after it failed, a cell keeps a state file
//! (`<work>/cells/<label>.json`: host, pid, SLURM job, log, error) that
//! `--status` reads; a cell that is done removes it, its summary being the
//! record from then on.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{ExitCode, ExitStatus};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::cells::{all_cells, is_done};
use super::{Job, Plan, discover_command, discovery_done, record, start, tail, train_command};
use sim::atomic_file::write_atomic;

/// Where a cell that is not done stands, as its process last wrote it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct CellState {
    /// Cell index.
    pub cell: usize,
    /// What it runs (`small/multigoal/a2c/seed-0`).
    pub label: String,
    /// Running, or failed.
    pub phase: Phase,
    /// The machine its process runs on.
    pub host: String,
    /// Its process.
    pub pid: u32,
    /// `<array job>_<task>` when a SLURM array task runs it.
    pub slurm_job: Option<String>,
    /// Its log.
    pub log: PathBuf,
    /// Why it failed.
    pub error: Option<String>,
}

/// A cell's phase in its state file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum Phase {
    /// Its process started the run.
    Running,
    /// Its run ended without a summary.
    Failed,
}

impl CellState {
    /// The state file of `job`, if it has a readable one.
    pub fn read(plan: &Plan, job: &Job) -> Option<CellState> {
        serde_json::from_slice(&std::fs::read(plan.cell_state_path(job)).ok()?).ok()
    }

    fn save(&self, plan: &Plan, job: &Job) -> anyhow::Result<()> {
        let path = plan.cell_state_path(job);
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
        }
        write_atomic(&path, &serde_json::to_vec_pretty(self)?)?;
        Ok(())
    }
}

/// This machine's host name.
pub(super) fn this_host() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

/// The SLURM array task this process runs in, `<array job>_<task>`.
fn slurm_task() -> Option<String> {
    let job = std::env::var("SLURM_ARRAY_JOB_ID").ok()?;
    let task = std::env::var("SLURM_ARRAY_TASK_ID").ok()?;
    Some(format!("{job}_{task}"))
}

/// How a cell's `discover` or `train` ended.
enum Ended {
    /// On its own, with this status.
    Exited(ExitStatus),
    /// Stopped by a signal to the cell (Ctrl-C, SIGTERM from the local
    /// runner or from SLURM's `scancel` or time limit).
    Stopped,
}

/// Runs cell `index` of `plan`'s grid: nothing if it is done, else its run
/// (resumed from its checkpoint if it has one), then its summary. Exits
/// non-zero, with its state file saying why, when the run fails.
pub(super) fn run(plan: &Plan, index: usize, digest: Option<&str>) -> anyhow::Result<ExitCode> {
    if let Some(d) = digest {
        anyhow::ensure!(
            d == plan.grid_digest,
            "{} changed since this cell was started from it (digest {d} then, {} now): \
             its cell indices may name other runs; run or submit the grid again",
            plan.grid_path.display(),
            plan.grid_digest
        );
    }
    let all = all_cells(&plan.grid)?;
    let job = all.get(index).with_context(|| {
        format!(
            "{} has {} cells (0 to {}): there is no cell {index}",
            plan.grid_path.display(),
            all.len(),
            all.len().saturating_sub(1)
        )
    })?;
    let label = Plan::label(job);
    if is_done(plan, job)? {
        eprintln!("cell {index} ({label}) is done already");
        return Ok(ExitCode::SUCCESS);
    }
    let graph = world_graph(plan, &all, job)?;
    let stop = crate::shutdown::stop_flag_with_hangup()?;
    let log = plan.log_path(job);
    let mut state = CellState {
        cell: index,
        label: label.clone(),
        phase: Phase::Running,
        host: this_host(),
        pid: std::process::id(),
        slurm_job: slurm_task(),
        log: log.clone(),
        error: None,
    };
    state.save(plan, job)?;
    append_line(
        &log,
        &format!(
            "== cell {index} ({label}) on {}, pid {}{} ==",
            state.host,
            state.pid,
            state
                .slurm_job
                .as_ref()
                .map_or(String::new(), |j| format!(", SLURM job {j}"))
        ),
    )?;
    let failure = match run_to_end(plan, job, graph.as_deref(), &log, &stop) {
        Ok(Ended::Exited(s)) if s.success() => match record(plan, job) {
            Ok(()) => {
                let _ = std::fs::remove_file(plan.cell_state_path(job));
                eprintln!("cell {index} ({label}) done");
                return Ok(ExitCode::SUCCESS);
            }
            Err(e) => format!("{e:#}"),
        },
        Ok(Ended::Exited(s)) => format!("{} ended with {s}: {}", job.command(), tail(&log, 1)),
        Ok(Ended::Stopped) => {
            "stopped by a signal; it resumes from its last checkpoint when run again".to_string()
        }
        Err(e) => format!("{e:#}"),
    };
    state.phase = Phase::Failed;
    state.error = Some(failure.clone());
    state.save(plan, job)?;
    eprintln!("cell {index} ({label}) failed: {failure}");
    Ok(ExitCode::FAILURE)
}

/// The finished discovery a training cell trains on, if it needs one.
fn world_graph(plan: &Plan, all: &[Job], job: &Job) -> anyhow::Result<Option<PathBuf>> {
    let Job::Train { needs: Some(n), .. } = job else {
        return Ok(None);
    };
    let Job::Discover { spec } = &all[*n] else {
        unreachable!("needs points at a discovery")
    };
    let dir = plan.discover_dir(spec);
    anyhow::ensure!(
        discovery_done(&dir, spec).is_some(),
        "{} needs the world graph of cell {n} ({}), which has not finished: \
         run the grid (or submit it with --slurm), which runs the discoveries first",
        Plan::label(job),
        Plan::label(&all[*n])
    );
    Ok(Some(std::fs::canonicalize(&dir)?))
}

/// Starts the cell's `discover` or `train` with its output in `log` and
/// waits for it; a signal to this process stops it (SIGTERM) first.
fn run_to_end(
    plan: &Plan,
    job: &Job,
    graph: Option<&Path>,
    log: &Path,
    stop: &AtomicBool,
) -> anyhow::Result<Ended> {
    let cmd = match job {
        Job::Discover { spec } => discover_command(plan, spec)?,
        Job::Train {
            maze,
            task,
            config,
            seed,
            ..
        } => train_command(
            plan,
            &plan.grid.train_config(*maze),
            *maze,
            *task,
            config,
            *seed,
            graph,
        )?,
    };
    let mut child = start(cmd, log, plan.threads)?;
    loop {
        // The stop first: `scancel` signals the run too, which may end
        // before this process looks.
        if stop.load(Ordering::Relaxed) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(child.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
            child.wait()?;
            return Ok(Ended::Stopped);
        }
        if let Some(status) = child.try_wait()? {
            return Ok(Ended::Exited(status));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Appends one line to a log.
fn append_line(log: &Path, line: &str) -> anyhow::Result<()> {
    if let Some(d) = log.parent() {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .with_context(|| format!("cannot open {}", log.display()))?;
    writeln!(f, "{line}").with_context(|| format!("cannot write {}", log.display()))
}
