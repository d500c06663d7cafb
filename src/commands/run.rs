//! `worldgraph run`: the three processes side by side.
//!
//! Starts the planner, the sim and the learner as separate processes of one
//! run, stops them together on Ctrl-C / SIGTERM (or after `--duration`),
//! restarts a process that died when `--on-peer-death wait` (its peers wait
//! for it and it rejoins), tears the run's shared memory down at the end
//! and prints a summary table from the processes' reports.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use clap::Args;
use iceoryx2::prelude::ipc;
use shm_schemas::service::{RunName, run_config};

use crate::pipeline::{Pipeline, Role, world_words};
use crate::roles::learner::PolicyKind;
use crate::roles::planner::GraphArgs;
use crate::roles::{EXIT_CONFIG, EXIT_PEER_DIED, OnPeerDeath, RunArgs};
use crate::shutdown::{stop_flag, teardown};
use crate::world::WorldArgs;

/// `run` options.
#[derive(Debug, Clone, Args)]
pub struct RunCmdArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[command(flatten)]
    pub graph: GraphArgs,
    /// Run name, directory, peer-death policy (`wait` also restarts a
    /// process that died) and duration, passed on to every process.
    #[command(flatten)]
    pub run: RunArgs,
    /// Environments in the batch.
    #[arg(long, default_value_t = 256)]
    pub envs: usize,
    /// Slices the sim publishes its batch in (1–4, dividing --envs): with 2
    /// the sim steps one half while the learner chooses the other half's
    /// actions (double-buffered sampling); 1 is plain lock-step.
    #[arg(long, default_value_t = 2)]
    pub slices: usize,
    /// Threads stepping the batch in the sim process.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// The learner's policy.
    #[arg(long, value_enum, default_value = "random")]
    pub policy: PolicyKind,
    /// The learner asks the planner for a route every this many batches (0 = never).
    #[arg(long, default_value_t = 0)]
    pub route_every: u64,
    /// With `--policy train-gcp`: the learner checkpoints π_g every this
    /// many training iterations (and at a clean stop).
    #[arg(long, default_value_t = 10)]
    pub checkpoint_every: u64,
    /// Write each process's messages to `<run dir>/<role>.log` instead of the terminal.
    #[arg(long)]
    pub logs_to_files: bool,
    /// Pin the sim (one-thread) to the first allowed CPU and the learner to
    /// the second; the planner, which mostly sleeps, stays unpinned. Off by
    /// default: on the 2-vCPU target it made no measurable difference
    /// (`bench pipeline`: 0.73–0.76 of in-process either way), but on
    /// larger machines it keeps the two busy-polling processes apart.
    #[arg(long)]
    pub pin: bool,
}

