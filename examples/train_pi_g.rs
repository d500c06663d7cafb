//! Train the goal-conditioned policy `π_g` (section 3.2 of the paper) alone:
//! A2C iterations on goals at most `--goal-moves` moves away, without the
//! discovery loop around it (no latent model, so no curiosity bonus; no
//! rounds). Every `--every` iterations it prints the training goals'
//! success, the policy's entropy and, every fifth report, the greedy
//! policy's success on goals ten random moves away (environments of
//! another seed), the figure `discover` reports.
//!
//! `cargo run --release --example train_pi_g` trains 400 iterations in two
//! small rooms; `-- --maze large --iters 2500` shows how long `π_g` stays
//! at the success of a random policy before it takes off on the large
//! maze, and `--goal-moves 2` how much sooner it takes off on near goals
//! (docs/findings.md, stage 1).

use clap::Parser;
use learner::batch_env::InProcess;
use learner::gcp::{GcpConfig, GoalConditionedPolicy};
use sim::{BallSpawn, EnvConfig, Layout, Maze, Task};

/// Two rooms joined by a doorway; goals may lie on either side.
const ROOMS: &str = "\
#########
#...#...#
#...#...#
#>......#
#...#...#
#...#..E#
#########
";

/// Trains `π_g` alone on a maze and reports its success as it learns.
#[derive(Debug, Parser)]
struct Args {
    /// An embedded maze (small, medium, large) instead of the two rooms.
    #[arg(long)]
    maze: Option<Maze>,
    /// A2C iterations (one rollout and one update each).
    #[arg(long, default_value_t = 400)]
    iters: usize,
    /// Seed of the environments and of `π_g`.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Training goals lie 1 to this many moves away (`gcp.goal_walk_len`).
    #[arg(long, default_value_t = 4)]
    goal_moves: usize,
    /// Iterations per printed report.
    #[arg(long, default_value_t = 100)]
    every: usize,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = Args::parse();
    let layout = match a.maze {
        Some(m) => m.layout(false),
        None => Layout::parse("two rooms", ROOMS)?,
    };
    // MultiGoal's rules without its random balls and with discovery's long
    // episodes: π_g's rewards are its goals.
    let env_cfg = EnvConfig {
        balls: BallSpawn::Layout,
        max_steps: 100_000,
        ..EnvConfig::for_task(Task::MultiGoal, &layout)
    };
    let envs = 32;
    let cfg = GcpConfig {
        goal_walk_len: a.goal_moves,
        ..GcpConfig::default()
    };
    // Small networks: one libtorch thread is the fastest.
    tch::set_num_threads(1);
    let mut train_env = InProcess::new(layout.clone(), env_cfg, envs, a.seed, 1)?;
    let mut eval_env = InProcess::new(layout.clone(), env_cfg, envs, a.seed + 10_000, 1)?;
    let num_actions = env_cfg.task.num_actions();
    let mut pi_g = GoalConditionedPolicy::new(&cfg, &layout, envs, num_actions, a.seed)?;

    let before = pi_g.evaluate(&mut eval_env, 10, 200)?;
    println!(
        "{}: greedy success on goals 10 moves away {before:.3}",
        layout.name
    );
    let start = std::time::Instant::now();
    let mut window = Vec::with_capacity(a.every);
    for i in 1..=a.iters {
        window.push(pi_g.train_iteration(&mut train_env, None)?);
        if i % a.every == 0 || i == a.iters {
            let mean = |f: fn(&learner::gcp::GcpStats) -> f64| {
                window.iter().map(f).sum::<f64>() / window.len() as f64
            };
            let greedy = if i % (5 * a.every) == 0 || i == a.iters {
                format!("{:.3}", pi_g.evaluate(&mut eval_env, 10, 200)?)
            } else {
                "-".into()
            };
            println!(
                "iteration {i:5} ({:4.0} s): goal success {:.3}, entropy {:.3} nats, greedy 10-move success {greedy}",
                start.elapsed().as_secs_f64(),
                mean(|s| s.success_rate),
                mean(|s| s.entropy),
            );
            window.clear();
        }
    }
    Ok(())
}
