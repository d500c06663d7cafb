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
    let mut agent = A2cAgent::new(&cfg, &layout, Task::MultiGoal, 1).expect("agent");
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
                agent.learner.rollout.rewards[i],
                agent.learner.rollout.dones[i],
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
    let obs = crate::a2c::input::test_view(&cells, &meta, layout.width, layout.height);
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

/// A corridor nine cells wide: the agent starts on `(1, 1)` facing the
/// exit on `(7, 1)`.
const CORRIDOR: &str = "#########\n#>.....E#\n#########\n";

/// The cell index of `(x, y)` in the corridor.
fn at(x: u32, y: u32) -> u32 {
    y * 9 + x
}

/// A small agent of `kind` over `candidates` for `n` environments.
fn small(kind: AgentKind, candidates: Candidates, n: usize) -> AgentConfig {
    AgentConfig {
        kind,
        candidates,
        envs: n,
        rollout_len: 6,
        horizon: 50,
        hidden: 16,
        conv_channels: [4, 8],
        ..AgentConfig::default()
    }
}

/// `n` corridors of MultiGoal whose episodes the step limit `max_steps`
/// cuts, reset.
fn corridors(n: usize, max_steps: u32) -> InProcess {
    let env_cfg = EnvConfig {
        task: Task::MultiGoal,
        max_steps,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::SameStep,
    };
    let layout = Layout::parse("corridor", CORRIDOR).expect("layout");
    InProcess::new(layout, env_cfg, n, 3, 1).expect("env")
}

/// Gives every environment of `ctl` the goals `(wide, narrow)` as if the
/// Manager had named them with the agent on `here`.
fn hand_goals(ctl: &mut controller::Controller, wide: u32, narrow: u32, here: u32) {
    for c in &mut ctl.envs {
        c.goal = WorkerGoal::new(wide, narrow, here);
        c.need_decision = false;
        c.manager_reset = false;
    }
}

#[test]
fn the_manager_decides_for_every_environment_on_the_first_step() {
    let layout = Layout::parse("corridor", CORRIDOR).expect("layout");
    let n = 4;
    let cfg = small(AgentKind::WideNarrow, Candidates::All, n);
    let mut agent = HrlAgent::new(&cfg, &layout, Task::MultiGoal, None, 5).expect("agent");
    let mut env = corridors(n, 100);
    let mut ctl = agent.controller(n, 11);
    agent.worker.learner.rollout.start(&ctl.worker_state);
    let mut counts = reports::StepCounts::default();
    agent
        .step_batch(&mut ctl, &mut env, true, None, &mut counts)
        .expect("step");
    assert_eq!(counts.decisions, n, "one decision per environment");
    assert_eq!(counts.steps, n as u64);
    let side = agent.window_coverage().expect("WN has a window").side as i64;
    let free: Vec<u32> = (1..8).map(|x| at(x, 1)).collect();
    for (e, c) in ctl.envs.iter().enumerate() {
        let g = c.goal;
        assert!(agent.candidates().contains(&g.wide), "g_w ∈ V: {g:?}");
        assert!(free.contains(&g.narrow), "g_n is a free cell: {g:?}");
        let (dx, dy) = (
            i64::from(g.narrow % 9) - i64::from(g.wide % 9),
            i64::from(g.narrow / 9) - i64::from(g.wide / 9),
        );
        assert!(
            dx.abs() <= side / 2 && dy.abs() <= side / 2,
            "g_n in the window around g_w: {g:?}"
        );
        let queue = &ctl.queues[e].decisions;
        assert_eq!(queue.len(), 1, "the decision joins the training queue");
        assert!(queue[0].reset_before, "the first decision of an episode");
        assert_eq!(
            agent.candidates()[queue[0].wide as usize],
            g.wide,
            "the queue trains the wide goal the Worker got"
        );
    }
}

