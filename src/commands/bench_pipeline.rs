//! `worldgraph bench pipeline`: the pipeline's throughput against the same
//! workload in one process and over a copying transport, in one run.
//!
//! 1. **in-process**: the simulator and the null policy in one loop, no IPC
//!    (the upper bound).
//! 2. **ipc**: the three processes over iceoryx2 shared memory (`run`),
//!    measured in windows alternating with the in-process loop's (the
//!    pipeline paused meanwhile), so the ratio of the two is not at the
//!    mercy of the machine's speed drifting between two long phases.
//! 3. **socket**: the same three processes' data flow over Unix domain
//!    sockets: the sim writes every observation batch (metas + cells) into
//!    the learner's and the planner's sockets, the learner copies it out,
//!    picks actions and writes them back.
//!
//! Throughput is env-steps per second; round trips are the sim's publish of
//! observation `k` → receipt of action `k`.
//!
//! Each round also measures the machine's **core-to-core round trip** (two
//! threads on two CPUs passing one cache line back and forth): every batch
//! crosses cores several times, so the pipeline's share of the in-process
//! figure follows it. On a shared VM it is not constant (it can move by a
//! factor of several within minutes: docs/implementation_details.md,
//! "Pipeline throughput"), which is why it is printed next to the ratio.

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::PathBuf;
use std::process::Stdio;
use std::time::{Duration, Instant};

use clap::Args;
use learner::batch_env::{BatchEnvironment, InProcess};
use learner::serving_policy::{Policy, RandomPolicy};
use nix::sys::signal::Signal;
use serde::Serialize;
use shm_schemas::EnvMeta;
use sim::{BatchEnv, StepOut};

use crate::latency::Latencies;
use crate::pipeline::{Pipeline, RunCmdArgs};
use crate::roles::learner::PolicyKind;
use crate::roles::planner::GraphArgs;
use crate::roles::{OnPeerDeath, RunArgs};
use crate::shutdown::teardown;
use crate::world_args::WorldArgs;

/// `bench pipeline` options.
#[derive(Debug, Clone, Args)]
pub struct BenchPipelineArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    /// Environments in the batch.
    #[arg(long, default_value_t = 256)]
    pub envs: usize,
    /// Slices the pipeline's sim publishes its batch in (see `run --slices`;
    /// the in-process and socket setups step the whole batch at once).
    #[arg(long, default_value_t = 2)]
    pub slices: usize,
    /// Threads stepping the batch (the same in all three setups).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Seconds measured per setup (after a warm-up); in-process and
    /// shared memory alternate in 5 windows of a fifth each.
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Figures of `bench pipeline`.
#[derive(Debug, Serialize)]
pub struct PipelineBenchReport {
    /// Batch size.
    pub envs: usize,
    /// Maze.
    pub maze: String,
    /// Env-steps/s of the three processes over shared memory.
    pub ipc_steps_per_sec: f64,
    /// Env-steps/s of the same workload in one process.
    pub inprocess_steps_per_sec: f64,
    /// Env-steps/s over Unix domain sockets.
    pub socket_steps_per_sec: f64,
    /// Median over the rounds of `ipc / inprocess` measured back to back.
    pub ipc_to_inprocess: f64,
    /// `ipc / socket`.
    pub ipc_to_socket: f64,
    /// Shared-memory round trip p50 (µs).
    pub roundtrip_p50_us: f64,
    /// Shared-memory round trip p99 (µs).
    pub roundtrip_p99_us: f64,
    /// Shared-memory round trip p99.9 (µs).
    pub roundtrip_p999_us: f64,
    /// Socket round trip p50 (µs).
    pub socket_roundtrip_p50_us: f64,
    /// Socket round trip p99 (µs).
    pub socket_roundtrip_p99_us: f64,
    /// Batches the learner lost over shared memory (must be 0).
    pub ipc_batches_lost: u64,
    /// Share of the pipeline sim's time spent waiting for actions instead
    /// of stepping: near 0 means the sim process is the bottleneck.
    pub sim_wait_fraction: f64,
    /// Median over the rounds of the core-to-core round trip (ns); `null`
    /// with fewer than two CPUs.
    pub core_to_core_rtt_ns: Option<f64>,
    /// Each round: in-process and shared-memory env-steps/s, their ratio,
    /// and the core-to-core round trip measured just before.
    pub rounds: Vec<BenchRound>,
}

