//! `worldgraph experiment GRID.toml`: the paper's ablation study (section 5,
//! Control Experiments) as a grid of runs — maze × task × agent
//! configuration × training seed — under the paper's protocol (each run's
//! best checkpoint picked on 10 validation seeds, scored on 100 held-out
//! test seeds; see `train`).
//!
//! The grid discovers the world graphs its configurations need (`V_p` and
//! `V_rand` come from one `discover` run per maze and seed) and reuses them;
//! it runs as many runs side by side as asked (one libtorch thread each by
//! default), each a `worldgraph train` child process with its log in
//! `<work>/logs/`. Every finished run writes its summary under `results/`
//! ([`crate::results`]); killed and restarted, the grid skips the runs that
//! have one and resumes the others from their checkpoints.

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use sim::render::write_atomic;
use sim::{Maze, Task};

use learner::a2c::rollout::GradPath;
use learner::run::config::TrainConfig;
use learner::run::protocol::TestSummary;
mod grid;
mod reproduce;

pub use self::grid::Grid;
use self::grid::{Group, config_named, train_args};
use crate::results::{
    CurvePoint, DiscoverResult, DiscoverSpec, RESULT_SCHEMA, RunResult, build_commit,
    discover_path, read_run, run_path,
};

/// `experiment` options.
#[derive(Debug, Clone, Args)]
pub struct ExperimentArgs {
    /// The grid file (see `experiments/`).
    #[arg(required_unless_present = "reproduce")]
    pub grid: Option<PathBuf>,
    /// Runs side by side [default: the machine's cores].
    #[arg(long)]
    pub jobs: Option<usize>,
    /// libtorch threads of each run.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Where the summaries go (committed to the repository).
    #[arg(long, default_value = "results")]
    pub results: PathBuf,
    /// Working directory of the runs (checkpoints, logs, discovery runs)
    /// [default: runs/experiments/<grid name>].
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
    /// List the runs and what is left, and exit.
    #[arg(long)]
    pub dry_run: bool,
    /// Only the world graph discoveries the selected runs need, no
    /// training: each summary goes to `<results>/<maze>/discover/`.
    #[arg(long)]
    pub discoveries_only: bool,
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

struct Plan {
    grid: Grid,
    grid_label: String,
    work: PathBuf,
    results: PathBuf,
    threads: usize,
    jobs: usize,
    commit: String,
}

impl Plan {
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

    fn log_path(&self, job: &Job) -> PathBuf {
        self.work
            .join("logs")
            .join(format!("{}.log", Self::label(job).replace(['/', ' '], "_")))
    }
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
                commit: plan.commit.clone(),
                grad_path: GradPath::default().name().to_string(),
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
        grad_path: GradPath::default().name().to_string(),
    }
}

fn write_result(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    write_atomic(path, bytes)?;
    Ok(())
}

/// The grid's runs that match the filters: discoveries first, then the
/// training runs cell by cell (all seeds of a cell together, so a stopped
/// grid leaves whole cells).
fn jobs(grid: &Grid, a: &ExperimentArgs) -> anyhow::Result<Vec<Job>> {
    for c in &a.configs {
        config_named(c)?;
    }
    let keep_maze = |m: Maze| a.mazes.is_empty() || a.mazes.contains(&m);
    let keep_seed = |s: u64| a.seeds.is_empty() || a.seeds.contains(&s);
    let mut discover: HashMap<(Maze, u64), usize> = HashMap::new();
    let mut out = Vec::new();
    let mut train = Vec::new();
    for g in &grid.group {
        let mazes: Vec<Maze> = if g.mazes.is_empty() {
            grid.maze.iter().map(|m| m.name).collect()
        } else {
            g.mazes.clone()
        };
        for maze in mazes.into_iter().filter(|&m| keep_maze(m)) {
            for &task in g
                .tasks
                .iter()
                .filter(|t| a.tasks.is_empty() || a.tasks.contains(t))
            {
                for config in g
                    .configs
                    .iter()
                    .filter(|c| a.configs.is_empty() || a.configs.contains(c))
                {
                    let needs_graph = config_named(config)?.needs_discovery(task);
                    for &seed in grid.seeds.iter().filter(|&&s| keep_seed(s)) {
                        let needs = needs_graph.then(|| {
                            *discover.entry((maze, seed)).or_insert_with(|| {
                                out.push(Job::Discover {
                                    spec: DiscoverSpec {
                                        maze: maze.name().to_string(),
                                        seed,
                                        rounds: grid.budget(maze).expect("checked").discover_rounds,
                                    },
                                });
                                out.len() - 1
                            })
                        });
                        train.push(Job::Train {
                            maze,
                            task,
                            config: config.clone(),
                            seed,
                            needs,
                        });
                    }
                }
            }
        }
    }
    if !a.discoveries_only {
        out.extend(train);
    }
    Ok(out)
}

