//! `worldgraph train`: stage 2 of the paper — one agent (A2C, FN or WN),
//! one task, one maze, one seed — under the paper's protocol: periodic
//! validation on 10 validation seeds keeps the best checkpoint, which is
//! scored at the end on 100 held-out test seeds (section 5, Control
//! Experiments). `worldgraph evaluate` ([`super::evaluate`]) scores a run on
//! any seeds.
//!
//! Training runs in segments of `eval_every` env steps; after each, the
//! agent is validated and the run checkpointed (weights, optimiser moments,
//! metrics), so a killed run resumes at the last segment boundary and ends
//! exactly as an uninterrupted one.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use learner::batch_env::{BatchEnvironment, InProcess};
use learner::hrl::{AgentConfig, AgentKind, Candidates, EpisodeTrace, EvalResult, IterationStats};
use learner::run::artefact::{check_world_graph_layout, known_candidates, load_inputs};
use learner::run::config::{
    TrainConfig, auto_values, check_budget, config_with_overrides, resolve_auto, trained_env_steps,
};
use learner::run::dir::{RunKind, kind_of, name_in};
use learner::run::protocol::{MAX_TRAIN_SEED, MetricsRow, Observer, RunState, TestSummary};
use learner::run::train_run::{TrainRun, TrainSpec};
use sim::{EnvConfig, Layout, Maze, Task};

use crate::chart::{LineChart, Series, XScale};
use crate::episode_picture::episode_picture;
use crate::update_log::{UpdateLog, UpdateRow};

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
    #[arg(long, default_value = "small", conflicts_with = "layout")]
    pub maze: Maze,
    /// A layout file instead of an embedded maze, in `sim --layout`'s
    /// format (# wall, . floor, E exit, K key, D locked door, C closed door,
    /// O open door, B ball, L lava, > v < ^ the agent). Door-Key's key and
    /// locked door are the layout's (it must hold both); the MultiGoal
    /// tasks use the layout's balls, or spawn 5 at random when it has none.
    /// `--world-graph` should be a `discover --layout` run of the same
    /// file, whose world graph is found with the doors passable. The run
    /// keeps a copy of the layout (`layout.txt`) for `evaluate`.
    #[arg(long)]
    pub layout: Option<PathBuf>,
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

/// A sim process stepping `envs` environments seeded by `seed` with the
/// run's episode step limit, and the shared-memory client of its batch.
fn pipeline_env(
    a: &TrainArgs,
    envs: usize,
    seed: u64,
    max_steps: u32,
    dir: &Path,
) -> anyhow::Result<(
    Box<dyn BatchEnvironment>,
    (crate::pipeline::Pipeline, String),
)> {
    let run_name = format!("train-{}", std::process::id());
    let w = crate::world_args::WorldArgs {
        maze: a.maze,
        layout: a.layout.clone(),
        task: a.task,
        seed,
        max_steps: Some(max_steps),
        balls: None,
    };
    let (env, p) = crate::pipeline::spawn_sim_env(&w, envs, &run_name, dir)?;
    Ok((Box::new(env), (p, run_name)))
}

/// The layout and environments of a run: the embedded `maze` (its Door-Key
/// variant for Door-Key) or the layout `file` (`--layout`), whose objects
/// are the task's.
pub(super) fn train_world(
    maze: Maze,
    file: Option<&Path>,
    task: Task,
) -> anyhow::Result<(Layout, EnvConfig)> {
    let Some(path) = file else {
        let layout = maze.layout(task.uses_door_key_layout());
        let cfg = EnvConfig::for_task(task, &layout);
        return Ok((layout, cfg));
    };
    let layout = Layout::from_file(path).context("cannot use the layout")?;
    let has = |o: sim::Object| layout.cells.contains(&(o as u8));
    if task == Task::DoorKey {
        anyhow::ensure!(
            has(sim::Object::Key) && has(sim::Object::DoorLocked),
            "--layout {}: the doorkey task needs a key (K) and a locked door (D) in the layout",
            path.display()
        );
    }
    let mut cfg = EnvConfig::for_task(task, &layout);
    if has(sim::Object::Ball) {
        cfg.balls = sim::BallSpawn::Layout;
    }
    Ok((layout, cfg))
}

