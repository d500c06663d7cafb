//! `worldgraph demo`: the main job on the embedded default.

use std::path::PathBuf;

use clap::Args;
use sim::{BatchEnv, Maze, Task, render};

use super::bench::{BenchSimArgs, bench_sim, print_sim_report};
use crate::world::WorldArgs;

/// `demo` options.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Directory for the pictures.
    #[arg(long, default_value = "runs/demo")]
    pub out: PathBuf,
    /// Seconds of the throughput measurement.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// Base seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Renders the medium maze (ASCII and PNG, plus a grid of 16 episodes'
/// starts) and measures batched simulation throughput.
pub fn run(a: DemoArgs) -> anyhow::Result<std::process::ExitCode> {
    let world = WorldArgs {
        maze: Maze::Medium,
        layout: None,
        task: Task::MultiGoal,
        seed: a.seed,
        max_steps: None,
        balls: None,
    };
    let (layout, cfg) = world.build()?;
    let (w, h) = (layout.width, layout.height);
    let mut batch = BatchEnv::new(layout, cfg, 16, a.seed, 1)?;
    let mut buf = batch.buffers();
    batch.reset(buf.out());
    print!("{}", render::ascii(&buf.cells[..w * h], w, &buf.meta[0]));
    let one = a.out.join("medium-multigoal.png");
    render::render_env(&buf.cells, w, h, &buf.meta[0], 24).save_png(&one)?;
    let grid = a.out.join("medium-multigoal-batch.png");
    render::render_batch(&buf.cells, &buf.meta, w, h, 16, 4, 12).save_png(&grid)?;
    println!("wrote {} and {}", one.display(), grid.display());
    let r = bench_sim(&BenchSimArgs {
        world,
        envs: 1024,
        threads: 2,
        seconds: a.seconds,
        json: false,
    })?;
    print_sim_report(&r);
    Ok(std::process::ExitCode::SUCCESS)
}
