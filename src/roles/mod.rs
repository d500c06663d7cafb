//! The three processes of the pipeline (README.md, "The pipeline") and what they
//! share: the run's identity and directory, stop signals, peer watching.
//!
//! - [`sim`]: steps the batch on each action batch, writing observations
//!   straight into loaned shared-memory samples.
//! - [`learner`]: reads observation batches in place, runs a policy, sends
//!   action batches.
//!   Its policy loops (serving, and `train-gcp`'s in [`learner_train`])
//!   share what [`policy_loop`] holds.
//! - [`planner`]: reads the same stream (coverage), owns the world graph,
//!   answers route requests, publishes graph snapshots.
//!
//! Each role registers SIGINT/SIGTERM handlers that only set a flag; the hot
//! loops poll it, so a stop always ends with reports written. SIGUSR1 asks a
//! running process for its latency table and reports without stopping it. Peers are
//! watched through iceoryx2's node registry: a process whose peer's node is
//! dead or missing for [`PEER_TIMEOUT`] says so and, as the user chose with
//! `--on-peer-death`, waits for a restarted peer or exits cleanly.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Args, ValueEnum};
use iceoryx2::config::Config;
use iceoryx2::prelude::ipc;
use serde::Serialize;
use shm_schemas::service::{RunName, list_nodes, run_config};

pub mod learner;
pub mod learner_train;
pub mod planner;
pub mod policy_loop;
pub mod shm_env;
pub mod sim;

/// iceoryx2 node name of the simulator process.
pub const SIM_NODE: &str = "sim";
/// iceoryx2 node name of the learner process.
pub const LEARNER_NODE: &str = "learner";
/// iceoryx2 node name of the planner process.
pub const PLANNER_NODE: &str = "planner";
/// How long a peer's node may be dead or missing before a process says so.
pub const PEER_TIMEOUT: Duration = Duration::from_millis(500);
/// How often the hot loops look at the node registry while waiting.
pub const PEER_CHECK_EVERY: Duration = Duration::from_millis(50);

/// What a process does when a peer it depends on dies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
pub enum OnPeerDeath {
    /// Say so and wait for a restarted peer to rejoin.
    Wait,
    /// Say so, write the reports and exit (status 3).
    Exit,
}

/// Exit status of a role that stopped because a peer died (`--on-peer-death exit`).
pub const EXIT_PEER_DIED: u8 = 3;
/// Exit status of a role that refused its configuration (a bad layout,
/// batch shape, node file, or a run whose role is already taken): `run`
/// never restarts such a process, since the next start would fail the same way.
pub const EXIT_CONFIG: u8 = 2;
/// A run's shared memory older than this with no live process is swept at
/// a role's start (younger files may belong to a run that is starting).
pub const STALE_AFTER: Duration = Duration::from_secs(10);

/// A configuration error: printed and turned into [`EXIT_CONFIG`] by the
/// roles ([`config_exit`]), so `run` can tell it from a crash.
pub fn config_exit(role: &str, e: &anyhow::Error) -> std::process::ExitCode {
    eprintln!("{role}: configuration refused: {e:#}");
    std::process::ExitCode::from(EXIT_CONFIG)
}

/// The live process, if any, that holds node `name` (e.g. the sim) of the
/// run with `config`: `(pid, executable)`.
pub fn node_holder(config: &Config, name: &str) -> Option<(i64, String)> {
    list_nodes::<ipc::Service>(config)
        .ok()?
        .into_iter()
        .find(|n| n.alive && n.name == name)
        .map(|n| (n.pid, n.executable))
}

/// Sweeps the shared memory of dead runs of any name (`wg_*` with no live
/// process, older than [`STALE_AFTER`]); says what it removed.
pub fn sweep_stale_runs(who: &str) {
    match shm_schemas::service::sweep_stale_prefixes::<ipc::Service>(
        shm_schemas::service::PREFIX_ROOT,
        STALE_AFTER,
    ) {
        Ok(swept) => {
            for s in swept {
                eprintln!(
                    "{who}: removed {} stale shared-memory file(s) of dead run prefix {}",
                    s.removed.len(),
                    s.prefix
                );
            }
        }
        Err(e) => tracing::debug!("sweeping stale runs: {e}"),
    }
}