/// One round of the interleaved measurement.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRound {
    /// In-process env-steps/s.
    pub inprocess_steps_per_sec: f64,
    /// Shared-memory env-steps/s.
    pub ipc_steps_per_sec: f64,
    /// `ipc / inprocess`.
    pub ratio: f64,
    /// Core-to-core round trip (ns), if measurable.
    pub core_to_core_rtt_ns: Option<f64>,
}

/// Runs the benchmark.
pub fn run(a: BenchPipelineArgs) -> anyhow::Result<std::process::ExitCode> {
    anyhow::ensure!(a.seconds > 0.0, "--seconds must be positive");
    let (layout, _) = a.world.build()?;
    let Interleaved {
        inprocess,
        ipc,
        ratio,
        rtt,
        lost,
        sim_wait,
        rounds,
    } = bench_interleaved(&a)?;
    let (socket, srtt) = bench_socket(&a)?;
    let r = PipelineBenchReport {
        envs: a.envs,
        maze: layout.name.clone(),
        ipc_steps_per_sec: ipc,
        inprocess_steps_per_sec: inprocess,
        socket_steps_per_sec: socket,
        ipc_to_inprocess: ratio,
        ipc_to_socket: ipc / socket,
        roundtrip_p50_us: rtt.0,
        roundtrip_p99_us: rtt.1,
        roundtrip_p999_us: rtt.2,
        socket_roundtrip_p50_us: srtt.0,
        socket_roundtrip_p99_us: srtt.1,
        ipc_batches_lost: lost,
        sim_wait_fraction: sim_wait,
        core_to_core_rtt_ns: {
            let c: Vec<f64> = rounds
                .iter()
                .filter_map(|r| r.core_to_core_rtt_ns)
                .collect();
            (!c.is_empty()).then(|| median(c))
        },
        rounds,
    };
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        print_table(&r, &a);
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// Prints the `bench pipeline` table.
fn print_table(r: &PipelineBenchReport, a: &BenchPipelineArgs) {
    println!(
        "bench pipeline: {} maze, {} envs ({} slice(s) over shared memory), {} sim thread(s), null policy",
        r.maze, r.envs, a.slices, a.threads
    );
    println!("  {:<36} {:>14} {:>10}", "setup", "env-steps/s", "ratio");
    println!(
        "  {:<36} {:>13.2}M {:>10}",
        "in-process (no IPC)",
        r.inprocess_steps_per_sec / 1e6,
        "1.00"
    );
    println!(
        "  {:<36} {:>13.2}M {:>10.2}",
        "3 processes, iceoryx2 shared memory",
        r.ipc_steps_per_sec / 1e6,
        r.ipc_to_inprocess
    );
    println!(
        "  {:<36} {:>13.2}M {:>10.2}",
        "3 processes, Unix sockets (copying)",
        r.socket_steps_per_sec / 1e6,
        r.socket_steps_per_sec / r.inprocess_steps_per_sec
    );
    println!("  {:<36} {:>14.2}", "ipc / socket", r.ipc_to_socket);
    println!("  round trip (us)            p50        p99      p99.9");
    println!(
        "  shared memory       {:>10.2} {:>10.2} {:>10.2}",
        r.roundtrip_p50_us, r.roundtrip_p99_us, r.roundtrip_p999_us
    );
    println!(
        "  unix socket         {:>10.2} {:>10.2}",
        r.socket_roundtrip_p50_us, r.socket_roundtrip_p99_us
    );
    println!("  batches lost over shared memory: {}", r.ipc_batches_lost);
    println!(
        "  pipeline sim waiting for actions: {:.1} % of its loop (near 0: the sim is the bottleneck)",
        100.0 * r.sim_wait_fraction
    );
    println!("  rounds (in-process, shared memory, ratio, core-to-core round trip):");
    for (i, round) in r.rounds.iter().enumerate() {
        println!(
            "    {}  {:>7.2}M {:>7.2}M {:>6.2}  {}",
            i + 1,
            round.inprocess_steps_per_sec / 1e6,
            round.ipc_steps_per_sec / 1e6,
            round.ratio,
            round
                .core_to_core_rtt_ns
                .map_or("-".to_string(), |ns| format!("{ns:.0} ns"))
        );
    }
}

/// The in-process setup: the simulator and the null policy in one loop.
struct InProcessLoop {
    env: InProcess,
    policy: RandomPolicy,
    actions: Vec<u8>,
    envs: usize,
}

impl InProcessLoop {
    fn new(a: &BenchPipelineArgs) -> anyhow::Result<InProcessLoop> {
        let (layout, cfg) = a.world.build()?;
        let env = InProcess::new(layout, cfg, a.envs, a.world.seed, a.threads)?;
        let policy = RandomPolicy::new(env.num_actions(), a.world.seed);
        Ok(InProcessLoop {
            env,
            policy,
            actions: vec![0u8; a.envs],
            envs: a.envs,
        })
    }

    /// Env-steps per second over `d`.
    fn run_for(&mut self, d: Duration) -> anyhow::Result<f64> {
        let t0 = Instant::now();
        let until = t0 + d;
        let mut n = 0u64;
        while Instant::now() < until {
            self.policy.act(&self.env.observe(), &mut self.actions);
            self.env.step(&self.actions)?;
            n += 1;
        }
        Ok((n * self.envs as u64) as f64 / t0.elapsed().as_secs_f64())
    }
}

/// The sim's latest progress line (`t`, `env_steps`) in `sim.stats.jsonl`.
fn sim_progress(dir: &std::path::Path) -> Option<(f64, u64)> {
    let text = std::fs::read_to_string(dir.join("sim.stats.jsonl")).ok()?;
    let line: serde_json::Value = serde_json::from_str(text.lines().last()?).ok()?;
    Some((line["t"].as_f64()?, line["env_steps"].as_u64()?))
}

/// How long the first progress line may take: the three processes start,
/// load libtorch and open their services (slow on a loaded machine, e.g.
/// beside a test suite's other tests).
const STARTUP_WAIT: Duration = Duration::from_secs(60);
/// How long a later progress line may take before the pipeline counts as
/// stalled.
const STALL_WAIT: Duration = Duration::from_secs(20);

/// Waits for a progress line newer than `after` (the first: up to
/// [`STARTUP_WAIT`]; later ones: up to [`STALL_WAIT`]).
fn next_progress(dir: &std::path::Path, after: Option<(f64, u64)>) -> anyhow::Result<(f64, u64)> {
    let until = Instant::now()
        + if after.is_none() {
            STARTUP_WAIT
        } else {
            STALL_WAIT
        };
    loop {
        if let Some(p) = sim_progress(dir)
            && after.is_none_or(|a| p.0 > a.0)
        {
            return Ok(p);
        }
        anyhow::ensure!(
            Instant::now() < until,
            "the pipeline made no progress; see {}",
            dir.display()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// What the interleaved measurement gives.
struct Interleaved {
    inprocess: f64,
    ipc: f64,
    ratio: f64,
    rtt: (f64, f64, f64),
    lost: u64,
    sim_wait: f64,
    rounds: Vec<BenchRound>,
}

/// Rounds of the interleaved measurement.
const ROUNDS: usize = 5;

/// The in-process loop and the three processes over shared memory, measured
/// in alternating windows ([`ROUNDS`] of each, the pipeline paused with
/// SIGSTOP while the in-process loop runs), so that drift in the machine's
/// speed (a shared VM's neighbours) hits both alike. Throughputs and their
/// ratio are medians over the rounds; a pipeline window is timed by the
/// sim's own progress lines (every 250 ms).
fn bench_interleaved(a: &BenchPipelineArgs) -> anyhow::Result<Interleaved> {
    let window = Duration::from_secs_f64((a.seconds / ROUNDS as f64).max(0.5));
    let mut local = InProcessLoop::new(a)?;
    local.run_for(Duration::from_secs(1))?; // warm-up

    let dir = tempfile::tempdir()?;
    let run = format!("bench-{}", std::process::id());
    let mut p = pipeline_args(a, &run, dir.path()).pipeline()?;
    p.start_all()?;
    let measured = alternate_rounds(&p, dir.path(), &mut local, window);
    p.signal_all(Signal::SIGCONT);
    p.stop_all(Duration::from_secs(3));
    teardown(&run)?;
    summarise_rounds(dir.path(), measured?)
}

/// The pipeline `bench pipeline` measures: `run`'s three processes with the
/// random policy, logging into `dir`, under the run name `run`.
fn pipeline_args(a: &BenchPipelineArgs, run: &str, dir: &std::path::Path) -> RunCmdArgs {
    RunCmdArgs {
        world: a.world.clone(),
        graph: GraphArgs {
            nodes: 32,
            node_file: None,
            walks_per_node: 64,
            walk_len: 64,
            graph_seed: None,
            no_shorten: false,
        },
        run: RunArgs {
            run: run.to_string(),
            run_dir: Some(dir.to_path_buf()),
            on_peer_death: OnPeerDeath::Exit,
            duration: None,
            cpu: None,
        },
        envs: a.envs,
        slices: a.slices,
        threads: a.threads,
        policy: PolicyKind::Random,
        route_every: 0,
        checkpoint_every: 10,
        logs_to_files: true,
        pin: false,
    }
}

/// Env-steps/s of each round's two windows, and the core-to-core round
/// trip measured before each.
struct RoundRates {
    local: Vec<f64>,
    ipc: Vec<f64>,
    c2c: Vec<Option<f64>>,
}

/// After the started pipeline `p` (logging into `dir`) has warmed up,
/// [`ROUNDS`] rounds of: the pipeline stopped, the core-to-core round trip
/// and a `window` of the in-process loop; the pipeline resumed, a `window`
/// of it timed by its progress lines. Leaves the pipeline running.
fn alternate_rounds(
    p: &Pipeline,
    dir: &std::path::Path,
    local: &mut InProcessLoop,
    window: Duration,
) -> anyhow::Result<RoundRates> {
    // Warm-up: the planner builds its graph, the learner connects.
    let first = next_progress(dir, None)?;
    std::thread::sleep(Duration::from_secs(1));
    next_progress(dir, Some(first))?;
    let mut rates = RoundRates {
        local: Vec::new(),
        ipc: Vec::new(),
        c2c: Vec::new(),
    };
    for _ in 0..ROUNDS {
        p.signal_all(Signal::SIGSTOP);
        rates.c2c.push(core_to_core_round_trip_ns());
        rates.local.push(local.run_for(window)?);
        p.signal_all(Signal::SIGCONT);
        std::thread::sleep(Duration::from_millis(200));
        let start = next_progress(dir, sim_progress(dir))?;
        std::thread::sleep(window);
        let end = next_progress(dir, sim_progress(dir))?;
        anyhow::ensure!(end.0 > start.0, "the pipeline's clock did not advance");
        rates.ipc.push((end.1 - start.1) as f64 / (end.0 - start.0));
    }
    Ok(rates)
}

/// The rounds' medians, and the round trips, losses and waiting the
/// pipeline's sim and learner reported into `dir` when they stopped.
fn summarise_rounds(dir: &std::path::Path, rates: RoundRates) -> anyhow::Result<Interleaved> {
    let RoundRates {
        local: local_rates,
        ipc: ipc_rates,
        c2c,
    } = rates;
    let ratios: Vec<f64> = ipc_rates
        .iter()
        .zip(&local_rates)
        .map(|(i, l)| i / l)
        .collect();

    let sim: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("sim.report.json"))?)?;
    let pct = |k: &str| sim[k].as_f64().unwrap_or(f64::NAN);
    let learner: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("learner.report.json"))?)?;
    let rounds = (0..ratios.len())
        .map(|i| BenchRound {
            inprocess_steps_per_sec: local_rates[i],
            ipc_steps_per_sec: ipc_rates[i],
            ratio: ratios[i],
            core_to_core_rtt_ns: c2c.get(i).copied().flatten(),
        })
        .collect();
    Ok(Interleaved {
        rounds,
        inprocess: median(local_rates),
        ipc: median(ipc_rates),
        ratio: median(ratios),
        rtt: (
            pct("roundtrip_p50_us"),
            pct("roundtrip_p99_us"),
            pct("roundtrip_p999_us"),
        ),
        lost: learner["stream"]["lost"].as_u64().unwrap_or(u64::MAX),
        sim_wait: pct("wait_fraction"),
    })
}

