//! `worldgraph`: the command-line entry point.
//!
//! Starts each role of the pipeline, runs the simulator's tools and the
//! benchmarks. Shang et al. 2019 (arXiv:1907.00664) is implemented by the
//! library crates, the paper's protocol and run directories included
//! (`learner::run`); this binary parses arguments (clap), turns them into
//! validated configs, calls the libraries and prints. Beside the commands
//! it holds the experiment grid's process scheduling and its result files
//! (`commands/experiment/`, `results.rs`), the pipeline's process roles
//! (`roles/`), the update log (`update_log.rs`) and the pictures
//! (`chart/`, `episode_picture.rs`).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod chart;
mod commands;
mod episode_picture;
mod latency;
mod picture_path;
mod pipeline;
mod progress;
mod results;
mod rliable;
mod roles;
mod shutdown;
mod update_log;
mod world_args;
mod world_graph_picture;

/// worldgraph: learn a graph of a maze's structure (pivotal states and the
/// paths between them) and use it to make hierarchical RL fast.
#[derive(Debug, Parser)]
#[command(
    name = "worldgraph",
    version,
    about,
    long_about = None,
    propagate_version = true,
    after_help = ENVIRONMENT
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The environment variables every command reads (`--help`'s epilogue).
const ENVIRONMENT: &str = "\
Environment:
  WORLDGRAPH_TORCH_THREADS  libtorch's intra-op threads of this process [default: 1]
  WORLDGRAPH_LOG            the log filter, tracing's EnvFilter syntax (e.g. debug, learner=debug) [default: info]
  WORLDGRAPH_CACHE          where scripts/setup-libtorch.sh keeps libtorch [default: ~/.cache/worldgraph]
  WORLDGRAPH_PYTHON         bench learner's Python for the PyTorch reference [default: .venv/bin/python, else python3]";

#[derive(Debug, Subcommand)]
enum Command {
    /// The main job on the embedded default: the whole method on the small
    /// maze, briefly (discover the world graph, train Wide-then-Narrow with
    /// the graph and the A2C baseline, print both test scores).
    Demo(commands::demo::DemoArgs),
    /// The three processes side by side (sim, learner, planner) over shared
    /// memory, stopped together on Ctrl-C.
    Run(pipeline::RunCmdArgs),
    /// The three processes for M minutes, optionally killing one every S
    /// seconds; reports losses, leaks, recoveries and p99 per minute.
    Soak(commands::soak::SoakArgs),
    /// Stage 1: discover pivotal states and build the world graph (latent
    /// model + goal-conditioned policy), resumable, with pictures.
    Discover(commands::discover::DiscoverArgs),
    /// Stage 2: train one agent (A2C, FN, WN) on one task and maze with the
    /// paper's protocol (validation picks the best checkpoint, held-out test
    /// seeds score it), resumable, with curves and an episode picture.
    Train(commands::train::TrainArgs),
    /// Score a `train` run's best checkpoint on any range of test seeds.
    Evaluate(commands::evaluate::EvaluateArgs),
    /// The paper's ablation study: a grid of (maze, task, agent, seed) runs,
    /// side by side here or as SLURM job arrays (--slurm), resumable, each
    /// summary written under `results/`.
    Experiment(commands::experiment::ExperimentArgs),
    /// Render `results/` as the paper's Tables 1 and 2 with time to score
    /// and the Figure 4 curves (`docs/results.md`).
    Table(commands::table::TableArgs),
    /// Simulator tools: render a maze, trace an action sequence.
    #[command(subcommand)]
    Sim(commands::sim::SimCommand),
    /// The learner process of the pipeline.
    #[command(subcommand)]
    Learner(LearnerCommand),
    /// The planner process of the pipeline.
    #[command(subcommand)]
    Planner(PlannerCommand),
    /// Benchmarks that print figures (never assertions).
    #[command(subcommand)]
    Bench(commands::bench::BenchCommand),
    /// Remove the shared memory (`/dev/shm/wg_*`) that dead runs left
    /// behind, saying what was removed; runs with a live process are kept.
    Clean(commands::clean::CleanArgs),
}

#[derive(Debug, Subcommand)]
enum LearnerCommand {
    /// Read observation batches from the sim over shared memory, run a
    /// policy, send action batches.
    Serve(roles::learner::LearnerServeArgs),
}

#[derive(Debug, Subcommand)]
enum PlannerCommand {
    /// Keep the world graph, count visits from the observation stream and
    /// answer route requests.
    Serve(roles::planner::PlannerServeArgs),
}

fn run() -> anyhow::Result<ExitCode> {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo(args) => commands::demo::run(args),
        Command::Run(a) => commands::run::run(a),
        Command::Discover(a) => commands::discover::run(a),
        Command::Soak(a) => commands::soak::run(a),
        Command::Train(a) => commands::train::run(a),
        Command::Evaluate(a) => commands::evaluate::evaluate(a),
        Command::Experiment(a) => commands::experiment::run(a),
        Command::Table(a) => commands::table::run(a),
        Command::Sim(cmd) => commands::sim::run(cmd),
        Command::Learner(LearnerCommand::Serve(a)) => roles::learner::serve(a),
        Command::Planner(PlannerCommand::Serve(a)) => roles::planner::serve(a),
        Command::Bench(cmd) => commands::bench::run(cmd),
        Command::Clean(a) => commands::clean::run(a),
    }
}