#[test]
fn the_workers_goal_marks_land_on_the_goal_cells() {
    let layout = Layout::parse("corridor", CORRIDOR).expect("layout");
    let n = 2;
    for (kind, planes) in [(AgentKind::WideNarrow, 2), (AgentKind::Feudal, 1)] {
        let cfg = small(kind, Candidates::All, n);
        let mut agent = HrlAgent::new(&cfg, &layout, Task::MultiGoal, None, 5).expect("agent");
        let mut env = corridors(n, 100);
        let mut ctl = agent.controller(n, 11);
        let (wide, narrow) = (at(6, 1), at(5, 1));
        hand_goals(&mut ctl, wide, narrow, at(1, 1));
        let mut counts = reports::StepCounts::default();
        agent
            .step_batch(&mut ctl, &mut env, false, None, &mut counts)
            .expect("step");
        assert_eq!(counts.decisions, 0, "no decision while the interval runs");
        let marks = agent.worker.goal_marks(ctl.goals());
        let input = agent
            .worker
            .learner
            .input(&env.observe(), agent.worker.marks(&marks))
            .to_dense();
        assert_eq!(
            input.size()[1],
            (crate::a2c::input::BASE_CHANNELS + planes) as i64
        );
        // FN's Worker sees its one subgoal, g_n; WN's g_w and g_n.
        let expected: Vec<u32> = match kind {
            AgentKind::WideNarrow => vec![wide, narrow],
            _ => vec![narrow],
        };
        for e in 0..n as i64 {
            for (k, &goal) in expected.iter().enumerate() {
                let plane = input
                    .get(e)
                    .get((crate::a2c::input::GOAL_CHANNEL + k) as i64)
                    .flatten(0, -1);
                let marked: Vec<f32> = Vec::try_from(&plane).expect("floats");
                let cells: Vec<u32> = (0..marked.len() as u32)
                    .filter(|&c| marked[c as usize] == 1.0)
                    .collect();
                assert_eq!(cells, vec![goal], "{kind:?} goal plane {k}");
            }
        }
    }
}

#[test]
fn an_environment_whose_episode_ends_gets_a_fresh_decision_next_step() {
    let layout = Layout::parse("corridor", CORRIDOR).expect("layout");
    let n = 3;
    let cfg = small(AgentKind::WideNarrow, Candidates::All, n);
    let mut agent = HrlAgent::new(&cfg, &layout, Task::MultiGoal, None, 5).expect("agent");
    // Episodes of two steps; goals five moves away: the first step ends
    // neither the episode nor the interval, the second ends both.
    let mut env = corridors(n, 2);
    let mut ctl = agent.controller(n, 11);
    agent.worker.learner.rollout.start(&ctl.worker_state);
    hand_goals(&mut ctl, at(6, 1), at(6, 1), at(1, 1));
    let mut counts = reports::StepCounts::default();
    agent
        .step_batch(&mut ctl, &mut env, true, None, &mut counts)
        .expect("step");
    assert_eq!((counts.episodes, counts.intervals), (0, 0));
    assert!(ctl.envs.iter().all(|c| !c.need_decision));
    agent
        .step_batch(&mut ctl, &mut env, true, None, &mut counts)
        .expect("step");
    assert_eq!((counts.episodes, counts.intervals), (n, n));
    assert_eq!(counts.decisions, 0);
    for c in &ctl.envs {
        assert!(c.need_decision && c.manager_reset, "a decision is due");
    }
    agent
        .step_batch(&mut ctl, &mut env, true, None, &mut counts)
        .expect("step");
    assert_eq!(
        counts.decisions, n,
        "every environment got a fresh decision"
    );
    for (c, q) in ctl.envs.iter().zip(&ctl.queues) {
        assert!(!c.need_decision);
        let d = q.decisions.last().expect("the new decision");
        assert!(d.reset_before, "the Manager's core starts afresh");
        assert!(!d.complete);
    }
}

