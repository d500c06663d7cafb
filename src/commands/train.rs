//! `worldgraph train`: stage 2 of the paper — one agent (A2C, FN or WN),
//! one task, one maze, one seed — under the paper's protocol: periodic
//! validation on 10 validation seeds keeps the best checkpoint, which is
//! scored at the end on 100 held-out test seeds (section 5, Control
//! Experiments). `worldgraph evaluate` scores a run on any seeds.
//!
//! Training runs in segments of `eval_every` env steps; after each, the
//! agent is validated and the run checkpointed (weights, optimiser moments,
//! metrics), so a killed run resumes at the last segment boundary and ends
//! exactly as an uninterrupted one.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use learner::batch_env::{BatchEnvironment, InProcess};
use learner::gcp::{GcpConfig, GoalConditionedPolicy};
use learner::hrl::wide_narrow::Coverage;
use learner::hrl::{
    AgentConfig, AgentKind, Candidates, EpisodeTrace, EvalResult, HrlAgent, IterationStats,
    WorldGraphInputs,
};
use serde::{Deserialize, Serialize};
use sim::render::{Canvas, Rgb, draw_grid, object_color, write_atomic};
use sim::{BatchEnv, EnvConfig, Layout, Maze, Object, Task};

use crate::chart::{LEGEND_CELL, LegendEntry, LineChart, Mark, Series, XScale, captioned};
use crate::update_log::{UpdateLog, UpdateRow};

/// Environment stream of the validation seeds: validation seed `v` is the
/// environment `(VALIDATION_STREAM, v)`.
pub const VALIDATION_STREAM: u64 = 1_000_003;
/// Environment stream of the test seeds.
pub const TEST_STREAM: u64 = 2_000_003;
/// Training seeds are below this (so their streams `(seed, i)` never meet
/// the validation and test streams).
pub const MAX_TRAIN_SEED: u64 = 1_000_000;
/// The most seeds one evaluation steps side by side (`evaluate --seeds`,
/// `validation_seeds`, `test_seeds`): each is an environment of one batch.
pub const MAX_EVAL_SEEDS: u64 = 10_000;

/// The agent on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AgentArg {
    /// The A2C-LSTM baseline.
    A2c,
    /// The Feudal Network.
    Fn,
    /// Wide-then-Narrow.
    Wn,
}

/// `--candidates`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CandidatesArg {
    /// `V_all`: every valid cell.
    All,
    /// `V_rand`: random cells, as many as `V_p`.
    Random,
    /// `V_p`: the discovery run's pivotal states.
    Pivotal,
}

/// `--init`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InitArg {
    /// Fresh weights.
    None,
    /// The Manager's and Worker's encoders (and the Worker's core and
    /// heads) from the discovery run's `π_g`.
    PiG,
}

/// `train` options.
#[derive(Debug, Clone, Args)]
pub struct TrainArgs {
    /// Task: multigoal, multigoal-sparse, multigoal-stochastic or doorkey.
    #[arg(long, default_value = "multigoal")]
    pub task: Task,
    /// Embedded maze: small, medium or large (Door-Key uses its Door-Key variant).
    #[arg(long, default_value = "small")]
    pub maze: Maze,
    /// Agent [default: the --config file's, else wn].
    #[arg(long, value_enum)]
    pub agent: Option<AgentArg>,
    /// Wide-goal candidates of WN [default: the --config file's, else pivotal].
    #[arg(long, value_enum)]
    pub candidates: Option<CandidatesArg>,
    /// Initialisation [default: the --config file's, else none].
    #[arg(long, value_enum)]
    pub init: Option<InitArg>,
    /// World graph traversal (WN over random or pivotal candidates).
    #[arg(long)]
    pub traversal: bool,
    /// The `worldgraph discover` run whose world graph (V_p) and π_g the
    /// agent uses (needed for --candidates random|pivotal, --init pi-g).
    #[arg(long)]
    pub world_graph: Option<PathBuf>,
    /// Training seed (below 1,000,000): weights, training environments
    /// `(seed, i)`, V_rand.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A TOML file of training settings (any subset of the resolved
    /// `config.toml` a run writes; unknown fields are refused).
    /// `agent.horizon = 0` and `agent.window = 0` mean auto: the Manager
    /// horizon a third of `rollout_len`; the narrow window 5×5 (7×7 on
    /// grids wider than 25), widened to the smallest odd side whose windows
    /// around the wide-goal candidates cover every free cell. The run's
    /// `config.toml` holds the values they resolved to (0 where the agent
    /// has no such setting: A2C's horizon, A2C's and FN's window); a run
    /// resumes whether a setting is given as 0 or as that value.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Env-step budget [default: the --config file's, else 1,000,000],
    /// rounded up to whole validation segments: `eval_every` rounded up to
    /// whole iterations of envs × rollout_len env steps (so 2000 trains
    /// 51,840 with the defaults); `train` prints the rounding.
    #[arg(long)]
    pub env_steps: Option<u64>,
    /// Run directory: new, empty, or a train run to resume (any other
    /// directory is refused untouched) [default:
    /// runs/train-<maze>-<task>-<agent>-<seed>].
    #[arg(long)]
    pub run: Option<PathBuf>,
    /// Step the training environments in a sim process over shared memory
    /// (one for the whole run); same result as in-process for the same
    /// seed.
    #[arg(long)]
    pub pipeline: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// Set one field of the training settings, as a dotted TOML path and a
    /// TOML value (repeatable; applied over --config, before the options
    /// above): `--set agent.worker.learning_rate=3e-4`, `--set
    /// eval_every=100000`, `--set agent.horizon=15`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Print the resolved training settings (TOML, as the run's
    /// `config.toml` would hold them: `0 = auto` settings replaced by their
    /// values; WN's window over V_rand or V_p needs --world-graph) and exit
    /// without training or writing anything.
    #[arg(long)]
    pub print_config: bool,
}

/// Everything `train` is configured by (the run's `config.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Env-step budget.
    pub env_steps: u64,
    /// Env steps per segment (validation and checkpoint after each).
    pub eval_every: u64,
    /// Validation seeds.
    pub validation_seeds: usize,
    /// Test seeds.
    pub test_seeds: usize,
    /// The agent.
    pub agent: AgentConfig,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            env_steps: 1_000_000,
            eval_every: 50_000,
            validation_seeds: 10,
            test_seeds: 100,
            agent: AgentConfig::default(),
        }
    }
}

/// A run's identity: what must match to resume it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunIdentity {
    /// Maze.
    pub maze: String,
    /// Task.
    pub task: Task,
    /// Seed.
    pub seed: u64,
    /// The discovery run (canonical path), if any.
    pub world_graph: Option<String>,
    /// The resolved configuration, less the budget.
    pub config: TrainConfig,
}

/// One row of `metrics.csv` (one segment).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct MetricsRow {
    /// Segments done.
    pub segment: u64,
    /// Iterations done.
    pub iteration: u64,
    /// Env steps done.
    pub env_steps: u64,
    /// Mean return of the training episodes of the segment.
    pub train_return: f64,
    /// Validation score after the segment.
    pub validation_score: f64,
    /// Worker (or baseline) policy loss, mean over the segment.
    pub worker_policy_loss: f64,
    /// Worker value loss.
    pub worker_value_loss: f64,
    /// Worker entropy.
    pub worker_entropy: f64,
    /// Manager policy loss.
    pub manager_policy_loss: f64,
    /// Manager value loss.
    pub manager_value_loss: f64,
    /// Manager entropy.
    pub manager_entropy: f64,
    /// Share of Manager intervals in which the Worker reached its goal.
    pub goals_reached: f64,
    /// Share of env steps taken by traversal.
    pub traversal_share: f64,
}

/// The run's progress (`checkpoint/state.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RunState {
    identity: RunIdentity,
    segments_done: u64,
    env_steps: u64,
    best_score: Option<f64>,
    best_segment: u64,
    rows: Vec<MetricsRow>,
    wall_seconds: Vec<f64>,
}

/// `test.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TestSummary {
    /// The agent's short name.
    pub agent: String,
    /// Maze.
    pub maze: String,
    /// Task.
    pub task: String,
    /// Training seed.
    pub seed: u64,
    /// Test score of the best checkpoint (mean reward, or Door-Key success rate).
    pub test_score: f64,
    /// Mean test return.
    pub test_return: f64,
    /// Test success rate.
    pub test_success_rate: f64,
    /// Test seeds: environments `(test_stream, 0..test_seeds)`.
    pub test_stream: u64,
    /// Number of test seeds.
    pub test_seeds: usize,
    /// Validation seeds: `(validation_stream, 0..validation_seeds)`.
    pub validation_stream: u64,
    /// Number of validation seeds.
    pub validation_seeds: usize,
    /// Best validation score and the env steps it was reached at.
    pub best_validation: f64,
    /// Env steps at the best checkpoint.
    pub best_env_steps: u64,
    /// Env steps trained.
    pub env_steps: u64,
    /// Wall seconds of training (all sessions).
    pub wall_seconds: f64,
    /// Training env-steps per second.
    pub train_steps_per_sec: f64,
    /// Validation curve: `(env steps, score)`.
    pub validation_curve: Vec<(u64, f64)>,
    /// Training wall seconds at each point of the validation curve (for
    /// time to score).
    #[serde(default)]
    pub validation_wall_seconds: Vec<f64>,
    /// Side `N` of the narrow window (WN).
    #[serde(default)]
    pub window_side: Option<usize>,
    /// Which free cells the narrow goals can reach under the candidate set
    /// the run used (WN).
    #[serde(default)]
    pub window_coverage: Option<Coverage>,
}

