//! `worldgraph bench learner`: training throughput of a learner (env-steps
//! per second of rollout + update), where an iteration's time goes, and the
//! same updates on the reference gradient path (`tch`: autograd at every
//! rollout step) measured in alternating windows of the same run, the
//! baseline of the production path's (`rust-core`) speed-up.
//! Also the model's FLOPs per env-step against a dense matrix product's
//! GFLOP/s on the same threads, and, after the Rust windows, the PyTorch
//! reference of the same networks and update (`benches/learner_pytorch.py`,
//! issue 26) on the same maze, batch, rollout and threads when a Python
//! with `torch` is found: the fast path's env-steps/s as a ratio to it.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use clap::{Args, ValueEnum};
use learner::a2c::PhaseTimes;
use learner::a2c::rollout::GradPath;
use learner::batch_env::{BatchEnvironment, InProcess};
use learner::hrl::{Agent, AgentConfig, AgentKind, Candidates, WorldGraphInputs};
use serde::Serialize;
use tch::{Device, Kind, Tensor};

use crate::world_args::WorldArgs;

/// Which learner to train.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BenchAgent {
    /// The goal-conditioned policy π_g of stage 1.
    Gcp,
    /// The A2C-LSTM baseline.
    A2c,
    /// The Feudal Network (Manager over all cells, Worker).
    Fn,
    /// Wide-then-Narrow over random candidate states, with traversal.
    Wn,
}

/// Whether to measure the PyTorch reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PytorchMode {
    /// When a Python with `torch` is found; otherwise a note says how to
    /// install it (`make bench-learner-python`).
    Auto,
    /// Never.
    Off,
    /// Always: fail when it cannot run.
    Required,
}

/// `bench learner` options.
#[derive(Debug, Clone, Args)]
pub struct BenchLearnerArgs {
    /// Learner to train.
    #[arg(long, value_enum, default_value = "gcp")]
    pub agent: BenchAgent,
    #[command(flatten)]
    pub world: WorldArgs,
    /// Environments per update.
    #[arg(long, default_value_t = 32)]
    pub envs: usize,
    /// Rollout length per update [default: 16 for gcp, 60 for the stage 2 agents].
    #[arg(long)]
    pub rollout: Option<usize>,
    /// libtorch intra-op threads (the simulator runs on one thread).
    #[arg(long, default_value_t = 2)]
    pub threads: i32,
    /// Threads of the own kernels' GEMMs (rayon) [default: --threads].
    #[arg(long)]
    pub kernel_threads: Option<usize>,
    /// Seconds of measurement in total, split into alternating windows of
    /// the fast (`rust-core`) and the `tch` path (the PyTorch reference then gets as
    /// many, split among its variants).
    #[arg(long, default_value_t = 12.0)]
    pub seconds: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// The PyTorch reference (`benches/learner_pytorch.py`: the same
    /// networks and update in PyTorch, on the same environments through the
    /// Python package), run after the Rust windows for `--seconds` on the
    /// same agent, maze, batch, rollout and threads (gcp, a2c and wn only).
    /// Its Python is `WORLDGRAPH_PYTHON`, else the repository's
    /// `.venv/bin/python`, else `python3`; `make bench-learner-python`
    /// installs `torch` there.
    #[arg(long, value_enum, default_value = "auto")]
    pub pytorch: PytorchMode,
}

/// Figures of one path.
#[derive(Debug, Clone, Default, Serialize)]
pub struct PathFigures {
    /// Training env-steps per second (median over windows).
    pub env_steps_per_sec: f64,
    /// Env steps trained in all windows.
    pub env_steps: u64,
    /// Share of the iteration time per phase.
    pub phases: PhaseShares,
    /// Model FLOPs per env-step (acting, update forward and backward).
    pub flops_per_env_step: f64,
    /// Achieved GFLOP/s (FLOPs per env-step × env-steps/s).
    pub achieved_gflops: f64,
}

