//! `worldgraph experiment --reproduce SUMMARY`: reruns the one run a
//! committed summary describes (its discovery too, when it had one) on
//! this binary, and compares the test scores.

use std::path::{Path, PathBuf};
use std::process::Child;

use anyhow::Context;
use learner::a2c::rollout::GradPath;
use learner::run::protocol::TestSummary;
use sim::{Maze, Task};

use super::grid::{Grid, MazeBudget};
use super::{
    ExperimentArgs, Job, Plan, discover_command, discovery_done, start, tail, train_command,
};
use crate::results::{RunResult, build_commit, cpu_model, read_run};

/// `--reproduce`: reruns one recorded run in a scratch working directory.
pub(super) fn reproduce(
    summary: &Path,
    a: &ExperimentArgs,
) -> anyhow::Result<std::process::ExitCode> {
    let r = read_run(summary)?;
    check_grad_path(&r, summary)?;
    let maze: Maze = r
        .maze
        .parse()
        .map_err(|e| anyhow::anyhow!("{}: maze {:?}: {e}", summary.display(), r.maze))?;
    let task: Task = r
        .task
        .parse()
        .map_err(|e| anyhow::anyhow!("{}: task {:?}: {e}", summary.display(), r.task))?;
    let plan = scratch_plan(&r, summary, maze, a)?;
    let graph = world_graph(&r, summary, &plan, a)?;
    let job = Job::Train {
        maze,
        task,
        config: r.config.clone(),
        seed: r.seed,
        needs: r.discover.as_ref().map(|_| 0),
    };
    eprintln!(
        "reproduce: training {} in {}",
        Plan::label(&job),
        plan.work.display()
    );
    let cmd = train_command(
        &plan,
        &r.train_config,
        maze,
        task,
        &r.config,
        r.seed,
        graph.as_deref(),
    )?;
    // The summary's training config carries its gradient path
    // (`agent.grad_path`).
    eprintln!(
        "reproduce: on the gradient path {}; recorded on the CPU {}, rerun on {}",
        r.grad_path,
        r.cpu,
        cpu_model()
    );
    wait_ok(
        start(cmd, &plan.log_path(&job), plan.threads)?,
        &plan.log_path(&job),
    )?;
    let dir = plan.train_dir(maze, task, &r.config, r.seed);
    let t: TestSummary = serde_json::from_slice(&std::fs::read(dir.join("test.json"))?)?;
    println!(
        "recorded test score {:.6} (commit {}), reproduced {:.6} (commit {})",
        r.test_score, r.commit, t.test_score, plan.commit
    );
    let cpu = cpu_model();
    if t.test_score == r.test_score {
        println!("reproduced: the same test score");
        Ok(std::process::ExitCode::SUCCESS)
    } else if r.cpu != cpu {
        eprintln!(
            "error: the rerun's test score differs from the summary's, which was made on another \
             CPU ({}; this one: {cpu}). libtorch's MKL and the own kernels' GEMM choose their \
             kernels and blocking by CPU, so floats, and the agent trained on them, differ from \
             one CPU model to another: rerun on a machine with the summary's CPU",
            r.cpu
        );
        Ok(std::process::ExitCode::FAILURE)
    } else {
        eprintln!("error: the rerun's test score differs from the summary's");
        Ok(std::process::ExitCode::FAILURE)
    }
}

/// Refuses a summary trained on a gradient path this version no longer
/// has, naming the commit to check out instead: the same function in
/// another float order reproduces only on its own path.
fn check_grad_path(r: &RunResult, summary: &Path) -> anyhow::Result<()> {
    anyhow::ensure!(
        GradPath::from_name(&r.grad_path).is_some(),
        "{} was trained on the gradient path {:?}, which this version no longer has: it keeps \
         `rust-core` and the `tch` reference. The same function in another float order \
         reproduces only on its own path: check out the summary's commit (`git checkout {}`{}) \
         and run this command there",
        summary.display(),
        r.grad_path,
        r.commit.trim_end_matches("+dirty"),
        if r.commit.ends_with("+dirty") {
            "; the run's tree had uncommitted changes, so that commit is the nearest"
        } else {
            ""
        }
    );
    Ok(())
}

