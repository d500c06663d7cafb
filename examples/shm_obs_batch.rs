//! One observation batch over iceoryx2 shared memory: the simulator steps
//! its environments straight into a loaned sample, the reader borrows the
//! same bytes. Both ends live in this process here; in the pipeline they
//! are the `sim` and `learner` processes (`worldgraph run`).
//!
//! `cargo run --release --example shm_obs_batch`

use iceoryx2::prelude::ipc;
use shm_schemas::ObsShape;
use shm_schemas::service::{PipelineNode, RunName, isolated_config, teardown_run};
use sim::{BatchEnv, EnvConfig, Maze, StepOut, Task};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let layout = Maze::Small.layout(false);
    let cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
    let mut envs = BatchEnv::new(layout.clone(), cfg, 4, 0, 1)?;
    let shape = ObsShape::new(4, layout.width, layout.height)?;

    // A shared-memory prefix of its own, so no real run's services are met.
    let config = isolated_config(&format!("wgexample_{}_", std::process::id()))?;
    let run = RunName::new("example")?;
    {
        let sim = PipelineNode::<ipc::Service>::new(&config, run.clone(), "sim")?;
        let learner = PipelineNode::<ipc::Service>::new(&config, run, "learner")?;
        let subscriber = learner.obs_subscriber(shape)?;
        let publisher = sim.obs_publisher(shape)?;

        // The simulator: loan a sample, reset the environments into it, send.
        let mut sample = publisher.loan(0, 0)?;
        let (_, meta, cells, final_cells) = sample.batch_mut().into_parts();
        envs.reset(StepOut {
            cells,
            final_cells,
            meta,
        });
        sample.send()?;

        // The reader: the received sample is the simulator's memory.
        let received = subscriber.receive()?.ok_or("a batch was sent")?;
        let batch = received.batch();
        println!(
            "batch {} of {} environments:",
            batch.header.seq,
            batch.meta.len()
        );
        for (i, m) in batch.meta.iter().enumerate() {
            println!("  env {i}: agent at ({}, {}) facing {}", m.x, m.y, m.dir);
        }
        let grid = &batch.cells[..shape.cells_per_env()];
        println!("{}", sim::render::ascii(grid, layout.width, &batch.meta[0]));
    }
    // The nodes are gone: remove the run's shared-memory files.
    teardown_run::<ipc::Service>(&config)?;
    Ok(())
}
