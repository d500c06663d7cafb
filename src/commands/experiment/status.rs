//! `experiment GRID --status`: where each cell of the grid stands, whichever
//! runner ran it. Done is a summary (or a finished discovery); queued and
//! running come from SLURM's queue for the grid's submissions and from the
//! cells' own state files (a local cell's pid); failed is a state file
//! saying so, or a cell whose process or array task ended without a
//! summary; left is the rest.

use std::collections::HashMap;
use std::process::ExitCode;

use super::cell::{CellState, Phase, this_host};
use super::cells::Cells;
use super::slurm::{Queued, queue, slurm_output, submissions};
use super::{Job, Plan};

/// Where a cell stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Standing {
    /// Its summary is written.
    Done,
    /// Waiting in SLURM's queue.
    Queued {
        /// `<array job>_<cell>`.
        job: String,
        /// Why it waits.
        reason: String,
    },
    /// Its process runs: a SLURM array task, or a pid on a host.
    Running {
        /// Which.
        by: String,
    },
    /// It ended without a summary.
    Failed {
        /// Why, in one line.
        why: String,
        /// Where its logs are.
        logs: String,
    },
    /// Submitted to SLURM, which does not answer.
    Unknown,
    /// Not started, or stopped with the runner that started it.
    Left,
}

/// Whether process `pid` of this host is alive.
fn alive(pid: u32) -> bool {
    std::path::Path::new(&format!("/proc/{pid}")).exists()
}

/// Where cell `i` stands; `queue` is `None` when SLURM did not answer.
pub(super) fn classify(
    plan: &Plan,
    cells: &Cells,
    queue: Option<&HashMap<usize, Queued>>,
    i: usize,
) -> Standing {
    let job = &cells.all[i];
    if cells.done[i] {
        return Standing::Done;
    }
    let queued = queue.and_then(|q| q.get(&i));
    if let Some(q) = queued.filter(|q| q.pending()) {
        return Standing::Queued {
            job: q.job_task.clone(),
            reason: q.reason.clone(),
        };
    }
    if let Some(q) = queued.filter(|q| q.running()) {
        return Standing::Running {
            by: format!("SLURM job {}", q.job_task),
        };
    }
    let state = CellState::read(plan, job);
    let failed = |why: String, slurm_job: Option<&str>| Standing::Failed {
        why: why.lines().next().unwrap_or_default().to_string(),
        logs: logs(plan, job, slurm_job),
    };
    match state {
        Some(s) if s.phase == Phase::Failed => {
            let slurm_job = s.slurm_job.as_deref();
            failed(s.error.clone().unwrap_or_default(), slurm_job)
        }
        Some(s) => match (&s.slurm_job, queue) {
            (Some(_), None) => Standing::Unknown,
            (Some(j), Some(_)) => {
                let end = queued.map_or("and SLURM forgot it".to_string(), |q| {
                    format!("{} (SLURM job {})", q.state, q.job_task)
                });
                failed(
                    format!("its array task {j} ended {end} without a summary"),
                    Some(j),
                )
            }
            (None, _) if s.host != this_host() => Standing::Running {
                by: format!("pid {} on {} (not checked from here)", s.pid, s.host),
            },
            (None, _) if alive(s.pid) => Standing::Running {
                by: format!("pid {} on {}", s.pid, s.host),
            },
            (None, _) => failed(
                format!("its process (pid {}) ended without a summary", s.pid),
                None,
            ),
        },
        None => match queued {
            Some(q) => failed(
                format!(
                    "SLURM job {} ended {} before its run started",
                    q.job_task, q.state
                ),
                Some(&q.job_task),
            ),
            None if queue.is_none() && submitted(plan, i) => Standing::Unknown,
            None => Standing::Left,
        },
    }
}

/// Whether cell `i` was ever submitted to SLURM.
fn submitted(plan: &Plan, i: usize) -> bool {
    submissions(plan).is_ok_and(|subs| subs.iter().any(|s| s.cells.contains(&i)))
}

/// A failed cell's logs: its own, and SLURM's output of its array task.
fn logs(plan: &Plan, job: &Job, slurm_job: Option<&str>) -> String {
    let mut s = format!("log {}", plan.log_path(job).display());
    if let Some(j) = slurm_job {
        s += &format!(", SLURM output {}", slurm_output(plan, j).display());
    }
    s
}

/// Prints where the selected cells stand: the counts, then a line per cell
/// that is not done. Fails (after printing) when SLURM does not answer.
pub(super) fn show(plan: &Plan, cells: &Cells) -> anyhow::Result<ExitCode> {
    let (queue, slurm_error) = match queue(plan) {
        Ok(q) => (Some(q), None),
        Err(e) => (None, Some(e)),
    };
    let shown: Vec<(usize, Standing)> = cells
        .selected
        .iter()
        .filter(|&&i| cells.done[i] || cells.wanted(i))
        .map(|&i| (i, classify(plan, cells, queue.as_ref(), i)))
        .collect();
    let count = |f: fn(&Standing) -> bool| shown.iter().filter(|(_, s)| f(s)).count();
    let (trains, _) = cells.trains();
    println!(
        "experiment {} ({}): {} cells ({trains} training runs, {} discoveries); work in {}, results in {}",
        plan.grid.name,
        plan.grid_path.display(),
        shown.len(),
        shown.len() - trains,
        plan.work.display(),
        plan.results.display()
    );
    println!(
        "done {}, queued {}, running {}, failed {}, left {}{}",
        count(|s| matches!(s, Standing::Done)),
        count(|s| matches!(s, Standing::Queued { .. })),
        count(|s| matches!(s, Standing::Running { .. })),
        count(|s| matches!(s, Standing::Failed { .. })),
        count(|s| matches!(s, Standing::Left)),
        match count(|s| matches!(s, Standing::Unknown)) {
            0 => String::new(),
            n => format!(", unknown {n} (submitted to SLURM, which does not answer)"),
        }
    );
    print_cells(cells, &shown);
    match slurm_error {
        None => Ok(ExitCode::SUCCESS),
        Some(e) => Err(e.context("the cells submitted to SLURM cannot be told apart")),
    }
}

/// At most this many queued, unknown or left cells are listed one by one;
/// more are counted in one line (running and failed ones are always listed).
const LISTED: usize = 20;

/// A line per cell that is not done: running and failed ones always, the
/// others while they are few.
fn print_cells(cells: &Cells, shown: &[(usize, Standing)]) {
    let many = |f: fn(&Standing) -> bool| shown.iter().filter(|(_, s)| f(s)).count() > LISTED;
    let (queued, unknown, left) = (
        many(|s| matches!(s, Standing::Queued { .. })),
        many(|s| matches!(s, Standing::Unknown)),
        many(|s| matches!(s, Standing::Left)),
    );
    for (i, s) in shown {
        let label = Plan::label(&cells.all[*i]);
        match s {
            Standing::Done => {}
            Standing::Queued { job, reason } if !queued => {
                println!("queued   {label}  SLURM job {job} ({reason})")
            }
            Standing::Running { by } => println!("running  {label}  {by}"),
            Standing::Failed { why, logs } => println!("failed   {label}  {why}; {logs}"),
            Standing::Unknown if !unknown => println!("unknown  {label}"),
            Standing::Left if !left => println!("left     {label}"),
            Standing::Queued { .. } | Standing::Unknown | Standing::Left => {}
        }
    }
    for (many, what) in [(queued, "queued"), (unknown, "unknown"), (left, "left")] {
        if many {
            println!(
                "(the {what} cells are more than {LISTED}: not listed one by one; `--dry-run` lists the cells not done)"
            );
        }
    }
}