/// A one-run plan of the summary's settings in a scratch working
/// directory (`--work`, or `runs/reproduce/<maze>-<task>-<config>-seed-<n>`).
fn scratch_plan(
    r: &RunResult,
    summary: &Path,
    maze: Maze,
    a: &ExperimentArgs,
) -> anyhow::Result<Plan> {
    let work = a.work.clone().unwrap_or_else(|| {
        PathBuf::from("runs/reproduce").join(format!(
            "{}-{}-{}-seed-{}",
            r.maze, r.task, r.config, r.seed
        ))
    });
    // The discovery settings the summary's grid pins, if it does.
    let discover_config = match &r.discover {
        Some(_) => {
            Grid::read(Path::new(&r.grid))
                .with_context(|| {
                    format!(
                        "{} names grid {}, whose discover_config the world graph needs",
                        summary.display(),
                        r.grid
                    )
                })?
                .discover_config
        }
        None => None,
    };
    let grid = Grid {
        name: "reproduce".to_string(),
        seeds: vec![r.seed],
        validation_seeds: r.validation_seeds,
        test_seeds: r.test_seeds,
        maze: vec![MazeBudget {
            name: maze,
            env_steps: r.train_config.env_steps,
            eval_every: r.train_config.eval_every,
            discover_rounds: r.discover.as_ref().map_or(1, |d| d.rounds),
        }],
        discover_config,
        set: Vec::new(),
        group: Vec::new(),
    };
    Ok(Plan {
        grid,
        grid_path: PathBuf::from(&r.grid),
        grid_label: r.grid.clone(),
        grid_digest: String::new(),
        results: work.join("results"),
        work,
        threads: r.torch_threads,
        jobs: 1,
        commit: build_commit(),
    })
}

/// The world graph the rerun trains on: `--world-graph` (checked to be a
/// finished discovery of the summary's rounds), or discovered again in the
/// scratch directory; none for a run without one.
fn world_graph(
    r: &RunResult,
    summary: &Path,
    plan: &Plan,
    a: &ExperimentArgs,
) -> anyhow::Result<Option<PathBuf>> {
    match (&r.discover, &a.world_graph) {
        (Some(spec), Some(given)) => {
            anyhow::ensure!(
                discovery_done(given, spec).is_some(),
                "--world-graph {}: not a finished discover run of {} rounds (the summary's)",
                given.display(),
                spec.rounds
            );
            eprintln!("reproduce: on the world graph of {}", given.display());
            Ok(Some(std::fs::canonicalize(given)?))
        }
        (None, Some(given)) => anyhow::bail!(
            "--world-graph {}: {} trained without a world graph",
            given.display(),
            summary.display()
        ),
        (Some(spec), None) => {
            let dir = plan.discover_dir(spec);
            if discovery_done(&dir, spec).is_none() {
                eprintln!(
                    "reproduce: discovering the world graph ({} rounds)",
                    spec.rounds
                );
                let job = Job::Discover { spec: spec.clone() };
                let cmd = discover_command(plan, spec)?;
                wait_ok(
                    start(cmd, &plan.log_path(&job), plan.threads)?,
                    &plan.log_path(&job),
                )?;
            }
            Ok(Some(std::fs::canonicalize(&dir)?))
        }
        (None, None) => Ok(None),
    }
}

fn wait_ok(mut child: Child, log: &Path) -> anyhow::Result<()> {
    let status = child.wait()?;
    anyhow::ensure!(
        status.success(),
        "{status}; the end of {}:\n{}",
        log.display(),
        tail(log, 6)
    );
    Ok(())
}
