//! The SLURM runner: the grid's cells as SLURM job arrays, submitted with
//! `sbatch` (no Python). The discoveries go first as one array, the
//! training runs as a second that starts once the first has succeeded
//! (`--dependency=afterok`). An array task's id is its cell's index, and
//! its job script `exec`s `worldgraph experiment GRID --cell
//! $SLURM_ARRAY_TASK_ID` ([`super::cell`]), the process the local runner
//! starts for that cell.
//!
//! Each submission is appended to `<work>/slurm/submissions.jsonl`; the
//! scripts are kept in `<work>/slurm/scripts/` and SLURM's output of each
//! task goes to `<work>/slurm/logs/<array job>_<cell>.out`. `squeue` then
//! tells which cells are queued or running ([`queue`]), so a resubmission
//! leaves those alone and `--status` can name their jobs.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::Context;
use clap::Args;
use serde::{Deserialize, Serialize};

use super::cells::Cells;
use super::status::{Standing, classify};
use super::{Job, Plan, record_finished_discoveries};

/// The `--help` heading of the SLURM settings.
const HEADING: &str = "SLURM (with --slurm)";

/// The SLURM settings of `experiment --slurm`.
#[derive(Debug, Clone, Default, Args)]
pub struct SbatchArgs {
    /// Partition the array tasks run in (sbatch --partition) [default:
    /// the cluster's default partition].
    #[arg(long, value_name = "NAME", requires = "slurm", help_heading = HEADING)]
    pub partition: Option<String>,
    /// Time limit of each array task, one run (sbatch --time: MINUTES,
    /// HH:MM:SS or DAYS-HH:MM:SS) [default: the partition's]. A run cut
    /// off by it resumes from its last checkpoint when the grid is
    /// submitted again.
    #[arg(long, value_name = "LIMIT", requires = "slurm", help_heading = HEADING)]
    pub time: Option<String>,
    /// CPUs of each array task (sbatch --cpus-per-task) [default:
    /// --threads].
    #[arg(long, value_name = "N", requires = "slurm", help_heading = HEADING)]
    pub cpus_per_task: Option<usize>,
    /// One more argument for sbatch, e.g. --sbatch-arg=--account=rl or
    /// --sbatch-arg=--mem=4G (repeatable; given on sbatch's command line,
    /// so it wins over the script's lines).
    #[arg(
        long = "sbatch-arg",
        value_name = "ARG",
        allow_hyphen_values = true,
        requires = "slurm",
        help_heading = HEADING
    )]
    pub sbatch_args: Vec<String>,
    /// A file whose text goes into each job script after the generated
    /// #SBATCH lines and before the command: more #SBATCH lines, `module
    /// load ...`, environment settings.
    #[arg(long, value_name = "FILE", requires = "slurm", help_heading = HEADING)]
    pub sbatch_preamble: Option<PathBuf>,
}

/// What can go wrong between this command and SLURM.
#[derive(Debug, thiserror::Error)]
pub(super) enum SlurmError {
    /// A SLURM command is not installed here.
    #[error(
        "{program} is not on PATH: --slurm and --status talk to SLURM through its commands \
         (sbatch, squeue); run this on a machine of the cluster, such as a login node"
    )]
    Missing {
        /// The command.
        program: &'static str,
    },
    /// A SLURM command could not be started.
    #[error("cannot run {program}: {source}")]
    Start {
        /// The command.
        program: &'static str,
        /// Why.
        source: std::io::Error,
    },
    /// sbatch refused a script.
    #[error("sbatch refused {}: {message}", script.display())]
    Refused {
        /// The script.
        script: PathBuf,
        /// What sbatch said (or its exit status).
        message: String,
    },
    /// sbatch answered something that is not a job id.
    #[error("sbatch printed {output:?} for {}, not a job id", script.display())]
    NoJobId {
        /// The script.
        script: PathBuf,
        /// Its output.
        output: String,
    },
    /// squeue failed: slurmctld down or unreachable.
    #[error("SLURM is not answering (squeue: {message})")]
    NotAnswering {
        /// What squeue said (or its exit status).
        message: String,
    },
}

