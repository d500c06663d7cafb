//! `worldgraph experiment GRID.toml`: the paper's ablation study (section 5,
//! Control Experiments) as a grid of runs — maze × task × agent
//! configuration × training seed — under the paper's protocol (each run's
//! best checkpoint picked on 10 validation seeds, scored on 100 held-out
//! test seeds; see `train`).
//!
//! The grid discovers the world graphs its configurations need (`V_p` and
//! `V_rand` come from one `discover` run per maze and seed) and reuses them.
//! Each run is a *cell* with a fixed index into the grid ([`cells`]), and
//! one code path runs a cell: `experiment GRID --cell INDEX` ([`cell`])
//! starts its `discover` or `train` with the log in `<work>/logs/` and
//! writes its summary under `results/` ([`crate::results`]). Two runners
//! start those cell processes: this machine, as many side by side as asked
//! ([`local`]), or a SLURM cluster, as job arrays whose task ids are the
//! cell indices ([`slurm`]). Stopped and started again, either skips the
//! cells that have a summary and resumes the others from their
//! checkpoints; `--status` tells where each cell stands ([`status`]).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use anyhow::Context;
use clap::Args;
use sim::atomic_file::write_atomic;
use sim::{Maze, Task};

use learner::run::artefact::DiscoveryIdentity;
use learner::run::config::TrainConfig;
use learner::run::dir::last_invocation_commit;
use learner::run::protocol::TestSummary;
mod cell;
mod cells;
mod grid;
mod local;
mod reproduce;
mod slurm;
mod status;

pub use self::grid::Grid;
use self::grid::train_args;
pub use self::slurm::SbatchArgs;
use crate::results::{
    CurvePoint, DiscoverResult, DiscoverSpec, RESULT_SCHEMA, RunResult, build_commit, cpu_model,
    discover_path, read_run, run_path,
};

/// `experiment` options.
#[derive(Debug, Clone, Args)]
pub struct ExperimentArgs {
    /// The grid file (see `experiments/`).
    #[arg(required_unless_present = "reproduce")]
    pub grid: Option<PathBuf>,
    /// At most this many runs at once: side by side on this machine
    /// [default: its cores], or with --slurm the array tasks running at
    /// once (sbatch --array=...%N) [default: no limit].
    #[arg(long)]
    pub jobs: Option<usize>,
    /// libtorch threads of each run.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Where the summaries go (committed to the repository).
    #[arg(long, default_value = "results")]
    pub results: PathBuf,
    /// Working directory of the runs (checkpoints, logs, discovery runs,
    /// SLURM scripts and output) [default: <results>/runs/<grid name>,
    /// beside the summaries, so that on a cluster one shared directory
    /// holds everything; runs/experiments/<grid name> when a grid begun
    /// before that default has its runs there].
    #[arg(long)]
    pub work: Option<PathBuf>,
    /// Only these mazes (repeatable).
    #[arg(long = "maze")]
    pub mazes: Vec<Maze>,
    /// Only these tasks (repeatable).
    #[arg(long = "task")]
    pub tasks: Vec<Task>,
    /// Only these configurations (repeatable), e.g. wn-pivotal-trav-init.
    #[arg(long = "config")]
    pub configs: Vec<String>,
    /// Only these training seeds (repeatable).
    #[arg(long = "seed")]
    pub seeds: Vec<u64>,
    /// List the runs and what is left (with --slurm: print the job scripts
    /// and the sbatch command lines), and exit.
    #[arg(long)]
    pub dry_run: bool,
    /// Only the world graph discoveries the selected runs need, no
    /// training: each summary goes to `<results>/<maze>/discover/`.
    #[arg(long)]
    pub discoveries_only: bool,
    /// Submit the grid to SLURM instead of running it here: the
    /// discoveries as one job array, the training runs as another that
    /// starts after it (--dependency=afterok), each array task one cell.
    /// Submitted again, it skips the cells that are done, queued or
    /// running and resumes the others.
    #[arg(long, conflicts_with = "status")]
    pub slurm: bool,
    /// Show how many cells are done, queued or running (with their SLURM
    /// job ids or local pids), failed (with their logs) and left, whichever
    /// runner ran them, and exit.
    #[arg(long)]
    pub status: bool,
    /// SLURM settings of --slurm.
    #[command(flatten)]
    pub sbatch: SbatchArgs,
    /// Run cell INDEX of the grid (an index into its runs, discoveries
    /// first) to its end and record its summary: what the local runner's
    /// child processes and each SLURM array task run.
    #[arg(long, value_name = "INDEX", hide = true, conflicts_with_all = ["slurm", "status", "dry_run"])]
    pub cell: Option<usize>,
    /// With --cell: the digest of the grid file its runner read; a grid
    /// file changed since (its cell indices may have moved) is refused.
    #[arg(long, value_name = "HEX", hide = true, requires = "cell")]
    pub grid_digest: Option<String>,
    /// Rerun the run a summary records (discovery included) in a scratch
    /// directory and check that it gives the same test score; exits
    /// non-zero if not.
    #[arg(long, value_name = "SUMMARY.json", conflicts_with = "grid")]
    pub reproduce: Option<PathBuf>,
    /// With --reproduce: train on this discover run instead of discovering
    /// again (checked to have the summary's rounds), for a summary whose
    /// world graph was discovered on an earlier commit (a grid reuses its
    /// discoveries; the discovery's own summary names its commit).
    #[arg(long, value_name = "DISCOVER_RUN", requires = "reproduce")]
    pub world_graph: Option<PathBuf>,
}