/// Where an iteration's time goes (fractions of the measured time).
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct PhaseShares {
    /// Stepping the environments.
    pub step: f64,
    /// Encoding observations.
    pub encode: f64,
    /// Acting forward passes.
    pub act: f64,
    /// The update's forward pass and loss.
    pub loss: f64,
    /// Backward and optimiser.
    pub backward: f64,
    /// Everything else (goal and Manager bookkeeping, sampling, ...).
    pub other: f64,
}

/// One gradient path's figures in the alternating windows.
#[derive(Debug, Clone, Serialize)]
pub struct NamedPath {
    /// `GradPath::name` (`rust-core`, `tch`).
    pub path: String,
    /// Whether it is the fast path (the learners' production path).
    pub fast: bool,
    /// Its figures.
    pub figures: PathFigures,
    /// Its env-steps/s over the tch reference's, median of the windows.
    pub over_tch: f64,
}

/// `bench learner`'s report.
#[derive(Debug, Clone, Serialize)]
pub struct LearnerBenchReport {
    /// Learner.
    pub agent: BenchAgent,
    /// Maze.
    pub maze: String,
    /// Task.
    pub task: String,
    /// Environments.
    pub envs: usize,
    /// Rollout length.
    pub rollout: usize,
    /// libtorch threads.
    pub threads: i32,
    /// The production path (`rust-core`: the whole network in the
    /// project's own kernels).
    pub fast: PathFigures,
    /// The reference path (`tch`: autograd at every step).
    pub tch: PathFigures,
    /// Fast over tch env-steps/s, median of the paired windows.
    pub speedup: f64,
    /// Every path measured (the fast one, then `tch`), with its ratio to
    /// the tch path.
    pub paths: Vec<NamedPath>,
    /// Dense matrix product GFLOP/s on the same threads (the compute bound).
    pub matmul_gflops: f64,
    /// Fast path's achieved GFLOP/s over the matmul bound.
    pub share_of_bound: f64,
    /// Manager decisions per env step of the fast path (FN, WN; `None`
    /// for the others).
    pub manager_decisions_per_env_step: Option<f64>,
    /// The PyTorch reference's figures (`None` when it did not run; see
    /// `pytorch_note`).
    pub pytorch: Option<PytorchFigures>,
    /// Fast path's env-steps/s over the PyTorch reference's.
    pub fast_over_pytorch: Option<f64>,
    /// Why the PyTorch reference did not run (or what to know about it).
    pub pytorch_note: Option<String>,
}

/// What the PyTorch reference measured (run after the Rust windows).
#[derive(Debug, Clone, Serialize)]
pub struct PytorchFigures {
    /// Training env-steps per second (median over its windows, of its
    /// faster gradient path).
    pub env_steps_per_sec: f64,
    /// The variant reported, its fastest: gradient path (`per-step` or
    /// `recompute`) and layout (`nchw` or `channels-last`).
    pub variant: String,
    /// `torch.__version__`.
    pub torch_version: String,
    /// Share of its time spent stepping the environments.
    pub env_share: f64,
    /// The Python that ran it.
    pub python: String,
    /// The script's whole JSON report.
    pub report: serde_json::Value,
}

/// A learner the bench can train.
enum Learner {
    Gcp(Box<learner::gcp::GoalConditionedPolicy>),
    Stage2(Box<Agent>),
}

impl Learner {
    /// One training iteration; returns the Manager's decisions in it (0
    /// without a Manager).
    fn iterate(&mut self, env: &mut dyn BatchEnvironment) -> anyhow::Result<u64> {
        Ok(match self {
            Learner::Gcp(g) => {
                g.train_iteration(env, None)?;
                0
            }
            Learner::Stage2(a) => a.train_iteration(env)?.decisions as u64,
        })
    }
    /// The narrow window's side (WN).
    fn window_side(&self) -> Option<usize> {
        match self {
            Learner::Stage2(a) => a.window_coverage().map(|c| c.side),
            Learner::Gcp(_) => None,
        }
    }
    fn take_times(&mut self) -> PhaseTimes {
        match self {
            Learner::Gcp(g) => g.take_times(),
            Learner::Stage2(a) => a.take_times(),
        }
    }
    fn flops(&self) -> f64 {
        match self {
            Learner::Gcp(g) => {
                let net = g.network();
                learner::a2c::net::flops_per_env_step(net.trunk(), net.config().num_actions)
            }
            Learner::Stage2(a) => a.flops_per_env_step(),
        }
    }
}