/// A WN agent of `cfg` with traversal over the corridor's world graph with
/// `nodes` (cells), on `cfg.envs` corridors (episodes of at most 100
/// steps), its controller and its Worker's rollout started.
fn traversing_agent(
    cfg: &AgentConfig,
    nodes: &[u32],
) -> (HrlAgent, InProcess, controller::Controller) {
    let layout = Layout::parse("corridor", CORRIDOR).expect("layout");
    let planner_cfg = planner::PlannerConfig {
        candidates: planner::CandidateSet::Given,
        edge_search: planner::EdgeSearch::Exhaustive,
        task: Task::MultiGoal,
        ..planner::PlannerConfig::default()
    };
    let nodes: Vec<planner::CellIdx> = nodes.iter().copied().map(planner::CellIdx).collect();
    let graph = planner::WorldGraph::build(&layout, &planner_cfg, &nodes).expect("graph");
    let cfg = AgentConfig {
        traversal: true,
        ..cfg.clone()
    };
    let inputs = WorldGraphInputs {
        graph: Some(graph),
        gcp: None,
    };
    let mut agent = HrlAgent::new(&cfg, &layout, Task::MultiGoal, Some(inputs), 5).expect("agent");
    let env = corridors(cfg.envs, 100);
    let ctl = agent.controller(cfg.envs, 11);
    agent.worker.learner.rollout.start(&ctl.worker_state);
    (agent, env, ctl)
}

#[test]
fn a_traversal_replays_its_route_and_its_steps_are_counted() {
    let n = 2;
    let cfg = small(AgentKind::WideNarrow, Candidates::Pivotal, n);
    let (mut agent, mut env, mut ctl) = traversing_agent(&cfg, &[at(1, 1), at(4, 1)]);
    // The agent stands on a node with a route to g_w: it traverses.
    hand_goals(&mut ctl, at(4, 1), at(5, 1), at(1, 1));
    let mut counts = reports::StepCounts::default();
    for step in 1..=3 {
        agent
            .step_batch(&mut ctl, &mut env, true, None, &mut counts)
            .expect("step");
        let obs = env.observe();
        for e in 0..n {
            assert_eq!(
                obs.meta[e].cell(9) as u32,
                at(1 + step, 1),
                "the route's action is replayed"
            );
        }
        assert_eq!(counts.traversal_steps, u64::from(step) * n as u64);
    }
    assert_eq!(
        agent.worker.learner.rollout.weights,
        vec![0.0; 3 * n],
        "traversal steps are no Worker steps"
    );
    for c in &ctl.envs {
        assert!(c.traversal.is_none(), "arrived at g_w");
        assert!(c.goal.wide_paid);
        assert!(!c.need_decision, "the Worker goes on towards g_n");
    }
    assert_eq!(counts.intervals, 0);
}

/// Traversal steps of the first batch step of an agent on the corridor
/// whose world graph has nodes on `(1, 1)` (the start), `(3, 1)` and
/// `(6, 1)`, given `(g_w, g_n)` = (`wide`, the exit) with
/// `traverse_outside_window` set to `outside` (window side 5).
fn first_step_traversal(wide: u32, outside: bool) -> u64 {
    let cfg = AgentConfig {
        window: 5,
        traverse_outside_window: outside,
        ..small(AgentKind::WideNarrow, Candidates::Pivotal, 2)
    };
    let (mut agent, mut env, mut ctl) = traversing_agent(&cfg, &[at(1, 1), at(3, 1), at(6, 1)]);
    hand_goals(&mut ctl, wide, at(7, 1), at(1, 1));
    let mut counts = reports::StepCounts::default();
    agent
        .step_batch(&mut ctl, &mut env, true, None, &mut counts)
        .expect("step");
    counts.traversal_steps
}

