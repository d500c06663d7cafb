//! The arguments that choose a world: an embedded maze or a layout file, a
//! task, a seed and a step limit; shared by every command that builds
//! environments.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use sim::{BallSpawn, EnvConfig, Layout, Maze, Task};

/// Which maze and task to simulate.
#[derive(Debug, Clone, Args)]
pub struct WorldArgs {
    /// Embedded maze: small (13x13), medium (25x19) or large (31x25). The
    /// Door-Key task uses the maze's Door-Key variant.
    #[arg(long, default_value = "medium", conflicts_with = "layout")]
    pub maze: Maze,
    /// A layout file instead of an embedded maze (one character per cell:
    /// # wall, . floor, E exit, K key, D locked door, C closed door, O open
    /// door, B ball, L lava, > v < ^ agent). Its objects are the episode's
    /// objects: no balls are spawned at random.
    #[arg(long)]
    pub layout: Option<PathBuf>,
    /// Task: multigoal, multigoal-sparse, multigoal-stochastic or doorkey.
    #[arg(long, default_value = "multigoal")]
    pub task: Task,
    /// Base seed; environment i draws from a stream seeded by (seed, i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Episode step limit (truncation). Default: twice the free cells.
    #[arg(long)]
    pub max_steps: Option<u32>,
    /// Balls spawned at random per episode in the MultiGoal tasks (default
    /// 5, the paper's; 0 keeps only the layout's balls, which makes the
    /// dynamics deterministic, as world-graph discovery wants).
    #[arg(long)]
    pub balls: Option<u8>,
}

impl WorldArgs {
    /// The validated layout and environment configuration.
    pub fn build(&self) -> anyhow::Result<(Layout, EnvConfig)> {
        let (layout, from_file) = match &self.layout {
            Some(path) => (
                Layout::from_file(path).with_context(|| "cannot use the layout")?,
                true,
            ),
            None => (self.maze.layout(self.task.uses_door_key_layout()), false),
        };
        let mut cfg = EnvConfig::for_task(self.task, &layout);
        if from_file {
            cfg.balls = BallSpawn::Layout;
        }
        match self.balls {
            Some(0) => cfg.balls = BallSpawn::Layout,
            Some(n) if !from_file => cfg.balls = BallSpawn::Random(n),
            _ => {}
        }
        if let Some(m) = self.max_steps {
            anyhow::ensure!(m > 0, "--max-steps must be at least 1");
            cfg.max_steps = m;
        }
        Ok((layout, cfg))
    }
}
