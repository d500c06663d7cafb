//! Train the goal-conditioned policy `π_g` (section 3.2 of the paper) for
//! 400 A2C iterations in two small rooms: goals are the ends of 4-move random
//! walks, and the greedy policy's success on goals of another seed is
//! measured before and after.
//!
//! `cargo run --release --example train_pi_g`

use learner::batch_env::InProcess;
use learner::gcp::{GcpConfig, GoalConditionedPolicy};
use sim::{BallSpawn, EnvConfig, Layout, Task};

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

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let layout = Layout::parse("two rooms", ROOMS)?;
    // MultiGoal's rules without its random balls: π_g's rewards are its goals.
    let env_cfg = EnvConfig {
        balls: BallSpawn::Layout,
        ..EnvConfig::for_task(Task::MultiGoal, &layout)
    };
    let (envs, seed, walk_len) = (32, 1, 4);
    let cfg = GcpConfig {
        goal_walk_len: walk_len,
        ..GcpConfig::default()
    };
    // Tiny networks: one libtorch thread is the fastest.
    tch::set_num_threads(1);
    let mut train_env = InProcess::new(layout.clone(), env_cfg, envs, seed, 1)?;
    let mut eval_env = InProcess::new(layout.clone(), env_cfg, envs, seed + 10_000, 1)?;
    let num_actions = env_cfg.task.num_actions();
    let mut pi_g = GoalConditionedPolicy::new(&cfg, &layout, envs, num_actions, seed)?;

    let before = pi_g.evaluate(&mut eval_env, walk_len, 200)?;
    for i in 1..=400 {
        // One rollout and one update; no latent model, so no curiosity bonus.
        let stats = pi_g.train_iteration(&mut train_env, None)?;
        if i % 100 == 0 {
            println!(
                "iteration {i}: goal success {:.2}, policy loss {:.3}",
                stats.success_rate, stats.policy_loss
            );
        }
    }
    let after = pi_g.evaluate(&mut eval_env, walk_len, 200)?;
    println!("greedy success on held-out goals: {before:.2} before, {after:.2} after");
    Ok(())
}