fn agent_config(a: &TrainArgs, base: &AgentConfig) -> AgentConfig {
    let mut cfg = base.clone();
    if let Some(k) = a.agent {
        cfg.kind = match k {
            AgentArg::A2c => AgentKind::A2c,
            AgentArg::Fn => AgentKind::Feudal,
            AgentArg::Wn => AgentKind::WideNarrow,
        };
    }
    if let Some(c) = a.candidates {
        cfg.candidates = match c {
            CandidatesArg::All => Candidates::All,
            CandidatesArg::Random => Candidates::Random,
            CandidatesArg::Pivotal => Candidates::Pivotal,
        };
    }
    if let Some(i) = a.init {
        cfg.init_from_gcp = i == InitArg::PiG;
    }
    if a.traversal {
        cfg.traversal = true;
    }
    cfg
}

/// Refuses a budget that cannot run (before anything is written): no
/// segment, no validation or test seed, or batches larger than a run can
/// hold (`file`, the --config file, is named).
fn check_budget(cfg: &TrainConfig, file: Option<&Path>) -> anyhow::Result<()> {
    let from = file.map_or(String::new(), |f| format!(" (in {})", f.display()));
    anyhow::ensure!(cfg.eval_every > 0, "eval_every must be at least 1");
    anyhow::ensure!(
        cfg.validation_seeds > 0 && cfg.test_seeds > 0,
        "validation_seeds and test_seeds must be at least 1"
    );
    let max_envs = super::discover::MAX_ENVS;
    anyhow::ensure!(
        cfg.agent.envs <= max_envs,
        "[agent] envs = {}{from}: at most {max_envs} environments",
        cfg.agent.envs
    );
    for (name, n) in [
        ("validation_seeds", cfg.validation_seeds),
        ("test_seeds", cfg.test_seeds),
    ] {
        anyhow::ensure!(
            n as u64 <= MAX_EVAL_SEEDS,
            "{name} = {n}{from}: at most {MAX_EVAL_SEEDS} seeds"
        );
    }
    Ok(())
}

/// The training settings of `--config` (or the defaults) with every
/// `--set KEY=VALUE` applied: each names a dotted path into the TOML and a
/// TOML value (a bare word that is not one is taken as a string).
pub fn config_with_overrides(
    file: Option<&Path>,
    overrides: &[String],
) -> anyhow::Result<TrainConfig> {
    let base = match file {
        Some(p) => read_config(p)?,
        None => TrainConfig::default(),
    };
    if overrides.is_empty() {
        return Ok(base);
    }
    let mut doc = toml::Value::try_from(&base).context("the settings do not serialise")?;
    for o in overrides {
        let (key, value) = o
            .split_once('=')
            .with_context(|| format!("--set {o}: expected KEY=VALUE, e.g. agent.horizon=15"))?;
        let (key, value) = (key.trim(), value.trim());
        let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut at = &mut doc;
        let parts: Vec<&str> = key.split('.').collect();
        for (i, part) in parts.iter().enumerate() {
            let table = at
                .as_table_mut()
                .with_context(|| format!("--set {o}: {} is not a table", parts[..i].join(".")))?;
            if i + 1 == parts.len() {
                anyhow::ensure!(
                    table.contains_key(*part),
                    "--set {o}: the training settings have no field {key}"
                );
                table.insert(part.to_string(), value.clone());
                break;
            }
            at = table
                .get_mut(*part)
                .with_context(|| format!("--set {o}: the training settings have no field {key}"))?;
        }
    }
    TrainConfig::deserialize(doc).map_err(|e| anyhow::anyhow!("--set: {}", e.message()))
}

/// Reads a TOML config file.
pub fn read_config(path: &Path) -> anyhow::Result<TrainConfig> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    toml::from_str(&text)
        .with_context(|| format!("{} is not a valid training config", path.display()))
}

/// `π_g` of a discovery run, for `layout` (its weights fit any layout of
/// the same size).
pub fn load_gcp(dir: &Path, layout: &Layout) -> anyhow::Result<GoalConditionedPolicy> {
    let cfg_path = dir.join("pi_g.json");
    let cfg: GcpConfig = serde_json::from_slice(&std::fs::read(&cfg_path).with_context(|| {
        format!(
            "cannot read {} (a discover run writes it)",
            cfg_path.display()
        )
    })?)
    .with_context(|| format!("{} is not a π_g config", cfg_path.display()))?;
    let mut gcp = GoalConditionedPolicy::new(&cfg, layout, 1, Task::MultiGoal.num_actions(), 0)?;
    gcp.load(dir.join("pi_g.ot"))?;
    Ok(gcp)
}

/// The world graph over the candidate set on the task's layout: `V_p` as
/// discovered (re-walked on the Door-Key layout when the task's layout
/// differs), or `V_rand` of the same size with edges formed the same way
/// (random walks, then `π_g` refinement).
pub fn world_graph_for(
    dir: &Path,
    layout: &Layout,
    task: Task,
    candidates: Candidates,
    seed: u64,
    gcp: &mut GoalConditionedPolicy,
) -> anyhow::Result<planner::WorldGraph> {
    let path = dir.join("graph.json");
    let discovered = planner::WorldGraph::load(&path)
        .with_context(|| format!("cannot load the world graph {}", path.display()))?;
    let same_layout = discovered.layout().cells == layout.cells;
    let pivotal: Vec<u32> = discovered
        .nodes()
        .iter()
        .map(|c| c.0)
        .filter(|&c| {
            planner::pivotal::is_node_object(
                layout.object(c as usize % layout.width, c as usize / layout.width),
            )
        })
        .collect();
    if candidates == Candidates::Pivotal && same_layout && task != Task::DoorKey {
        return Ok(discovered);
    }
    let nodes = match candidates {
        Candidates::Pivotal => planner::pivotal::nodes_from_cells(layout, &pivotal),
        _ => planner::pivotal::v_rand(layout, pivotal.len(), seed)?,
    };
    let cfg = planner::PlannerConfig {
        candidates: planner::CandidateSet::Given,
        seed,
        task: if task == Task::DoorKey {
            Task::DoorKey
        } else {
            Task::MultiGoal
        },
        shorten: false,
        ..planner::PlannerConfig::default()
    };
    let mut graph = planner::WorldGraph::build(layout, &cfg, &nodes)?;
    learner::edge_refinement::refine_with_gcp(&mut graph, gcp)?;
    Ok(graph)
}

/// The agent of a run: configuration, layout, and the stage 1 inputs.
pub fn build_agent(
    cfg: &AgentConfig,
    layout: &Layout,
    task: Task,
    world_graph: Option<&Path>,
    seed: u64,
) -> anyhow::Result<HrlAgent> {
    let needs_run = cfg.needs_graph()
        || cfg.init_from_gcp
        || (cfg.traversal && task == Task::MultiGoalStochastic);
    let inputs = match world_graph {
        Some(dir) => {
            let mut gcp = load_gcp(dir, layout)?;
            let graph = if cfg.needs_graph() {
                Some(world_graph_for(
                    dir,
                    layout,
                    task,
                    cfg.candidates,
                    seed,
                    &mut gcp,
                )?)
            } else {
                None
            };
            Some(WorldGraphInputs {
                graph,
                gcp: Some(gcp),
            })
        }
        None if needs_run => bail!(
            "{} needs --world-graph DISCOVER_RUN (its V_p and π_g); run `worldgraph discover --maze ...` first",
            cfg.name()
        ),
        None => None,
    };
    Ok(HrlAgent::new(cfg, layout, task, inputs, seed)?)
}

/// Evaluation environments: `count` seeds of `stream` from `first`, one
/// episode each.
pub fn eval_env(
    layout: &Layout,
    env_cfg: EnvConfig,
    stream: u64,
    first: u64,
    count: usize,
) -> anyhow::Result<InProcess> {
    let batch =
        BatchEnv::with_first_index(layout.clone(), env_cfg, first as usize, count, stream, 1)?;
    Ok(InProcess::from_batch(batch))
}

/// A sim process stepping `envs` environments seeded by `seed`, and the
/// shared-memory client of its batch.
fn pipeline_env(
    a: &TrainArgs,
    envs: usize,
    seed: u64,
    dir: &Path,
) -> anyhow::Result<(
    Box<dyn BatchEnvironment>,
    (crate::pipeline::Pipeline, String),
)> {
    let run_name = format!("train-{}", std::process::id());
    let w = crate::world::WorldArgs {
        maze: a.maze,
        layout: None,
        task: a.task,
        seed,
        max_steps: None,
        balls: None,
    };
    let (env, p) = crate::pipeline::spawn_sim_env(&w, envs, &run_name, dir)?;
    Ok((Box::new(env), (p, run_name)))
}

fn run_dir(a: &TrainArgs, layout: &Layout, cfg: &AgentConfig) -> PathBuf {
    a.run.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!(
            "train-{}-{}-{}-{}",
            layout.name,
            a.task.name(),
            cfg.name(),
            a.seed
        ))
    })
}

/// `--world-graph` as a canonical path, checked to be a discovery run of
/// this maze.
fn world_graph_dir(a: &TrainArgs, layout: &Layout) -> anyhow::Result<Option<PathBuf>> {
    let Some(p) = &a.world_graph else {
        return Ok(None);
    };
    let wg =
        std::fs::canonicalize(p).with_context(|| format!("no discovery run at {}", p.display()))?;
    if super::run_dir::kind_of(&wg) == Some(super::run_dir::RunKind::Train) {
        bail!(
            "--world-graph {} is a train run; give the discover run whose world graph \
             it used",
            wg.display()
        );
    }
    super::discover::check_world_graph_layout(&wg, a.maze, layout)?;
    Ok(Some(wg))
}