impl RunCmdArgs {
    /// The run directory.
    pub fn dir(&self) -> PathBuf {
        self.run
            .run_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(&self.run.run))
    }

    /// The argument list of `role`'s process.
    pub fn role_args(&self, role: Role) -> Vec<String> {
        let mut v: Vec<String> = match role {
            Role::Sim => vec!["sim".into(), "serve".into()],
            Role::Learner => vec!["learner".into(), "serve".into()],
            Role::Planner => vec!["planner".into(), "serve".into()],
        };
        v.extend(world_words(&self.world));
        v.extend([
            "--run".into(),
            self.run.run.clone(),
            "--run-dir".into(),
            self.dir().display().to_string(),
            "--on-peer-death".into(),
            match self.run.on_peer_death {
                OnPeerDeath::Wait => "wait".into(),
                OnPeerDeath::Exit => "exit".into(),
            },
            "--envs".into(),
            self.envs.to_string(),
            "--slices".into(),
            self.slices.to_string(),
        ]);
        if let Some(cpu) = self.pinned_cpu(role) {
            v.extend(["--cpu".into(), cpu.to_string()]);
        }
        match role {
            Role::Sim => v.extend(["--threads".into(), self.threads.to_string()]),
            Role::Learner => {
                v.extend([
                    "--policy".into(),
                    self.policy.name().into(),
                    "--route-every".into(),
                    self.route_every.to_string(),
                ]);
                if self.policy == PolicyKind::TrainGcp {
                    v.extend([
                        "--checkpoint-every".into(),
                        self.checkpoint_every.to_string(),
                    ]);
                }
            }
            Role::Planner => {
                let g = &self.graph;
                v.extend([
                    "--nodes".into(),
                    g.nodes.to_string(),
                    "--walks-per-node".into(),
                    g.walks_per_node.to_string(),
                    "--walk-len".into(),
                    g.walk_len.to_string(),
                ]);
                if let Some(f) = &g.node_file {
                    v.extend(["--node-file".into(), f.display().to_string()]);
                }
                if let Some(s) = g.graph_seed {
                    v.extend(["--graph-seed".into(), s.to_string()]);
                }
            }
        }
        v
    }

    /// The CPU `role` is pinned to (see `--pin`).
    fn pinned_cpu(&self, role: Role) -> Option<usize> {
        if !self.pin || self.threads != 1 {
            return None;
        }
        let cpus = crate::roles::allowed_cpus();
        match role {
            _ if cpus.len() < 2 => None,
            Role::Sim => Some(cpus[0]),
            Role::Learner => Some(cpus[1]),
            Role::Planner => None,
        }
    }

    /// Checks everything the roles would refuse before starting any of
    /// them: the layout, the batch shape, the planner's settings and node
    /// file, and that no live process holds the run already.
    pub fn validate(&self) -> anyhow::Result<()> {
        let run = RunName::new(&self.run.run)?;
        let (layout, _) = self.world.build()?;
        shm_schemas::ObsShape::sliced(self.envs, self.slices, layout.width, layout.height)?;
        crate::roles::learner_train::check_slices(self.policy, self.slices)?;
        anyhow::ensure!(
            self.checkpoint_every >= 1,
            "--checkpoint-every must be at least 1"
        );
        self.graph.config(&self.world).validate()?;
        if let Some(path) = &self.graph.node_file {
            planner::pivotal::read_node_file(&layout, path)?;
        }
        if let Some(d) = self.run.duration {
            anyhow::ensure!(d > 0.0, "--duration must be positive");
        }
        anyhow::ensure!(self.threads >= 1, "--threads must be at least 1");
        refuse_live_run(&run)
    }

    /// A pipeline of the three roles.
    pub fn pipeline(&self) -> anyhow::Result<Pipeline> {
        anyhow::ensure!(
            self.run.cpu.is_none(),
            "--cpu pins a single role (sim|learner|planner serve); `run --pin` pins the sim \
             and the learner"
        );
        let dir = self.dir();
        std::fs::create_dir_all(&dir)?;
        let roles = Role::ALL.iter().map(|&r| (r, self.role_args(r))).collect();
        Pipeline::new(roles, self.logs_to_files.then_some(dir.as_path()))
    }
}

/// Refuses a run name that a live process already uses (another `run`,
/// `soak` or a role started by hand), naming the process: two runs of one
/// name would share the services and the run directory.
pub fn refuse_live_run(run: &RunName) -> anyhow::Result<()> {
    let config = run_config(run)?;
    let live: Vec<_> = shm_schemas::service::list_nodes::<ipc::Service>(&config)
        .unwrap_or_default()
        .into_iter()
        .filter(|n| n.alive)
        .collect();
    if let Some(n) = live.first() {
        anyhow::bail!(
            "run '{run}' is in use: its {} node is held by process {} ({}); stop that run \
             or choose another --run",
            n.name,
            n.pid,
            n.executable
        );
    }
    Ok(())
}

/// A role that dies this soon after its start counts as a fast failure.
pub const FAST_FAILURE: Duration = Duration::from_secs(3);
/// Consecutive fast failures of one role after which `run` gives up.
pub const MAX_FAST_FAILURES: u32 = 3;

fn read_json(dir: &Path, name: &str) -> Option<serde_json::Value> {
    serde_json::from_slice(&std::fs::read(dir.join(name)).ok()?).ok()
}

