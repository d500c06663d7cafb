//! The committed results of the paper's experiments (section 5): one small
//! JSON summary per finished run under
//! `results/<maze>/<task>/<config>/seed-<n>.json`, and one per world graph
//! discovery under `results/<maze>/discover/seed-<n>.json`. They outlive the
//! machine that ran them: `worldgraph table` renders them, `worldgraph
//! experiment` skips the runs they record, and `worldgraph experiment
//! --reproduce` reruns one and checks its test score.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::{Deserialize, Serialize};

use learner::run::config::TrainConfig;

/// Version of the summary format.
pub const RESULT_SCHEMA: u32 = 1;

/// How a run's world graph was discovered (what reproducing it reruns).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscoverSpec {
    /// Maze (`small`, `medium`, `large`).
    pub maze: String,
    /// Discovery seed (the run's training seed).
    pub seed: u64,
    /// Rounds of discovery.
    pub rounds: u32,
}

/// One point of a validation curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CurvePoint {
    /// Env steps trained when validated.
    pub env_steps: u64,
    /// Training wall seconds by then.
    pub wall_seconds: f64,
    /// Validation score (mean reward, or Door-Key success rate).
    pub score: f64,
}

/// The summary of one finished `train` run of a grid.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunResult {
    /// [`RESULT_SCHEMA`].
    pub schema: u32,
    /// Maze.
    pub maze: String,
    /// Task (`multigoal`, `multigoal-sparse`, `multigoal-stochastic`, `doorkey`).
    pub task: String,
    /// Agent configuration (`a2c`, `fn`, `fn-init`, `wn-pivotal-trav-init`, ...).
    pub config: String,
    /// Training seed.
    pub seed: u64,
    /// The grid file the run belongs to.
    pub grid: String,
    /// The resolved training configuration (budget included).
    pub train_config: TrainConfig,
    /// The discovery run the agent used, if any.
    pub discover: Option<DiscoverSpec>,
    /// Validation seeds: environments `(validation_stream, 0..validation_seeds)`.
    pub validation_stream: u64,
    /// Number of validation seeds.
    pub validation_seeds: usize,
    /// Test seeds: environments `(test_stream, 0..test_seeds)`.
    pub test_stream: u64,
    /// Number of test seeds.
    pub test_seeds: usize,
    /// Test score of the best validation checkpoint.
    pub test_score: f64,
    /// Mean test return.
    pub test_return: f64,
    /// Test success rate.
    pub test_success_rate: f64,
    /// Best validation score.
    pub best_validation: f64,
    /// Env steps at the best validation checkpoint.
    pub best_env_steps: u64,
    /// The validation curve.
    pub validation_curve: Vec<CurvePoint>,
    /// Env steps trained.
    pub env_steps: u64,
    /// Training wall seconds.
    pub wall_seconds: f64,
    /// Training env-steps per second.
    pub train_steps_per_sec: f64,
    /// libtorch threads of the run.
    pub torch_threads: usize,
    /// Runs side by side on the machine while it ran.
    pub jobs: usize,
    /// The commit the binary that ran it was built from ([`build_commit`]).
    pub commit: String,
    /// The learners' gradient path (`agent.grad_path`, `gcp.grad_path`; up
    /// to this version the `WORLDGRAPH_GRAD_PATH` variable): the same
    /// function in another float order, so a rerun reproduces bit for bit
    /// only on the same path ([`grad_path_before_recorded`] where absent).
    #[serde(default = "grad_path_before_recorded")]
    pub grad_path: String,
    /// The CPU it ran on ([`cpu_model`]): libtorch's MKL and the own
    /// kernels' GEMM choose their kernels and blocking by CPU, so the same
    /// commit, seed and gradient path give the same floats only on the same
    /// CPU model ([`cpu_before_recorded`] where absent).
    #[serde(default = "cpu_before_recorded")]
    pub cpu: String,
}