/// One run of the grid.
#[derive(Debug, Clone)]
enum Job {
    /// A world graph discovery (maze, seed).
    Discover { spec: DiscoverSpec },
    /// A training run.
    Train {
        maze: Maze,
        task: Task,
        config: String,
        seed: u64,
        /// Index of the discovery it needs.
        needs: Option<usize>,
    },
}

impl Job {
    /// The command that runs it: `discover` or `train`.
    fn command(&self) -> &'static str {
        match self {
            Job::Discover { .. } => "discover",
            Job::Train { .. } => "train",
        }
    }
}

/// A grid and where its runs work and write.
struct Plan {
    grid: Grid,
    /// The grid file as given on the command line: cell processes read it
    /// from the same directory, and summaries name it.
    grid_path: PathBuf,
    /// `grid_path` as summaries name it.
    grid_label: String,
    /// [`digest`] of the grid file's bytes.
    grid_digest: String,
    work: PathBuf,
    results: PathBuf,
    threads: usize,
    /// Runs of the grid at once (a summary records it): side by side here,
    /// or the SLURM array's limit.
    jobs: usize,
    commit: String,
}

/// The default working directory of grid `name` with summaries under
/// `results`: `<results>/runs/<name>`, or the `runs/experiments/<name>`
/// of a grid begun before that default, so its runs resume where they are.
fn default_work(results: &Path, name: &str) -> PathBuf {
    let legacy = PathBuf::from("runs/experiments").join(name);
    let beside = results.join("runs").join(name);
    if legacy.is_dir() && !beside.exists() {
        legacy
    } else {
        beside
    }
}

impl Plan {
    /// The plan of `worldgraph experiment GRID` with the options in `a`.
    fn new(a: &ExperimentArgs, grid_path: &Path) -> anyhow::Result<Plan> {
        let bytes = std::fs::read(grid_path)
            .with_context(|| format!("cannot read {}", grid_path.display()))?;
        let grid = Grid::read(grid_path)?;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = a.threads.max(1);
        Ok(Plan {
            work: a
                .work
                .clone()
                .unwrap_or_else(|| default_work(&a.results, &grid.name)),
            results: a.results.clone(),
            threads,
            jobs: a.jobs.unwrap_or((cores / threads).max(1)).max(1),
            commit: build_commit(),
            grid_path: grid_path.to_path_buf(),
            grid_label: grid_path.display().to_string(),
            grid_digest: digest(&bytes),
            grid,
        })
    }

    fn discover_dir(&self, spec: &DiscoverSpec) -> PathBuf {
        self.work
            .join("discover")
            .join(format!("{}-seed-{}", spec.maze, spec.seed))
    }

    fn train_dir(&self, maze: Maze, task: Task, config: &str, seed: u64) -> PathBuf {
        self.work
            .join(maze.name())
            .join(task.name())
            .join(config)
            .join(format!("seed-{seed}"))
    }

    fn label(job: &Job) -> String {
        match job {
            Job::Discover { spec } => format!("discover {} seed {}", spec.maze, spec.seed),
            Job::Train {
                maze,
                task,
                config,
                seed,
                ..
            } => format!("{}/{}/{config}/seed-{seed}", maze.name(), task.name()),
        }
    }

    /// The label as a file name: `small_multigoal_a2c_seed-0`.
    fn file_stem(job: &Job) -> String {
        Self::label(job).replace(['/', ' '], "_")
    }

    /// The run's log: its cell's lines and the output of its `discover` or
    /// `train`, every attempt appended.
    fn log_path(&self, job: &Job) -> PathBuf {
        self.work
            .join("logs")
            .join(format!("{}.log", Self::file_stem(job)))
    }

    /// The state file of a cell that is running or failed ([`cell`]).
    fn cell_state_path(&self, job: &Job) -> PathBuf {
        self.work
            .join("cells")
            .join(format!("{}.json", Self::file_stem(job)))
    }

