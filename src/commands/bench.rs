//! `worldgraph bench ...`: throughput and latency figures, each against a
//! baseline measured in the same run.

use std::time::{Duration, Instant};

use clap::{Args, Subcommand};
use rayon::prelude::*;
use serde::Serialize;
use sim::{BatchEnv, EnvMeta, StepBuffers};

use crate::world_args::WorldArgs;

/// Benchmarks.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Batched simulator throughput against a memcpy of the same bytes.
    Sim(BenchSimArgs),
    /// The three processes over shared memory against the same workload in
    /// one process and over Unix sockets.
    Pipeline(super::bench_pipeline::BenchPipelineArgs),
    /// Training throughput of a learner (π_g, A2C, FN, WN): the fast path
    /// against the plain one, where the time goes, FLOPs against a matmul,
    /// and against the PyTorch reference of the same update when `torch`
    /// is importable.
    Learner(super::bench_learner::BenchLearnerArgs),
    /// Route-query latency and all-pairs shortest-path rebuild time.
    Planner(super::bench_planner::BenchPlannerArgs),
    /// Internal: the peer end of `bench pipeline`'s socket transport.
    #[command(hide = true)]
    SocketPeer(super::bench_pipeline::SocketPeerArgs),
}

/// `bench sim` options.
#[derive(Debug, Clone, Args)]
pub struct BenchSimArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    /// Environments in the batch.
    #[arg(long, default_value_t = 1024)]
    pub envs: usize,
    /// Threads stepping the batch (and copying, for the baseline).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Seconds of each measurement (the simulator and the memcpy baseline,
    /// each in five windows that alternate between the two).
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Figures of `bench sim`.
#[derive(Debug, Clone, Serialize)]
pub struct SimBenchReport {
    /// Maze name.
    pub maze: String,
    /// Task name.
    pub task: String,
    /// Batch size.
    pub envs: usize,
    /// Threads.
    pub threads: usize,
    /// Environment steps per second of the batch (observations written).
    pub steps_per_sec: f64,
    /// Bytes of one environment's observation: grid cells + its `EnvMeta`.
    pub obs_bytes_per_step: usize,
    /// Bandwidth of copying the same observation bytes with the same threads.
    pub memcpy_bytes_per_sec: f64,
    /// Simulator env-steps per second over the memcpy bound's
    /// (`memcpy bytes/s ÷ obs_bytes_per_step`): the median over alternating
    /// windows, each ratio from a simulator window and the copy window
    /// right after it.
    pub ratio_to_memcpy_bound: f64,
    /// Smallest window ratio.
    pub ratio_min: f64,
    /// Largest window ratio.
    pub ratio_max: f64,
    /// One environment stepped on one thread, observation written.
    pub single_env_steps_per_sec: f64,
    /// Episodes finished during the batch measurement.
    pub episodes: u64,
}

/// Runs a `bench` subcommand.
pub fn run(cmd: BenchCommand) -> anyhow::Result<std::process::ExitCode> {
    match cmd {
        BenchCommand::Pipeline(a) => return super::bench_pipeline::run(a),
        BenchCommand::Planner(a) => return super::bench_planner::run(a),
        BenchCommand::Learner(a) => return super::bench_learner::run(a),
        BenchCommand::SocketPeer(a) => return super::bench_pipeline::socket_peer(a),
        BenchCommand::Sim(a) => {
            let r = bench_sim(&a)?;
            if a.json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                print_sim_report(&r);
            }
        }
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// A fixed table of uniformly random actions (the null policy), drawn once
/// so the measured loop spends nothing on choosing actions.
fn action_table(n: usize, num_actions: usize, seed: u64) -> Vec<u8> {
    let mut x = sim::env_seed(seed, 0xac7) | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            ((x >> 33) % num_actions as u64) as u8
        })
        .collect()
}

/// Alternating measurement windows of `bench sim` (simulator, then memcpy,
/// five times): on a shared VM the machine's speed drifts over seconds, so
/// each ratio compares two neighbouring windows and the report gives their
/// median.
const WINDOWS: usize = 5;

