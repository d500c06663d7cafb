//! World graph traversal (Shang et al. 2019, section 4.3).
//!
//! 1. **When to traverse:** "When a Worker is given a goal pair
//!    `(g_w, g_n)`, it can traverse the world via `G_w` if it encounters a
//!    pivotal state `g_w'` that has a feasible connection to `g_w`", and it
//!    has not reached `g_w` yet in the current Manager interval
//!    ([`Traversal::plan`]).
//! 2. **Planning:** the route is the dynamic programme's shortest path over
//!    the edge weights (the planner's all-pairs tables, [`WorldGraph`]).
//! 3. **Execution:** in deterministic worlds the agent replays the edges'
//!    actions ([`Execution::Replay`]); a route through a door that is closed
//!    or locked *now* is not taken, so the Manager has to plan around it
//!    (Door-Key). In stochastic worlds `π_g` steers edge by edge towards the
//!    next node, and "if the agent fails to reach the next target pivotal
//!    state within a certain time limit, it would simply stop its current
//!    pursuit" ([`Execution::Steer`], limit [`edge_time_limit`]).
//!
//! Every traversal step is a real environment step: the caller sends
//! [`Traversal::next_action`] to the environment, and books the step's
//! rewards for the Manager. A replayed action whose outcome differs from the
//! recorded one (a world that changed under the route) ends the traversal.
//!
//! Inside the agent, `Traverser` runs the traversals of a batch: it starts
//! them (`Traverser::try_start`), chooses their actions — replayed, or
//! steered by `π_g` and recorded for its fine-tuning ([`super::steering`])
//! — and books their steps ([`book_step`]).

use planner::{CellIdx, NodeId, Route, WorldGraph};
use sim::{Object, ReplayRng, Task, action};
use tch::nn;

use super::config::AgentConfig;
use super::steering::{Leg, Steering};
use super::wide_narrow::Window;
use super::worker::WorkerGoal;
use crate::a2c::input::{NO_GOAL, mask};
use crate::a2c::net::LstmState;
use crate::batch_env::ObsView;
use crate::error::{ConfigError, LearnerError};
use crate::gcp::GoalConditionedPolicy;

/// How a route is executed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Execution {
    /// Replay the edges' recorded actions (deterministic tasks).
    Replay,
    /// `π_g` steers towards each next node (MultiGoal-Stochastic).
    Steer,
}

/// Steps `π_g` may take on an edge of weight `w` before the pursuit stops:
/// twice the recorded path plus a margin for the turns at its ends.
pub fn edge_time_limit(weight: u32) -> u32 {
    2 * weight + 4
}

/// What a step did to a traversal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// Still under way.
    Continue,
    /// The agent stands on the target node.
    Arrived,
    /// Stopped short: a time limit, a replay that went astray, or the
    /// episode ended.
    Stopped,
}

/// One traversal under way.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Traversal {
    execution: Execution,
    /// The target cell `g_w`.
    target: u32,
    /// The target is an object the agent acts on (a key, a closed door):
    /// the route ends on the cell in front of it, facing it.
    stops_in_front: bool,
    /// Replay: the actions and the cell after each.
    actions: Vec<u8>,
    cells: Vec<u32>,
    next: usize,
    /// Steer: the nodes still to reach (cells), the time limit of each edge.
    waypoints: Vec<u32>,
    limits: Vec<u32>,
    leg: usize,
    leg_steps: u32,
    /// Actions taken.
    steps: u32,
}

/// True when the observed `grid` blocks the agent from entering `cell`:
/// a door that is not open, or a key lying there (the world graph is found
/// on the maze's structure, [`sim::Layout::structural`], so its routes pass
/// doors and keys' cells).
fn blocked(grid: &[u8], cell: u32) -> bool {
    Object::from_code(grid[cell as usize]).is_some_and(Object::is_acted_on)
}