fn build(
    a: &BenchLearnerArgs,
    path: GradPath,
    rollout: usize,
) -> anyhow::Result<(Learner, InProcess)> {
    let (layout, env_cfg) = a.world.build()?;
    let env = InProcess::new(layout.clone(), env_cfg, a.envs, a.world.seed, 1)?;
    let num_actions = env_cfg.task.num_actions();
    let learner = match a.agent {
        BenchAgent::Gcp => {
            let cfg = learner::gcp::GcpConfig {
                rollout_len: rollout,
                ..Default::default()
            };
            let mut g = learner::gcp::GoalConditionedPolicy::new(
                &cfg,
                &layout,
                a.envs,
                num_actions,
                a.world.seed,
            )?;
            g.set_grad_path(path);
            Learner::Gcp(Box::new(g))
        }
        kind => {
            let mut cfg = AgentConfig {
                envs: a.envs,
                rollout_len: rollout,
                ..AgentConfig::default()
            };
            cfg.kind = match kind {
                BenchAgent::A2c => AgentKind::A2c,
                BenchAgent::Fn => AgentKind::Feudal,
                _ => AgentKind::WideNarrow,
            };
            if kind == BenchAgent::Wn {
                cfg.candidates = Candidates::Random;
                cfg.traversal = true;
            }
            let graph = if cfg.needs_graph() {
                Some(WorldGraphInputs::random_for_bench(
                    &layout,
                    env_cfg.task,
                    a.world.seed,
                )?)
            } else {
                None
            };
            let mut agent = Agent::new(&cfg, &layout, env_cfg.task, graph, a.world.seed)?;
            agent.set_grad_path(path);
            Learner::Stage2(Box::new(agent))
        }
    };
    Ok((learner, env))
}

/// The paths measured: the production one ("fast"), then the tch
/// reference.
fn measured_paths() -> Vec<GradPath> {
    vec![GradPath::RustCore, GradPath::Tch]
}

/// Dense `n × n` matrix products on the current threads: GFLOP/s.
fn matmul_gflops(seconds: f64) -> f64 {
    let n = 384;
    let a = Tensor::randn([n, n], (Kind::Float, Device::Cpu));
    let b = Tensor::randn([n, n], (Kind::Float, Device::Cpu));
    let _ = a.matmul(&b);
    let start = Instant::now();
    let mut count = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        let _ = a.matmul(&b);
        count += 1;
    }
    2.0 * (n as f64).powi(3) * count as f64 / start.elapsed().as_secs_f64() / 1e9
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() { 0.0 } else { v[v.len() / 2] }
}

fn shares(t: &PhaseTimes, wall: f64) -> PhaseShares {
    let w = wall.max(1e-9);
    PhaseShares {
        step: t.step / w,
        encode: t.encode / w,
        act: t.act / w,
        loss: t.loss / w,
        backward: t.backward / w,
        other: ((wall - t.total()) / w).max(0.0),
    }
}