/// Measures the batched simulator and its memcpy bound.
pub fn bench_sim(a: &BenchSimArgs) -> anyhow::Result<SimBenchReport> {
    anyhow::ensure!(a.seconds > 0.0, "--seconds must be positive");
    let (layout, cfg) = a.world.build()?;
    let maze = layout.name.clone();
    let mut batch = BatchEnv::new(layout.clone(), cfg, a.envs, a.world.seed, a.threads)?;
    let mut buf = batch.buffers();
    batch.reset(buf.out());
    let n = a.envs;
    // Offsets into the table change every step, so consecutive steps differ.
    let table = action_table(n + 4099, cfg.task.num_actions(), a.world.seed);
    let window = Duration::from_secs_f64(a.seconds / WINDOWS as f64);
    let obs_bytes_per_step = batch.cells_per_env() + std::mem::size_of::<EnvMeta>();
    let mut memcpy = Memcpy::new(n, obs_bytes_per_step, a.threads)?;

    // Warm-up: page in buffers, start threads.
    for s in 0..50 {
        let o = (s * 7919) % 4099;
        batch.step(&table[o..o + n], buf.out());
        memcpy.copy();
    }
    let w = alternate_windows(&mut batch, &mut buf, &table, &mut memcpy, window);
    let steps_per_sec = w.steps as f64 / w.sim_secs;
    let memcpy_bytes_per_sec = (w.copied * (n * obs_bytes_per_step) as u64) as f64 / w.copy_secs;
    let single_budget = Duration::from_secs_f64(a.seconds).min(Duration::from_secs(1));
    let single = BatchEnv::new(layout, cfg, 1, a.world.seed, 1)?;
    let single_env_steps_per_sec = single_env_rate(single, &table, single_budget);

    Ok(SimBenchReport {
        maze,
        task: cfg.task.name().to_string(),
        envs: n,
        threads: a.threads,
        steps_per_sec,
        obs_bytes_per_step,
        memcpy_bytes_per_sec,
        ratio_to_memcpy_bound: w.ratios[WINDOWS / 2],
        ratio_min: w.ratios[0],
        ratio_max: w.ratios[WINDOWS - 1],
        single_env_steps_per_sec,
        episodes: w.episodes,
    })
}

/// The baseline of `bench sim`: copying the bytes of one batch step's
/// observations (cells and metas) with the simulator's threads (on one
/// thread, in the calling thread, as the batch steps).
struct Memcpy {
    src: Vec<u8>,
    dst: Vec<u8>,
    pool: rayon::ThreadPool,
    /// Bytes per parallel chunk: whole environments' observations.
    chunk: usize,
    threads: usize,
}

impl Memcpy {
    /// The observations of `envs` environments, `obs_bytes_per_step`
    /// each, copied on `threads` threads.
    fn new(envs: usize, obs_bytes_per_step: usize, threads: usize) -> anyhow::Result<Memcpy> {
        let bytes = envs * obs_bytes_per_step;
        Ok(Memcpy {
            src: (0..bytes).map(|i| i as u8).collect(),
            dst: vec![0u8; bytes],
            pool: rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?,
            chunk: envs.div_ceil(threads * 4).max(16) * obs_bytes_per_step,
            threads,
        })
    }

    /// One copy of all the bytes.
    fn copy(&mut self) {
        let (src, dst, chunk) = (&self.src, &mut self.dst, self.chunk);
        if self.threads == 1 {
            dst.copy_from_slice(src);
        } else {
            self.pool.install(|| {
                dst.par_chunks_mut(chunk)
                    .zip(src.par_chunks(chunk))
                    .for_each(|(d, s)| d.copy_from_slice(s));
            });
        }
        std::hint::black_box(&dst);
    }
}

/// What the alternating windows of `bench sim` measured.
struct Windows {
    /// Env-steps in the simulator windows.
    steps: u64,
    /// Episodes finished in them.
    episodes: u64,
    /// Seconds of the simulator windows.
    sim_secs: f64,
    /// Seconds of the memcpy windows.
    copy_secs: f64,
    /// Copies of the batch's bytes made in them.
    copied: u64,
    /// Each window pair's ratio of simulator env-steps/s to the memcpy
    /// bound's, sorted.
    ratios: Vec<f64>,
}