/// What `0 = auto` stands for in `cfg` on this run: the Manager horizon
/// `c` (FN and WN; A2C has no Manager) and the narrow window's side (WN,
/// from `agent`'s wide-goal candidates, so `None` without an agent).
fn auto_values(
    cfg: &AgentConfig,
    agent: Option<&HrlAgent>,
    layout: &Layout,
) -> (Option<usize>, Option<usize>) {
    let horizon = (cfg.kind != AgentKind::A2c).then(|| {
        AgentConfig {
            horizon: 0,
            ..cfg.clone()
        }
        .horizon() as usize
    });
    let window = agent
        .filter(|_| cfg.kind == AgentKind::WideNarrow)
        .and_then(|agent| {
            if cfg.window == 0 {
                // The side the agent resolved and uses.
                agent.window_coverage().map(|c| c.side)
            } else {
                let base = AgentConfig {
                    window: 0,
                    ..cfg.clone()
                }
                .window_side(layout.width);
                Some(learner::hrl::wide_narrow::covering_side(
                    base,
                    agent.candidates(),
                    layout,
                ))
            }
        });
    (horizon, window)
}

/// `cfg` with each `0 = auto` replaced by the value it stands for (from
/// [`auto_values`]); a setting the agent does not have (A2C's horizon and
/// window, FN's window), or whose value is unknown, stays as given.
fn resolve_auto(
    cfg: &AgentConfig,
    (horizon, window): (Option<usize>, Option<usize>),
) -> AgentConfig {
    let mut r = cfg.clone();
    if r.horizon == 0
        && let Some(h) = horizon
    {
        r.horizon = h;
    }
    if r.window == 0
        && let Some(w) = window
    {
        r.window = w;
    }
    r
}

/// `--print-config`: the settings as the run's `config.toml` would hold
/// them, `0 = auto` resolved. The window of WN over `V_rand` or `V_p`
/// needs the world graph: without `--world-graph` it stays 0, said on
/// stderr.
fn print_config(a: &TrainArgs, mut cfg: TrainConfig, layout: &Layout) -> anyhow::Result<()> {
    let world_graph = world_graph_dir(a, layout)?;
    let agent = if cfg.agent.kind == AgentKind::WideNarrow {
        match build_agent(&cfg.agent, layout, a.task, world_graph.as_deref(), a.seed) {
            Ok(agent) => Some(agent),
            Err(e) if world_graph.is_some() => return Err(e),
            Err(_) => {
                if cfg.agent.window == 0 {
                    eprintln!(
                        "train: window = {} stays as given: the auto side is resolved from the \
                     world graph's wide-goal candidates; give --world-graph to print it",
                        cfg.agent.window
                    );
                }
                None
            }
        }
    } else {
        None
    };
    cfg.agent = resolve_auto(&cfg.agent, auto_values(&cfg.agent, agent.as_ref(), layout));
    print!("{}", toml::to_string(&cfg)?);
    Ok(())
}

/// Holds `<run>/lock` for the run's lifetime: a second `train` on the same
/// directory is refused at once, naming the process that holds it.
fn lock_run_dir(dir: &Path) -> anyhow::Result<std::fs::File> {
    use std::io::Write;
    let path = dir.join("lock");
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(&path)
        .with_context(|| format!("cannot open {}", path.display()))?;
    match f.try_lock() {
        Ok(()) => {
            f.set_len(0)?;
            write!(f, "{}", std::process::id())?;
            Ok(f)
        }
        Err(std::fs::TryLockError::WouldBlock) => {
            let holder = std::fs::read_to_string(&path).unwrap_or_default();
            bail!(
                "{} is in use by another train process (pid {}); wait for it to end or use another --run",
                dir.display(),
                holder.trim()
            )
        }
        Err(std::fs::TryLockError::Error(e)) => {
            Err(e).with_context(|| format!("cannot lock {}", path.display()))
        }
    }
}

/// The files of segment `k`'s checkpoint besides `state.json`: the agent's
/// weights and optimiser moments, the training controller (record and
/// tensors) and the training environments' states.
fn checkpoint_files(k: u64) -> [String; 4] {
    [
        format!("agent-{k}.ot"),
        format!("controller-{k}.json"),
        format!("controller-{k}.ot"),
        format!("envs-{k}.json"),
    ]
}

fn save_state(
    dir: &Path,
    state: &RunState,
    agent: &HrlAgent,
    best: Option<&[u8]>,
    env: Option<&dyn BatchEnvironment>,
) -> anyhow::Result<()> {
    let ckpt = dir.join("checkpoint");
    std::fs::create_dir_all(&ckpt).with_context(|| format!("cannot create {}", ckpt.display()))?;
    let [weights, record, tensors, envs] = checkpoint_files(state.segments_done);
    write_atomic(&ckpt.join(weights), &agent.to_bytes()?)?;
    if let Some(snapshot) = env.and_then(|e| e.snapshot()) {
        let saved = agent.save_controller()?;
        write_atomic(&ckpt.join(record), &saved.record)?;
        write_atomic(&ckpt.join(tensors), &saved.tensors)?;
        write_atomic(&ckpt.join(envs), &serde_json::to_vec(&snapshot)?)?;
    }
    if let Some(b) = best {
        write_atomic(&ckpt.join("best.ot"), b)?;
    }
    // The state names its files: written last, it commits the set.
    write_atomic(&ckpt.join("state.json"), &serde_json::to_vec_pretty(state)?)?;
    if state.segments_done > 0 {
        for old in checkpoint_files(state.segments_done - 1) {
            let _ = std::fs::remove_file(ckpt.join(old));
        }
    }
    write_metrics(dir, state)?;
    Ok(())
}

/// Puts the training environments and the agent's controller back in the
/// states the checkpoint of `state` saved; false when it saved none (a
/// pipeline run, or a run made before they were saved).
fn restore_training(
    dir: &Path,
    state: &RunState,
    agent: &mut HrlAgent,
    env: &mut dyn BatchEnvironment,
) -> anyhow::Result<bool> {
    let ckpt = dir.join("checkpoint");
    let [_, record, tensors, envs] = checkpoint_files(state.segments_done);
    let (record, tensors, envs) = (ckpt.join(record), ckpt.join(tensors), ckpt.join(envs));
    if !(record.exists() && tensors.exists() && envs.exists()) {
        return Ok(false);
    }
    let read = |p: &Path| std::fs::read(p).with_context(|| format!("cannot read {}", p.display()));
    let states: Vec<sim::EnvState> = serde_json::from_slice(&read(&envs)?)
        .with_context(|| format!("{} is not a set of environment states", envs.display()))?;
    if !env
        .restore(&states)
        .with_context(|| format!("cannot restore {}", envs.display()))?
    {
        return Ok(false);
    }
    agent.load_controller(&read(&record)?, &read(&tensors)?, &record)?;
    Ok(true)
}

fn write_metrics(dir: &Path, state: &RunState) -> anyhow::Result<()> {
    let mut w = csv_writer();
    for r in &state.rows {
        w.push_str(&format!(
            "{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}\n",
            r.segment,
            r.iteration,
            r.env_steps,
            r.train_return,
            r.validation_score,
            r.worker_policy_loss,
            r.worker_value_loss,
            r.worker_entropy,
            r.manager_policy_loss,
            r.manager_value_loss,
            r.manager_entropy,
            r.goals_reached,
            r.traversal_share
        ));
    }
    write_atomic(&dir.join("metrics.csv"), w.as_bytes())?;
    let mut t = String::from("segment,env_steps,wall_seconds\n");
    for (r, s) in state.rows.iter().zip(&state.wall_seconds) {
        t.push_str(&format!("{},{},{:.3}\n", r.segment, r.env_steps, s));
    }
    write_atomic(&dir.join("timing.csv"), t.as_bytes())?;
    Ok(())
}

/// Appends the command line, the crate's version and the commit the binary
/// was built from to the run's `invocations.txt`.
fn record_invocation(dir: &Path) -> anyhow::Result<()> {
    use std::io::Write as _;
    let args: Vec<String> = std::env::args_os()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let line = format!(
        "worldgraph {} (commit {}): {}\n",
        env!("CARGO_PKG_VERSION"),
        env!("WORLDGRAPH_BUILD_COMMIT"),
        args.join(" ")
    );
    let path = dir.join("invocations.txt");
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(line.as_bytes()))
        .with_context(|| format!("cannot append to {}", path.display()))
}

fn csv_writer() -> String {
    String::from(
        "segment,iteration,env_steps,train_return,validation_score,worker_policy_loss,worker_value_loss,worker_entropy,manager_policy_loss,manager_value_loss,manager_entropy,goals_reached,traversal_share\n",
    )
}