#[test]
fn traversal_outside_the_window_leaves_a_near_wide_goal_to_the_worker() {
    let n = 2;
    // g_w two cells away, inside the 5×5 window around it.
    assert_eq!(
        first_step_traversal(at(3, 1), false),
        n,
        "the paper's rule traverses"
    );
    assert_eq!(
        first_step_traversal(at(3, 1), true),
        0,
        "inside g_w's window the Worker walks"
    );
    // g_w five cells away, outside its window: both traverse.
    assert_eq!(first_step_traversal(at(6, 1), true), n);
    assert_eq!(first_step_traversal(at(6, 1), false), n);
}

/// `traversal_ends_in_window`: from the start `(1, 1)` to `g_w = (6, 1)`
/// the traversal replays east and ends on entering `g_w`'s 5×5 window
/// (`x ≥ 4`), `g_w` counted as reached; the Worker walks on. Off, the same
/// traversal is still under way there.
#[test]
fn a_traversal_that_ends_in_the_window_hands_g_n_to_the_worker_there() {
    let n = 2;
    let under_way_after_three = |ends_in_window: bool| {
        let cfg = AgentConfig {
            window: 5,
            traversal_ends_in_window: ends_in_window,
            ..small(AgentKind::WideNarrow, Candidates::Pivotal, n)
        };
        let (mut agent, mut env, mut ctl) = traversing_agent(&cfg, &[at(1, 1), at(6, 1)]);
        hand_goals(&mut ctl, at(6, 1), at(5, 1), at(1, 1));
        let mut counts = reports::StepCounts::default();
        for _ in 0..3 {
            agent
                .step_batch(&mut ctl, &mut env, true, None, &mut counts)
                .expect("step");
        }
        let obs = env.observe();
        for e in 0..n {
            assert_eq!(obs.meta[e].cell(9) as u32, at(4, 1), "the route replayed");
        }
        assert_eq!(counts.traversal_steps, 3 * n as u64);
        ctl.envs
            .iter()
            .map(|c| (c.traversal.is_some(), c.goal.wide_paid, c.need_decision))
            .collect::<Vec<_>>()
    };
    assert_eq!(
        under_way_after_three(true),
        vec![(false, true, false); n],
        "ended in the window, g_w paid, the interval goes on towards g_n"
    );
    assert_eq!(
        under_way_after_three(false),
        vec![(true, false, false); n],
        "the paper's traversal runs on to g_w"
    );
}

/// An agent of `cfg` on `n` corridors (episodes of at most 100 steps), its
/// controller and its Worker's rollout started, ready to train.
fn corridor_training(cfg: &AgentConfig, n: usize) -> (HrlAgent, InProcess, controller::Controller) {
    let layout = Layout::parse("corridor", CORRIDOR).expect("layout");
    let mut agent = HrlAgent::new(cfg, &layout, Task::MultiGoal, None, 5).expect("agent");
    let ctl = agent.controller(n, 11);
    agent.worker.learner.rollout.start(&ctl.worker_state);
    (agent, corridors(n, 100), ctl)
}

/// The rewards environment `e`'s Manager has booked in this rollout.
fn booked_manager_reward(ctl: &controller::Controller, e: usize) -> f32 {
    ctl.queues[e]
        .decisions
        .iter()
        .flat_map(|d| d.rewards.iter())
        .sum()
}