impl Traversal {
    /// Plans a traversal for environment `env` of `obs` towards the wide
    /// goal `target`: only when the agent stands on a node of `graph` other
    /// than `target`, `target` is a node, the graph has a path, and (for
    /// replay) no door on the route is closed or locked now. `route` is the
    /// caller's scratch buffer.
    pub fn plan(
        graph: &WorldGraph,
        obs: &ObsView<'_>,
        env: usize,
        target: u32,
        execution: Execution,
        route: &mut Route,
    ) -> Option<Traversal> {
        let m = &obs.meta[env];
        let here = CellIdx::from_xy(m.x as usize, m.y as usize, obs.width);
        if here.0 == target {
            return None;
        }
        let from = graph.node_at(here)?;
        let to = graph.node_at(CellIdx(target))?;
        let grid = obs.env_cells(env);
        let world = graph.observe_world(grid, m.carrying);
        graph
            .route_in_world_into(from, m.dir, to, world, route)
            .ok()?;
        if route.is_empty() {
            return None;
        }
        match execution {
            Execution::Replay => {
                // A route through a cell blocked now (a closed door, the
                // key) is not taken (section 4.3, "Execution"); one that
                // ends on the blocked target stops in front of it, facing
                // it, so the Worker can act on it (object goals).
                let mut cells: Vec<u32> = route.cells().iter().map(|c| c.0).collect();
                let mut actions = route.actions().to_vec();
                let stops_in_front = blocked(grid, target);
                if stops_in_front {
                    while cells.last() == Some(&target) {
                        cells.pop();
                        actions.pop();
                    }
                }
                if actions.is_empty() || cells.iter().any(|&c| blocked(grid, c)) {
                    return None;
                }
                Some(Traversal {
                    execution,
                    target,
                    stops_in_front,
                    actions,
                    cells,
                    next: 0,
                    waypoints: Vec::new(),
                    limits: Vec::new(),
                    leg: 0,
                    leg_steps: 0,
                    steps: 0,
                })
            }
            Execution::Steer => {
                let nodes: Vec<NodeId> = route.nodes().to_vec();
                let waypoints: Vec<u32> = nodes[1..]
                    .iter()
                    .map(|n| graph.nodes()[n.index()].0)
                    .collect();
                let limits = nodes
                    .windows(2)
                    .map(|w| edge_time_limit(graph.edge(w[0], w[1]).map_or(1, |e| e.weight())))
                    .collect();
                Some(Traversal {
                    execution,
                    target,
                    stops_in_front: false,
                    actions: Vec::new(),
                    cells: Vec::new(),
                    next: 0,
                    waypoints,
                    limits,
                    leg: 0,
                    leg_steps: 0,
                    steps: 0,
                })
            }
        }
    }

    /// How it is executed.
    pub fn execution(&self) -> Execution {
        self.execution
    }

    /// The target cell `g_w`.
    pub fn target(&self) -> u32 {
        self.target
    }

    /// True when the route ends in front of its target, an object to act
    /// on, rather than on it.
    pub fn stops_in_front(&self) -> bool {
        self.stops_in_front
    }

    /// Actions taken so far.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Replay: the next recorded action.
    pub fn next_action(&self) -> Option<u8> {
        self.actions.get(self.next).copied()
    }

    /// Steer: the node `π_g` heads for now (its goal cell).
    pub fn waypoint(&self) -> Option<u32> {
        self.waypoints.get(self.leg).copied()
    }

    /// Steer: the index of the edge under way (its waypoint's position
    /// in the route).
    pub fn leg(&self) -> usize {
        self.leg
    }

    /// True when a new edge starts with the next step (`π_g`'s core state
    /// is then reset: each edge is a goal episode of its own).
    pub fn leg_starts(&self) -> bool {
        self.leg_steps == 0
    }

    /// Books the step just taken; `cell` is where its action led the agent
    /// (on a step that ended the environment's episode, the finished
    /// episode's final cell: [`ObsView::end_cell`]) and `episode_ended`
    /// whether the episode ended. A route that reaches its target on the
    /// episode's last step has arrived; otherwise the episode's end stops it.
    pub fn advance(&mut self, cell: u32, episode_ended: bool) -> Progress {
        self.steps += 1;
        let progress = self.progress(cell);
        match progress {
            Progress::Continue if episode_ended => Progress::Stopped,
            p => p,
        }
    }