/// The run a role belongs to.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Run name: names the shared-memory services (`wg/<run>/...`) and files
    /// (`/dev/shm/wg_<run>_*`); letters, digits, '_', '.', '-'.
    #[arg(long, default_value = "default")]
    pub run: String,
    /// Run directory for reports, histograms and pictures [default: runs/<run>].
    #[arg(long)]
    pub run_dir: Option<PathBuf>,
    /// When a peer process dies: wait for its restart, or exit.
    #[arg(long, value_enum, default_value = "wait")]
    pub on_peer_death: OnPeerDeath,
    /// Stop after this many seconds (default: run until Ctrl-C / SIGTERM).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Pin this process to one CPU (its id as the kernel numbers them), e.g.
    /// to keep the busy-polling sim and learner on separate cores of a
    /// larger machine. Only for a single role (`sim`, `learner`, `planner
    /// serve`); `run` refuses it (`run --pin` pins the sim and the learner).
    #[arg(long)]
    pub cpu: Option<usize>,
}

/// The CPUs this process may run on, in the kernel's numbering.
pub fn allowed_cpus() -> Vec<usize> {
    use nix::sched::{CpuSet, sched_getaffinity};
    use nix::unistd::Pid;
    match sched_getaffinity(Pid::from_raw(0)) {
        Ok(set) => (0..CpuSet::count())
            .filter(|&c| set.is_set(c).unwrap_or(false))
            .collect(),
        Err(_) => Vec::new(),
    }
}

/// Pins the calling process (its current thread, and every thread it
/// starts afterwards) to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> anyhow::Result<()> {
    use nix::sched::{CpuSet, sched_setaffinity};
    use nix::unistd::Pid;
    let allowed = allowed_cpus();
    anyhow::ensure!(
        allowed.contains(&cpu),
        "--cpu {cpu}: this process may only run on CPUs {allowed:?}"
    );
    let mut set = CpuSet::new();
    set.set(cpu)
        .with_context(|| format!("--cpu {cpu}: no such CPU"))?;
    sched_setaffinity(Pid::from_raw(0), &set).with_context(|| format!("cannot pin to CPU {cpu}"))
}

/// The resolved identity of a role's run.
pub struct RunCtx {
    /// Run name.
    pub run: RunName,
    /// The run's iceoryx2 config (its own prefix).
    pub config: Config,
    /// Run directory (created).
    pub dir: PathBuf,
    /// Peer-death policy.
    pub on_peer_death: OnPeerDeath,
    /// Set by SIGINT/SIGTERM or when the duration is over.
    pub stop: Arc<AtomicBool>,
    /// Set by SIGUSR1: print the latency table and write the reports now.
    report: Arc<AtomicBool>,
    deadline: Option<Instant>,
}