    /// The arguments of `worldgraph experiment` that run one cell of this
    /// plan, all but the cell index: the local runner's children and the
    /// SLURM job scripts start cells with them.
    fn cell_args(&self, jobs: usize) -> Vec<std::ffi::OsString> {
        let mut v: Vec<std::ffi::OsString> =
            vec!["experiment".into(), self.grid_path.clone().into()];
        v.extend([
            "--results".into(),
            self.results.clone().into(),
            "--work".into(),
            self.work.clone().into(),
            "--threads".into(),
            self.threads.to_string().into(),
            "--jobs".into(),
            jobs.to_string().into(),
            "--grid-digest".into(),
            self.grid_digest.clone().into(),
        ]);
        v
    }
}

/// FNV-1a (64 bits) of `bytes` in hex: a grid file's digest, which tells a
/// cell process that its grid is the one its runner indexed.
fn digest(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

fn discover_command(plan: &Plan, spec: &DiscoverSpec) -> anyhow::Result<Command> {
    let mut cmd = crate::pipeline::worldgraph_command()?;
    cmd.args(["discover", "--maze", &spec.maze, "--seed"])
        .arg(spec.seed.to_string())
        .arg("--rounds")
        .arg(spec.rounds.to_string())
        .arg("--run")
        .arg(plan.discover_dir(spec))
        .arg("--json");
    if let Some(config) = &plan.grid.discover_config {
        cmd.arg("--config").arg(config);
    }
    Ok(cmd)
}

fn train_command(
    plan: &Plan,
    cfg: &TrainConfig,
    maze: Maze,
    task: Task,
    config: &str,
    seed: u64,
    graph: Option<&Path>,
) -> anyhow::Result<Command> {
    let dir = plan.train_dir(maze, task, config, seed);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let cfg_file = dir.join("grid-config.toml");
    write_atomic(&cfg_file, toml::to_string(cfg)?.as_bytes())?;
    let mut cmd = crate::pipeline::worldgraph_command()?;
    cmd.args(["train", "--maze", maze.name(), "--task", task.name()])
        .args(train_args(config)?)
        .arg("--seed")
        .arg(seed.to_string())
        .arg("--config")
        .arg(&cfg_file)
        .arg("--run")
        .arg(&dir)
        .arg("--json");
    if let Some(g) = graph {
        cmd.arg("--world-graph").arg(g);
    }
    Ok(cmd)
}

/// Starts `cmd` with its output in `log` (appended) and `threads` libtorch
/// threads.
fn start(mut cmd: Command, log: &Path, threads: usize) -> anyhow::Result<Child> {
    if let Some(d) = log.parent() {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    let out = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .with_context(|| format!("cannot open {}", log.display()))?;
    let err = out.try_clone()?;
    cmd.stdin(Stdio::null())
        .stdout(out)
        .stderr(err)
        .env("WORLDGRAPH_TORCH_THREADS", threads.to_string())
        .spawn()
        .context("cannot start a run")
}

/// The last lines of a log, for a failure report.
fn tail(log: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let v: Vec<&str> = text.lines().collect();
    v[v.len().saturating_sub(lines)..].join("\n")
}

/// A finished discovery's summary, if its run directory has one for these
/// rounds.
fn discovery_done(dir: &Path, spec: &DiscoverSpec) -> Option<serde_json::Value> {
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("discovery.json")).ok()?).ok()?;
    (v.get("rounds")?.as_u64()? == u64::from(spec.rounds) && dir.join("graph.json").exists())
        .then_some(v)
}