fn mean_row(stats: &[IterationStats]) -> MetricsRow {
    let n = stats.len().max(1) as f64;
    let with_episodes: Vec<&IterationStats> = stats.iter().filter(|s| s.episodes > 0).collect();
    let episodes: usize = with_episodes.iter().map(|s| s.episodes).sum();
    let intervals: usize = stats.iter().map(|s| s.intervals).sum();
    MetricsRow {
        train_return: if episodes > 0 {
            with_episodes
                .iter()
                .map(|s| s.mean_return * s.episodes as f64)
                .sum::<f64>()
                / episodes as f64
        } else {
            0.0
        },
        worker_policy_loss: stats.iter().map(|s| s.worker.policy_loss).sum::<f64>() / n,
        worker_value_loss: stats.iter().map(|s| s.worker.value_loss).sum::<f64>() / n,
        worker_entropy: stats.iter().map(|s| s.worker.entropy).sum::<f64>() / n,
        manager_policy_loss: stats.iter().map(|s| s.manager.policy_loss).sum::<f64>() / n,
        manager_value_loss: stats.iter().map(|s| s.manager.value_loss).sum::<f64>() / n,
        manager_entropy: stats.iter().map(|s| s.manager.entropy).sum::<f64>() / n,
        goals_reached: if intervals > 0 {
            stats
                .iter()
                .map(|s| s.goals_reached * s.intervals as f64)
                .sum::<f64>()
                / intervals as f64
        } else {
            0.0
        },
        traversal_share: stats.iter().map(|s| s.traversal_share).sum::<f64>() / n,
        ..MetricsRow::default()
    }
}

/// The env steps a run of `cfg` trains: its budget rounded up to whole
/// segments of whole iterations.
pub fn trained_env_steps(cfg: &TrainConfig) -> u64 {
    let steps_per_iter = (cfg.agent.envs * cfg.agent.rollout_len) as u64;
    let per_segment = cfg.eval_every.div_ceil(steps_per_iter).max(1) * steps_per_iter;
    cfg.env_steps.div_ceil(per_segment) * per_segment
}

/// Runs `worldgraph train`.
pub fn run(a: TrainArgs) -> anyhow::Result<std::process::ExitCode> {
    anyhow::ensure!(
        a.seed < MAX_TRAIN_SEED,
        "--seed must be below {MAX_TRAIN_SEED} (higher streams hold the validation and test seeds)"
    );
    let mut cfg = config_with_overrides(a.config.as_deref(), &a.set)?;
    cfg.agent = agent_config(&a, &cfg.agent);
    if let Some(s) = a.env_steps {
        cfg.env_steps = s;
    }
    cfg.agent.validate()?;
    check_budget(&cfg, a.config.as_deref())?;
    let layout = a.maze.layout(a.task.uses_door_key_layout());
    if a.print_config {
        print_config(&a, cfg, &layout)?;
        return Ok(std::process::ExitCode::SUCCESS);
    }
    let env_cfg = EnvConfig::for_task(a.task, &layout);
    let dir = run_dir(&a, &layout, &cfg.agent);
    // Nothing is written before the directory, the world graph and the
    // run it may hold are known to fit this run.
    let mut own = vec!["lock".to_string()];
    own.extend(
        a.config
            .as_deref()
            .and_then(|c| super::run_dir::name_in(&dir, c)),
    );
    super::run_dir::check("--run", &dir, super::run_dir::RunKind::Train, &own)?;
    let world_graph = world_graph_dir(&a, &layout)?;
    let mut agent = build_agent(&cfg.agent, &layout, a.task, world_graph.as_deref(), a.seed)?;
    // The run's files and identity hold what `0 = auto` resolved to.
    let auto = auto_values(&cfg.agent, Some(&agent), &layout);
    cfg.agent = resolve_auto(&cfg.agent, auto);
    let identity = RunIdentity {
        maze: layout.name.clone(),
        task: a.task,
        seed: a.seed,
        world_graph: world_graph.as_ref().map(|p| p.display().to_string()),
        config: TrainConfig {
            env_steps: 0,
            ..cfg.clone()
        },
    };
    let state_path = dir.join("checkpoint").join("state.json");
    let read_state = || -> anyhow::Result<Option<RunState>> {
        if !state_path.exists() {
            return Ok(None);
        }
        let mut old: RunState = serde_json::from_slice(&std::fs::read(&state_path)?)
            .with_context(|| format!("{} is not a training state", state_path.display()))?;
        // A run recorded before its identity held resolved values says
        // 0 = auto: resolved for this maze and world graph, as this one.
        old.identity.config.agent = resolve_auto(&old.identity.config.agent, auto);
        if old.identity != identity {
            bail!(
                "{} holds another run ({}); use another --run",
                dir.display(),
                identity_diff(&old.identity, &identity)
            );
        }
        Ok(Some(old))
    };
    let trained = trained_env_steps(&cfg);
    if let Some(old) = read_state()?
        && old.env_steps > trained
    {
        bail!(
            "{} already trained {} env steps, more than --env-steps {} ({trained} rounded); \
             give at least {} to go on, or another --run (its config.toml is left as it is)",
            dir.display(),
            old.env_steps,
            cfg.env_steps,
            old.env_steps
        );
    }
    if trained != cfg.env_steps {
        eprintln!(
            "train: the budget of {} env steps rounds up to {trained}: whole segments of eval_every {} \
             rounded up to whole iterations of {} envs × {} steps",
            cfg.env_steps, cfg.eval_every, cfg.agent.envs, cfg.agent.rollout_len
        );
    }

    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let _lock = lock_run_dir(&dir)?;
    write_atomic(&dir.join("config.toml"), toml::to_string(&cfg)?.as_bytes())?;
    write_atomic(
        &dir.join("seeds.json"),
        &serde_json::to_vec_pretty(&serde_json::json!({
            "train": {"seed": a.seed, "environments": cfg.agent.envs, "streams": format!("(env_seed({}, 0), 0..{}), carried across segments", a.seed, cfg.agent.envs)},
            "validation": {"stream": VALIDATION_STREAM, "seeds": format!("0..{}", cfg.validation_seeds)},
            "test": {"stream": TEST_STREAM, "seeds": format!("0..{}", cfg.test_seeds)},
        }))?,
    )?;

    // What made the run: the command line, the crate's version and the
    // commit the binary was built from (`build.rs`), one line per start
    // (a resumed run appends its own).
    record_invocation(&dir)?;

    let window_coverage = agent.window_coverage();
    if let Some(c) = &window_coverage {
        eprintln!("train: narrow goals: {c}");
    }
    let mut state = RunState {
        identity: identity.clone(),
        segments_done: 0,
        env_steps: 0,
        best_score: None,
        best_segment: 0,
        rows: Vec::new(),
        wall_seconds: Vec::new(),
    };
    // Read again under the lock: the state a finished holder left.
    if let Some(old) = read_state()? {
        let weights = dir
            .join("checkpoint")
            .join(format!("agent-{}.ot", old.segments_done));
        agent.load_bytes(
            &std::fs::read(&weights)
                .with_context(|| format!("cannot read {}", weights.display()))?,
            &weights,
        )?;
        eprintln!(
            "train: resuming {} after {} env steps",
            dir.display(),
            old.env_steps
        );
        state = old;
    }
    let mut best_bytes: Option<Vec<u8>> = None;

    let steps_per_iter = (cfg.agent.envs * cfg.agent.rollout_len) as u64;
    let iters_per_segment = cfg.eval_every.div_ceil(steps_per_iter).max(1);
    let segments = cfg.env_steps.div_ceil(iters_per_segment * steps_per_iter);
    let bar = crate::progress::bar(segments * iters_per_segment, "train");
    bar.set_position(state.segments_done * iters_per_segment);
    let started = Instant::now();
    let mut wall_before: f64 = state.wall_seconds.last().copied().unwrap_or(0.0);
    // The training environments live for the whole run: validation plays
    // its own environments with a controller of its own, so it leaves the
    // training stream untouched, and a checkpoint saves the environments'
    // and the controller's states, so a resumed run goes on mid-episode
    // exactly where it stopped. (In the pipeline the sim process owns the
    // environments; there a resumed run starts fresh episodes seeded by
    // (seed, segment).)
    let (mut env, pipeline) = if state.segments_done < segments {
        let seg_seed = sim::env_seed(a.seed, state.segments_done);
        if a.pipeline {
            let (env, p) = pipeline_env(&a, cfg.agent.envs, seg_seed, &dir)?;
            (Some(env), Some(p))
        } else {
            let env: Box<dyn BatchEnvironment> = Box::new(InProcess::new(
                layout.clone(),
                env_cfg,
                cfg.agent.envs,
                seg_seed,
                1,
            )?);
            (Some(env), None)
        }
    } else {
        (None, None)
    };
    if let Some(env) = env.as_mut() {
        let resumed =
            state.segments_done > 0 && restore_training(&dir, &state, &mut agent, env.as_mut())?;
        if !resumed {
            agent.start_segment(env.as_mut(), state.segments_done)?;
        }
    }
    // One row per update (`updates.csv`, TensorBoard), kept up to the
    // checkpoint the run resumes from.
    let mut updates = if state.segments_done < segments {
        Some(UpdateLog::open(
            &dir,
            state.env_steps,
            cfg.agent.kind != AgentKind::A2c,
        )?)
    } else {
        None
    };
    while state.segments_done < segments {
        let seg_start = Instant::now();
        let train_env = env
            .as_mut()
            .expect("invariant: made above while segments remain");
        let mut stats = Vec::with_capacity(iters_per_segment as usize);
        for k in 0..iters_per_segment {
            let t0 = Instant::now();
            let s = agent.train_iteration(train_env.as_mut())?;
            if let Some(log) = updates.as_mut() {
                let update = state.segments_done * iters_per_segment + k + 1;
                log.push(&UpdateRow {
                    update,
                    env_steps: update * steps_per_iter,
                    wall_seconds: wall_before + seg_start.elapsed().as_secs_f64(),
                    episodes: s.episodes,
                    episodic_return: if s.episodes > 0 {
                        s.mean_return
                    } else {
                        f64::NAN
                    },
                    policy_loss: s.worker.policy_loss,
                    value_loss: s.worker.value_loss,
                    entropy: s.worker.entropy,
                    manager_policy_loss: s.manager.policy_loss,
                    manager_value_loss: s.manager.value_loss,
                    manager_entropy: s.manager.entropy,
                    intervals: s.intervals,
                    goals_reached: s.goals_reached,
                    traversal_share: s.traversal_share,
                    sps: s.env_steps as f64 / t0.elapsed().as_secs_f64().max(1e-9),
                    exit_share: if s.episodes > 0 {
                        s.exit_share
                    } else {
                        f64::NAN
                    },
                    exit_goal_share: s.exit_goal_share,
                    ball_goal_share: s.ball_goal_share,
                    key_share: if s.episodes > 0 {
                        s.key_share
                    } else {
                        f64::NAN
                    },
                    door_share: if s.episodes > 0 {
                        s.door_share
                    } else {
                        f64::NAN
                    },
                })?;
            }
            bar.inc(1);
            bar.set_message(format!(
                "return {:.2}  validation {}",
                s.mean_return,
                state
                    .rows
                    .last()
                    .map_or("-".to_string(), |r| format!("{:.2}", r.validation_score))
            ));
            stats.push(s);
        }
        // The same validation episodes every time: fresh environments of
        // the validation seeds.
        let mut val_env = eval_env(&layout, env_cfg, VALIDATION_STREAM, 0, cfg.validation_seeds)?;
        let val = agent.evaluate(&mut val_env, state.segments_done, None)?;
        state.segments_done += 1;
        state.env_steps += iters_per_segment * steps_per_iter;
        let mut row = mean_row(&stats);
        row.segment = state.segments_done;
        row.iteration = state.segments_done * iters_per_segment;
        row.env_steps = state.env_steps;
        row.validation_score = val.score;
        crate::progress::note(
            &bar,
            &format!(
                "segment {}/{}: {} env steps, train return {:.3}, validation {:.3}",
                state.segments_done,
                segments,
                state.env_steps,
                row.train_return,
                row.validation_score
            ),
        );
        state.rows.push(row);
        wall_before += seg_start.elapsed().as_secs_f64();
        state.wall_seconds.push(wall_before);
        best_bytes = None;
        if state.best_score.is_none_or(|b| val.score > b) {
            state.best_score = Some(val.score);
            state.best_segment = state.segments_done;
            best_bytes = Some(agent.to_bytes()?);
        }
        save_state(&dir, &state, &agent, best_bytes.as_deref(), env.as_deref())?;
    }
    drop(env);
    if let Some((mut p, run_name)) = pipeline {
        p.stop_all(std::time::Duration::from_secs(3));
        crate::shutdown::teardown(&run_name)?;
    }
    bar.finish_and_clear();
    let _ = started;
    let _ = best_bytes;

    // The best checkpoint on the held-out test seeds.
    let best = dir.join("checkpoint").join("best.ot");
    agent.load_bytes(
        &std::fs::read(&best).with_context(|| format!("cannot read {}", best.display()))?,
        &best,
    )?;
    let mut test_env = eval_env(&layout, env_cfg, TEST_STREAM, 0, cfg.test_seeds)?;
    let mut trace = EpisodeTrace::default();
    let test = agent.evaluate(&mut test_env, u64::MAX, Some(&mut trace))?;
    let wall = state.wall_seconds.last().copied().unwrap_or(0.0);
    let summary = TestSummary {
        agent: cfg.agent.name(),
        maze: layout.name.clone(),
        task: a.task.name().to_string(),
        seed: a.seed,
        test_score: test.score,
        test_return: test.mean_return,
        test_success_rate: test.success_rate,
        test_stream: TEST_STREAM,
        test_seeds: cfg.test_seeds,
        validation_stream: VALIDATION_STREAM,
        validation_seeds: cfg.validation_seeds,
        best_validation: state.best_score.unwrap_or(0.0),
        best_env_steps: state.best_segment * iters_per_segment * steps_per_iter,
        env_steps: state.env_steps,
        wall_seconds: wall,
        train_steps_per_sec: state.env_steps as f64 / wall.max(1e-9),
        validation_curve: state
            .rows
            .iter()
            .map(|r| (r.env_steps, r.validation_score))
            .collect(),
        validation_wall_seconds: state.wall_seconds.clone(),
        window_side: window_coverage.as_ref().map(|c| c.side),
        window_coverage,
    };
    write_atomic(
        &dir.join("test.json"),
        &serde_json::to_vec_pretty(&summary)?,
    )?;
    write_atomic(&dir.join("test_episode.json"), &serde_json::to_vec(&trace)?)?;
    curves(&state.rows, &summary)
        .render(900, 520)
        .save_png(&dir.join("curves.png"))?;
    // The trace is environment 0's episode: test seed 0.
    episode_picture(&layout, &trace, agent.graph(), &cfg.agent, a.task, 0)
        .save_png(&dir.join("episode.png"))?;
    if a.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print_summary(&summary, &test, &dir);
    }
    Ok(std::process::ExitCode::SUCCESS)
}