/// Prints the end-of-run table from the processes' reports.
pub fn print_summary(dir: &Path, restarts: &[(Role, u32)], leftovers: &[PathBuf]) {
    let sim = read_json(dir, "sim.report.json");
    let learner = read_json(dir, "learner.report.json");
    let planner = read_json(dir, "planner.report.json");
    let f = |v: &Option<serde_json::Value>, k: &str| -> String {
        v.as_ref()
            .and_then(|v| v.pointer(k))
            .map_or("-".into(), |x| match x.as_f64() {
                Some(n) if n.fract() != 0.0 => format!("{n:.2}"),
                _ => x.to_string(),
            })
    };
    println!("\nrun summary ({})", dir.display());
    println!("  {:<40} {:>14}", "figure", "value");
    let rows = [
        ("sim: batches", f(&sim, "/batches")),
        ("sim: env-steps/s", f(&sim, "/steps_per_sec")),
        (
            "sim: action round trip p50 (us)",
            f(&sim, "/roundtrip_p50_us"),
        ),
        (
            "sim: action round trip p99 (us)",
            f(&sim, "/roundtrip_p99_us"),
        ),
        ("sim: episodes", f(&sim, "/episodes")),
        ("learner: batches answered", f(&learner, "/batches")),
        ("learner: batches lost", f(&learner, "/stream/lost")),
        (
            "learner: batches reordered",
            f(&learner, "/stream/reordered"),
        ),
        (
            "learner: mean episode return",
            f(&learner, "/mean_episode_return"),
        ),
        (
            "planner: graph nodes / edges",
            format!("{} / {}", f(&planner, "/nodes"), f(&planner, "/edges")),
        ),
        ("planner: cells visited", f(&planner, "/cells_visited")),
        ("planner: routes answered", f(&planner, "/routes_answered")),
    ];
    for (k, v) in rows {
        println!("  {k:<40} {v:>14}");
    }
    for (r, n) in restarts {
        println!("  {:<40} {:>14}", format!("{} restarts", r.name()), n);
    }
    println!(
        "  {:<40} {:>14}",
        "shared-memory files left behind",
        leftovers.len()
    );
}

/// Runs `worldgraph run`.
pub fn run(a: RunCmdArgs) -> anyhow::Result<std::process::ExitCode> {
    a.validate()?;
    crate::roles::sweep_stale_runs("run");
    let stop = stop_flag()?;
    let mut p = a.pipeline()?;
    p.start_all()?;
    let started = Instant::now();
    let deadline = a.run.duration.map(|d| started + Duration::from_secs_f64(d));
    let quiet_stderr = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut next_progress = started + Duration::from_secs(10);
    let mut fast_failures = [0u32; 3];
    let mut failed = false;
    'watch: loop {
        std::thread::sleep(Duration::from_millis(50));
        if stop.load(Ordering::Relaxed) || deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        if quiet_stderr && Instant::now() >= next_progress {
            next_progress += Duration::from_secs(10);
            let restarts: u32 = Role::ALL.iter().map(|&r| p.restarts(r)).sum();
            eprintln!(
                "run: {:.0} s, {restarts} restart(s)",
                started.elapsed().as_secs_f64()
            );
        }
        for (role, status) in p.poll_exited() {
            if status.code() == Some(EXIT_CONFIG as i32) {
                eprintln!(
                    "run: the {} process refused its configuration (see above); stopping the run",
                    role.name()
                );
                failed = true;
                break 'watch;
            }
            if status.code() == Some(EXIT_PEER_DIED as i32) || status.success() {
                eprintln!(
                    "run: the {} process ended ({status}); stopping the run",
                    role.name()
                );
                break 'watch;
            }
            eprintln!("run: the {} process died ({status})", role.name());
            let slot = Role::ALL.iter().position(|&r| r == role).unwrap_or(0);
            if p.uptime(role) < FAST_FAILURE {
                fast_failures[slot] += 1;
            } else {
                fast_failures[slot] = 1;
            }
            if fast_failures[slot] >= MAX_FAST_FAILURES {
                eprintln!(
                    "run: the {} process died {MAX_FAST_FAILURES} times within {} s of its \
                     start; giving up",
                    role.name(),
                    FAST_FAILURE.as_secs()
                );
                failed = true;
                break 'watch;
            }
            if a.run.on_peer_death == OnPeerDeath::Wait {
                eprintln!("run: restarting the {} process", role.name());
                p.spawn(role)?;
            } else {
                failed = true;
                break 'watch;
            }
        }
    }
    p.stop_all(Duration::from_secs(3));
    let leftovers = teardown(&a.run.run)?;
    let restarts: Vec<(Role, u32)> = Role::ALL.iter().map(|&r| (r, p.restarts(r))).collect();
    print_summary(&a.dir(), &restarts, &leftovers);
    Ok(if failed {
        std::process::ExitCode::FAILURE
    } else {
        std::process::ExitCode::SUCCESS
    })
}