/// Runs `bench learner`.
pub fn run(a: BenchLearnerArgs) -> anyhow::Result<std::process::ExitCode> {
    anyhow::ensure!(a.envs > 0, "--envs must be at least 1");
    anyhow::ensure!(a.threads > 0, "--threads must be at least 1");
    anyhow::ensure!(a.seconds > 0.0, "--seconds must be positive");
    tch::set_num_threads(a.threads);
    learner::a2c::gemm::set_threads(a.kernel_threads.unwrap_or(a.threads as usize));
    let rollout = a
        .rollout
        .unwrap_or(if a.agent == BenchAgent::Gcp { 16 } else { 60 });
    anyhow::ensure!(rollout > 0, "--rollout must be at least 1");
    let paths = measured_paths();
    let mut learners = paths
        .iter()
        .map(|&p| build(&a, p, rollout))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let steps_per_iter = (a.envs * rollout) as u64;
    // Warm-up: one iteration each (allocator, libtorch's kernels).
    for (l, env) in learners.iter_mut() {
        l.iterate(env)?;
        l.take_times();
    }
    let windows = alternate_windows(&mut learners, a.seconds, steps_per_iter)?;
    let gflops = matmul_gflops(1.0);
    let report = learner_report(&a, rollout, &paths, &learners, &windows, gflops)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// What the alternating windows measured, per path (in the order of
/// [`measured_paths`]).
struct PathWindows {
    /// Env-steps/s of each window.
    rates: Vec<Vec<f64>>,
    /// Phase times summed over the windows.
    times: Vec<PhaseTimes>,
    /// Seconds of the windows, summed.
    walls: Vec<f64>,
    /// Env steps trained in the windows.
    steps: Vec<u64>,
    /// The Manager's decisions in the fast path's windows.
    fast_decisions: u64,
}

impl PathWindows {
    /// Path `i`'s figures, its model making `flops` FLOPs per env-step.
    fn figures(&self, i: usize, flops: f64) -> PathFigures {
        let rate = median(self.rates[i].clone());
        PathFigures {
            env_steps_per_sec: rate,
            env_steps: self.steps[i],
            phases: shares(&self.times[i], self.walls[i]),
            flops_per_env_step: flops,
            achieved_gflops: flops * rate / 1e9,
        }
    }

    /// Path `i`'s env-steps/s over path `j`'s: the median of the ratios per
    /// window (the paths of one window ran back to back).
    fn ratio(&self, i: usize, j: usize) -> f64 {
        median(
            self.rates[i]
                .iter()
                .zip(&self.rates[j])
                .map(|(a, b)| a / b.max(1e-9))
                .collect(),
        )
    }
}

/// Trains every learner in turn for a window, in `WINDOWS` rounds, the
/// windows splitting `seconds` evenly.
fn alternate_windows(
    learners: &mut [(Learner, InProcess)],
    seconds: f64,
    steps_per_iter: u64,
) -> anyhow::Result<PathWindows> {
    const WINDOWS: usize = 3;
    let k = learners.len();
    let window = seconds / (k * WINDOWS) as f64;
    let mut w = PathWindows {
        rates: vec![Vec::new(); k],
        times: vec![PhaseTimes::default(); k],
        walls: vec![0.0; k],
        steps: vec![0u64; k],
        fast_decisions: 0,
    };
    let bar = crate::progress::bar((k * WINDOWS) as u64, "bench learner windows");
    for _ in 0..WINDOWS {
        for (i, (l, env)) in learners.iter_mut().enumerate() {
            let start = Instant::now();
            let (mut n, mut decisions) = (0, 0);
            while start.elapsed().as_secs_f64() < window {
                decisions += l.iterate(env)?;
                n += steps_per_iter;
            }
            let wall = start.elapsed().as_secs_f64();
            if i == 0 {
                w.fast_decisions += decisions;
            }
            w.times[i].add(&l.take_times());
            w.walls[i] += wall;
            w.steps[i] += n;
            w.rates[i].push(n as f64 / wall);
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok(w)
}

/// The report of the windows `w` of `learners` (one per path of `paths`),
/// against the matmul bound `gflops` and, after running it, the PyTorch
/// reference.
fn learner_report(
    a: &BenchLearnerArgs,
    rollout: usize,
    paths: &[GradPath],
    learners: &[(Learner, InProcess)],
    w: &PathWindows,
    gflops: f64,
) -> anyhow::Result<LearnerBenchReport> {
    let figures = |i: usize| w.figures(i, learners[i].0.flops());
    let index = |p: GradPath| paths.iter().position(|&q| q == p).expect("measured");
    let tch_i = index(GradPath::Tch);
    let named: Vec<NamedPath> = (0..paths.len())
        .map(|i| NamedPath {
            path: paths[i].name().to_string(),
            fast: i == 0,
            figures: figures(i),
            over_tch: w.ratio(i, tch_i),
        })
        .collect();
    let fast_fig = figures(0);
    let fast = &learners[0].0;
    let (layout, env_cfg) = a.world.build()?;
    let decisions_per_step = w.fast_decisions as f64 / w.steps[0].max(1) as f64;
    let horizon = (a.agent == BenchAgent::Wn && w.fast_decisions > 0)
        .then(|| (1.0 / decisions_per_step).round().max(1.0) as usize);
    let (pytorch, pytorch_note) = pytorch_reference(a, rollout, fast.window_side(), horizon)?;
    let fast_over_pytorch = pytorch
        .as_ref()
        .map(|p| fast_fig.env_steps_per_sec / p.env_steps_per_sec.max(1e-9));
    Ok(LearnerBenchReport {
        agent: a.agent,
        maze: layout.name.clone(),
        task: env_cfg.task.name().to_string(),
        envs: a.envs,
        rollout,
        threads: a.threads,
        share_of_bound: fast_fig.achieved_gflops / gflops.max(1e-9),
        fast: fast_fig,
        tch: figures(tch_i),
        speedup: w.ratio(0, tch_i),
        paths: named,
        matmul_gflops: gflops,
        manager_decisions_per_env_step: matches!(a.agent, BenchAgent::Fn | BenchAgent::Wn)
            .then_some(decisions_per_step),
        pytorch,
        fast_over_pytorch,
        pytorch_note,
    })
}

/// The repository this binary was built from (where the PyTorch script
/// and the project's virtual environment are).
fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Python to run the PyTorch reference with: `WORLDGRAPH_PYTHON`, else
/// the repository's `.venv/bin/python` when it exists, else `python3`.
fn reference_python() -> PathBuf {
    if let Some(p) = std::env::var_os("WORLDGRAPH_PYTHON").filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    let venv = repo_root().join(".venv/bin/python");
    if venv.exists() {
        venv
    } else {
        PathBuf::from("python3")
    }
}

/// Runs `cmd` to completion, killing it after `limit`: `(success, stdout,
/// stderr)`, or why it could not run.
fn run_with_limit(cmd: &mut Command, limit: Duration) -> Result<(bool, String, String), String> {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| e.to_string())?;
    // Drain both pipes on threads so a chatty child cannot block on a full
    // pipe while we wait.
    let drain = |pipe: Option<Box<dyn std::io::Read + Send>>| {
        std::thread::spawn(move || {
            use std::io::Read;
            let mut text = String::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_string(&mut text);
            }
            text
        })
    };
    let out = drain(child.stdout.take().map(|p| Box::new(p) as _));
    let err = drain(child.stderr.take().map(|p| Box::new(p) as _));
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            break Some(status);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let (out, err) = (
        out.join().unwrap_or_default(),
        err.join().unwrap_or_default(),
    );
    match status {
        Some(s) => Ok((s.success(), out, err)),
        None => Err(format!("killed after {} s", limit.as_secs())),
    }
}

/// The last few lines of a child's stderr, for a note.
fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.trim().lines().collect();
    lines[lines.len().saturating_sub(3)..].join(" | ")
}

