//! Stage 2 agents learn (Shang et al. 2019, section 4), on a two-room
//! layout with two random balls per episode, within a CI-sized budget: the
//! A2C baseline raises its mean test return well above the untrained
//! agent's; in Wide-then-Narrow over pivotal states (the doorway and the
//! room centres) with `π_g` initialisation, the Worker learns to reach the
//! Manager's goals.

use learner::batch_env::InProcess;
use learner::gcp::{GcpConfig, GoalConditionedPolicy};
use learner::hrl::{Agent, AgentConfig, AgentKind, Candidates, WorldGraphInputs};
use planner::{CandidateSet, PlannerConfig, WorldGraph};
use sim::{AutoReset, BallSpawn, BatchEnv, EnvConfig, Layout, Task};

const ROOMS: &str = "\
#########
#...#...#
#.>.....#
#...#..E#
#########
";

fn world() -> (Layout, EnvConfig) {
    let layout = Layout::parse("rooms", ROOMS).expect("layout");
    let env = EnvConfig {
        task: Task::MultiGoal,
        max_steps: 60,
        balls: BallSpawn::Random(2),
        auto_reset: AutoReset::SameStep,
    };
    (layout, env)
}

fn test_score(agent: &mut Agent, layout: &Layout, env: EnvConfig) -> f64 {
    let batch = BatchEnv::with_first_index(layout.clone(), env, 0, 64, 77, 1).expect("batch");
    agent
        .evaluate(&mut InProcess::from_batch(batch), 5, None)
        .expect("evaluate")
        .mean_return
}

/// Trains `iterations` updates; returns the share of Manager intervals in
/// which the Worker reached its goal, over the first and the last 50.
fn train(
    agent: &mut Agent,
    layout: &Layout,
    env: EnvConfig,
    seed: u64,
    iterations: usize,
) -> (f64, f64) {
    let mut reached = Vec::new();
    for segment in 0..(iterations / 50) as u64 {
        let mut e =
            InProcess::new(layout.clone(), env, 16, sim::env_seed(seed, segment), 1).expect("env");
        agent.start_segment(&mut e, segment).expect("segment");
        for _ in 0..50 {
            let s = agent.train_iteration(&mut e).expect("iteration");
            reached.push((s.goals_reached * s.intervals as f64, s.intervals as f64));
        }
    }
    let share = |w: &[(f64, f64)]| {
        w.iter().map(|x| x.0).sum::<f64>() / w.iter().map(|x| x.1).sum::<f64>().max(1.0)
    };
    (share(&reached[..50]), share(&reached[reached.len() - 50..]))
}

fn config(kind: AgentKind) -> AgentConfig {
    AgentConfig {
        kind,
        envs: 16,
        rollout_len: 24,
        hidden: 32,
        conv_channels: [8, 16],
        ..AgentConfig::default()
    }
}

#[test]
fn a2c_learns_the_two_rooms() {
    tch::set_num_threads(1);
    let (layout, env) = world();
    let mut agent =
        Agent::new(&config(AgentKind::A2c), &layout, Task::MultiGoal, None, 2).expect("agent");
    let before = test_score(&mut agent, &layout, env);
    let _ = train(&mut agent, &layout, env, 2, 400);
    let after = test_score(&mut agent, &layout, env);
    eprintln!("A2C on two rooms: mean test return {before:.3} → {after:.3}");
    assert!(
        after > before + 0.8 && after > 1.0,
        "{before:.3} → {after:.3}"
    );
}

#[test]
fn the_wide_then_narrow_worker_learns_to_reach_the_managers_goals() {
    tch::set_num_threads(1);
    let (layout, env) = world();
    // π_g, briefly trained on the layout's geometry.
    let gcp_cfg = GcpConfig {
        conv_channels: [8, 16],
        hidden: 32,
        goal_walk_len: 4,
        ..GcpConfig::default()
    };
    let walk_env = EnvConfig {
        balls: BallSpawn::Layout,
        max_steps: 200,
        ..env
    };
    let mut gcp = GoalConditionedPolicy::new(&gcp_cfg, &layout, 16, 3, 4).expect("π_g");
    let mut e = InProcess::new(layout.clone(), walk_env, 16, 4, 1).expect("env");
    for _ in 0..150 {
        gcp.train_iteration(&mut e, None).expect("π_g iteration");
    }
    // V_p: the doorway and one cell in each room.
    let cells = [
        layout.cell_index(4, 2),
        layout.cell_index(2, 2),
        layout.cell_index(6, 2),
    ];
    let nodes = planner::pivotal::nodes_from_cells(&layout, &cells.map(|c| c as u32));
    let pcfg = PlannerConfig {
        candidates: CandidateSet::Given,
        seed: 4,
        task: Task::MultiGoal,
        ..PlannerConfig::default()
    };
    let graph = WorldGraph::build(&layout, &pcfg, &nodes).expect("graph");
    let cfg = AgentConfig {
        candidates: Candidates::Pivotal,
        init_from_gcp: true,
        window: 3,
        ..config(AgentKind::WideNarrow)
    };
    let inputs = WorldGraphInputs {
        graph: Some(graph),
        gcp: Some(gcp),
    };
    let mut agent = Agent::new(&cfg, &layout, Task::MultiGoal, Some(inputs), 3).expect("agent");
    assert!(agent.init_report().is_some_and(|r| !r.copied.is_empty()));
    let before = test_score(&mut agent, &layout, env);
    let (first, last) = train(&mut agent, &layout, env, 3, 300);
    let after = test_score(&mut agent, &layout, env);
    eprintln!(
        "WN + V_p + π_g init on two rooms: Worker reaches its goal in {first:.3} → {last:.3} of the intervals; mean test return {before:.3} → {after:.3}"
    );
    // The Worker learns the Manager's goals (it reaches them half again as
    // often, or more), and with `π_g`'s initialisation on the structure
    // (its unseen ball plane as floor, its goal plane in `g_n`'s) the task
    // return rises within this budget too; with the old initialisation it
    // did not (docs/notes/2026-12-01-stage2-findings.md).
    assert!(last > 1.5 * first, "goals reached {first:.3} → {last:.3}");
    assert!(
        after > before + 0.5,
        "mean test return {before:.3} → {after:.3}"
    );
}