/// The CPU of a summary written before summaries recorded it.
pub fn cpu_before_recorded() -> String {
    "unrecorded".to_string()
}

/// This machine's CPU model (`model name` of `/proc/cpuinfo`; `unknown`
/// where there is none).
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find_map(|l| l.strip_prefix("model name"))
                .and_then(|rest| rest.split_once(':'))
                .map(|(_, name)| name.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".to_string())
}

/// The gradient path of a summary written before summaries recorded it:
/// `rust-encoder`, the default from `ea285dd` (the own-kernel encoder) until
/// `rust-core` became it (summaries of earlier commits ran `per-step`).
pub fn grad_path_before_recorded() -> String {
    "rust-encoder".to_string()
}

impl RunResult {
    /// True if the run failed by the paper's rule: the validation score
    /// never rose above 0 (section 5, the notes of Table 1).
    pub fn failed(&self) -> bool {
        !self.validation_curve.iter().any(|p| p.score > 0.0)
    }
}

/// The summary of one world graph discovery of a grid.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscoverResult {
    /// [`RESULT_SCHEMA`].
    pub schema: u32,
    /// What was run.
    pub spec: DiscoverSpec,
    /// The grid file.
    pub grid: String,
    /// `discovery.json` of the run, as `discover` wrote it.
    pub summary: serde_json::Value,
    /// The commit the binary that ran it was built from: the last start in
    /// the run's `invocations.txt`, so a discovery a grid reuses (copied
    /// from another grid, or finished by an earlier binary) keeps its own;
    /// `unknown` for a run made before `discover` recorded its starts.
    pub commit: String,
    /// The gradient path `π_g` trained on ([`RunResult::grad_path`]).
    #[serde(default = "grad_path_before_recorded")]
    pub grad_path: String,
    /// The CPU it ran on ([`RunResult::cpu`]).
    #[serde(default = "cpu_before_recorded")]
    pub cpu: String,
}

/// `results/<maze>/<task>/<config>/seed-<n>.json`.
pub fn run_path(root: &Path, maze: &str, task: &str, config: &str, seed: u64) -> PathBuf {
    root.join(maze)
        .join(task)
        .join(config)
        .join(format!("seed-{seed}.json"))
}

/// `results/<maze>/discover/seed-<n>.json`.
pub fn discover_path(root: &Path, maze: &str, seed: u64) -> PathBuf {
    root.join(maze)
        .join("discover")
        .join(format!("seed-{seed}.json"))
}

/// Reads one run summary.
pub fn read_run(path: &Path) -> anyhow::Result<RunResult> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut v: serde_json::Value = serde_json::from_slice(&bytes)
        .with_context(|| format!("{} is not a run summary", path.display()))?;
    // A summary written before the Manager's goal map, its windows or the
    // Worker's booking of the task's end existed ran without the first two
    // and with the terminal booking: its recorded agent settings say so,
    // not today's defaults.
    if let Some(agent) = v
        .get_mut("train_config")
        .and_then(|t| t.get_mut("agent"))
        .and_then(|a| a.as_object_mut())
    {
        agent
            .entry("goal_map")
            .or_insert(serde_json::Value::Bool(false));
        agent
            .entry("goal_map_windows")
            .or_insert(serde_json::Value::Bool(false));
        agent
            .entry("worker_task_end")
            .or_insert(serde_json::Value::String("terminal".into()));
    }
    let r: RunResult = serde_json::from_value(v)
        .with_context(|| format!("{} is not a run summary", path.display()))?;
    check_schema(path, r.schema)?;
    Ok(r)
}