fn identity_diff(old: &RunIdentity, new: &RunIdentity) -> String {
    let a = serde_json::to_value(old).unwrap_or_default();
    let b = serde_json::to_value(new).unwrap_or_default();
    let mut diffs = Vec::new();
    fn walk(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        match (a, b) {
            (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                for (k, v) in x {
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    walk(&p, v, y.get(k).unwrap_or(&serde_json::Value::Null), out);
                }
            }
            _ if a != b => out.push(format!("{path}: {a} there, {b} here")),
            _ => {}
        }
    }
    walk("", &a, &b, &mut diffs);
    diffs.join("; ")
}

fn curves(rows: &[MetricsRow], s: &TestSummary) -> LineChart {
    LineChart {
        title: format!("{} on {} {} (seed {})", s.agent, s.maze, s.task, s.seed),
        x_label: "env steps".into(),
        y_label: "score".into(),
        series: vec![
            Series {
                name: "validation score".into(),
                points: rows
                    .iter()
                    .map(|r| (r.env_steps as f64, r.validation_score))
                    .collect(),
            },
            Series {
                name: "training return".into(),
                points: rows
                    .iter()
                    .map(|r| (r.env_steps as f64, r.train_return))
                    .collect(),
            },
            Series {
                name: "worker goals reached".into(),
                points: rows
                    .iter()
                    .map(|r| (r.env_steps as f64, r.goals_reached))
                    .collect(),
            },
        ],
        x_scale: XScale::Linear,
    }
}

/// What a traced episode did with the task's objects: the balls it started
/// with and collected, whether it ended on the exit, the key and the door
/// (from the grids it started and ended on).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EpisodeOutcome {
    /// Balls on the grid at the start.
    pub balls: usize,
    /// Of those, the ones missing from the final grid.
    pub collected: usize,
    /// The episode ended on an exit cell.
    pub exited: bool,
    /// A key on the start grid was gone from its cell at the end.
    pub key_taken: bool,
    /// A door closed or locked at the start was open at the end.
    pub door_opened: bool,
}

impl EpisodeOutcome {
    /// The outcome of `t`; `None` when it holds no start and end grids.
    pub fn of(t: &EpisodeTrace) -> Option<EpisodeOutcome> {
        let (a, b) = (&t.start_cells, &t.end_cells);
        if a.is_empty() || a.len() != b.len() {
            return None;
        }
        let code = |o: Object| o as u8;
        let gone = |o: Object| {
            a.iter()
                .zip(b)
                .filter(|&(&x, &y)| x == code(o) && y != code(o))
                .count()
        };
        let last = t.cells.last().map(|&c| c as usize);
        Some(EpisodeOutcome {
            balls: a.iter().filter(|&&c| c == code(Object::Ball)).count(),
            collected: gone(Object::Ball),
            exited: last.and_then(|c| b.get(c)) == Some(&code(Object::Exit)),
            key_taken: gone(Object::Key) > 0,
            door_opened: a.iter().zip(b).any(|(&x, &y)| {
                (x == code(Object::DoorLocked) || x == code(Object::DoorClosed))
                    && y == code(Object::DoorOpen)
            }),
        })
    }
}

/// The paper's name of an agent configuration: `A2C`, `FN + π_g init`,
/// `WN V_p + traversal + π_g init`, ...
pub fn agent_label(cfg: &AgentConfig) -> String {
    let mut s = match cfg.kind {
        AgentKind::A2c => "A2C".to_string(),
        AgentKind::Feudal => "FN".to_string(),
        AgentKind::WideNarrow => format!("WN {}", candidates_label(cfg.candidates)),
    };
    if cfg.traversal {
        s.push_str(" + traversal");
    }
    if cfg.init_from_gcp {
        s.push_str(" + π_g init");
    }
    s
}

fn candidates_label(c: Candidates) -> &'static str {
    match c {
        Candidates::All => "V_all",
        Candidates::Random => "V_rand",
        Candidates::Pivotal => "V_p",
    }
}

/// The paper's name of a task.
pub fn task_label(task: Task) -> &'static str {
    match task {
        Task::MultiGoal => "MultiGoal",
        Task::MultiGoalSparse => "MultiGoal-Sparse",
        Task::MultiGoalStochastic => "MultiGoal-Stochastic",
        Task::DoorKey => "Door-Key",
    }
}