#[test]
fn the_count_bonus_fades_linearly_to_nothing_over_its_fade_steps() {
    let n = 3;
    let (beta, fade_batches) = (0.5, 6u64);
    let cfg = AgentConfig {
        count_bonus: beta,
        count_bonus_fade: fade_batches * n as u64,
        ..small(AgentKind::WideNarrow, Candidates::All, n)
    };
    let (mut agent, mut env, mut ctl) = corridor_training(&cfg, n);
    let mut counts = reports::StepCounts::default();
    let mut visits = vec![std::collections::HashMap::<u32, u32>::new(); n];
    let (mut expected, mut task_only) = (vec![0f32; n], vec![0f32; n]);
    for step in 1..=12u64 {
        agent
            .step_batch(&mut ctl, &mut env, true, None, &mut counts)
            .expect("step");
        let obs = env.observe();
        // The share of the bonus left after `step` batch steps.
        let left = (1.0 - step as f32 / fade_batches as f32).max(0.0);
        for e in 0..n {
            let v = visits[e].entry(obs.end_cell(e)).or_default();
            *v += 1;
            expected[e] += obs.meta[e].reward + left * beta / (*v as f32).sqrt();
            task_only[e] += obs.meta[e].reward;
        }
    }
    for e in 0..n {
        let booked = booked_manager_reward(&ctl, e);
        assert!(
            (booked - expected[e]).abs() < 1e-4,
            "env {e}: the Manager booked {booked}, the task and the fading bonus {}",
            expected[e]
        );
        assert!(
            booked > task_only[e] + 0.1,
            "env {e}: a bonus was paid before the fade ended"
        );
    }
    // Past the fade, a step pays the task's reward alone.
    let before: Vec<f32> = (0..n).map(|e| booked_manager_reward(&ctl, e)).collect();
    agent
        .step_batch(&mut ctl, &mut env, true, None, &mut counts)
        .expect("step");
    let obs = env.observe();
    for (e, before) in before.iter().enumerate() {
        let after = booked_manager_reward(&ctl, e);
        assert!(
            (after - before - obs.meta[e].reward).abs() < 1e-5,
            "env {e}: a bonus was paid after the fade"
        );
    }
}

#[test]
fn the_count_bonus_pays_the_manager_beta_over_root_visits_and_outlives_a_checkpoint() {
    let n = 3;
    let beta = 0.5;
    let cfg = AgentConfig {
        count_bonus: beta,
        ..small(AgentKind::WideNarrow, Candidates::All, n)
    };
    let (mut agent, mut env, mut ctl) = corridor_training(&cfg, n);
    let mut counts = reports::StepCounts::default();
    let mut visits = vec![std::collections::HashMap::<u32, u32>::new(); n];
    let mut expected = vec![0f32; n];
    for _ in 0..12 {
        agent
            .step_batch(&mut ctl, &mut env, true, None, &mut counts)
            .expect("step");
        let obs = env.observe();
        for (e, sum) in expected.iter_mut().enumerate() {
            let v = visits[e].entry(obs.end_cell(e)).or_default();
            *v += 1;
            *sum += obs.meta[e].reward + beta / (*v as f32).sqrt();
        }
    }
    for (e, sum) in expected.iter().enumerate() {
        let booked = booked_manager_reward(&ctl, e);
        assert!(
            (booked - sum).abs() < 1e-4,
            "env {e}: the Manager booked {booked}, the task and the bonus {sum}"
        );
    }
    assert!(
        visits.iter().any(|v| v.values().any(|&c| c > 1)),
        "some cell was visited twice, so the bonus faded somewhere"
    );
    let saved = ctl.save().expect("save");
    let mut back = agent.controller(n, 0);
    back.restore(
        &saved.record,
        &saved.tensors,
        std::path::Path::new("test"),
        n,
    )
    .expect("restore");
    assert_eq!(back.visits, ctl.visits, "the counts resume with the run");
}

/// A corridor with two balls on the way to the exit.
const BALL_CORRIDOR: &str = "#########\n#>.B.B.E#\n#########\n";

/// One scripted episode that walks the ball corridor east
/// (MultiGoal-Sparse), cut after `max_steps` steps: each step's balls
/// before it ([`controller::balls_before`]) and its record.
fn ball_corridor_walk(max_steps: u32) -> Vec<(u8, EnvMeta)> {
    let layout = Layout::parse("balls", BALL_CORRIDOR).expect("layout");
    let env_cfg = EnvConfig {
        task: Task::MultiGoalSparse,
        max_steps,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::SameStep,
    };
    let mut env = InProcess::new(layout, env_cfg, 1, 3, 1).expect("env");
    let mut out = Vec::new();
    loop {
        let before = controller::balls_before(&env.observe().meta[0]);
        env.step(&[sim::action::FORWARD]).expect("step");
        let m = env.observe().meta[0];
        out.push((before, m));
        if m.done() {
            return out;
        }
    }
}