/// Runs the PyTorch reference (`benches/learner_pytorch.py`) as
/// `--pytorch` asks: its figures, or `None` and a note saying why not (an
/// error under `--pytorch required`). For WN it gets the Rust agent's
/// window side and, as its Manager horizon, one over the Rust agent's
/// measured decisions per env step (the reference does not traverse, and
/// traversal steps lengthen the Rust agent's intervals), so both Managers
/// do about the same work per env step.
fn pytorch_reference(
    a: &BenchLearnerArgs,
    rollout: usize,
    window_side: Option<usize>,
    horizon: Option<usize>,
) -> anyhow::Result<(Option<PytorchFigures>, Option<String>)> {
    if a.pytorch == PytorchMode::Off {
        return Ok((None, Some("PyTorch reference off (--pytorch off)".into())));
    }
    match run_reference(a, rollout, window_side, horizon) {
        Ok(figures) => Ok((Some(figures), None)),
        Err(note) => {
            anyhow::ensure!(
                a.pytorch != PytorchMode::Required,
                "--pytorch required: {note}"
            );
            Ok((None, Some(note)))
        }
    }
}

/// The PyTorch reference's figures (see [`pytorch_reference`]), or why it
/// did not run.
fn run_reference(
    a: &BenchLearnerArgs,
    rollout: usize,
    window_side: Option<usize>,
    horizon: Option<usize>,
) -> Result<PytorchFigures, String> {
    let agent = reference_agent(a)?;
    let python = reference_python();
    let shown = python.display().to_string();
    probe_reference_python(&python)?;
    let script = repo_root().join("benches/learner_pytorch.py");
    let mut cmd = Command::new(&python);
    cmd.arg(&script)
        .args(["--agent", agent, "--maze"])
        .arg(a.world.maze.to_string())
        .args(["--envs", &a.envs.to_string()])
        .args(["--rollout", &rollout.to_string()])
        .args(["--threads", &a.threads.to_string()])
        .args(["--seconds", &a.seconds.to_string()])
        .args(["--seed", &a.world.seed.to_string()])
        // π_g, the baseline and the Worker share one width by default.
        .args(["--hidden", &AgentConfig::default().hidden.to_string()]);
    if let Some(side) = window_side {
        cmd.args(["--window", &side.to_string()]);
    }
    if let Some(h) = horizon {
        cmd.args(["--horizon", &h.to_string()]);
    }
    // Its own start-up, warm-up and windows: generous, but bounded.
    let limit = Duration::from_secs_f64(a.seconds * 4.0 + 300.0);
    let (ok, out, err) = run_with_limit(&mut cmd, limit)
        .map_err(|e| format!("the PyTorch reference did not finish: {e}"))?;
    if !ok {
        return Err(format!(
            "the PyTorch reference failed under {shown}: {}",
            tail(&err)
        ));
    }
    reference_figures(&out, shown)
}