    fn progress(&mut self, cell: u32) -> Progress {
        match self.execution {
            Execution::Replay => {
                let expected = self.cells[self.next];
                self.next += 1;
                if cell != expected {
                    Progress::Stopped
                } else if self.next == self.actions.len() {
                    if cell == self.target || self.stops_in_front {
                        Progress::Arrived
                    } else {
                        Progress::Stopped
                    }
                } else {
                    Progress::Continue
                }
            }
            Execution::Steer => {
                self.leg_steps += 1;
                if Some(cell) == self.waypoint() {
                    self.leg += 1;
                    self.leg_steps = 0;
                    if self.leg == self.waypoints.len() {
                        return Progress::Arrived;
                    }
                    Progress::Continue
                } else if self.leg_steps >= self.limits[self.leg] {
                    Progress::Stopped
                } else {
                    Progress::Continue
                }
            }
        }
    }
}

/// What a traversal step did to its environment's interval
/// ([`book_step`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TraversalStep {
    /// The interval is over: the traversal arrived on `g_n`, or it ended
    /// after the horizon `c`.
    pub interval_over: bool,
    /// The traversal arrived on `g_n`.
    pub reached: bool,
    /// How the step went for `π_g`'s fine-tuning ([`Leg::Idle`] unless it
    /// was steered).
    pub leg: Leg,
}

/// Books a traversal step that led the agent to `cell` (`episode_ended`:
/// the step ended the episode) for the traversal under way in `slot` and
/// the Worker's `goal` of the interval (horizon `horizon`); `leg_before`:
/// the leg a steered traversal was on before the step; `near`: the narrow
/// window whose entry around `g_w` counts as arriving
/// ([`super::config::AgentConfig::traversal_ends_in_window`]). Arriving
/// pays `g_w` (the Worker does not take it again) and ends the traversal;
/// so does stopping short.
pub fn book_step(
    slot: &mut Option<Traversal>,
    goal: &mut WorkerGoal,
    cell: u32,
    episode_ended: bool,
    horizon: u32,
    leg_before: Option<usize>,
    near: Option<&Window>,
) -> TraversalStep {
    goal.moved_to(cell);
    let t = slot.as_mut().expect("a traversal under way");
    let mut progress = t.advance(cell, episode_ended);
    if progress == Progress::Continue
        && !t.stops_in_front()
        && near.is_some_and(|w| w.slot_of(goal.wide, cell).is_some())
    {
        progress = Progress::Arrived;
    }
    let leg = match leg_before {
        None => Leg::Idle,
        Some(before) => match progress {
            Progress::Continue if t.leg() > before => Leg::Reached,
            Progress::Continue => Leg::Going,
            Progress::Arrived => Leg::Reached,
            Progress::Stopped => Leg::Ended,
        },
    };
    let mut step = TraversalStep {
        interval_over: false,
        reached: false,
        leg,
    };
    match progress {
        Progress::Continue => {}
        Progress::Arrived => {
            // In front of an object goal, `g_w` is paid when the Worker
            // acts on it.
            if !t.stops_in_front() {
                goal.wide_paid = true;
            }
            *slot = None;
            if cell == goal.narrow {
                step.interval_over = true;
                step.reached = true;
            }
            step.interval_over |= goal.steps >= horizon;
        }
        Progress::Stopped => {
            *slot = None;
            step.interval_over |= goal.steps >= horizon;
        }
    }
    step
}

/// What `π_g` steers towards in each environment ([`steer_targets`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SteerTargets {
    /// The waypoint of each environment's traversal (`NO_GOAL` where none
    /// is steered).
    pub goals: Vec<u32>,
    /// Whether its core state starts afresh (a new edge begins).
    pub fresh: Vec<bool>,
}

/// What `π_g` steers towards under the traversals under way, by
/// environment.
pub fn steer_targets(traversals: &[Option<&Traversal>]) -> SteerTargets {
    let (goals, fresh) = traversals
        .iter()
        .map(|t| match t {
            Some(t) => (t.waypoint().unwrap_or(NO_GOAL), t.leg_starts()),
            None => (NO_GOAL, false),
        })
        .unzip();
    SteerTargets { goals, fresh }
}

