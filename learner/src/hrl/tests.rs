//! Tests of the agent as a whole: its steps' booking and the Worker's
//! view of its goals.

use shm_schemas::EnvMeta;
use sim::{AutoReset, BallSpawn, EnvConfig, Layout, Task};

use super::worker::{WorkerGoal, goal_marks};
use super::*;
use crate::a2c::input::{GoalMarks, NO_GOAL};
use crate::batch_env::{BatchEnvironment, EnvError, InProcess, ObsView};

/// A batch environment that keeps every step record it produced.
struct Recorder {
    env: InProcess,
    steps: Vec<Vec<EnvMeta>>,
}

impl BatchEnvironment for Recorder {
    fn num_envs(&self) -> usize {
        self.env.num_envs()
    }
    fn num_actions(&self) -> usize {
        self.env.num_actions()
    }
    fn observe(&self) -> ObsView<'_> {
        self.env.observe()
    }
    fn step(&mut self, actions: &[u8]) -> Result<(), EnvError> {
        self.env.step(actions)?;
        self.steps.push(self.env.observe().meta.to_vec());
        Ok(())
    }
}

#[test]
fn a_truncated_step_is_bootstrapped_and_a_terminated_one_is_not() {
    // A corridor whose exit is two moves away and a step limit of 3:
    // random actions end episodes both ways.
    let layout = Layout::parse("corridor", "#####\n#>.E#\n#####\n").expect("layout");
    let env_cfg = EnvConfig {
        task: Task::MultiGoal,
        max_steps: 3,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::SameStep,
    };
    let cfg = AgentConfig {
        kind: AgentKind::A2c,
        envs: 8,
        rollout_len: 12,
        hidden: 16,
        conv_channels: [4, 8],
        ..AgentConfig::default()
    };
    let mut agent = HrlAgent::new(&cfg, &layout, Task::MultiGoal, None, 1).expect("agent");
    let mut env = Recorder {
        env: InProcess::new(layout.clone(), env_cfg, 8, 2, 1).expect("env"),
        steps: Vec::new(),
    };
    agent.start_segment(&mut env, 0).expect("segment");
    env.steps.clear();
    // Keep the rollout: the update does not clear it.
    agent.train_iteration(&mut env).expect("iteration");
    let (mut terminated, mut truncated) = (0, 0);
    let gamma = cfg.worker.gamma as f32;
    for (t, metas) in env.steps.iter().enumerate() {
        for (e, m) in metas.iter().enumerate() {
            let i = t * 8 + e;
            let (booked, done) = (
                agent.worker.rollout.rewards[i],
                agent.worker.rollout.dones[i],
            );
            if m.terminated() {
                terminated += 1;
                assert_eq!(booked, m.reward, "a terminated step is not bootstrapped");
                assert_eq!(done, 1.0);
            } else if m.truncated() {
                truncated += 1;
                let bootstrap = booked - m.reward;
                assert!(
                    bootstrap.abs() > 1e-6 && bootstrap.abs() <= gamma * 10.0,
                    "a truncated step adds γ·V(s_final), got {bootstrap}"
                );
                assert_eq!(done, 1.0, "nothing flows back from the next episode");
            } else {
                assert_eq!(booked, m.reward);
                assert_eq!(done, 0.0);
            }
        }
    }
    assert!(
        terminated > 0 && truncated > 0,
        "{terminated} / {truncated}"
    );
}

#[test]
fn the_wide_narrow_worker_sees_which_goal_is_which() {
    let goals = [WorkerGoal::new(5, 9, 1), WorkerGoal::new(9, 5, 1)];
    let marks = goal_marks(AgentKind::WideNarrow, goals.iter());
    assert_eq!(marks, vec![5, 9, 9, 5]);
    let layout = sim::Maze::Small.layout(false);
    let (cells, meta) = (layout.cells.repeat(2), vec![EnvMeta::EMPTY; 2]);
    let obs = ObsView {
        seq: 0,
        cells: &cells,
        final_cells: &[],
        meta: &meta,
        width: layout.width,
        height: layout.height,
    };
    let dense = crate::a2c::input::encode_obs(
        &obs,
        Some(GoalMarks {
            cells: &marks,
            per_env: 2,
        }),
    );
    assert!(
        !dense.get(0).equal(&dense.get(1)),
        "swapping g_w and g_n changes the Worker's input"
    );
    // Once g_w is paid its mark goes.
    let mut paid = WorkerGoal::new(5, 9, 1);
    paid.wide_paid = true;
    let marks = goal_marks(AgentKind::WideNarrow, std::iter::once(&paid));
    assert_eq!(marks, vec![NO_GOAL, 9]);
}