/// Round trip of one cache line between threads pinned to the first two
/// CPUs this process may use (median of 5 runs of 20,000 exchanges), in ns;
/// `None` with fewer than two CPUs or when pinning is refused.
pub fn core_to_core_round_trip_ns() -> Option<f64> {
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
    #[repr(align(128))]
    struct Line(AtomicU64);
    const EXCHANGES: u64 = 20_000;
    let cpus = crate::roles::allowed_cpus();
    let (&a, &b) = (cpus.first()?, cpus.get(1)?);
    let (ping, pong) = (Line(AtomicU64::new(0)), Line(AtomicU64::new(0)));
    let failed = AtomicBool::new(false);
    // Spins until `line` holds `i`; false if the other thread gave up.
    let wait_for = |line: &Line, i: u64| {
        while line.0.load(Ordering::Acquire) != i {
            if failed.load(Ordering::Relaxed) {
                return false;
            }
            std::hint::spin_loop();
        }
        true
    };
    let pinned = |cpu: usize| {
        let ok = crate::roles::pin_to_cpu(cpu).is_ok();
        if !ok {
            failed.store(true, Ordering::Relaxed);
        }
        ok
    };
    let mut runs = Vec::new();
    for run in 0..5u64 {
        let exchanges = run * EXCHANGES + 1..=(run + 1) * EXCHANGES;
        let ns = std::thread::scope(|s| {
            let echo = s.spawn(|| {
                pinned(b)
                    && exchanges.clone().all(|i| {
                        let seen = wait_for(&ping, i);
                        pong.0.store(i, Ordering::Release);
                        seen
                    })
            });
            let lead = s.spawn(|| {
                if !pinned(a) {
                    return None;
                }
                let t0 = Instant::now();
                for i in exchanges.clone() {
                    ping.0.store(i, Ordering::Release);
                    if !wait_for(&pong, i) {
                        return None;
                    }
                }
                Some(t0.elapsed().as_nanos() as f64 / EXCHANGES as f64)
            });
            let ns = lead.join().ok().flatten();
            let echoed = echo.join().unwrap_or(false);
            ns.filter(|_| echoed)
        });
        runs.push(ns?);
    }
    Some(median(runs))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// The socket setup: the sim steps the batch in this process and writes
/// every observation batch into the sockets of a learner and a planner
/// peer (`bench socket-peer`), the learner answering with actions.
/// Env-steps/s, and the round trip's p50 and p99 (µs). One frame on the
/// socket: `seq`, then `N` metas and `N × H × W` cells.
fn bench_socket(a: &BenchPipelineArgs) -> anyhow::Result<(f64, (f64, f64))> {
    let (layout, cfg) = a.world.build()?;
    let cpe = layout.width * layout.height;
    let frame = 8 + a.envs * (std::mem::size_of::<EnvMeta>() + cpe);
    let dir = tempfile::tempdir()?;
    let (peers, streams) = spawn_socket_peers(a, dir.path(), frame, cfg.task.num_actions())?;
    let mut batch = BatchEnv::new(layout, cfg, a.envs, a.world.seed, a.threads)?;
    let mut buf = batch.buffers();
    batch.reset(buf.out());
    let mut out = vec![0u8; frame];
    let mut actions = vec![0u8; a.envs];
    let mut lat = Latencies::new("socket");
    let (learner, planner) = (&streams[0], &streams[1]);
    let mut run_for = |d: Duration, lat: &mut Latencies| -> anyhow::Result<u64> {
        let until = Instant::now() + d;
        let mut n = 0u64;
        while Instant::now() < until {
            out[..8].copy_from_slice(&n.to_le_bytes());
            let metas: &[u8] = bytemuck::cast_slice(&buf.meta);
            out[8..8 + metas.len()].copy_from_slice(metas);
            out[8 + metas.len()..].copy_from_slice(&buf.cells);
            let t0 = Instant::now();
            (&*learner).write_all(&out)?;
            (&*planner).write_all(&out)?;
            (&*learner).read_exact(&mut actions)?;
            lat.record("round_trip", t0.elapsed().as_nanos() as u64);
            batch.step(
                &actions,
                StepOut {
                    cells: &mut buf.cells,
                    final_cells: &mut buf.final_cells,
                    meta: &mut buf.meta,
                },
            );
            n += 1;
        }
        Ok(n)
    };
    run_for(Duration::from_secs(1), &mut lat)?;
    lat.reset();
    let t0 = Instant::now();
    let n = run_for(Duration::from_secs_f64(a.seconds), &mut lat)?;
    let sps = (n * a.envs as u64) as f64 / t0.elapsed().as_secs_f64();
    drop(streams);
    for mut c in peers {
        let _ = c.wait();
    }
    Ok((
        sps,
        (
            lat.percentile_us("round_trip", 50.0),
            lat.percentile_us("round_trip", 99.0),
        ),
    ))
}

/// Starts the learner and the planner socket peers, each on its own socket
/// in `dir` for frames of `frame` bytes: the children and, in the same
/// order, the accepted streams.
fn spawn_socket_peers(
    a: &BenchPipelineArgs,
    dir: &std::path::Path,
    frame: usize,
    num_actions: usize,
) -> anyhow::Result<(Vec<std::process::Child>, Vec<UnixStream>)> {
    let mut peers = Vec::new();
    let mut streams = Vec::new();
    for role in ["learner", "planner"] {
        let path: PathBuf = dir.join(format!("{role}.sock"));
        let listener = UnixListener::bind(&path)?;
        let child = crate::pipeline::worldgraph_command()?
            .args([
                "bench",
                "socket-peer",
                "--socket",
                &path.display().to_string(),
                "--role",
                role,
            ])
            .args([
                "--frame-bytes",
                &frame.to_string(),
                "--envs",
                &a.envs.to_string(),
            ])
            .args(["--num-actions", &num_actions.to_string()])
            .stdin(Stdio::null())
            .spawn()?;
        peers.push(child);
        let (s, _) = listener.accept()?;
        streams.push(s);
    }
    Ok((peers, streams))
}

/// `bench socket-peer` (internal): the learner or planner end of the socket transport.
#[derive(Debug, Clone, Args)]
pub struct SocketPeerArgs {
    /// Socket to connect to.
    #[arg(long)]
    pub socket: PathBuf,
    /// `learner` (answers with actions) or `planner` (reads only).
    #[arg(long)]
    pub role: String,
    /// Bytes per observation frame.
    #[arg(long)]
    pub frame_bytes: usize,
    /// Environments.
    #[arg(long)]
    pub envs: usize,
    /// Actions of the task.
    #[arg(long)]
    pub num_actions: usize,
}

/// Runs a socket peer until the sim closes the socket.
pub fn socket_peer(a: SocketPeerArgs) -> anyhow::Result<std::process::ExitCode> {
    let mut s = UnixStream::connect(&a.socket)?;
    // u64 words keep the metas 4-byte aligned for the cast below.
    let mut words = vec![0u64; a.frame_bytes.div_ceil(8)];
    let frame: &mut [u8] = &mut bytemuck::cast_slice_mut(&mut words)[..a.frame_bytes];
    let mut policy = RandomPolicy::new(a.num_actions, 7);
    let mut actions = vec![0u8; a.envs];
    let mut visits = 0u64;
    while s.read_exact(frame).is_ok() {
        let metas: &[EnvMeta] =
            bytemuck::cast_slice(&frame[8..8 + a.envs * std::mem::size_of::<EnvMeta>()]);
        visits += metas.len() as u64;
        if a.role == "learner" {
            let view = learner::batch_env::ObsView {
                seq: 0,
                cells: &[],
                final_cells: &[],
                meta: metas,
                width: 0,
                height: 0,
            };
            policy.act(&view, &mut actions);
            s.write_all(&actions)?;
        }
    }
    std::hint::black_box(visits);
    Ok(std::process::ExitCode::SUCCESS)
}