/// The filters given, in words: `--maze medium --seed 7`.
fn filters(a: &ExperimentArgs) -> String {
    let mut v: Vec<String> = Vec::new();
    v.extend(a.mazes.iter().map(|m| format!("--maze {}", m.name())));
    v.extend(a.tasks.iter().map(|t| format!("--task {}", t.name())));
    v.extend(a.configs.iter().map(|c| format!("--config {c}")));
    v.extend(a.seeds.iter().map(|s| format!("--seed {s}")));
    if v.is_empty() {
        "none".to_string()
    } else {
        v.join(" ")
    }
}

/// Each filter value the grid has no run of (`--seed 9` in a grid of
/// seeds 0 to 2).
fn unmatched_filters(grid: &Grid, a: &ExperimentArgs) -> Vec<String> {
    let mazes = |g: &Group| -> Vec<Maze> {
        if g.mazes.is_empty() {
            grid.maze.iter().map(|m| m.name).collect()
        } else {
            g.mazes.clone()
        }
    };
    let mut out = Vec::new();
    for m in &a.mazes {
        if !grid.group.iter().any(|g| mazes(g).contains(m)) {
            out.push(format!("--maze {}", m.name()));
        }
    }
    for t in &a.tasks {
        if !grid.group.iter().any(|g| g.tasks.contains(t)) {
            out.push(format!("--task {}", t.name()));
        }
    }
    for c in &a.configs {
        if !grid.group.iter().any(|g| g.configs.contains(c)) {
            out.push(format!("--config {c}"));
        }
    }
    for s in &a.seeds {
        if !grid.seeds.contains(s) {
            out.push(format!("--seed {s}"));
        }
    }
    out
}