/// Runs the world graph traversals of a batch: the graph (with
/// traversal), how routes are executed, `π_g` (which steers them in
/// stochastic worlds) and its fine-tuning.
#[derive(Debug)]
pub(super) struct Traverser {
    /// The graph traversal follows (`None`: no traversal).
    graph: Option<WorldGraph>,
    /// `π_g` of stage 1.
    pi_g: Option<GoalConditionedPolicy>,
    execution: Execution,
    /// `π_g`'s fine-tuning while it steers traversals (training only).
    steering: Option<Steering>,
    /// Scratch buffer of the planner.
    route: Route,
    /// No traversal starts while the agent stands in the narrow window
    /// around `g_w` ([`AgentConfig::traverse_outside_window`]).
    window: Option<Window>,
    /// A traversal ends on entering that window
    /// ([`AgentConfig::traversal_ends_in_window`]).
    end_in_window: bool,
}

impl Traverser {
    /// Traversals over `graph` (with `cfg.traversal`) for `task`, steered
    /// by `pi_g` in MultiGoal-Stochastic (which needs it there) and
    /// fine-tuned as `cfg` says, for `cfg.envs` environments.
    pub(super) fn new(
        cfg: &AgentConfig,
        task: Task,
        graph: Option<WorldGraph>,
        pi_g: Option<GoalConditionedPolicy>,
    ) -> Result<Traverser, LearnerError> {
        let execution = if task == Task::MultiGoalStochastic {
            Execution::Steer
        } else {
            Execution::Replay
        };
        if cfg.traversal && execution == Execution::Steer && pi_g.is_none() {
            return Err(ConfigError::new(
                "traversal",
                "MultiGoal-Stochastic traversal is steered by π_g: give a discovery run",
            )
            .into());
        }
        let steering = match &pi_g {
            Some(gcp) if cfg.traversal && execution == Execution::Steer && cfg.fine_tune_pi_g => {
                Some(Steering::new(
                    gcp,
                    cfg.envs,
                    cfg.grad_path,
                    cfg.goal_reward,
                    cfg.step_penalty,
                ))
            }
            _ => None,
        };
        Ok(Traverser {
            graph: if cfg.traversal { graph } else { None },
            pi_g,
            execution,
            steering,
            route: Route::with_capacity(1024, 64),
            window: None,
            end_in_window: false,
        })
    }

    /// Starts no traversal while the agent stands in `window` around `g_w`
    /// ([`AgentConfig::traverse_outside_window`]), and with `end_inside`
    /// ends each on entering it ([`AgentConfig::traversal_ends_in_window`]).
    pub(super) fn start_outside(&mut self, window: Window, end_inside: bool) {
        self.window = Some(window);
        self.end_in_window = end_inside;
    }

    /// The window whose entry ends a traversal, if any ([`book_step`]).
    pub(super) fn end_window(&self) -> Option<&Window> {
        self.window.as_ref().filter(|_| self.end_in_window)
    }

    /// The world graph traversal follows (`None`: no traversal).
    pub(super) fn graph(&self) -> Option<&WorldGraph> {
        self.graph.as_ref()
    }

    /// `π_g` of stage 1.
    pub(super) fn pi_g(&self) -> Option<&GoalConditionedPolicy> {
        self.pi_g.as_ref()
    }

    /// `π_g`'s weights while they are fine-tuned (a checkpoint's).
    pub(super) fn fine_tuned(&self) -> Option<&nn::VarStore> {
        self.pi_g
            .as_ref()
            .filter(|_| self.steering.is_some())
            .map(GoalConditionedPolicy::var_store)
    }

    /// `π_g`'s fine-tuning, if on.
    pub(super) fn steering(&self) -> Option<&Steering> {
        self.steering.as_ref()
    }

    /// `π_g`'s fine-tuning, to restore a checkpoint.
    pub(super) fn steering_mut(&mut self) -> Option<&mut Steering> {
        self.steering.as_mut()
    }