fn run_dir(a: &TrainArgs, layout: &Layout, cfg: &AgentConfig) -> PathBuf {
    let name = match &a.layout {
        Some(p) => p.file_stem().map_or_else(
            || "layout".to_string(),
            |s| s.to_string_lossy().into_owned(),
        ),
        None => layout.name.clone(),
    };
    a.run.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!(
            "train-{}-{}-{}-{}",
            name,
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
    if kind_of(&wg) == Some(RunKind::Train) {
        bail!(
            "--world-graph {} is a train run; give the discover run whose world graph \
             it used",
            wg.display()
        );
    }
    if let Some(warning) = check_world_graph_layout(&wg, a.maze, layout)? {
        eprintln!("warning: {warning}");
    }
    Ok(Some(wg))
}

/// `--print-config`: the settings as the run's `config.toml` would hold
/// them, `0 = auto` resolved. The window of WN over `V_rand` or `V_p`
/// needs the world graph: without `--world-graph` it stays 0, said on
/// stderr.
fn print_config(
    a: &TrainArgs,
    mut cfg: TrainConfig,
    layout: &Layout,
    auto_episode_steps: u32,
) -> anyhow::Result<()> {
    cfg.max_episode_steps = cfg.episode_limit(auto_episode_steps);
    let world_graph = world_graph_dir(a, layout)?;
    let inputs = if cfg.agent.kind == AgentKind::WideNarrow {
        match load_inputs(&cfg.agent, layout, a.task, world_graph.as_deref(), a.seed) {
            Ok(inputs) => inputs,
            Err(e) if world_graph.is_some() => return Err(e),
            Err(_) => None,
        }
    } else {
        None
    };
    let candidates = known_candidates(&cfg.agent, layout, inputs.as_ref());
    if cfg.agent.kind == AgentKind::WideNarrow && candidates.is_none() && cfg.agent.window == 0 {
        eprintln!(
            "train: window = 0 stays as given: the auto side is resolved from the world graph's \
             wide-goal candidates; give --world-graph to print it"
        );
    }
    cfg.agent = resolve_auto(
        &cfg.agent,
        auto_values(&cfg.agent, layout, candidates.as_deref()),
    );
    print!("{}", toml::to_string(&cfg)?);
    Ok(())
}

/// What `train` shows of a run as it trains: the progress bar and its
/// notes, and the per-update log (`updates.csv`, TensorBoard).
struct Progress {
    bar: indicatif::ProgressBar,
    updates: UpdateLog,
    steps_per_iter: u64,
    segments: u64,
    last_validation: Option<f64>,
}

impl Observer for Progress {
    fn update(
        &mut self,
        update: u64,
        s: &IterationStats,
        wall_seconds: f64,
        seconds: f64,
    ) -> anyhow::Result<()> {
        let per_episode = |x: f64| if s.episodes > 0 { x } else { f64::NAN };
        self.updates.push(&UpdateRow {
            update,
            env_steps: update * self.steps_per_iter,
            wall_seconds,
            episodes: s.episodes,
            episodic_return: per_episode(s.mean_return),
            policy_loss: s.worker.policy_loss,
            value_loss: s.worker.value_loss,
            entropy: s.worker.entropy,
            manager_policy_loss: s.manager.policy_loss,
            manager_value_loss: s.manager.value_loss,
            manager_entropy: s.manager.entropy,
            intervals: s.intervals,
            goals_reached: s.goals_reached,
            traversal_share: s.traversal_share,
            sps: s.env_steps as f64 / seconds.max(1e-9),
            exit_share: per_episode(s.exit_share),
            exit_goal_share: s.exit_goal_share,
            ball_goal_share: s.ball_goal_share,
            key_share: per_episode(s.key_share),
            door_share: per_episode(s.door_share),
            key_taken_share: per_episode(s.key_taken_share),
            key_goal_share: s.key_goal_share,
            door_goal_share: s.door_goal_share,
        })?;
        self.bar.inc(1);
        self.bar.set_message(format!(
            "return {:.2}  validation {}",
            s.mean_return,
            self.last_validation
                .map_or("-".to_string(), |v| format!("{v:.2}"))
        ));
        Ok(())
    }

    fn segment(&mut self, state: &RunState) -> anyhow::Result<()> {
        let row = state
            .rows
            .last()
            .expect("invariant: a segment was just pushed");
        self.last_validation = Some(row.validation_score);
        crate::progress::note(
            &self.bar,
            &format!(
                "segment {}/{}: {} env steps, train return {:.3}, validation {:.3}",
                state.segments_done,
                self.segments,
                state.env_steps,
                row.train_return,
                row.validation_score
            ),
        );
        Ok(())
    }
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
    let (layout, env_cfg) = train_world(a.maze, a.layout.as_deref(), a.task)?;
    if a.print_config {
        print_config(&a, cfg, &layout, env_cfg.max_steps)?;
        return Ok(std::process::ExitCode::SUCCESS);
    }
    let dir = run_dir(&a, &layout, &cfg.agent);
    let mut own_files = vec!["lock".to_string()];
    own_files.extend(a.config.as_deref().and_then(|c| name_in(&dir, c)));
    let trained = trained_env_steps(&cfg);
    let mut run = TrainRun::open(TrainSpec {
        world_graph: world_graph_dir(&a, &layout)?,
        dir,
        config: cfg,
        layout,
        env_cfg,
        task: a.task,
        seed: a.seed,
        own_files,
        keep_layout: a.layout.is_some(),
        version: env!("CARGO_PKG_VERSION").to_string(),
        commit: env!("WORLDGRAPH_BUILD_COMMIT").to_string(),
    })?;
    if trained != run.config().env_steps {
        eprintln!(
            "train: the budget of {} env steps rounds up to {trained}: whole segments of eval_every {} \
             rounded up to whole iterations of {} envs × {} steps",
            run.config().env_steps,
            run.config().eval_every,
            run.config().agent.envs,
            run.config().agent.rollout_len
        );
    }
    if let Some(c) = &run.agent.window_coverage() {
        eprintln!("train: narrow goals: {c}");
    }
    if let Some(steps) = run.resumed_after() {
        eprintln!(
            "train: resuming {} after {steps} env steps",
            run.dir().display()
        );
    }
    if run.needs_training() {
        train_segments(&a, &mut run)?;
    }
    let (summary, test, trace) = run.test()?;
    save_pictures(&run, a.task, &summary, &trace)?;
    if a.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print_summary(&summary, &test, run.dir());
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// Trains `run`'s remaining segments on its environments: in process, or
/// in a sim process of the pipeline (`--pipeline`), which owns them; there
/// a resumed run starts fresh episodes seeded by (seed, segment). Validation
/// plays environments of its own, so it leaves the training stream
/// untouched.
fn train_segments(a: &TrainArgs, run: &mut TrainRun) -> anyhow::Result<()> {
    let (envs, seed) = (run.config().agent.envs, run.segment_seed());
    let (mut env, pipeline) = if a.pipeline {
        let (env, p) = pipeline_env(a, envs, seed, run.env_cfg().max_steps, run.dir())?;
        (env, Some(p))
    } else {
        let env: Box<dyn BatchEnvironment> = Box::new(InProcess::new(
            run.layout().clone(),
            run.env_cfg(),
            envs,
            seed,
            1,
        )?);
        (env, None)
    };
    let schedule = run.schedule();
    let bar = crate::progress::bar(schedule.segments * schedule.iters_per_segment, "train");
    bar.set_position(run.state.segments_done * schedule.iters_per_segment);
    // One row per update (`updates.csv`, TensorBoard), kept up to the
    // checkpoint the run resumes from.
    let mut progress = Progress {
        bar,
        updates: UpdateLog::open(
            run.dir(),
            run.state.env_steps,
            run.config().agent.kind != AgentKind::A2c,
        )?,
        steps_per_iter: schedule.steps_per_iter,
        segments: schedule.segments,
        last_validation: run.state.rows.last().map(|r| r.validation_score),
    };
    run.train(env.as_mut(), &mut progress)?;
    drop(env);
    if let Some((mut p, run_name)) = pipeline {
        p.stop_all(std::time::Duration::from_secs(3));
        crate::shutdown::teardown(&run_name)?;
    }
    progress.bar.finish_and_clear();
    Ok(())
}

/// The run's pictures: the validation curves, Door-Key's object curves,
/// and test seed 0's episode (the trace is environment 0's).
fn save_pictures(
    run: &TrainRun,
    task: Task,
    summary: &TestSummary,
    trace: &EpisodeTrace,
) -> anyhow::Result<()> {
    let dir = run.dir();
    curves(&run.state.rows, summary)
        .render(900, 520)
        .save_png(&dir.join("curves.png"))?;
    if task == Task::DoorKey {
        object_curves(&UpdateLog::read(dir)?, summary)
            .render(900, 520)
            .save_png(&dir.join(OBJECTS_PNG))?;
    }
    episode_picture(
        run.layout(),
        trace,
        run.agent.graph(),
        &run.config().agent,
        task,
        0,
    )
    .save_png(&dir.join("episode.png"))?;
    Ok(())
}

/// Door-Key's picture of how the task's steps were learnt.
const OBJECTS_PNG: &str = "objects.png";

/// Updates pooled into one point of [`object_curves`]: a hundred points
/// over a run, each a share over enough episodes to read (one update ends
/// anywhere from none to a few dozen).
const OBJECT_CURVE_POINTS: usize = 100;

/// Door-Key: the shares of the training episodes that took the key, opened
/// the door and reached the exit, and of the Manager's decisions that named
/// the key or the locked door, each pooled over a hundredth of the run
/// (episode shares weighted by the episodes that ended in each update,
/// decision shares by its Manager intervals; updates without any skipped).
fn object_curves(rows: &[UpdateRow], s: &TestSummary) -> LineChart {
    let per_point = rows.len().div_ceil(OBJECT_CURVE_POINTS).max(1);
    let line = |name: &str, f: fn(&UpdateRow) -> f64, weight: fn(&UpdateRow) -> usize| Series {
        name: name.into(),
        points: rows
            .chunks(per_point)
            .filter_map(|bin| {
                let (mut sum, mut n) = (0.0, 0usize);
                for r in bin.iter().filter(|r| weight(r) > 0 && f(r).is_finite()) {
                    sum += f(r) * weight(r) as f64;
                    n += weight(r);
                }
                let last = bin.last()?;
                (n > 0).then(|| (last.env_steps as f64, sum / n as f64))
            })
            .collect(),
    };
    let episodes = |r: &UpdateRow| r.episodes;
    let intervals = |r: &UpdateRow| r.intervals;
    let mut series = vec![
        line(
            "episodes that took the key",
            |r| r.key_taken_share,
            episodes,
        ),
        line("episodes that opened the door", |r| r.door_share, episodes),
        line("episodes that reached the exit", |r| r.exit_share, episodes),
    ];
    if rows.iter().any(|r| r.intervals > 0) {
        series.push(line(
            "decisions naming the key",
            |r| r.key_goal_share,
            intervals,
        ));
        series.push(line(
            "decisions naming the locked door",
            |r| r.door_goal_share,
            intervals,
        ));
    }
    LineChart {
        title: format!("Door-Key: key, door, exit ({}, seed {})", s.agent, s.seed),
        x_label: "env steps".into(),
        y_label: "share (each point: 1/100 of the run)".into(),
        series,
        x_scale: XScale::Linear,
    }
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
        "  files: config.toml metrics.csv updates.csv tensorboard/ invocations.txt curves.png test.json episode.png{}",
        if s.task == Task::DoorKey.name() {
            " objects.png"
        } else {
            ""
        }
    );
}