/// Runs `worldgraph experiment`.
pub fn run(a: ExperimentArgs) -> anyhow::Result<std::process::ExitCode> {
    if let Some(summary) = &a.reproduce {
        return reproduce::reproduce(summary, &a);
    }
    let grid_path = a.grid.clone().expect("clap: grid or --reproduce");
    let grid = Grid::read(&grid_path)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let plan = Plan {
        work: a
            .work
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs/experiments").join(&grid.name)),
        results: a.results.clone(),
        threads: a.threads.max(1),
        jobs: a.jobs.unwrap_or((cores / a.threads.max(1)).max(1)).max(1),
        commit: build_commit(),
        grid_label: grid_path.display().to_string(),
        grid,
    };
    let all = jobs(&plan.grid, &a)?;
    for f in unmatched_filters(&plan.grid, &a) {
        eprintln!("warning: {f} matches no run of {}", grid_path.display());
    }
    if all.is_empty() {
        eprintln!(
            "warning: the filters ({}) select no run of {}",
            filters(&a),
            grid_path.display()
        );
    }
    // What is already done: a summary under results/ (training), or a
    // finished discovery in the working directory.
    let mut finished = vec![false; all.len()];
    for (i, j) in all.iter().enumerate() {
        finished[i] = match j {
            Job::Discover { spec } => discovery_done(&plan.discover_dir(spec), spec).is_some(),
            Job::Train {
                maze,
                task,
                config,
                seed,
                ..
            } => {
                let path = run_path(&plan.results, maze.name(), task.name(), config, *seed);
                if path.exists() {
                    // A cell never mixes budgets: a summary of another
                    // budget or protocol is refused, not counted.
                    let r = read_run(&path)?;
                    let want = plan.grid.train_config(*maze);
                    let got = &r.train_config;
                    anyhow::ensure!(
                        (
                            got.env_steps,
                            got.eval_every,
                            got.validation_seeds,
                            got.test_seeds
                        ) == (
                            want.env_steps,
                            want.eval_every,
                            want.validation_seeds,
                            want.test_seeds
                        ),
                        "{} was run with env_steps {}, eval_every {}, {} validation and {} test seeds; \
                         this grid asks for {}, {}, {} and {}: give the grid another --results directory",
                        path.display(),
                        got.env_steps,
                        got.eval_every,
                        got.validation_seeds,
                        got.test_seeds,
                        want.env_steps,
                        want.eval_every,
                        want.validation_seeds,
                        want.test_seeds
                    );
                    true
                } else {
                    false
                }
            }
        };
    }
    // A discovery is needed only by training runs still to do (or for
    // itself, with --discoveries-only).
    let needed: Vec<bool> = (0..all.len())
        .map(|i| match &all[i] {
            Job::Discover { .. } if a.discoveries_only => true,
            Job::Discover { .. } => all.iter().enumerate().any(|(k, j)| {
                matches!(j, Job::Train { needs: Some(n), .. } if *n == i) && !finished[k]
            }),
            Job::Train { .. } => true,
        })
        .collect();
    let trains = all
        .iter()
        .filter(|j| matches!(j, Job::Train { .. }))
        .count();
    let trains_done = all
        .iter()
        .zip(&finished)
        .filter(|(j, f)| matches!(j, Job::Train { .. }) && **f)
        .count();
    let mut queue: VecDeque<usize> = (0..all.len())
        .filter(|&i| !finished[i] && needed[i])
        .collect();
    eprintln!(
        "experiment {}: {} training runs ({} done, {} to run), {} discoveries to run; {} side by side, {} libtorch thread(s) each; work in {}, results in {}",
        plan.grid.name,
        trains,
        trains_done,
        trains - trains_done,
        queue
            .iter()
            .filter(|&&i| matches!(all[i], Job::Discover { .. }))
            .count(),
        plan.jobs,
        plan.threads,
        plan.work.display(),
        plan.results.display()
    );
    if a.dry_run {
        for &i in &queue {
            println!("{}", Plan::label(&all[i]));
        }
        return Ok(std::process::ExitCode::SUCCESS);
    }
    // A discovery that finished after its grid was stopped, before its
    // summary was written: written now.
    for (i, j) in all.iter().enumerate() {
        if let Job::Discover { spec } = j
            && finished[i]
            && !discover_path(&plan.results, &spec.maze, spec.seed).exists()
        {
            record(&plan, j)?;
            eprintln!("recorded {} (it had finished)", Plan::label(j));
        }
    }

    let stop = crate::shutdown::stop_flag_with_hangup()?;
    let bar = crate::progress::bar(queue.len() as u64, "experiment");
    let mut running: Vec<(usize, Child, Instant)> = Vec::new();
    let mut failed: Vec<(usize, String)> = Vec::new();
    let mut done_now = 0usize;
    let is_failed = |failed: &Vec<(usize, String)>, i: usize| failed.iter().any(|(k, _)| *k == i);
    loop {
        if stop.load(Ordering::Relaxed) {
            for (_, child, _) in &mut running {
                let _ = nix::sys::signal::kill(
                    nix::unistd::Pid::from_raw(child.id() as i32),
                    nix::sys::signal::Signal::SIGTERM,
                );
            }
            for (_, child, _) in &mut running {
                let _ = child.wait();
            }
            bar.finish_and_clear();
            bail!(
                "stopped: {} runs finished this time; the rest resume from their checkpoints on the next start",
                done_now
            );
        }
        // Reap.
        let mut k = 0;
        while k < running.len() {
            let (i, child, started) = &mut running[k];
            match child.try_wait()? {
                None => k += 1,
                Some(status) => {
                    let i = *i;
                    let secs = started.elapsed().as_secs_f64();
                    let job = &all[i];
                    let outcome = if status.success() {
                        record(&plan, job)
                    } else {
                        Err(anyhow::anyhow!(
                            "{status}; the end of {}:\n{}",
                            plan.log_path(job).display(),
                            tail(&plan.log_path(job), 6)
                        ))
                    };
                    match outcome {
                        Ok(()) => {
                            finished[i] = true;
                            done_now += 1;
                            crate::progress::note(
                                &bar,
                                &format!(
                                    "done {} ({secs:.0} s){}",
                                    Plan::label(job),
                                    score_note(&plan, job)
                                ),
                            );
                        }
                        Err(e) => {
                            crate::progress::note(
                                &bar,
                                &format!("FAILED {}: {e:#}", Plan::label(job)),
                            );
                            failed.push((i, format!("{e:#}")));
                        }
                    }
                    bar.inc(1);
                    running.swap_remove(k);
                }
            }
        }
        // Launch what is ready.
        let mut k = 0;
        while running.len() < plan.jobs && k < queue.len() {
            let i = queue[k];
            let ready = match &all[i] {
                Job::Discover { .. } => Some(None),
                Job::Train { needs: None, .. } => Some(None),
                Job::Train { needs: Some(n), .. } if finished[*n] => {
                    let Job::Discover { spec } = &all[*n] else {
                        unreachable!("needs points at a discovery")
                    };
                    Some(Some(std::fs::canonicalize(plan.discover_dir(spec))?))
                }
                Job::Train { needs: Some(n), .. } if is_failed(&failed, *n) => {
                    failed.push((
                        i,
                        format!("its discovery ({}) failed", Plan::label(&all[*n])),
                    ));
                    bar.inc(1);
                    queue.remove(k);
                    continue;
                }
                Job::Train { .. } => None,
            };
            let Some(graph) = ready else {
                k += 1;
                continue;
            };
            let cmd = match &all[i] {
                Job::Discover { spec } => discover_command(&plan, spec)?,
                Job::Train {
                    maze,
                    task,
                    config,
                    seed,
                    ..
                } => train_command(
                    &plan,
                    &plan.grid.train_config(*maze),
                    *maze,
                    *task,
                    config,
                    *seed,
                    graph.as_deref(),
                )?,
            };
            let child = start(cmd, &plan.log_path(&all[i]), plan.threads)?;
            running.push((i, child, Instant::now()));
            queue.remove(k);
        }
        if running.is_empty() && queue.is_empty() {
            break;
        }
        let names: Vec<String> = running
            .iter()
            .map(|(i, _, _)| Plan::label(&all[*i]))
            .collect();
        bar.set_message(format!(
            "done {done_now}, running {} [{}], left {}, failed {}",
            running.len(),
            names.join(", "),
            queue.len(),
            failed.len()
        ));
        std::thread::sleep(Duration::from_millis(250));
    }
    bar.finish_and_clear();
    eprintln!(
        "experiment {}: {} runs finished, {} failed; `worldgraph table {}` renders the tables",
        plan.grid.name,
        done_now,
        failed.len(),
        plan.results.display()
    );
    for (i, e) in &failed {
        eprintln!("  failed {}: {e}", Plan::label(&all[*i]));
    }
    Ok(if failed.is_empty() {
        std::process::ExitCode::SUCCESS
    } else {
        std::process::ExitCode::FAILURE
    })
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