/// libtorch's intra-op threads. One by default: on the 2-core target the
/// other core belongs to the simulator (or to the peer process), and an
/// OpenMP pool spinning against a busy core costs far more than it gains on
/// these small models. `WORLDGRAPH_TORCH_THREADS` overrides it.
fn set_torch_threads() {
    let n = std::env::var("WORLDGRAPH_TORCH_THREADS")
        .ok()
        .and_then(|v| v.parse::<i32>().ok())
        .unwrap_or(1);
    tch::set_num_threads(n.max(1));
    tch::set_num_interop_threads(1);
}

/// Output into a closed pipe (`worldgraph train ... | head`) ends the
/// process quietly, as it ends any Unix tool: Rust ignores SIGPIPE, which
/// makes every `println!` into a closed pipe panic ("failed printing to
/// stdout"). With the signal's default back, the write ends the process
/// (status 141 in a shell), whatever the command. A parent's children go
/// with it (`pipeline::worldgraph_command`). iceoryx2 sends with
/// `MSG_NOSIGNAL`, so shared memory is unaffected.
#[allow(unsafe_code)]
fn end_quietly_on_a_closed_pipe() {
    // SAFETY: `signal` with `SIG_DFL` installs no handler (no code runs in
    // signal context); it is called first in `main`, before this program
    // starts a thread, and no library of it installs a SIGPIPE handler.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    end_quietly_on_a_closed_pipe();
    set_torch_threads();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("WORLDGRAPH_LOG")
                .unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    match run() {
        Ok(code) => code,
        Err(e) => {
            // A libtorch error carries a C++ backtrace after its first line:
            // kept for WORLDGRAPH_LOG=debug.
            // Each cause once: an error whose message already quotes its
            // source (a layout error naming the file and line) is not
            // followed by that source again.
            let mut parts: Vec<String> = Vec::new();
            for cause in e.chain() {
                let s = cause.to_string();
                if !parts.last().is_some_and(|p| p.contains(&s)) {
                    parts.push(s);
                }
            }
            let full = parts.join(": ");
            let short: Vec<&str> = full
                .lines()
                .take_while(|l| !l.starts_with("Exception raised from") && !l.contains("frame #"))
                .collect();
            eprintln!("error: {}", short.join("\n"));
            if short.len() < full.lines().count() {
                tracing::debug!("full error: {full}");
            }
            ExitCode::FAILURE
        }
    }
}