/// The shaping terms of the records of [`ball_corridor_walk`].
fn shaping_of_walk(weight: f32, gamma: f64, max_steps: u32) -> Vec<(EnvMeta, f32)> {
    ball_corridor_walk(max_steps)
        .into_iter()
        .map(|(before, m)| (m, controller::ball_shaping(weight, gamma, before, &m)))
        .collect()
}

#[test]
fn ball_shaping_pays_each_ball_when_collected_and_keeps_the_optimum() {
    let (weight, gamma) = (0.2, 0.99);
    // Six steps east: two balls, then the exit ends the episode.
    let walk = shaping_of_walk(weight, gamma, 100);
    assert_eq!(walk.len(), 6);
    let last = walk.last().expect("steps").0;
    assert!(
        last.terminated() && last.balls == 2,
        "exited with both balls"
    );
    let sparse: f32 = walk.iter().map(|(m, _)| m.reward).sum();
    assert!(
        sparse > 0.3,
        "Sparse pays the two balls at the exit: {sparse}"
    );
    // Each ball pays about its weight on the step that collects it.
    let mut held = 0;
    for (m, f) in &walk[..5] {
        if m.balls > held {
            assert!(*f > 0.9 * weight, "a ball collected pays {f}");
        } else {
            assert!(f.abs() < 0.01, "a step without a ball pays {f}");
        }
        held = m.balls;
    }
    assert!(
        walk[5].1 < -1.9 * weight,
        "the exit takes the balls' payment back: {}",
        walk[5].1
    );
    // Potential-based: the discounted shaping of an episode the task ended
    // telescopes to Φ(s_0) = 0, so no policy gains or loses by it.
    let discounted: f64 = walk
        .iter()
        .enumerate()
        .map(|(t, (_, f))| gamma.powi(t as i32) * f64::from(*f))
        .sum();
    assert!(discounted.abs() < 1e-5, "discounted shaping {discounted}");
    // An episode the step limit cuts keeps its potential: its value is
    // bootstrapped, so the sum telescopes to γ^T Φ(s_T).
    let cut = shaping_of_walk(weight, gamma, 4);
    let end = cut.last().expect("steps").0;
    assert!(end.truncated() && end.balls == 2);
    let discounted: f64 = cut
        .iter()
        .enumerate()
        .map(|(t, (_, f))| gamma.powi(t as i32) * f64::from(*f))
        .sum();
    let expected = gamma.powi(cut.len() as i32) * f64::from(weight) * 2.0;
    assert!(
        (discounted - expected).abs() < 1e-5,
        "{discounted} against {expected}"
    );
}

/// `agent.worker_ball_reward` counts the balls of the Worker's steps from
/// the simulator's records: one on each step onto a ball, none on the
/// others, none on the exit's step (whose record still holds the episode's
/// balls), and none on a step the limit cuts after the balls.
#[test]
fn the_worker_is_paid_for_the_balls_its_steps_collect_and_no_more() {
    let collected = |max_steps: u32| -> Vec<u8> {
        ball_corridor_walk(max_steps)
            .iter()
            .map(|(before, m)| controller::balls_collected(*before, m))
            .collect()
    };
    // `>.B.B.E`: balls on the 2nd and 4th steps, the exit on the 6th.
    assert_eq!(collected(100), vec![0, 1, 0, 1, 0, 0]);
    assert_eq!(collected(5), vec![0, 1, 0, 1, 0]);
    let mut cfg = AgentConfig {
        worker_ball_reward: -0.1,
        ..AgentConfig::default()
    };
    assert!(cfg.validate().is_err(), "a negative ball reward is refused");
    cfg.worker_ball_reward = 0.2;
    assert!(cfg.validate().is_ok());
}