/// The reference's name of the agent of `a`, or why the reference cannot
/// run these options.
fn reference_agent(a: &BenchLearnerArgs) -> Result<&'static str, String> {
    let agent = match a.agent {
        BenchAgent::Gcp => "gcp",
        BenchAgent::A2c => "a2c",
        BenchAgent::Wn => "wn",
        BenchAgent::Fn => {
            return Err("the PyTorch reference implements gcp, a2c and wn, not fn".into());
        }
    };
    if a.world.layout.is_some() || a.world.max_steps.is_some() || a.world.balls.is_some() {
        return Err(
            "the PyTorch reference runs the embedded mazes with their default episodes only \
             (no --layout, --max-steps, --balls)"
                .into(),
        );
    }
    if a.world.task != sim::Task::MultiGoal {
        return Err("the PyTorch reference runs the MultiGoal task only".into());
    }
    Ok(agent)
}

/// Whether `python` imports `torch` and `worldgraph`; if not, a note saying
/// why and how to install them.
fn probe_reference_python(python: &Path) -> Result<(), String> {
    let shown = python.display();
    let install = "install it with `make bench-learner-python` (torch from PyPI into .venv)";
    let probe = run_with_limit(
        Command::new(python).args(["-c", "import torch, worldgraph; print(torch.__version__)"]),
        Duration::from_secs(120),
    );
    match probe {
        Ok((true, _, _)) => Ok(()),
        Ok((false, _, err)) => Err(format!(
            "no PyTorch reference: `import torch, worldgraph` fails under {shown} ({}); {install}",
            tail(&err)
        )),
        Err(e) => Err(format!(
            "no PyTorch reference: cannot run {shown} ({e}); {install}"
        )),
    }
}