/// Colours of the episode picture's marks.
const WORKER_RED: Rgb = [220, 30, 40];
const TRAVERSAL_BLUE: Rgb = [100, 180, 255];
const NARROW_BLUE: Rgb = [120, 190, 255];
const WIDE_BLUE: Rgb = [20, 60, 220];
const NODE_BLUE: Rgb = [90, 90, 200];
/// The frame around the exit cells.
pub const EXIT_FRAME: Rgb = [255, 190, 0];
const TICK_GREEN: Rgb = [20, 140, 50];
/// Pixels per cell of the episode picture.
pub const EPISODE_PX: usize = 28;

/// The narrow goal's mark on the cell at `(x, y)`.
fn narrow_goal_mark(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let (p, d) = (px as i64, (px * 3 / 28) as i64);
    c.fill_rect(x + d, y + d, p - 2 * d, p - 2 * d, NARROW_BLUE, 0.55);
}

/// The wide goal's mark on the cell at `(x, y)`.
fn wide_goal_mark(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let (p, d) = (px as i64, (px * 5 / 28) as i64);
    c.fill_rect(x + d, y + d, p - 2 * d, p - 2 * d, WIDE_BLUE, 0.8);
}

/// A ball on the cell at `(x, y)`: as the grid draws one while it lies
/// there; a ring with a tick once collected.
fn ball_mark(c: &mut Canvas, x: i64, y: i64, px: usize, collected: bool) {
    let s = px as f32;
    let (cx, cy) = (x as f32 + s / 2.0, y as f32 + s / 2.0);
    let ball = object_color(Object::Ball);
    if !collected {
        c.fill_disc(cx, cy, s * 0.32, ball, 1.0);
        return;
    }
    let (r_out, r_in) = (s * 0.32, s * 0.21);
    for yy in y..y + px as i64 {
        for xx in x..x + px as i64 {
            let (dx, dy) = (xx as f32 + 0.5 - cx, yy as f32 + 0.5 - cy);
            let d2 = dx * dx + dy * dy;
            if d2 <= r_out * r_out && d2 > r_in * r_in {
                c.blend(xx, yy, ball, 1.0);
            }
        }
    }
    tick_mark(c, x, y, px);
}

/// A green tick over the cell at `(x, y)`: what the episode took.
fn tick_mark(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let s = px as f32;
    let at = |u: f32, v: f32| (x as f32 + u * s, y as f32 + v * s);
    c.line(at(0.3, 0.52), at(0.45, 0.68), s * 0.1, TICK_GREEN, 1.0);
    c.line(at(0.45, 0.68), at(0.72, 0.36), s * 0.1, TICK_GREEN, 1.0);
}

/// The frame that marks an exit cell at `(x, y)`.
fn exit_frame(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let (p, t) = (px as i64, (px / 9).max(2) as i64);
    c.fill_rect(x, y, p, t, EXIT_FRAME, 1.0);
    c.fill_rect(x, y + p - t, p, t, EXIT_FRAME, 1.0);
    c.fill_rect(x, y, t, p, EXIT_FRAME, 1.0);
    c.fill_rect(x + p - t, y, t, p, EXIT_FRAME, 1.0);
}

/// A legend sample: one floor cell with `draw` applied, as the picture
/// applies it.
fn legend_sample(base: Object, draw: impl Fn(&mut Canvas, i64, i64, usize)) -> Mark {
    let mut c = crate::chart::cell_sample(base as u8);
    draw(&mut c, 0, 0, LEGEND_CELL);
    Mark::Sample(c)
}

/// The maze with one test episode, `px` pixels a cell, without caption:
/// the grid the episode started on, the agent's path (red where the Worker
/// acted, light blue where the world graph was traversed), the wide goals
/// (dark blue squares) and narrow goals (light blue squares), the graph's
/// nodes (the paper's Figure 1, bottom), the balls (a ring with a tick
/// where collected), the key taken (ticked) and the exits (framed).
pub fn episode_maze(
    layout: &Layout,
    t: &EpisodeTrace,
    graph: Option<&planner::WorldGraph>,
    px: usize,
) -> Canvas {
    let start: &[u8] = if t.start_cells.len() == layout.cells.len() {
        &t.start_cells
    } else {
        &layout.cells
    };
    let end: Option<&[u8]> = (t.end_cells.len() == start.len()).then_some(&t.end_cells);
    // The grid as it started, less its balls (drawn on top), its doors as
    // they ended.
    let ground: Vec<u8> = start
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            let door = [Object::DoorOpen, Object::DoorClosed, Object::DoorLocked]
                .iter()
                .any(|&d| c == d as u8);
            match end {
                _ if c == Object::Ball as u8 => Object::Floor as u8,
                Some(e) if door => e[i],
                _ => c,
            }
        })
        .collect();
    let mut c = Canvas::new(layout.width * px, layout.height * px, [255, 255, 255]);
    draw_grid(&mut c, &ground, layout.width, 0, 0, px);
    let centre = |cell: u32| {
        let (x, y) = (cell as usize % layout.width, cell as usize / layout.width);
        ((x as f32 + 0.5) * px as f32, (y as f32 + 0.5) * px as f32)
    };
    let corner = |cell: usize| {
        (
            (cell % layout.width * px) as i64,
            (cell / layout.width * px) as i64,
        )
    };
    if let Some(g) = graph {
        for n in g.nodes() {
            let (x, y) = centre(n.0);
            c.fill_disc(x, y, px as f32 * 0.18, NODE_BLUE, 0.5);
        }
    }
    for &(_, gw, gn) in &t.goals {
        let (x, y) = corner(gn as usize);
        narrow_goal_mark(&mut c, x, y, px);
        let (x, y) = corner(gw as usize);
        wide_goal_mark(&mut c, x, y, px);
    }
    for (k, w) in t.cells.windows(2).enumerate() {
        let traversed = t.traversed.get(k).copied().unwrap_or(false);
        let colour = if traversed {
            TRAVERSAL_BLUE
        } else {
            WORKER_RED
        };
        c.line(
            centre(w[0]),
            centre(w[1]),
            if traversed { 5.0 } else { 3.0 },
            colour,
            0.8,
        );
    }
    for (i, &code) in start.iter().enumerate() {
        let (x, y) = corner(i);
        let taken = end.is_some_and(|e| e[i] != code);
        if code == Object::Ball as u8 {
            ball_mark(&mut c, x, y, px, taken);
        } else if code == Object::Key as u8 && taken {
            tick_mark(&mut c, x, y, px);
        } else if code == Object::Exit as u8 {
            exit_frame(&mut c, x, y, px);
        }
    }
    if let Some(&first) = t.cells.first() {
        let (x, y) = centre(first);
        c.fill_disc(x, y, px as f32 * 0.3, WORKER_RED, 1.0);
    }
    c
}

/// The picture of one test episode ([`episode_maze`]) with its title (the
/// agent, maze, task, test seed and what the episode did) and a legend of
/// every mark drawn.
pub fn episode_picture(
    layout: &Layout,
    t: &EpisodeTrace,
    graph: Option<&planner::WorldGraph>,
    agent: &AgentConfig,
    task: Task,
    test_seed: u64,
) -> Canvas {
    let maze = episode_maze(layout, t, graph, EPISODE_PX);
    let outcome = EpisodeOutcome::of(t);
    let mut title = format!(
        "{} — {} maze, {}, test seed {test_seed}: return {:.2}",
        agent_label(agent),
        layout.name,
        task_label(task),
        t.episode_return
    );
    if let Some(o) = outcome {
        if o.balls > 0 {
            title.push_str(&format!(", {} of {} balls", o.collected, o.balls));
        }
        if o.key_taken {
            title.push_str(", key taken");
        }
        if o.door_opened {
            title.push_str(", door opened");
        }
        title.push_str(if o.exited {
            ", exited"
        } else {
            ", did not exit"
        });
    }
    let start: &[u8] = if t.start_cells.len() == layout.cells.len() {
        &t.start_cells
    } else {
        &layout.cells
    };
    let has = |o: Object| start.contains(&(o as u8));
    let mut legend = vec![
        LegendEntry::new(
            Mark::Disc {
                fill: WORKER_RED,
                alpha: 1.0,
                radius: 0.3,
                outline: None,
            },
            "where the episode started",
        ),
        LegendEntry::new(
            Mark::Line {
                colour: WORKER_RED,
                alpha: 0.8,
                width: 3.0 / EPISODE_PX as f32,
                arrow: false,
            },
            if agent.kind == AgentKind::A2c {
                "a step of the agent"
            } else {
                "a step the Worker took"
            },
        ),
    ];
    if agent.traversal || t.traversed.iter().any(|&b| b) {
        legend.push(LegendEntry::new(
            Mark::Line {
                colour: TRAVERSAL_BLUE,
                alpha: 0.8,
                width: 5.0 / EPISODE_PX as f32,
                arrow: false,
            },
            "a step of world graph traversal",
        ));
    }
    if let Some(g) = graph {
        legend.push(LegendEntry::new(
            Mark::Disc {
                fill: NODE_BLUE,
                alpha: 0.5,
                radius: 0.18,
                outline: None,
            },
            format!(
                "world graph node ({}, {} nodes)",
                candidates_label(agent.candidates),
                g.num_nodes()
            ),
        ));
    }
    match agent.kind {
        AgentKind::WideNarrow => {
            legend.push(LegendEntry::new(
                legend_sample(Object::Floor, wide_goal_mark),
                "wide goal g_w the Manager chose",
            ));
            legend.push(LegendEntry::new(
                legend_sample(Object::Floor, narrow_goal_mark),
                "narrow goal g_n in its window",
            ));
        }
        AgentKind::Feudal => legend.push(LegendEntry::new(
            legend_sample(Object::Floor, |c, x, y, px| {
                narrow_goal_mark(c, x, y, px);
                wide_goal_mark(c, x, y, px);
            }),
            "subgoal the Manager chose",
        )),
        AgentKind::A2c => {}
    }
    if has(Object::Ball) {
        legend.push(LegendEntry::new(
            legend_sample(Object::Floor, |c, x, y, px| ball_mark(c, x, y, px, false)),
            "ball, not collected",
        ));
        legend.push(LegendEntry::new(
            legend_sample(Object::Floor, |c, x, y, px| ball_mark(c, x, y, px, true)),
            "ball collected in this episode (ring, ticked)",
        ));
    }
    if outcome.is_some_and(|o| o.key_taken) {
        legend.push(LegendEntry::new(
            legend_sample(Object::Key, tick_mark),
            "key, taken in this episode (ticked)",
        ));
    }
    if has(Object::Exit) {
        legend.push(LegendEntry::new(
            legend_sample(Object::Exit, exit_frame),
            match outcome.map(|o| o.exited) {
                Some(true) => "exit (framed): the episode ended here",
                Some(false) => "exit (framed): not reached",
                None => "exit (framed)",
            },
        ));
    }
    let mut skip = vec![Object::Ball, Object::Exit];
    if let Some(e) = Some(&t.end_cells).filter(|e| e.len() == start.len()) {
        // Doors are drawn as they ended.
        legend.extend(crate::chart::object_entries(
            e,
            &[
                Object::Floor,
                Object::Wall,
                Object::Ball,
                Object::Exit,
                Object::Key,
                Object::Lava,
            ],
        ));
        skip.extend([Object::DoorOpen, Object::DoorClosed, Object::DoorLocked]);
    }
    legend.extend(crate::chart::object_entries(start, &skip));
    captioned(&maze, &title, &legend)
}

