//! `π_g` steering traversals in MultiGoal-Stochastic (section 4.3) is
//! fine-tuned while the agent trains: its weights move only when it
//! steered, the fine-tuned weights and their optimiser moments go into the
//! agent's checkpoint, and a restored agent trains on exactly as the
//! original.

use learner::batch_env::InProcess;
use learner::gcp::{GcpConfig, GoalConditionedPolicy};
use learner::hrl::{AgentConfig, AgentKind, Candidates, HrlAgent, WorldGraphInputs};
use planner::{CandidateSet, PlannerConfig, WorldGraph};
use sim::{EnvConfig, Maze, Task};
use tch::Tensor;

fn agent(fine_tune: bool) -> HrlAgent {
    let layout = Maze::Small.layout(false);
    let graph = WorldGraph::build(
        &layout,
        &PlannerConfig {
            candidates: CandidateSet::Random { k: 24 },
            seed: 4,
            task: Task::MultiGoal,
            ..PlannerConfig::default()
        },
        &[],
    )
    .expect("graph");
    let gcp = GoalConditionedPolicy::new(&GcpConfig::default(), &layout, 1, 3, 8).expect("π_g");
    let cfg = AgentConfig {
        kind: AgentKind::WideNarrow,
        candidates: Candidates::Random,
        traversal: true,
        envs: 16,
        rollout_len: 24,
        fine_tune_pi_g: fine_tune,
        ..AgentConfig::default()
    };
    HrlAgent::new(
        &cfg,
        &layout,
        Task::MultiGoalStochastic,
        Some(WorldGraphInputs {
            graph: Some(graph),
            gcp: Some(gcp),
        }),
        3,
    )
    .expect("agent")
}

fn env(segment: u64) -> InProcess {
    let layout = Maze::Small.layout(false);
    let cfg = EnvConfig::for_task(Task::MultiGoalStochastic, &layout);
    InProcess::new(layout, cfg, 16, sim::env_seed(3, segment), 1).expect("env")
}

/// `π_g`'s tensors inside a checkpoint of the agent (empty if it keeps none).
fn pi_g_tensors(a: &HrlAgent) -> Vec<(String, Tensor)> {
    let bytes = a.to_bytes().expect("bytes");
    Tensor::load_multi_from_stream(std::io::Cursor::new(bytes))
        .expect("load")
        .into_iter()
        .filter(|(k, _)| k.starts_with("pi_g/"))
        .collect()
}

/// Trains `iterations` of one segment; returns the traversal share.
fn train(a: &mut HrlAgent, segment: u64, iterations: usize) -> f64 {
    let mut e = env(segment);
    a.start_segment(&mut e, segment).expect("segment");
    let mut share = 0.0;
    for _ in 0..iterations {
        share += a
            .train_iteration(&mut e)
            .expect("iteration")
            .traversal_share;
    }
    share / iterations as f64
}

#[test]
fn pi_g_is_fine_tuned_on_the_steps_it_steers_and_checkpointed() {
    let mut a = agent(true);
    let before = pi_g_tensors(&a);
    assert!(!before.is_empty(), "the checkpoint holds π_g");
    let share = train(&mut a, 0, 3);
    assert!(share > 0.0, "π_g steered some steps");
    let after = pi_g_tensors(&a);
    let moved = before
        .iter()
        .zip(&after)
        .filter(|((_, x), (_, y))| !x.equal(y))
        .count();
    assert!(
        moved > before.len() / 2,
        "{moved} of {} tensors moved",
        before.len()
    );

    // A restored agent trains on exactly as the original.
    let mut b = agent(true);
    b.load_bytes(&a.to_bytes().unwrap(), std::path::Path::new("mem"))
        .unwrap();
    train(&mut a, 1, 2);
    train(&mut b, 1, 2);
    for ((k, x), (_, y)) in pi_g_tensors(&a).iter().zip(&pi_g_tensors(&b)) {
        assert!(x.equal(y), "{k} differs after resuming");
    }

    // Without fine-tuning π_g keeps its weights and stays out of the
    // checkpoint.
    let mut c = agent(false);
    assert!(pi_g_tensors(&c).is_empty());
    assert!(train(&mut c, 0, 2) > 0.0);
}