/// The figures in the reference's report, the last non-empty line of its
/// stdout `out` (`python`: the Python that ran it), or what is wrong with it.
fn reference_figures(out: &str, python: String) -> Result<PytorchFigures, String> {
    let report: serde_json::Value = match out
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .map(serde_json::from_str)
    {
        Some(Ok(v)) => v,
        _ => {
            return Err(format!(
                "the PyTorch reference printed no JSON line: {}",
                tail(out)
            ));
        }
    };
    let Some(rate) = report["env_steps_per_sec"].as_f64().filter(|r| *r > 0.0) else {
        return Err(format!("the PyTorch reference reported no rate: {report}"));
    };
    let text = |k: &str| report[k].as_str().unwrap_or_default().to_string();
    Ok(PytorchFigures {
        env_steps_per_sec: rate,
        variant: text("variant"),
        torch_version: text("torch_version"),
        env_share: report["env_share"].as_f64().unwrap_or(f64::NAN),
        python,
        report,
    })
}

fn print_table(r: &LearnerBenchReport) {
    println!(
        "bench learner: {:?} on {} / {}, {} envs × rollout {}, {} libtorch thread(s)",
        r.agent, r.maze, r.task, r.envs, r.rollout, r.threads
    );
    println!(
        "{:<20} {:>11} {:>9} {:>9} {:>7} {:>7} {:>7} {:>9} {:>7} {:>12} {:>9}",
        "path",
        "env-steps/s",
        "step",
        "encode",
        "act",
        "loss",
        "bwd",
        "other",
        "",
        "FLOP/step",
        "GFLOP/s"
    );
    for n in &r.paths {
        let (f, p) = (&n.figures, &n.figures.phases);
        let name = if n.fast {
            format!("{} (fast)", n.path)
        } else {
            n.path.clone()
        };
        println!(
            "{:<20} {:>11.0} {:>8.1}% {:>8.1}% {:>6.1}% {:>6.1}% {:>6.1}% {:>8.1}% {:>7} {:>12.3e} {:>9.2}",
            name,
            f.env_steps_per_sec,
            100.0 * p.step,
            100.0 * p.encode,
            100.0 * p.act,
            100.0 * p.loss,
            100.0 * p.backward,
            100.0 * p.other,
            "",
            f.flops_per_env_step,
            f.achieved_gflops
        );
    }
    println!(
        "speedup fast/tch {:.2}× (median of paired windows); matmul bound {:.1} GFLOP/s, fast path at {:.1} % of it",
        r.speedup,
        r.matmul_gflops,
        100.0 * r.share_of_bound
    );
    if let Some(d) = r.manager_decisions_per_env_step {
        let reference = r
            .pytorch
            .as_ref()
            .and_then(|p| p.report["manager_decisions_per_env_step"].as_f64())
            .map(|p| format!(", PyTorch reference {p:.4}"))
            .unwrap_or_default();
        println!("Manager decisions per env step: fast path {d:.4}{reference}");
    }
    match (&r.pytorch, r.fast_over_pytorch) {
        (Some(p), Some(ratio)) => {
            println!(
                "{:<8} {:>14.0} {:>8.1}%   (torch {}, {}, run after the Rust windows)",
                "pytorch",
                p.env_steps_per_sec,
                100.0 * p.env_share,
                p.torch_version,
                p.variant
            );
            println!("fast/pytorch {ratio:.2}×");
        }
        _ => {
            if let Some(note) = &r.pytorch_note {
                println!("note: {note}");
            }
        }
    }
}