fn print_summary(s: &TestSummary, test: &EvalResult, dir: &Path) {
    println!(
        "stage 2: {} on the {} maze, {} (seed {}) — {}",
        s.agent,
        s.maze,
        s.task,
        s.seed,
        dir.display()
    );
    let rows = [
        (
            "test score (best checkpoint, 100 held-out seeds)",
            format!("{:.3}", s.test_score),
        ),
        ("test mean return", format!("{:.3}", s.test_return)),
        ("test success rate", format!("{:.3}", s.test_success_rate)),
        ("best validation score", format!("{:.3}", s.best_validation)),
        (
            "env steps at the best checkpoint",
            s.best_env_steps.to_string(),
        ),
        ("env steps trained", s.env_steps.to_string()),
        ("wall seconds (training)", format!("{:.1}", s.wall_seconds)),
        (
            "training env-steps/s",
            format!("{:.0}", s.train_steps_per_sec),
        ),
        (
            "share of test steps traversing",
            format!("{:.3}", test.traversal_share),
        ),
    ];
    println!("  {:<50} {:>12}", "figure", "value");
    for (k, v) in rows {
        println!("  {k:<50} {v:>12}");
    }
    println!(
        "  files: config.toml metrics.csv updates.csv tensorboard/ invocations.txt curves.png test.json episode.png"
    );
}