/// Writes a finished job's summary under `results/`.
fn record(plan: &Plan, job: &Job) -> anyhow::Result<()> {
    match job {
        Job::Discover { spec } => {
            let dir = plan.discover_dir(spec);
            let summary = discovery_done(&dir, spec)
                .with_context(|| format!("{} finished without its summary", dir.display()))?;
            let r = DiscoverResult {
                schema: RESULT_SCHEMA,
                spec: spec.clone(),
                grid: plan.grid_label.clone(),
                summary,
                commit: last_invocation_commit(&dir).unwrap_or_else(|| "unknown".to_string()),
                grad_path: DiscoveryIdentity::read(&dir)?
                    .config()
                    .gcp
                    .grad_path
                    .name()
                    .to_string(),
                cpu: cpu_model(),
            };
            let path = discover_path(&plan.results, &spec.maze, spec.seed);
            write_result(&path, &serde_json::to_vec_pretty(&r)?)
        }
        Job::Train {
            maze,
            task,
            config,
            seed,
            needs,
        } => {
            let dir = plan.train_dir(*maze, *task, config, *seed);
            let t: TestSummary = serde_json::from_slice(
                &std::fs::read(dir.join("test.json"))
                    .with_context(|| format!("{} finished without test.json", dir.display()))?,
            )?;
            let train_config: TrainConfig = toml::from_str(
                &std::fs::read_to_string(dir.join("config.toml"))
                    .with_context(|| format!("cannot read {}/config.toml", dir.display()))?,
            )?;
            let discover = needs.map(|_| DiscoverSpec {
                maze: maze.name().to_string(),
                seed: *seed,
                rounds: plan.grid.budget(*maze).expect("checked").discover_rounds,
            });
            let r = run_result(
                plan,
                *maze,
                *task,
                config,
                *seed,
                train_config,
                discover,
                &t,
            );
            let path = run_path(&plan.results, maze.name(), task.name(), config, *seed);
            write_result(&path, &serde_json::to_vec_pretty(&r)?)
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn run_result(
    plan: &Plan,
    maze: Maze,
    task: Task,
    config: &str,
    seed: u64,
    train_config: TrainConfig,
    discover: Option<DiscoverSpec>,
    t: &TestSummary,
) -> RunResult {
    let grad_path = train_config.agent.grad_path.name().to_string();
    RunResult {
        schema: RESULT_SCHEMA,
        maze: maze.name().to_string(),
        task: task.name().to_string(),
        config: config.to_string(),
        seed,
        grid: plan.grid_label.clone(),
        train_config,
        discover,
        validation_stream: t.validation_stream,
        validation_seeds: t.validation_seeds,
        test_stream: t.test_stream,
        test_seeds: t.test_seeds,
        test_score: t.test_score,
        test_return: t.test_return,
        test_success_rate: t.test_success_rate,
        best_validation: t.best_validation,
        best_env_steps: t.best_env_steps,
        validation_curve: t
            .validation_curve
            .iter()
            .enumerate()
            .map(|(i, &(env_steps, score))| CurvePoint {
                env_steps,
                wall_seconds: t
                    .validation_wall_seconds
                    .get(i)
                    .copied()
                    .unwrap_or(f64::NAN),
                score,
            })
            .collect(),
        env_steps: t.env_steps,
        wall_seconds: t.wall_seconds,
        train_steps_per_sec: t.train_steps_per_sec,
        torch_threads: plan.threads,
        jobs: plan.jobs,
        commit: plan.commit.clone(),
        grad_path,
        cpu: cpu_model(),
    }
}

fn write_result(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    write_atomic(path, bytes)?;
    Ok(())
}

/// Runs `worldgraph experiment`.
pub fn run(a: ExperimentArgs) -> anyhow::Result<std::process::ExitCode> {
    if let Some(summary) = &a.reproduce {
        return reproduce::reproduce(summary, &a);
    }
    let grid_path = a.grid.clone().expect("clap: grid or --reproduce");
    let plan = Plan::new(&a, &grid_path)?;
    if let Some(index) = a.cell {
        return cell::run(&plan, index, a.grid_digest.as_deref());
    }
    let cells = cells::Cells::load(&plan, &a)?;
    if a.status {
        return status::show(&plan, &cells);
    }
    if !a.dry_run {
        keep_grid_file(&plan, &grid_path)?;
    }
    if a.slurm {
        return slurm::submit(&plan, &cells, &a.sbatch, a.jobs, a.dry_run);
    }
    local::run(&plan, &cells, a.dry_run)
}

/// A result set keeps the grid file its summaries came from, beside them:
/// `<results>/<grid name>.toml` (rewritten only when the grid changed).
fn keep_grid_file(plan: &Plan, grid_path: &Path) -> anyhow::Result<()> {
    let text =
        std::fs::read(grid_path).with_context(|| format!("cannot read {}", grid_path.display()))?;
    let kept = plan.results.join(format!("{}.toml", plan.grid.name));
    if std::fs::read(&kept).ok().as_deref() != Some(&text[..]) {
        write_atomic(&kept, &text)?;
    }
    Ok(())
}

/// Records the discoveries that finished after their cell was stopped,
/// before it wrote their summary.
fn record_finished_discoveries(plan: &Plan, cells: &cells::Cells) -> anyhow::Result<()> {
    for &i in &cells.selected {
        let j = &cells.all[i];
        if let Job::Discover { spec } = j
            && cells.done[i]
            && !discover_path(&plan.results, &spec.maze, spec.seed).exists()
        {
            record(plan, j)?;
            eprintln!("recorded {} (it had finished)", Plan::label(j));
        }
    }
    Ok(())
}

fn score_note(plan: &Plan, job: &Job) -> String {
    match job {
        Job::Train {
            maze,
            task,
            config,
            seed,
            ..
        } => read_run(&run_path(
            &plan.results,
            maze.name(),
            task.name(),
            config,
            *seed,
        ))
        .map(|r| {
            format!(
                ": test {:.3}, best validation {:.3}, {} env steps",
                r.test_score, r.best_validation, r.env_steps
            )
        })
        .unwrap_or_default(),
        Job::Discover { .. } => String::new(),
    }
}