/// Runs a SLURM command and returns its standard output; its standard
/// error (or exit status) when it fails.
fn slurm_command(
    program: &'static str,
    args: &[String],
) -> Result<Result<String, String>, SlurmError> {
    let out = match Command::new(program).args(args).output() {
        Ok(out) => out,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(SlurmError::Missing { program });
        }
        Err(source) => return Err(SlurmError::Start { program, source }),
    };
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    if out.status.success() {
        return Ok(Ok(stdout));
    }
    let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
    Ok(Err(if stderr.is_empty() {
        out.status.to_string()
    } else {
        stderr
    }))
}

/// One array job submitted for the grid (a line of
/// `<work>/slurm/submissions.jsonl`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct Submission {
    /// SLURM's id of the array job.
    pub job: u64,
    /// `discover` or `train`.
    pub kind: String,
    /// Its cells, which are its array task ids.
    pub cells: Vec<usize>,
    /// Its job script.
    pub script: PathBuf,
}

fn slurm_dir(plan: &Plan) -> PathBuf {
    plan.work.join("slurm")
}

/// SLURM's output of array task `job_task` (`<array job>_<cell>`), under
/// the working directory.
pub(super) fn slurm_output(plan: &Plan, job_task: &str) -> PathBuf {
    slurm_dir(plan).join("logs").join(format!("{job_task}.out"))
}

/// The grid's submissions so far (none if it never went to SLURM).
pub(super) fn submissions(plan: &Plan) -> anyhow::Result<Vec<Submission>> {
    let path = slurm_dir(plan).join("submissions.jsonl");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(Vec::new());
    };
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            serde_json::from_str(l).with_context(|| format!("{}: bad line {l:?}", path.display()))
        })
        .collect()
}

fn append_submission(plan: &Plan, s: &Submission) -> anyhow::Result<()> {
    let path = slurm_dir(plan).join("submissions.jsonl");
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .with_context(|| format!("cannot open {}", path.display()))?;
    writeln!(f, "{}", serde_json::to_string(s)?)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// A cell's latest array task as SLURM's queue shows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Queued {
    /// Array job id.
    pub job: u64,
    /// `<array job>_<cell>`.
    pub job_task: String,
    /// SLURM's state: PENDING, RUNNING, COMPLETED, CANCELLED, ...
    pub state: String,
    /// Why it is pending (`Dependency`, `JobArrayTaskLimit`, ...).
    pub reason: String,
}

impl Queued {
    /// Waiting to start.
    pub fn pending(&self) -> bool {
        matches!(
            self.state.as_str(),
            "PENDING"
                | "CONFIGURING"
                | "REQUEUED"
                | "REQUEUE_HOLD"
                | "REQUEUE_FED"
                | "RESV_DEL_HOLD"
        )
    }

    /// Started and not ended.
    pub fn running(&self) -> bool {
        matches!(
            self.state.as_str(),
            "RUNNING"
                | "COMPLETING"
                | "SUSPENDED"
                | "STAGE_OUT"
                | "SIGNALING"
                | "STOPPED"
                | "RESIZING"
        )
    }

    /// Pending or running: SLURM will run it, or runs it now.
    pub fn active(&self) -> bool {
        self.pending() || self.running()
    }
}

/// The latest array task of every submitted cell that SLURM still knows
/// (it forgets ended jobs after its MinJobAge), by cell index. Asks
/// nothing when the grid was never submitted.
pub(super) fn queue(plan: &Plan) -> anyhow::Result<HashMap<usize, Queued>> {
    let subs = submissions(plan)?;
    if subs.is_empty() {
        return Ok(HashMap::new());
    }
    let mut ids: Vec<String> = subs.iter().map(|s| s.job.to_string()).collect();
    ids.dedup();
    let args = [
        "--noheader".to_string(),
        "--array".to_string(),
        "--states=all".to_string(),
        format!("--jobs={}", ids.join(",")),
        "--format=%i|%T|%r".to_string(),
    ];
    let text = match slurm_command("squeue", &args)? {
        Ok(text) => text,
        // Every job listed has ended and been forgotten.
        Err(e) if e.contains("Invalid job id") => String::new(),
        Err(message) => return Err(SlurmError::NotAnswering { message }.into()),
    };
    let mut out: HashMap<usize, Queued> = HashMap::new();
    for line in text.lines() {
        let mut parts = line.trim().split('|');
        let (Some(id), Some(state), reason) = (parts.next(), parts.next(), parts.next()) else {
            continue;
        };
        let Some((job, tasks)) = parse_job_tasks(id) else {
            continue;
        };
        for cell in tasks {
            if !subs.iter().any(|s| s.job == job && s.cells.contains(&cell)) {
                continue;
            }
            let q = Queued {
                job,
                job_task: format!("{job}_{cell}"),
                state: state.to_string(),
                reason: reason.unwrap_or_default().to_string(),
            };
            if out.get(&cell).is_none_or(|old| old.job < job) {
                out.insert(cell, q);
            }
        }
    }
    Ok(out)
}