/// `evaluate` options.
#[derive(Debug, Clone, Args)]
pub struct EvaluateArgs {
    /// A `worldgraph train` run directory.
    pub run: PathBuf,
    /// Test seeds as `A..B` (B exclusive), environments `(test stream, A..B)`;
    /// at most 10,000 at once.
    #[arg(long, default_value = "0..100")]
    pub seeds: String,
    /// Episodes per seed (the seed fixes the maze's randomness; the policy's
    /// sampling differs between episodes).
    #[arg(long, default_value_t = 1)]
    pub episodes_per_seed: usize,
    /// Write a picture of the first episode here.
    #[arg(long)]
    pub picture: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `worldgraph evaluate`.
pub fn evaluate(a: EvaluateArgs) -> anyhow::Result<std::process::ExitCode> {
    let (first, end) = a
        .seeds
        .split_once("..")
        .and_then(|(x, y)| Some((x.trim().parse::<u64>().ok()?, y.trim().parse::<u64>().ok()?)))
        .with_context(|| format!("--seeds {:?} is not A..B", a.seeds))?;
    anyhow::ensure!(end > first, "--seeds {:?} is empty", a.seeds);
    anyhow::ensure!(
        end - first <= MAX_EVAL_SEEDS,
        "--seeds {:?} asks for {} seeds: at most {MAX_EVAL_SEEDS} at once (score the range \
         in parts)",
        a.seeds,
        end - first
    );
    anyhow::ensure!(
        a.episodes_per_seed > 0,
        "--episodes-per-seed must be at least 1"
    );
    if let Some(path) = &a.picture {
        crate::output::prepare("--picture", path)?;
    }
    if let Some(kind @ super::run_dir::RunKind::Discover) = super::run_dir::kind_of(&a.run) {
        bail!(
            "{} is {}, not a train run: evaluate scores a train run's best checkpoint (give \
             this one to `train --world-graph`)",
            a.run.display(),
            super::run_dir::describe(&a.run, kind)
        );
    }
    let state_path = a.run.join("checkpoint").join("state.json");
    let state: RunState =
        serde_json::from_slice(&std::fs::read(&state_path).with_context(|| {
            format!(
                "{} is not a train run (no {})",
                a.run.display(),
                state_path.display()
            )
        })?)?;
    let id = &state.identity;
    // The budget is in the run's config.toml (the identity holds 0).
    let budget = read_config(&a.run.join("config.toml"))
        .ok()
        .map(|c| trained_env_steps(&c));
    let unfinished = budget.filter(|&b| state.env_steps < b);
    if let Some(b) = unfinished {
        eprintln!(
            "evaluate: {} is unfinished ({} of {b} env steps trained): scoring its best \
             checkpoint so far",
            a.run.display(),
            state.env_steps
        );
    }
    // A Door-Key run records its layout, `<maze>-doorkey`.
    let maze: Maze = id
        .maze
        .strip_suffix("-doorkey")
        .unwrap_or(&id.maze)
        .parse()
        .map_err(|e: String| anyhow::anyhow!(e))?;
    let layout = maze.layout(id.task.uses_door_key_layout());
    let env_cfg = EnvConfig::for_task(id.task, &layout);
    let mut agent = build_agent(
        &id.config.agent,
        &layout,
        id.task,
        id.world_graph.as_deref().map(Path::new),
        id.seed,
    )?;
    let best = a.run.join("checkpoint").join("best.ot");
    agent.load_bytes(
        &std::fs::read(&best).with_context(|| format!("cannot read {}", best.display()))?,
        &best,
    )?;
    let mut env = eval_env(&layout, env_cfg, TEST_STREAM, first, (end - first) as usize)?;
    let mut scores = Vec::new();
    let mut trace = EpisodeTrace::default();
    for k in 0..a.episodes_per_seed {
        let t = (k == 0).then_some(&mut trace);
        let r = if k == 0 {
            agent.evaluate(&mut env, u64::MAX, t)?
        } else {
            agent.evaluate(&mut env, k as u64, None)?
        };
        scores.push(r.score);
    }
    let score = scores.iter().sum::<f64>() / scores.len() as f64;
    if let Some(p) = &a.picture {
        episode_picture(
            &layout,
            &trace,
            agent.graph(),
            &id.config.agent,
            id.task,
            first,
        )
        .save_png(p)?;
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({"score": score, "seeds": a.seeds, "episodes_per_seed": a.episodes_per_seed, "per_round": scores, "finished": unfinished.is_none(), "env_steps": state.env_steps})
        );
    } else {
        println!(
            "{}: score {:.3} on test seeds {} ({} episode(s) per seed){}",
            a.run.display(),
            score,
            a.seeds,
            a.episodes_per_seed,
            match unfinished {
                Some(b) => format!(" (unfinished run: {} of {b} env steps)", state.env_steps),
                None => String::new(),
            }
        );
    }
    let _ = BatchEnvironment::num_envs(&env);
    Ok(std::process::ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 21, item 8: the budget a run trains is its rounding to whole
    /// segments (`--env-steps 2000` trains 51,840 with the defaults).
    #[test]
    fn the_budget_rounds_up_to_whole_segments() {
        for (budget, trained) in [(2000, 51_840), (51_840, 51_840), (51_841, 2 * 51_840)] {
            let cfg = TrainConfig {
                env_steps: budget,
                ..TrainConfig::default()
            };
            assert_eq!(trained_env_steps(&cfg), trained, "{budget}");
        }
    }

    fn pixel(c: &Canvas, x: usize, y: usize) -> Rgb {
        let i = (y * c.width + x) * 3;
        [c.rgb[i], c.rgb[i + 1], c.rgb[i + 2]]
    }

    /// The row at which `picture` sits at column `x` of `c`, if anywhere.
    fn find_picture(c: &Canvas, picture: &Canvas, x: usize) -> Option<usize> {
        let row = |cv: &Canvas, y: usize, x0: usize| {
            cv.rgb[(y * cv.width + x0) * 3..(y * cv.width + x0 + picture.width) * 3].to_vec()
        };
        (0..=c.height.saturating_sub(picture.height))
            .find(|&y| (0..picture.height).all(|r| row(c, y + r, x) == row(picture, r, 0)))
    }

    /// A hand-made episode on the small maze: balls on two floor cells
    /// `a` and `b` far from the start, the agent walking from the start to
    /// `a`; with `collected`, the end grid lacks `a`'s ball.
    fn ball_episode(collected: bool) -> (Layout, EpisodeTrace, usize, usize, usize) {
        let layout = Maze::Small.layout(false);
        let start = layout.cell_index(layout.start.x as usize, layout.start.y as usize);
        let free = layout.free_cells();
        let floor: Vec<usize> = free
            .iter()
            .map(|&c| c as usize)
            .filter(|&c| layout.cells[c] == Object::Floor as u8 && c != start)
            .collect();
        let (a, b) = (floor[floor.len() / 2], floor[floor.len() - 1]);
        let exit = (0..layout.cells.len())
            .find(|&i| layout.cells[i] == Object::Exit as u8)
            .expect("the small maze has an exit");
        let mut start_cells = layout.cells.clone();
        start_cells[a] = Object::Ball as u8;
        start_cells[b] = Object::Ball as u8;
        let mut end_cells = start_cells.clone();
        if collected {
            end_cells[a] = Object::Floor as u8;
        }
        let t = EpisodeTrace {
            cells: vec![start as u32, a as u32],
            traversed: vec![false],
            goals: Vec::new(),
            episode_return: 0.99,
            start_cells,
            end_cells,
        };
        (layout, t, a, b, exit)
    }

    /// Issue 21: the episode picture draws the balls the episode started
    /// with, a collected one as a ring (its centre no longer the ball's
    /// colour) and an uncollected one as the grid draws a ball, and frames
    /// the exit.
    #[test]
    fn the_episode_picture_tells_collected_balls_from_the_others_and_frames_the_exit() {
        let px = EPISODE_PX;
        let ball = object_color(Object::Ball);
        let centre = |layout: &Layout, cell: usize| {
            (
                cell % layout.width * px + px / 2,
                cell / layout.width * px + px / 2,
            )
        };
        let (layout, t, a, b, exit) = ball_episode(true);
        let c = episode_maze(&layout, &t, None, px);
        let (ax, ay) = centre(&layout, a);
        let (bx, by) = centre(&layout, b);
        assert_eq!(
            pixel(&c, bx, by),
            ball,
            "the uncollected ball is drawn whole"
        );
        assert_ne!(pixel(&c, ax, ay), ball, "the collected ball is hollow");
        let ring = (px as f32 * 0.27) as usize;
        assert_eq!(pixel(&c, ax, ay - ring), ball, "the collected ball's ring");
        // The same episode without the collection: a's ball is whole.
        let (_, t_kept, ..) = ball_episode(false);
        let kept = episode_maze(&layout, &t_kept, None, px);
        assert_eq!(
            pixel(&kept, ax, ay),
            ball,
            "an uncollected ball under the path"
        );
        // The exit is framed; a floor cell is not.
        let (ex, ey) = (exit % layout.width * px, exit / layout.width * px);
        assert_eq!(pixel(&c, ex + 1, ey + px / 2), EXIT_FRAME);
        assert_ne!(pixel(&c, bx - px / 2 + 1, by), EXIT_FRAME);
        assert_eq!(
            EpisodeOutcome::of(&t),
            Some(EpisodeOutcome {
                balls: 2,
                collected: 1,
                exited: false,
                ..EpisodeOutcome::default()
            })
        );
        let mut exited = t.clone();
        exited.cells.push(exit as u32);
        assert!(EpisodeOutcome::of(&exited).is_some_and(|o| o.exited));
    }

    /// Issue 21: the saved picture is the maze with a title above it and a
    /// legend below that shows the collected-ball mark.
    #[test]
    fn the_episode_picture_has_a_title_and_a_legend_of_its_marks() {
        let (layout, t, ..) = ball_episode(true);
        let agent = AgentConfig {
            kind: AgentKind::WideNarrow,
            traversal: true,
            init_from_gcp: true,
            ..AgentConfig::default()
        };
        let maze = episode_maze(&layout, &t, None, EPISODE_PX);
        let c = episode_picture(&layout, &t, None, &agent, Task::MultiGoal, 7);
        let x = (c.width - maze.width) / 2;
        let y = find_picture(&c, &maze, x).expect("the maze, whole");
        assert!(
            y > 20 && c.height > y + maze.height + 100,
            "{y} {}",
            c.height
        );
        let dark_title = (0..y * c.width)
            .filter(|&i| c.rgb[3 * i..3 * i + 3].iter().all(|&v| v < 100))
            .count();
        assert!(dark_title > 50, "the title is written: {dark_title} px");
        let legend = &c.rgb[(y + maze.height) * c.width * 3..];
        let ticks = legend.chunks(3).filter(|p| *p == TICK_GREEN).count();
        assert!(ticks > 5, "the legend shows the collected ball's tick");
        let frame = legend.chunks(3).filter(|p| *p == EXIT_FRAME).count();
        assert!(frame > 20, "the legend shows the exit's frame");
        assert_eq!(
            agent_label(&agent),
            "WN V_p + traversal + π_g init",
            "the configuration's name in the title"
        );
    }

    /// Issue 21: a real test episode records the grid it started on and
    /// the grid it ended on, and they agree with the simulator's return
    /// (MultiGoal: +1 a ball, +1 at the exit, −0.01 a step).
    #[test]
    fn a_traced_episode_records_its_start_and_end_grids() {
        let layout = Maze::Small.layout(false);
        let cfg = AgentConfig {
            kind: AgentKind::A2c,
            envs: 1,
            ..AgentConfig::default()
        };
        let mut agent = HrlAgent::new(&cfg, &layout, Task::MultiGoal, None, 3).unwrap();
        let env_cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
        let mut env = eval_env(&layout, env_cfg, TEST_STREAM, 0, 2).unwrap();
        let mut t = EpisodeTrace::default();
        let r = agent.evaluate(&mut env, 1, Some(&mut t)).unwrap();
        assert_eq!(t.start_cells.len(), layout.cells.len());
        assert_eq!(t.end_cells.len(), layout.cells.len());
        let o = EpisodeOutcome::of(&t).unwrap();
        assert_eq!(o.balls, sim::task::DEFAULT_BALLS as usize, "{o:?}");
        let steps = t.cells.len() - 1;
        assert_eq!(steps as u32, r.lengths[0]);
        let expected = o.collected as f32 + f32::from(u8::from(o.exited)) + steps as f32 * -0.01;
        assert!(
            (t.episode_return - expected).abs() < 1e-3,
            "return {} but the grids say {o:?} over {steps} steps",
            t.episode_return
        );
        // The walls and the exit are where the layout has them.
        for (i, (&s, &l)) in t.start_cells.iter().zip(&layout.cells).enumerate() {
            if l == Object::Wall as u8 || l == Object::Exit as u8 {
                assert_eq!(s, l, "cell {i}");
            }
        }
    }

    /// Issue 21: `0 = auto` resolves to the values the agent uses; a
    /// setting the agent lacks stays 0, and an explicit value stays.
    #[test]
    fn auto_settings_resolve_to_what_the_agent_uses() {
        let layout = Maze::Small.layout(false);
        let wn = AgentConfig {
            kind: AgentKind::WideNarrow,
            candidates: Candidates::All,
            envs: 1,
            rollout_len: 21,
            ..AgentConfig::default()
        };
        let agent = HrlAgent::new(&wn, &layout, Task::MultiGoal, None, 0).unwrap();
        let auto = auto_values(&wn, Some(&agent), &layout);
        let side = agent.window_coverage().unwrap().side;
        assert_eq!(auto, (Some(7), Some(side)));
        let r = resolve_auto(&wn, auto);
        assert_eq!((r.horizon, r.window), (7, side));
        assert!(side >= 5 && side % 2 == 1, "{side}");
        // The resolved settings build the same agent.
        let again = HrlAgent::new(&r, &layout, Task::MultiGoal, None, 0).unwrap();
        assert_eq!(again.window_coverage().unwrap().side, side);
        let explicit = AgentConfig {
            horizon: 4,
            ..wn.clone()
        };
        assert_eq!(resolve_auto(&explicit, auto).horizon, 4);
        let a2c = AgentConfig {
            kind: AgentKind::A2c,
            ..wn.clone()
        };
        let r = resolve_auto(&a2c, auto_values(&a2c, None, &layout));
        assert_eq!((r.horizon, r.window), (0, 0), "A2C has neither");
        let fnet = AgentConfig {
            kind: AgentKind::Feudal,
            ..wn
        };
        let r = resolve_auto(&fnet, auto_values(&fnet, None, &layout));
        assert_eq!((r.horizon, r.window), (7, 0), "FN has a horizon, no window");
    }

    /// Issue 21, item 8: the config's agent kind may be spelled as the
    /// CLI's `--agent` spells it.
    #[test]
    fn the_config_accepts_the_clis_agent_kinds() {
        for (text, kind) in [
            ("fn", AgentKind::Feudal),
            ("feudal", AgentKind::Feudal),
            ("wn", AgentKind::WideNarrow),
            ("wide-narrow", AgentKind::WideNarrow),
            ("a2c", AgentKind::A2c),
        ] {
            let cfg: TrainConfig = toml::from_str(&format!("[agent]\nkind = \"{text}\"\n"))
                .unwrap_or_else(|e| panic!("kind = {text:?}: {e}"));
            assert_eq!(cfg.agent.kind, kind, "{text}");
        }
    }
}
