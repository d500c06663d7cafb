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

use planner::{CellIdx, NodeId, Route, WorldGraph};
use sim::Object;

use crate::batch_env::ObsView;

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

/// Door cells on a route that are not open in the observed grid.
fn closed_door_on(route: &Route, grid: &[u8]) -> Option<u32> {
    route.cells().iter().map(|c| c.0).find(|&c| {
        Object::from_code(grid[c as usize]).is_some_and(|o| o.is_door() && o != Object::DoorOpen)
    })
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
                if closed_door_on(route, grid).is_some() {
                    return None;
                }
                Some(Traversal {
                    execution,
                    target,
                    actions: route.actions().to_vec(),
                    cells: route.cells().iter().map(|c| c.0).collect(),
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
                    if cell == self.target {
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