/// `12_3` → (12, [3]); `12_[4-6,9%2]` (a pending array squeue did not
/// expand) → (12, [4, 5, 6, 9]); a job that is no array → None.
fn parse_job_tasks(id: &str) -> Option<(u64, Vec<usize>)> {
    let (job, tasks) = id.split_once('_')?;
    let job: u64 = job.parse().ok()?;
    let Some(list) = tasks.strip_prefix('[') else {
        return Some((job, vec![tasks.parse().ok()?]));
    };
    let list = list.trim_end_matches(']');
    let list = list.split('%').next().unwrap_or_default();
    let mut out = Vec::new();
    for part in list.split(',') {
        match part.split_once('-') {
            Some((a, b)) => out.extend(a.parse::<usize>().ok()?..=b.parse::<usize>().ok()?),
            None => out.push(part.parse().ok()?),
        }
    }
    Some((job, out))
}

/// Cell indices as an sbatch `--array` list: `0-3,7,9-10`.
fn array_list(cells: &[usize]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut k = 0;
    while k < cells.len() {
        let first = cells[k];
        while k + 1 < cells.len() && cells[k + 1] == cells[k] + 1 {
            k += 1;
        }
        parts.push(if cells[k] == first {
            first.to_string()
        } else {
            format!("{first}-{}", cells[k])
        });
        k += 1;
    }
    parts.join(",")
}

/// `s` in single quotes for bash.
fn shell_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// One job array to submit: its kind, cells and settings.
struct ArrayJob<'a> {
    /// `discover` or `train`.
    kind: &'static str,
    cells: &'a [usize],
    /// `%N`: array tasks at once.
    limit: Option<usize>,
}

impl ArrayJob<'_> {
    /// Runs of the grid at once, as its summaries record it: the array's
    /// limit, or its size when it has none.
    fn jobs(&self) -> usize {
        self.limit.unwrap_or(self.cells.len()).max(1)
    }
}

/// The job script of one array: #SBATCH lines, the preamble, the
/// `WORLDGRAPH_*` settings of this environment, then the cell command.
fn job_script(
    plan: &Plan,
    s: &SbatchArgs,
    array: &ArrayJob,
    preamble: &str,
) -> anyhow::Result<String> {
    let cwd = std::env::current_dir().context("cannot read the current directory")?;
    let exe = std::env::current_exe().context("cannot find the worldgraph executable")?;
    let mut lines = vec![
        "#!/bin/bash".to_string(),
        format!(
            "# {} cells of {} (array task id = cell index), written by `worldgraph experiment --slurm`",
            array.kind,
            plan.grid_path.display()
        ),
        format!("#SBATCH --job-name=wg-{}-{}", plan.grid.name, array.kind),
        format!(
            "#SBATCH --array={}{}",
            array_list(array.cells),
            array.limit.map_or(String::new(), |n| format!("%{n}"))
        ),
        format!(
            "#SBATCH --cpus-per-task={}",
            s.cpus_per_task.unwrap_or(plan.threads)
        ),
        format!(
            "#SBATCH --output={}",
            cwd.join(slurm_dir(plan)).join("logs/%A_%a.out").display()
        ),
        format!("#SBATCH --chdir={}", cwd.display()),
    ];
    if let Some(p) = &s.partition {
        lines.push(format!("#SBATCH --partition={p}"));
    }
    if let Some(t) = &s.time {
        lines.push(format!("#SBATCH --time={t}"));
    }
    lines.push(preamble.trim_end().to_string());
    let mut env: Vec<(String, String)> = std::env::vars()
        .filter(|(k, _)| k.starts_with("WORLDGRAPH_") && k != "WORLDGRAPH_TORCH_THREADS")
        .collect();
    env.sort();
    lines.extend(
        env.iter()
            .map(|(k, v)| format!("export {k}={}", shell_quote(v))),
    );
    let args: Vec<String> = plan
        .cell_args(array.jobs())
        .iter()
        .map(|a| shell_quote(&a.to_string_lossy()))
        .collect();
    // SLURM starts it in --chdir; so does bash, for a task run by hand.
    lines.push(format!("cd {}", shell_quote(&cwd.to_string_lossy())));
    lines.push(format!(
        "exec {} {} --cell \"$SLURM_ARRAY_TASK_ID\"",
        shell_quote(&exe.to_string_lossy()),
        args.join(" ")
    ));
    lines.retain(|l| !l.is_empty());
    Ok(lines.join("\n") + "\n")
}