/// Every run summary under `root` (discovery summaries are skipped),
/// sorted by path, and the other result sets nested under it, which are not
/// read: a folder below `root` with a maze's folder of its own
/// (`results/goal-map/small/...` under `results/`) is a grid's results at
/// its own budget, and a table never mixes budgets. Two summaries of the
/// same run (configuration, maze, task and seed), such as a copy under
/// another name or folder, are refused naming both files: each would count
/// as a seed of its cell.
pub fn read_all_runs(root: &Path) -> anyhow::Result<(Vec<RunResult>, Vec<PathBuf>)> {
    let (files, nested) = summary_files(root)?;
    let mut seen: std::collections::BTreeMap<(String, String, String, u64), &Path> =
        std::collections::BTreeMap::new();
    let mut runs = Vec::new();
    for p in files
        .iter()
        .filter(|p| p.parent().and_then(|d| d.file_name()) != Some("discover".as_ref()))
    {
        let r = read_run(p)?;
        let key = (r.config.clone(), r.maze.clone(), r.task.clone(), r.seed);
        if let Some(first) = seen.insert(key, p) {
            anyhow::bail!(
                "{} and {} are summaries of the same run (config {}, maze {}, task {}, seed {}); \
                 remove one, or it is counted twice",
                first.display(),
                p.display(),
                r.config,
                r.maze,
                r.task,
                r.seed
            );
        }
        runs.push(r);
    }
    Ok((runs, nested))
}

/// Every world graph discovery summary of the result set `root`
/// (`<maze>/discover/seed-<n>.json`; the sets nested under it are not
/// read), sorted by path.
pub fn read_all_discoveries(root: &Path) -> anyhow::Result<Vec<DiscoverResult>> {
    let (files, _) = summary_files(root)?;
    files
        .iter()
        .filter(|p| p.parent().and_then(|d| d.file_name()) == Some("discover".as_ref()))
        .map(|p| {
            let bytes = std::fs::read(p).with_context(|| format!("cannot read {}", p.display()))?;
            let r: DiscoverResult = serde_json::from_slice(&bytes)
                .with_context(|| format!("{} is not a discovery summary", p.display()))?;
            check_schema(p, r.schema)?;
            Ok(r)
        })
        .collect()
}

/// Refuses a summary at `path` written in another format than this
/// build's ([`RESULT_SCHEMA`]).
fn check_schema(path: &Path, schema: u32) -> anyhow::Result<()> {
    anyhow::ensure!(
        schema == RESULT_SCHEMA,
        "{} has summary schema {schema}, this build reads {RESULT_SCHEMA}",
        path.display()
    );
    Ok(())
}

/// The summary files under `root` and the result sets nested under it,
/// each sorted by path.
fn summary_files(root: &Path) -> anyhow::Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let mut files = Vec::new();
    let mut nested = Vec::new();
    collect(root, true, &mut files, &mut nested)?;
    files.sort();
    nested.sort();
    Ok((files, nested))
}

fn collect(
    dir: &Path,
    root: bool,
    out: &mut Vec<PathBuf>,
    nested: &mut Vec<PathBuf>,
) -> anyhow::Result<()> {
    if !root && is_result_set(dir) {
        nested.push(dir.to_path_buf());
        return Ok(());
    }
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))?;
    for e in entries {
        let p = e?.path();
        if root && p.ends_with("runs") {
            // The grid runner's working directory (`experiment`'s default
            // `--work`: checkpoints and logs, no summaries).
            continue;
        }
        if p.is_dir() {
            collect(&p, false, out, nested)?;
        } else if p
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("seed-") && n.ends_with(".json"))
        {
            out.push(p);
        }
    }
    Ok(())
}

/// Whether `dir` holds a result set of its own: a folder named after a
/// maze (`<dir>/small/`, ...).
fn is_result_set(dir: &Path) -> bool {
    sim::Maze::ALL.iter().any(|m| dir.join(m.name()).is_dir())
}

/// The commit the binary was built from (`+dirty` when tracked files had
/// changes, `unknown` outside a git checkout; `build.rs`), not the working
/// tree's at run time: a grid keeps running on its binary while the
/// repository moves on, and its summaries must name the code that ran.
pub fn build_commit() -> String {
    env!("WORLDGRAPH_BUILD_COMMIT").to_string()
}