/// [`WINDOWS`] simulator windows of `window` each, every one followed by a
/// memcpy window as long.
fn alternate_windows(
    batch: &mut BatchEnv,
    buf: &mut StepBuffers,
    table: &[u8],
    memcpy: &mut Memcpy,
    window: Duration,
) -> Windows {
    let n = buf.meta.len();
    let (mut steps, mut episodes) = (0u64, 0u64);
    let (mut sim_secs, mut copy_secs, mut copied) = (0.0, 0.0, 0u64);
    let mut ratios = Vec::with_capacity(WINDOWS);
    for _ in 0..WINDOWS {
        let (s0, t0) = (steps, Instant::now());
        while t0.elapsed() < window {
            for _ in 0..16 {
                let o = (steps as usize * 7919 / n.max(1) + steps as usize) % 4099;
                batch.step(&table[o..o + n], buf.out());
                steps += n as u64;
            }
            episodes += buf.meta.iter().filter(|m| m.done()).count() as u64;
        }
        let sim_dt = t0.elapsed().as_secs_f64();
        let (c0, t0) = (copied, Instant::now());
        while t0.elapsed() < window {
            for _ in 0..16 {
                memcpy.copy();
                copied += 1;
            }
        }
        let copy_dt = t0.elapsed().as_secs_f64();
        let sim_rate = (steps - s0) as f64 / sim_dt;
        let bound = (copied - c0) as f64 * n as f64 / copy_dt;
        ratios.push(sim_rate / bound);
        sim_secs += sim_dt;
        copy_secs += copy_dt;
    }
    ratios.sort_by(f64::total_cmp);
    Windows {
        steps,
        episodes,
        sim_secs,
        copy_secs,
        copied,
        ratios,
    }
}

/// Steps per second of `single` (one environment on one thread, its
/// observation written) over `budget`.
fn single_env_rate(mut single: BatchEnv, table: &[u8], budget: Duration) -> f64 {
    let mut sbuf = single.buffers();
    single.reset(sbuf.out());
    let mut s_steps = 0u64;
    let t0 = Instant::now();
    while t0.elapsed() < budget {
        for k in 0..1024 {
            single.step(&table[k..k + 1], sbuf.out());
        }
        s_steps += 1024;
    }
    s_steps as f64 / t0.elapsed().as_secs_f64()
}

/// Prints the `bench sim` summary table.
pub fn print_sim_report(r: &SimBenchReport) {
    println!(
        "bench sim: {} maze, {}, {} envs, {} threads",
        r.maze, r.task, r.envs, r.threads
    );
    println!("  {:<34} {:>16}", "measure", "value");
    println!(
        "  {:<34} {:>16.2}M",
        "batched env-steps/s",
        r.steps_per_sec / 1e6
    );
    println!(
        "  {:<34} {:>16}",
        "observation bytes per env-step", r.obs_bytes_per_step
    );
    println!(
        "  {:<34} {:>16.2}",
        "memcpy of the same bytes (GB/s)",
        r.memcpy_bytes_per_sec / 1e9
    );
    println!(
        "  {:<34} {:>16.2}M",
        "memcpy bound (env-steps/s)",
        r.memcpy_bytes_per_sec / r.obs_bytes_per_step as f64 / 1e6
    );
    println!(
        "  {:<34} {:>16.1}%",
        "ratio to the memcpy bound (median)",
        r.ratio_to_memcpy_bound * 100.0
    );
    println!(
        "  {:<34} {:>17}",
        "  range over the 5 windows",
        format!("{:.1}–{:.1}%", r.ratio_min * 100.0, r.ratio_max * 100.0)
    );
    println!(
        "  {:<34} {:>16.2}M",
        "single env, one thread (steps/s)",
        r.single_env_steps_per_sec / 1e6
    );
    println!("  {:<34} {:>16}", "episodes finished", r.episodes);
}