/// sbatch's arguments for a script that starts after the jobs `after`.
fn sbatch_args(s: &SbatchArgs, after: &[String], script: &Path) -> Vec<String> {
    let mut v = vec!["--parsable".to_string()];
    if !after.is_empty() {
        v.push(format!("--dependency=afterok:{}", after.join(":")));
        // A discovery that fails cancels the runs that wait for it, rather
        // than leaving them pending for ever.
        v.push("--kill-on-invalid-dep=yes".to_string());
    }
    v.extend(s.sbatch_args.iter().cloned());
    v.push(script.display().to_string());
    v
}

/// Writes and submits one array (with `dry_run`, prints it); returns its
/// job id (a placeholder when dry).
fn submit_array(
    plan: &Plan,
    s: &SbatchArgs,
    array: &ArrayJob,
    after: &[String],
    dry_run: bool,
) -> anyhow::Result<String> {
    let preamble = match &s.sbatch_preamble {
        Some(p) => std::fs::read_to_string(p)
            .with_context(|| format!("cannot read --sbatch-preamble {}", p.display()))?,
        None => String::new(),
    };
    let script_text = job_script(plan, s, array, &preamble)?;
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis());
    let script = slurm_dir(plan)
        .join("scripts")
        .join(format!("{stamp}-{}.sh", array.kind));
    let args = sbatch_args(s, after, &script);
    if dry_run {
        println!("# sbatch {}\n{script_text}", args.join(" "));
        return Ok(format!("<job id of the {} array>", array.kind));
    }
    for d in [
        slurm_dir(plan).join("scripts"),
        slurm_dir(plan).join("logs"),
    ] {
        std::fs::create_dir_all(&d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    sim::atomic_file::write_atomic(&script, script_text.as_bytes())?;
    let out = slurm_command("sbatch", &args)?.map_err(|message| SlurmError::Refused {
        script: script.clone(),
        message,
    })?;
    // --parsable: `<job id>` or `<job id>;<cluster>`.
    let id = out.trim().split(';').next().unwrap_or_default();
    let job: u64 = id.parse().map_err(|_| SlurmError::NoJobId {
        script: script.clone(),
        output: out.trim().to_string(),
    })?;
    append_submission(
        plan,
        &Submission {
            job,
            kind: array.kind.to_string(),
            cells: array.cells.to_vec(),
            script,
        },
    )?;
    Ok(job.to_string())
}

/// `experiment GRID --slurm`: submits the selected cells that are neither
/// done nor queued or running in SLURM.
pub(super) fn submit(
    plan: &Plan,
    cells: &Cells,
    s: &SbatchArgs,
    limit: Option<usize>,
    dry_run: bool,
) -> anyhow::Result<ExitCode> {
    let queue = match queue(plan) {
        Ok(q) => q,
        Err(e) if dry_run => {
            eprintln!("warning: {e:#}; the dry run assumes no cell is queued or running");
            HashMap::new()
        }
        Err(e) => {
            return Err(e.context(
                "not submitting: the cells SLURM may still run cannot be told from the others, \
                 and a cell must not run twice",
            ));
        }
    };
    let (todo, active) = to_submit(plan, cells, &queue);
    let (discover, train): (Vec<usize>, Vec<usize>) = todo
        .iter()
        .partition(|&&i| matches!(cells.all[i], Job::Discover { .. }));
    let (trains, trains_done) = cells.trains();
    eprintln!(
        "experiment {}: {trains} training runs ({trains_done} done, {active} cells queued or running), \
         {} training runs and {} discoveries to submit; work in {}, results in {}",
        plan.grid.name,
        train.len(),
        discover.len(),
        plan.work.display(),
        plan.results.display()
    );
    if todo.is_empty() {
        eprintln!("nothing to submit");
        return Ok(ExitCode::SUCCESS);
    }
    if !dry_run {
        record_finished_discoveries(plan, cells)?;
    }
    let mut after = waiting_discoveries(cells, &queue, &train);
    if !discover.is_empty() {
        let array = ArrayJob {
            kind: "discover",
            cells: &discover,
            limit,
        };
        let id = submit_array(plan, s, &array, &[], dry_run)?;
        report(&array, &id, &[], dry_run);
        after.push(id);
    }
    if !train.is_empty() {
        let array = ArrayJob {
            kind: "train",
            cells: &train,
            limit,
        };
        let id = submit_array(plan, s, &array, &after, dry_run)?;
        report(&array, &id, &after, dry_run);
    }
    if !dry_run {
        eprintln!(
            "`worldgraph experiment {} --status` follows them (same --results/--work); \
             logs in {}, SLURM's output in {}",
            plan.grid_path.display(),
            plan.work.join("logs").display(),
            slurm_dir(plan).join("logs").display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// The selected cells to submit: those not done and neither queued nor
/// running (in SLURM, or here), each failed one reported with its logs;
/// and how many are queued or running.
fn to_submit(plan: &Plan, cells: &Cells, queue: &HashMap<usize, Queued>) -> (Vec<usize>, usize) {
    let mut todo: Vec<usize> = Vec::new();
    let mut active = 0;
    for i in cells.todo() {
        match classify(plan, cells, Some(queue), i) {
            Standing::Queued { .. } | Standing::Running { .. } => active += 1,
            Standing::Failed { why, logs } => {
                eprintln!(
                    "failed before: {} ({why}); {logs}; submitted again, it resumes",
                    Plan::label(&cells.all[i])
                );
                todo.push(i);
            }
            Standing::Done | Standing::Unknown | Standing::Left => todo.push(i),
        }
    }
    (todo, active)
}

/// The array tasks of discoveries still queued or running from an earlier
/// submission that the training cells `train` need.
fn waiting_discoveries(
    cells: &Cells,
    queue: &HashMap<usize, Queued>,
    train: &[usize],
) -> Vec<String> {
    let mut out: Vec<String> = train
        .iter()
        .filter_map(|&i| match &cells.all[i] {
            Job::Train { needs: Some(n), .. } => queue.get(n).filter(|q| q.active()),
            _ => None,
        })
        .map(|q| q.job_task.clone())
        .collect();
    out.sort();
    out.dedup();
    out
}

/// Says what was submitted.
fn report(array: &ArrayJob, id: &str, after: &[String], dry_run: bool) {
    if dry_run {
        return;
    }
    eprintln!(
        "submitted {} {} cells as SLURM job {id} (array {}{}){}",
        array.cells.len(),
        array.kind,
        array_list(array.cells),
        array
            .limit
            .map_or(String::new(), |n| format!(", {n} at once")),
        if after.is_empty() {
            String::new()
        } else {
            format!(", after {}", after.join(", "))
        }
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_lists_join_runs_of_consecutive_cells() {
        assert_eq!(array_list(&[0, 1, 2, 3, 7, 9, 10]), "0-3,7,9-10");
        assert_eq!(array_list(&[5]), "5");
        assert_eq!(array_list(&[]), "");
    }

    #[test]
    fn squeue_ids_name_the_array_job_and_its_cells() {
        assert_eq!(parse_job_tasks("12_3"), Some((12, vec![3])));
        assert_eq!(
            parse_job_tasks("12_[4-6,9%2]"),
            Some((12, vec![4, 5, 6, 9]))
        );
        assert_eq!(parse_job_tasks("12"), None);
        assert_eq!(parse_job_tasks("x_1"), None);
    }

    #[test]
    fn quoting_survives_quotes() {
        assert_eq!(shell_quote("a b"), "'a b'");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
    }
}