    /// Starts a traversal for environment `e` of `obs` into `slot` if the
    /// agent stands on a node with a route to its wide goal (of `goal`),
    /// no traversal is under way and `g_w` is not paid for yet (and, with
    /// [`Traverser::start_outside`], the agent stands outside the window
    /// around `g_w`).
    pub(super) fn try_start(
        &mut self,
        goal: &WorkerGoal,
        slot: &mut Option<Traversal>,
        obs: &ObsView<'_>,
        e: usize,
    ) -> bool {
        let Some(graph) = &self.graph else {
            return false;
        };
        if slot.is_some() || goal.wide_paid || goal.wide == NO_GOAL {
            return false;
        }
        if let Some(window) = &self.window {
            let m = &obs.meta[e];
            let here = CellIdx::from_xy(m.x as usize, m.y as usize, obs.width).0;
            if window.slot_of(goal.wide, here).is_some() {
                return false;
            }
        }
        match Traversal::plan(graph, obs, e, goal.wide, self.execution, &mut self.route) {
            Some(t) => {
                *slot = Some(t);
                true
            }
            None => false,
        }
    }

    /// Sets `actions` of the environments under `traversals`: the recorded
    /// action (replay) or `π_g`'s step towards the next node (steer, from
    /// `steer_state`, which it advances): sampled with `rng` and recorded
    /// for its fine-tuning when `train` and fine-tuning is on, greedy
    /// otherwise. Returns whether the step was recorded.
    pub(super) fn actions(
        &mut self,
        traversals: &[Option<&Traversal>],
        steer_state: &mut Option<LstmState>,
        rng: &mut ReplayRng,
        obs: &ObsView<'_>,
        actions: &mut [u8],
        train: bool,
    ) -> Result<bool, LearnerError> {
        let mut steer = false;
        let mut recorded = false;
        for (e, t) in traversals.iter().enumerate() {
            if let Some(t) = t {
                match t.execution() {
                    Execution::Replay => {
                        actions[e] = t
                            .next_action()
                            .expect("a traversal under way has an action")
                    }
                    Execution::Steer => steer = true,
                }
            }
        }
        if steer {
            let gcp = self.pi_g.as_mut().expect("steered traversal has π_g");
            let targets = steer_targets(traversals);
            let state = steer_state
                .as_ref()
                .expect("steer state")
                .reset_done(&mask(&targets.fresh));
            let (chosen, next) = match self.steering.as_mut().filter(|_| train) {
                Some(steering) => {
                    let (logits, next) = steering.act(gcp, obs, &targets.goals, &state);
                    let probs = tch::no_grad(|| logits.softmax(-1, tch::Kind::Float));
                    recorded = true;
                    (crate::seeding::sample_categorical(rng, &probs, false), next)
                }
                None => gcp.greedy_step(obs, &targets.goals, &state).map_err(|e| {
                    LearnerError::Checkpoint {
                        path: "π_g".into(),
                        message: e.to_string(),
                    }
                })?,
            };
            *steer_state = Some(next);
            for (e, t) in traversals.iter().enumerate() {
                if t.is_some_and(|t| t.execution() == Execution::Steer) {
                    // π_g was trained on the navigation actions.
                    actions[e] = chosen[e].min(action::FORWARD);
                }
            }
        }
        Ok(recorded)
    }

    /// Books the outcome of a steered step (of [`Self::actions`]) for
    /// `π_g`'s fine-tuning: `actions` where a leg was under way.
    pub(super) fn book_steered(&mut self, actions: &[u8], legs: &[Leg]) {
        if let Some(s) = self.steering.as_mut() {
            let steer_actions: Vec<u8> = actions
                .iter()
                .zip(legs)
                .map(|(&a, &l)| if l == Leg::Idle { 0 } else { a })
                .collect();
            s.book(&steer_actions, legs);
        }
    }

    /// Starts `π_g`'s fine-tuning rollout of a training iteration from
    /// `state`.
    pub(super) fn start_fine_tuning(&mut self, state: Option<&LstmState>) {
        if let (Some(s), Some(state)) = (self.steering.as_mut(), state) {
            s.start(state);
        }
    }