impl RunCtx {
    /// Resolves the run for the role whose node is `node_name`, refuses it
    /// when a live process already holds that role of the run (naming it),
    /// sweeps dead runs' shared memory, creates the run directory and
    /// installs the stop handlers. `--duration` bounds the whole process,
    /// waiting for peers included: a timer sets the stop flag.
    pub fn new(a: &RunArgs, node_name: &str) -> anyhow::Result<RunCtx> {
        let run = RunName::new(&a.run)?;
        let config = run_config(&run)?;
        if let Some((pid, exe)) = node_holder(&config, node_name) {
            anyhow::bail!(
                "run '{run}' already has a live {node_name} (process {pid}, {exe}); \
                 stop it or choose another --run"
            );
        }
        sweep_stale_runs(node_name);
        let dir = a
            .run_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(run.as_str()));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create run directory {}", dir.display()))?;
        let stop = Arc::new(AtomicBool::new(false));
        for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            signal_hook::flag::register(sig, Arc::clone(&stop))
                .context("cannot install signal handlers")?;
        }
        let report = Arc::new(AtomicBool::new(false));
        signal_hook::flag::register(signal_hook::consts::SIGUSR1, Arc::clone(&report))
            .context("cannot install the SIGUSR1 handler")?;
        if let Some(d) = a.duration {
            anyhow::ensure!(d > 0.0, "--duration must be positive");
        }
        let deadline = a
            .duration
            .map(|d| Instant::now() + Duration::from_secs_f64(d));
        if let Some(d) = a.duration {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_secs_f64(d));
                stop.store(true, Ordering::Relaxed);
            });
        }
        if let Some(cpu) = a.cpu {
            pin_to_cpu(cpu)?;
        }
        Ok(RunCtx {
            run,
            config,
            dir,
            on_peer_death: a.on_peer_death,
            stop,
            report,
            deadline,
        })
    }

    /// True once a stop was requested or the duration is over.
    pub fn should_stop(&self) -> bool {
        if self.deadline.is_some_and(|d| Instant::now() >= d) {
            self.stop.store(true, Ordering::Relaxed);
        }
        self.stop.load(Ordering::Relaxed)
    }

    /// On SIGUSR1 (`kill -USR1 <pid>`): prints `lat`'s percentile table and
    /// writes its `.hgrm` files and plot into the run directory.
    pub fn report_on_request(&self, lat: &crate::latency::Latencies) {
        if self.report.swap(false, Ordering::Relaxed) {
            eprint!("{}", lat.table());
            if let Err(e) = lat.write_reports(&self.dir) {
                eprintln!("cannot write the latency reports: {e:#}");
            }
        }
    }

    /// Whether a live node named `name` is registered in this run.
    pub fn peer_alive(&self, name: &str) -> bool {
        list_nodes::<ipc::Service>(&self.config)
            .map(|nodes| nodes.iter().any(|n| n.alive && n.name == name))
            .unwrap_or(false)
    }

    /// After this process dropped its ports: when no other process of the
    /// run is alive, removes the run's leftover shared memory (iceoryx2's
    /// per-prefix `global_mgmt` segment). The last process out tidies up.
    pub fn tidy(&self) {
        if let Ok(left) = shm_schemas::service::teardown_run::<ipc::Service>(&self.config)
            && !left.is_empty()
        {
            tracing::warn!("shared memory still present after teardown: {left:?}");
        }
    }

    /// Writes `value` as pretty JSON to `<run dir>/<name>` atomically.
    pub fn write_json<T: Serialize>(&self, name: &str, value: &T) -> anyhow::Result<()> {
        let bytes = serde_json::to_vec_pretty(value)?;
        ::sim::atomic_file::write_atomic(&self.dir.join(name), &bytes)?;
        Ok(())
    }
}

/// Watches one peer from a waiting loop: reports when it has been gone for
/// [`PEER_TIMEOUT`] and when it is back.
#[derive(Debug)]
pub struct PeerWatch {
    name: &'static str,
    next_check: Instant,
    missing_since: Option<Instant>,
    /// The peer was declared gone and has not come back yet.
    pub gone: bool,
    /// Times the peer was declared gone.
    pub deaths: u64,
}

/// What [`PeerWatch::poll`] saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeerEvent {
    /// Nothing new.
    Quiet,
    /// The peer has just been declared gone.
    Died,
    /// A gone peer is back.
    Back,
}

impl PeerWatch {
    /// Watches node `name`.
    pub fn new(name: &'static str) -> PeerWatch {
        PeerWatch {
            name,
            next_check: Instant::now(),
            missing_since: None,
            gone: false,
            deaths: 0,
        }
    }

    /// Checks the registry at most every [`PEER_CHECK_EVERY`].
    pub fn poll(&mut self, ctx: &RunCtx) -> PeerEvent {
        let now = Instant::now();
        if now < self.next_check {
            return PeerEvent::Quiet;
        }
        self.next_check = now + PEER_CHECK_EVERY;
        if ctx.peer_alive(self.name) {
            self.missing_since = None;
            if self.gone {
                self.gone = false;
                return PeerEvent::Back;
            }
            return PeerEvent::Quiet;
        }
        let since = *self.missing_since.get_or_insert(now);
        if !self.gone && now - since >= PEER_TIMEOUT {
            self.gone = true;
            self.deaths += 1;
            return PeerEvent::Died;
        }
        PeerEvent::Quiet
    }

    /// The peer just sent something, so it is alive: returns true when that
    /// ends a `gone` spell (the caller announces the rejoin). A peer that
    /// rejoins and keeps its partner busy may never leave it waiting long
    /// enough for [`PeerWatch::poll`] to look.
    pub fn heard_from(&mut self) -> bool {
        self.missing_since = None;
        std::mem::replace(&mut self.gone, false)
    }
}

/// Resident set size of process `pid` in KiB (Linux `/proc`), if readable.
pub fn rss_kib(pid: u32) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    s.lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}