    /// `π_g`'s update after a training iteration, bootstrapped at `obs`
    /// under `traversals` from `state`. (Environments not steering
    /// bootstrap nothing: their last recorded step ended its goal
    /// episode.)
    pub(super) fn fine_tune(
        &mut self,
        obs: &ObsView<'_>,
        traversals: &[Option<&Traversal>],
        state: Option<&LstmState>,
    ) {
        if let (Some(s), Some(gcp), Some(state)) =
            (self.steering.as_mut(), self.pi_g.as_ref(), state)
        {
            let targets = steer_targets(traversals);
            s.update(
                gcp,
                obs,
                &targets.goals,
                &state.reset_done(&mask(&targets.fresh)),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner::{CandidateSet, PlannerConfig};
    use shm_schemas::EnvMeta;
    use sim::{AutoReset, BallSpawn, Env, EnvConfig, Layout, Maze, Task};

    fn graph(layout: &Layout, task: Task, k: usize) -> WorldGraph {
        let cfg = PlannerConfig {
            candidates: CandidateSet::Random { k },
            seed: 3,
            walks_per_node: 256,
            walk_len: 256,
            task,
            ..PlannerConfig::default()
        };
        WorldGraph::build(layout, &cfg, &[]).expect("graph")
    }

    fn env_at(layout: &Layout, task: Task, cell: u32, dir: u8) -> Env {
        let cfg = EnvConfig {
            task,
            max_steps: 100_000,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::Off,
        };
        let mut env = Env::new(layout.clone(), cfg, 1, 0);
        env.teleport(sim::Pose {
            x: (cell as usize % layout.width) as u16,
            y: (cell as usize / layout.width) as u16,
            dir,
        });
        env
    }

    fn view<'a>(layout: &Layout, cells: &'a [u8], meta: &'a [EnvMeta]) -> ObsView<'a> {
        ObsView {
            seq: 0,
            cells,
            final_cells: &[],
            meta,
            width: layout.width,
            height: layout.height,
        }
    }

    #[test]
    fn every_route_on_every_embedded_maze_replays_to_its_target() {
        for maze in Maze::ALL {
            let layout = maze.layout(false);
            let g = graph(&layout, Task::MultiGoal, 12);
            let mut route = Route::default();
            let nodes: Vec<u32> = g.nodes().iter().map(|c| c.0).collect();
            let mut planned = 0;
            for &from in &nodes {
                for &to in &nodes {
                    let mut env = env_at(&layout, Task::MultiGoal, from, (from % 4) as u8);
                    let (mut cells, mut meta) = (vec![0u8; layout.cells.len()], [EnvMeta::EMPTY]);
                    let mut finals = vec![0u8; layout.cells.len()];
                    env.observe(&mut cells, &mut meta[0]);
                    let t = Traversal::plan(
                        &g,
                        &view(&layout, &cells, &meta),
                        0,
                        to,
                        Execution::Replay,
                        &mut route,
                    );
                    let reachable = g.distance(
                        g.node_at(CellIdx(from)).expect("node"),
                        g.node_at(CellIdx(to)).expect("node"),
                    ) != planner::UNREACHABLE;
                    let Some(mut t) = t else {
                        assert!(
                            from == to || !reachable,
                            "{}: the graph has a path {from} → {to} but no route was planned",
                            layout.name
                        );
                        continue;
                    };
                    planned += 1;
                    loop {
                        let a = t.next_action().expect("an action while under way");
                        env.step(a, &mut cells, &mut finals, &mut meta[0]);
                        match t.advance(env.cell() as u32, meta[0].done()) {
                            Progress::Continue => {}
                            Progress::Arrived => break,
                            Progress::Stopped => {
                                panic!("{}: route {from} → {to} went astray", layout.name)
                            }
                        }
                    }
                    assert_eq!(env.cell() as u32, to);
                }
            }
            // Random walks join most pairs of the 12 nodes.
            assert!(
                planned >= nodes.len() * (nodes.len() - 1) / 2,
                "{}: {planned} routes",
                layout.name
            );
        }
    }

    #[test]
    fn a_route_through_a_locked_door_is_refused_until_the_door_is_open() {
        // A corridor split by a closed door: walks open it (toggle) and
        // record an edge through it.
        let layout = Layout::parse("door", "#########\n#>..C..E#\n#########\n").expect("layout");
        let door = layout.cell_index(4, 1) as u32;
        let (left, right) = (door - 1, door + 1);
        let cfg = PlannerConfig {
            candidates: CandidateSet::Given,
            seed: 1,
            task: Task::DoorKey,
            ..PlannerConfig::default()
        };
        let nodes = planner::pivotal::nodes_from_cells(&layout, &[left, right]);
        let g = WorldGraph::build(&layout, &cfg, &nodes).expect("graph");
        let mut route = Route::default();
        let env = env_at(&layout, Task::DoorKey, left, 0);
        let (mut cells, mut meta) = (vec![0u8; layout.cells.len()], [EnvMeta::EMPTY]);
        let mut finals = vec![0u8; layout.cells.len()];
        env.observe(&mut cells, &mut meta[0]);
        let plan = |cells: &[u8], route: &mut Route| {
            Traversal::plan(
                &g,
                &view(&layout, cells, &meta),
                0,
                right,
                Execution::Replay,
                route,
            )
        };
        for shut in [Object::DoorClosed, Object::DoorLocked] {
            let mut grid = cells.clone();
            grid[door as usize] = shut as u8;
            assert!(plan(&grid, &mut route).is_none(), "the door is {shut:?}");
        }
        // Once the door is open the route is taken, through the door, and
        // replays to the other side.
        let mut open = cells.clone();
        open[door as usize] = Object::DoorOpen as u8;
        let mut t = plan(&open, &mut route).expect("a route once the door is open");
        assert!(t.cells.contains(&door));
        let mut env = env_at(&layout, Task::DoorKey, left, 0);
        env.step(sim::action::RIGHT, &mut cells, &mut finals, &mut meta[0]);
        env.step(sim::action::LEFT, &mut cells, &mut finals, &mut meta[0]);
        // Open the real door (toggle while facing it), then follow the route.
        env.step(sim::action::TOGGLE, &mut cells, &mut finals, &mut meta[0]);
        assert_eq!(cells[door as usize], Object::DoorOpen as u8);
        while let Some(a) = t.next_action() {
            env.step(a, &mut cells, &mut finals, &mut meta[0]);
            if t.advance(env.cell() as u32, meta[0].done()) != Progress::Continue {
                break;
            }
        }
        assert_eq!(env.cell() as u32, right);
    }

    /// The world graph of the small Door-Key maze, found on its structure
    /// (the door passable, no key): the route through the door exists, is
    /// refused while the door is locked and taken once it is open; a route
    /// to the key stops in front of it, facing it, so a pickup takes it.
    #[test]
    fn one_graph_serves_door_key_its_door_route_waits_for_the_door_and_the_key_route_faces_the_key()
    {
        let dk = Maze::Small.layout(true);
        let at = |x, y| dk.cell_index(x, y) as u32;
        let (left, right, door, key) = (at(4, 9), at(8, 9), at(6, 9), at(9, 2));
        let cfg = PlannerConfig {
            candidates: CandidateSet::Given,
            seed: 3,
            task: Task::MultiGoal,
            ..PlannerConfig::default()
        };
        let structure = dk.structural();
        let nodes = planner::pivotal::nodes_from_cells(&structure, &[left, right, key]);
        let g = WorldGraph::build(&structure, &cfg, &nodes).expect("graph");
        let mut route = Route::default();
        let mut env = env_at(&dk, Task::DoorKey, left, 0);
        let (mut cells, mut meta) = (vec![0u8; dk.cells.len()], [EnvMeta::EMPTY]);
        let mut finals = vec![0u8; dk.cells.len()];
        env.observe(&mut cells, &mut meta[0]);
        let plan = |cells: &[u8], meta: &[EnvMeta], target: u32, route: &mut Route| {
            Traversal::plan(
                &g,
                &view(&dk, cells, meta),
                0,
                target,
                Execution::Replay,
                route,
            )
        };
        assert_eq!(cells[door as usize], Object::DoorLocked as u8);
        assert!(
            plan(&cells, &meta, right, &mut route).is_none(),
            "the door is locked"
        );
        // The same route once the door is open: through the door cell.
        let mut open = cells.clone();
        open[door as usize] = Object::DoorOpen as u8;
        let through = plan(&open, &meta, right, &mut route).expect("a route once the door is open");
        assert!(through.cells.contains(&door) && !through.stops_in_front());
        // To the key: the route ends in front of it, facing it.
        let mut t = plan(&cells, &meta, key, &mut route).expect("a route to the key");
        assert!(t.stops_in_front() && !t.cells.contains(&key));
        let mut arrived = false;
        while let Some(a) = t.next_action() {
            env.step(a, &mut cells, &mut finals, &mut meta[0]);
            match t.advance(env.cell() as u32, meta[0].done()) {
                Progress::Continue => {}
                p => {
                    arrived = p == Progress::Arrived;
                    break;
                }
            }
        }
        assert!(
            arrived,
            "the replay follows the route to the cell before the key"
        );
        env.step(sim::action::PICKUP, &mut cells, &mut finals, &mut meta[0]);
        assert_eq!(
            meta[0].carrying,
            Object::Key as u8,
            "facing the key, pickup takes it"
        );
        assert_eq!(cells[key as usize], Object::Floor as u8);
    }

    #[test]
    fn steered_traversal_stops_at_its_time_limit() {
        let layout = Maze::Small.layout(false);
        let g = graph(&layout, Task::MultiGoal, 10);
        let nodes: Vec<u32> = g.nodes().iter().map(|c| c.0).collect();
        let mut route = Route::default();
        let (from, to) = (nodes[0], nodes[nodes.len() - 1]);
        let mut env = env_at(&layout, Task::MultiGoal, from, 0);
        let (mut cells, mut meta) = (vec![0u8; layout.cells.len()], [EnvMeta::EMPTY]);
        let mut finals = vec![0u8; layout.cells.len()];
        env.observe(&mut cells, &mut meta[0]);
        let mut t = Traversal::plan(
            &g,
            &view(&layout, &cells, &meta),
            0,
            to,
            Execution::Steer,
            &mut route,
        )
        .expect("a route");
        let limit = t.limits[0];
        // A steering policy that only turns never reaches the first node.
        let mut steps = 0;
        loop {
            env.step(sim::action::LEFT, &mut cells, &mut finals, &mut meta[0]);
            steps += 1;
            match t.advance(env.cell() as u32, false) {
                Progress::Continue => assert!(steps < limit),
                Progress::Stopped => break,
                Progress::Arrived => panic!("turning in place arrived"),
            }
        }
        assert_eq!(steps, limit);
        assert_eq!(t.steps(), limit);
    }

    #[test]
    fn a_traversal_whose_last_node_is_the_exit_arrives() {
        // Same-step auto-reset: the step onto the exit ends the episode and
        // the observation shows the next episode's start, but the record's
        // end cell is the exit.
        let layout = Maze::Small.layout(false);
        let exit = layout
            .cells
            .iter()
            .position(|&c| c == Object::Exit as u8)
            .expect("an exit") as u32;
        let from = layout.cell_index(8, 11) as u32;
        let cfg = PlannerConfig {
            candidates: CandidateSet::Given,
            seed: 1,
            walks_per_node: 256,
            walk_len: 64,
            task: Task::MultiGoal,
            ..PlannerConfig::default()
        };
        let nodes = planner::pivotal::nodes_from_cells(&layout, &[from, exit]);
        let g = WorldGraph::build(&layout, &cfg, &nodes).expect("graph");
        let env_cfg = EnvConfig {
            task: Task::MultiGoal,
            max_steps: 1000,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::SameStep,
        };
        let mut env = Env::new(layout.clone(), env_cfg, 1, 0);
        env.teleport(sim::Pose {
            x: 8,
            y: 11,
            dir: 0,
        });
        let (mut cells, mut meta) = (vec![0u8; layout.cells.len()], [EnvMeta::EMPTY]);
        let mut finals = vec![0u8; layout.cells.len()];
        env.observe(&mut cells, &mut meta[0]);
        let mut route = Route::default();
        let mut t = Traversal::plan(
            &g,
            &view(&layout, &cells, &meta),
            0,
            exit,
            Execution::Replay,
            &mut route,
        )
        .expect("a route to the exit");
        loop {
            let a = t.next_action().expect("an action while under way");
            env.step(a, &mut cells, &mut finals, &mut meta[0]);
            let end = meta[0].end_cell(layout.width) as u32;
            match t.advance(end, meta[0].done()) {
                Progress::Continue => assert!(!meta[0].done()),
                Progress::Arrived => break,
                Progress::Stopped => panic!("the route to the exit stopped"),
            }
        }
        assert!(meta[0].terminated(), "the last step reached the exit");
        assert_ne!(
            meta[0].cell(layout.width) as u32,
            exit,
            "the observation is the next start"
        );
    }
}
