//! The world graph `G_w` (Shang et al. 2019, arXiv:1907.00664, sections 3
//! and 4.2): nodes are pivotal states (or another candidate set), edges the
//! paths found by random walks ([`crate::edges`]), and traversal between
//! nodes follows the all-pairs shortest paths of
//! [`crate::shortest_path`].
//!
//! ## Routes
//! A route from node `A` to node `B` is the chain of edges on a shortest
//! path, each edge's recorded actions replayed in turn (paper section 4.3,
//! "Execution": in deterministic worlds the agent follows the action
//! sequences of the edge paths).
//!
//! - **Facing.** Node states are cells; an edge path starts at a specific
//!   facing. The route inserts the turns (at most two) from the facing the
//!   agent has on a node to the next edge's starting facing. Edge weights,
//!   and so the dynamic programme, count the edge actions only, as in the
//!   paper; a route's action count is its distance plus these turns.
//! - **World changes.** Edge paths are recorded from the layout's initial
//!   world and only ever open doors and pick up the key (see
//!   [`crate::edges`]). Replayed after earlier edges, a `toggle` aimed at a
//!   door that is already open, or a `pickup` while the key is in hand,
//!   would undo or waste a step, so the route leaves them out; every other
//!   action has the same effect as when it was recorded (a world that only
//!   opens up never blocks a move that succeeded before). [`RouteWorld`]
//!   tracks this, from the initial world or from an observed one.
//! - **Speed.** The tables are precomputed ([`WorldGraph::rebuild_shortest_paths`]);
//!   a query walks the next-hop table and copies edge paths into a
//!   caller-owned [`Route`], allocating nothing once its buffers are large
//!   enough.
//!
//! [`WorldGraph::route_from_pose_into`] also plans from an arbitrary pose:
//! the shortest turn-and-move path to the nearest node (a breadth-first
//! search precomputed over all poses), then the graph route from there.

use std::path::Path;

use serde::{Deserialize, Serialize};
use sim::render::{Canvas, Rgb, draw_grid};
use sim::{Env, Layout, Object, Pose, action};

use crate::config::PlannerConfig;
use crate::edges::{EdgePath, EdgeWorld, check_edge_path, discover_edges};
use crate::error::PlannerError;
use crate::ids::{CellIdx, NodeId};
use crate::pivotal::{candidates, check_nodes};
use crate::shortest_path::{ShortestPaths, UNREACHABLE};

/// `edge_of` entry of a pair without an edge.
const NO_EDGE: u32 = u32::MAX;
/// `door_slot` entry of a cell that is no door.
const NO_DOOR: u8 = u8::MAX;
/// Most doors a layout may have: door states are tracked in a `u64`.
pub const MAX_DOORS: usize = 64;
/// `approach` entry of a pose on a node.
const AT_NODE: u8 = u8::MAX;
/// `approach` entry of a pose from which no node can be reached.
const NO_APPROACH: u8 = u8::MAX - 1;

/// The state of the world that route replay depends on: which doors are
/// open and whether the key is in hand. Doors are numbered in cell order
/// ([`WorldGraph::door_cells`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct RouteWorld {
    /// Bit `i` set: door `i` is open.
    pub open_doors: u64,
    /// The key is in hand.
    pub carrying_key: bool,
}

/// A planned route, written by the route queries into buffers the caller
/// keeps from query to query.
///
/// `actions[i]` is the `i`-th action and `cells[i]` the agent's cell after
/// it; `nodes` are the graph nodes passed, from the first to the target.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Route {
    start: Option<Pose>,
    nodes: Vec<NodeId>,
    actions: Vec<u8>,
    cells: Vec<CellIdx>,
    world_after: RouteWorld,
}

impl Route {
    /// An empty route with room for `actions` actions and `nodes` nodes, so
    /// that queries up to that size allocate nothing.
    pub fn with_capacity(actions: usize, nodes: usize) -> Route {
        Route {
            start: None,
            nodes: Vec::with_capacity(nodes),
            actions: Vec::with_capacity(actions),
            cells: Vec::with_capacity(actions),
            world_after: RouteWorld::default(),
        }
    }

    fn clear(&mut self) {
        self.start = None;
        self.nodes.clear();
        self.actions.clear();
        self.cells.clear();
    }

    /// The pose the route starts from (`None` before the first query or
    /// after a failed one).
    pub fn start(&self) -> Option<Pose> {
        self.start
    }
    /// The nodes passed, first to target.
    pub fn nodes(&self) -> &[NodeId] {
        &self.nodes
    }
    /// The actions, MiniGrid numbering.
    pub fn actions(&self) -> &[u8] {
        &self.actions
    }
    /// The agent's cell after each action.
    pub fn cells(&self) -> &[CellIdx] {
        &self.cells
    }
    /// Number of actions.
    pub fn len(&self) -> usize {
        self.actions.len()
    }
    /// True when the route has no action (start on the target, facing
    /// irrelevant).
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }
    /// The world at the end of the route (input of a following query).
    pub fn world_after(&self) -> RouteWorld {
        self.world_after
    }

    /// Copies the route into wire-format arrays (a route response's
    /// `pivots`, `cells` and `actions`) and returns `(num_pivots,
    /// num_actions)`, or `None`, writing nothing, when it does not fit.
    pub fn write_wire(
        &self,
        pivots: &mut [u16],
        cells: &mut [u32],
        actions: &mut [u8],
    ) -> Option<(usize, usize)> {
        let (np, na) = (self.nodes.len(), self.actions.len());
        if np > pivots.len() || na > cells.len() || na > actions.len() {
            return None;
        }
        for (w, n) in pivots.iter_mut().zip(&self.nodes) {
            *w = n.0;
        }
        for (w, c) in cells.iter_mut().zip(&self.cells) {
            *w = c.0;
        }
        actions[..na].copy_from_slice(&self.actions);
        Some((np, na))
    }
}

/// What the route replay needs to know about an edge.
#[derive(Debug, Clone, Copy)]
struct EdgeInfo {
    /// Offset of the path in the flat action and cell arrays.
    start: u32,
    len: u32,
    start_dir: u8,
    end_dir: u8,
    changes_world: bool,
}

/// The world graph: nodes, edges with their paths, and the precomputed
/// tables that answer route queries. See the module docs.
#[derive(Debug, Clone)]
pub struct WorldGraph {
    config: PlannerConfig,
    world: EdgeWorld,
    edges: Vec<EdgePath>,
    // Derived tables (rebuilt by `rebuild_shortest_paths`).
    paths: ShortestPaths,
    edge_of: Vec<u32>,
    edge_info: Vec<EdgeInfo>,
    flat_actions: Vec<u8>,
    flat_cells: Vec<CellIdx>,
    door_slot: Vec<u8>,
    door_cells: Vec<CellIdx>,
    initial_world: RouteWorld,
    /// Per pose (`cell · 4 + dir`): the first action towards the nearest
    /// node, [`AT_NODE`] or [`NO_APPROACH`].
    approach: Vec<u8>,
}

impl WorldGraph {
    /// Builds the graph of `layout`: nodes from `cfg.candidates` (`given`
    /// supplies [`crate::CandidateSet::Given`]), edges by random walks, then
    /// the all-pairs shortest paths.
    pub fn build(
        layout: &Layout,
        cfg: &PlannerConfig,
        given: &[CellIdx],
    ) -> Result<WorldGraph, PlannerError> {
        cfg.validate()?;
        check_layout(layout)?;
        let nodes = candidates(layout, cfg, given)?;
        let world = EdgeWorld::new(layout, &nodes, cfg.walk_task());
        let edges = discover_edges(&world, cfg);
        Ok(Self::assemble(cfg.clone(), world, edges))
    }

    /// A graph from nodes and edges computed elsewhere (or loaded). The
    /// nodes are checked, and every edge is replayed in the simulator
    /// ([`check_edge_path`]); `source` names the input in errors.
    pub fn from_parts(
        layout: &Layout,
        cfg: &PlannerConfig,
        nodes: &[CellIdx],
        mut edges: Vec<EdgePath>,
        source: &str,
    ) -> Result<WorldGraph, PlannerError> {
        check_layout(layout)?;
        let nodes = check_nodes(layout, nodes)?;
        let world = EdgeWorld::new(layout, &nodes, cfg.walk_task());
        let invalid = |message: String| PlannerError::InvalidGraph {
            source_name: source.to_string(),
            message,
        };
        edges.sort_by_key(|e| (e.from, e.to));
        if let Some(w) = edges
            .windows(2)
            .find(|w| (w[0].from, w[0].to) == (w[1].from, w[1].to))
        {
            return Err(invalid(format!("two edges {} -> {}", w[0].from, w[0].to)));
        }
        for e in &edges {
            check_edge_path(&world, e).map_err(invalid)?;
        }
        Ok(Self::assemble(cfg.clone(), world, edges))
    }

    fn assemble(config: PlannerConfig, world: EdgeWorld, edges: Vec<EdgePath>) -> WorldGraph {
        let layout = world.layout();
        let door_cells: Vec<CellIdx> = (0..layout.cells.len())
            .filter(|&i| Object::from_code(layout.cells[i]).is_some_and(Object::is_door))
            .map(|i| CellIdx(i as u32))
            .collect();
        let mut door_slot = vec![NO_DOOR; layout.cells.len()];
        let mut initial_world = RouteWorld::default();
        for (k, c) in door_cells.iter().enumerate() {
            door_slot[c.index()] = k as u8;
            if layout.cells[c.index()] == Object::DoorOpen as u8 {
                initial_world.open_doors |= 1 << k;
            }
        }
        let approach = approach_table(&world);
        let mut g = WorldGraph {
            config,
            world,
            edges,
            paths: ShortestPaths::default(),
            edge_of: Vec::new(),
            edge_info: Vec::new(),
            flat_actions: Vec::new(),
            flat_cells: Vec::new(),
            door_slot,
            door_cells,
            initial_world,
            approach,
        };
        g.rebuild_shortest_paths();
        g
    }

    /// Refines edge paths (paper section 3.3: "each path is further refined
    /// by `π_g` if feasible"): `propose` sees each edge and may return
    /// another path for it, e.g. one followed by the goal-conditioned
    /// policy. A proposal replaces the edge when it joins the same nodes,
    /// is strictly shorter and replays in the simulator
    /// ([`check_edge_path`]); the route tables are then rebuilt. Returns how
    /// many edges changed.
    pub fn refine_edges(
        &mut self,
        mut propose: impl FnMut(&EdgePath) -> Option<EdgePath>,
    ) -> usize {
        let mut changed = 0;
        for k in 0..self.edges.len() {
            let Some(p) = propose(&self.edges[k]) else {
                continue;
            };
            let e = &self.edges[k];
            if (p.from, p.to) == (e.from, e.to)
                && p.weight() < e.weight()
                && check_edge_path(&self.world, &p).is_ok()
            {
                self.edges[k] = p;
                changed += 1;
            }
        }
        if changed > 0 {
            self.rebuild_shortest_paths();
        }
        changed
    }

    /// Recomputes the route tables from the edges: Floyd–Warshall over the
    /// edge weights, the edge lookup and the flat path storage. Called by
    /// the constructors; public so that its cost can be measured.
    pub fn rebuild_shortest_paths(&mut self) {
        let n = self.num_nodes();
        self.paths =
            ShortestPaths::floyd_warshall(n, self.edges.iter().map(|e| (e.from, e.to, e.weight())));
        self.edge_of.clear();
        self.edge_of.resize(n * n, NO_EDGE);
        self.edge_info.clear();
        self.flat_actions.clear();
        self.flat_cells.clear();
        for (k, e) in self.edges.iter().enumerate() {
            self.edge_of[e.from.index() * n + e.to.index()] = k as u32;
            self.edge_info.push(EdgeInfo {
                start: self.flat_actions.len() as u32,
                len: e.actions.len() as u32,
                start_dir: e.start_dir,
                end_dir: e.end_dir(),
                changes_world: e.changes_world(),
            });
            self.flat_actions.extend_from_slice(&e.actions);
            self.flat_cells.extend_from_slice(&e.cells);
        }
    }

    /// The simulator the edges are walked in, in the layout's initial world
    /// (no step limit, no auto-reset, only the layout's balls): start a
    /// clone of it at a node with [`Env::teleport`] to follow a candidate
    /// edge path, e.g. `π_g`'s ([`Self::refine_edges`]).
    pub fn walk_env(&self) -> &Env {
        self.world.template()
    }

    /// `edge`'s path with its loops cut out ([`crate::edges::loop_erase`]).
    pub fn loop_erased(&self, edge: &EdgePath) -> EdgePath {
        crate::edges::loop_erase(&self.world, edge)
    }

    /// The length of the shortest path `from → to` that touches no third
    /// node ([`crate::edges::shortest_edge_path`]), `None` when there is
    /// none: the floor any refinement of that edge can reach.
    pub fn shortest_edge_weight(&self, from: NodeId, to: NodeId) -> Option<u32> {
        crate::edges::shortest_edge_path(&self.world, from, to).map(|p| p.weight())
    }

    /// The layout.
    pub fn layout(&self) -> &Layout {
        self.world.layout()
    }
    /// The configuration the graph was built with.
    pub fn config(&self) -> &PlannerConfig {
        &self.config
    }
    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.world.nodes().len()
    }
    /// Node cells; node `i` is `nodes()[i]`.
    pub fn nodes(&self) -> &[CellIdx] {
        self.world.nodes()
    }
    /// The node on `cell`, if any.
    pub fn node_at(&self, cell: CellIdx) -> Option<NodeId> {
        self.world.node_at(cell)
    }
    /// The edges, sorted by `(from, to)`.
    pub fn edges(&self) -> &[EdgePath] {
        &self.edges
    }
    /// The edge `from → to`, if any.
    pub fn edge(&self, from: NodeId, to: NodeId) -> Option<&EdgePath> {
        let n = self.num_nodes();
        if from.index() >= n || to.index() >= n {
            return None;
        }
        self.edges
            .get(self.edge_of[from.index() * n + to.index()] as usize)
    }
    /// The all-pairs tables.
    pub fn shortest_paths(&self) -> &ShortestPaths {
        &self.paths
    }
    /// Shortest distance (sum of edge weights) from `a` to `b`, or
    /// [`UNREACHABLE`].
    pub fn distance(&self, a: NodeId, b: NodeId) -> u32 {
        self.paths.dist(a, b)
    }
    /// The layout's doors, in the order of [`RouteWorld::open_doors`].
    pub fn door_cells(&self) -> &[CellIdx] {
        &self.door_cells
    }
    /// The world at the start of an episode (doors as drawn, empty hands).
    pub fn initial_world(&self) -> RouteWorld {
        self.initial_world
    }
    /// The route-relevant part of an observed world: `grid` in the layout's
    /// cell order, `carrying` the carried object's code
    /// (`EnvMeta::carrying`). Routes planned from it are executable when
    /// the hands hold nothing or the key.
    pub fn observe_world(&self, grid: &[u8], carrying: u8) -> RouteWorld {
        let mut w = RouteWorld {
            open_doors: 0,
            carrying_key: carrying == Object::Key as u8,
        };
        for (k, c) in self.door_cells.iter().enumerate() {
            if grid.get(c.index()) == Some(&(Object::DoorOpen as u8)) {
                w.open_doors |= 1 << k;
            }
        }
        w
    }

    fn check_node(&self, node: NodeId) -> Result<(), PlannerError> {
        if node.index() < self.num_nodes() {
            Ok(())
        } else {
            Err(PlannerError::UnknownNode {
                node,
                num_nodes: self.num_nodes(),
            })
        }
    }

    /// Plans the route from node `from`, standing there facing `facing`, to
    /// node `to`, in the layout's initial world, into `out`; returns its
    /// action count. See [`WorldGraph::route_in_world_into`].
    #[inline]
    pub fn route_into(
        &self,
        from: NodeId,
        facing: u8,
        to: NodeId,
        out: &mut Route,
    ) -> Result<usize, PlannerError> {
        self.route_in_world_into(from, facing, to, self.initial_world, out)
    }

    /// Plans the route from node `from` (facing `facing`) to node `to`
    /// starting in `world`, into `out` (cleared first); returns its action
    /// count. Errors: an unknown node, or no path in the graph
    /// ([`PlannerError::Unreachable`]). On error `out` is empty.
    pub fn route_in_world_into(
        &self,
        from: NodeId,
        facing: u8,
        to: NodeId,
        world: RouteWorld,
        out: &mut Route,
    ) -> Result<usize, PlannerError> {
        out.clear();
        self.check_node(from)?;
        self.check_node(to)?;
        if self.paths.dist(from, to) == UNREACHABLE {
            return Err(PlannerError::Unreachable { from, to });
        }
        let width = self.layout().width;
        out.start = Some(self.nodes()[from.index()].pose(width, facing & 3));
        out.world_after = world;
        self.append_route(from, facing & 3, to, out);
        Ok(out.actions.len())
    }

    /// Appends the graph route `from → to` (reachable, checked by the
    /// caller) to `out`, starting with `from` in `out.nodes`.
    fn append_route(&self, from: NodeId, facing: u8, to: NodeId, out: &mut Route) {
        let n = self.num_nodes();
        let mut world = out.world_after;
        let (mut cur, mut dir) = (from, facing);
        out.nodes.push(from);
        while cur != to {
            let Some(hop) = self.paths.next_hop(cur, to) else {
                break;
            };
            let info = self.edge_info[self.edge_of[cur.index() * n + hop.index()] as usize];
            let here = self.nodes()[cur.index()];
            // Turn to the edge's starting facing: +1 right, +3 left, +2 two rights.
            match (info.start_dir + 4 - dir) & 3 {
                1 => push(out, action::RIGHT, here),
                2 => {
                    push(out, action::RIGHT, here);
                    push(out, action::RIGHT, here);
                }
                3 => push(out, action::LEFT, here),
                _ => {}
            }
            let span = info.start as usize..(info.start + info.len) as usize;
            if info.changes_world {
                self.replay_changing_edge(
                    &self.flat_actions[span.clone()],
                    &self.flat_cells[span],
                    here,
                    info.start_dir,
                    &mut world,
                    out,
                );
            } else {
                out.actions
                    .extend_from_slice(&self.flat_actions[span.clone()]);
                out.cells.extend_from_slice(&self.flat_cells[span]);
            }
            dir = info.end_dir;
            cur = hop;
            out.nodes.push(hop);
        }
        out.world_after = world;
    }

    /// Copies an edge path that opens doors or picks up the key, leaving out
    /// the toggles of doors already open and the pickups with the key in
    /// hand (module docs, "World changes").
    fn replay_changing_edge(
        &self,
        actions: &[u8],
        cells: &[CellIdx],
        start: CellIdx,
        start_dir: u8,
        world: &mut RouteWorld,
        out: &mut Route,
    ) {
        let (mut cell, mut dir) = (start, start_dir);
        for (&a, &next) in actions.iter().zip(cells) {
            let keep = match a {
                action::TOGGLE => {
                    let slot = self.door_slot[cell.step(dir, self.layout()).index()];
                    let bit = if slot == NO_DOOR { 0 } else { 1u64 << slot };
                    let open = world.open_doors & bit != 0;
                    world.open_doors |= bit;
                    !open
                }
                action::PICKUP => !std::mem::replace(&mut world.carrying_key, true),
                action::LEFT => {
                    dir = (dir + 3) & 3;
                    true
                }
                action::RIGHT => {
                    dir = (dir + 1) & 3;
                    true
                }
                _ => true,
            };
            if keep {
                push(out, a, next);
            }
            cell = next;
        }
    }

    /// Plans a route from an arbitrary `pose` to node `to` in `world`: the
    /// shortest path (turns and moves through cells open at the start of an
    /// episode, no node on the way) to the nearest node, then the graph
    /// route from it. When `pose` is on a node this is
    /// [`WorldGraph::route_in_world_into`]. Errors as there, plus
    /// [`PlannerError::NotOnGraph`] when no node can be reached.
    pub fn route_from_pose_into(
        &self,
        pose: Pose,
        to: NodeId,
        world: RouteWorld,
        out: &mut Route,
    ) -> Result<usize, PlannerError> {
        out.clear();
        self.check_node(to)?;
        let layout = self.layout();
        let not_on_graph = PlannerError::NotOnGraph {
            x: pose.x,
            y: pose.y,
        };
        if pose.x as usize >= layout.width || pose.y as usize >= layout.height {
            return Err(not_on_graph);
        }
        let (mut cell, mut dir) = (CellIdx::of_pose(pose, layout.width), pose.dir & 3);
        // Follow the approach table to the nearest node.
        loop {
            match self.approach[cell.index() * 4 + dir as usize] {
                AT_NODE => break,
                NO_APPROACH => {
                    out.clear();
                    return Err(not_on_graph);
                }
                a => {
                    match a {
                        action::LEFT => dir = (dir + 3) & 3,
                        action::RIGHT => dir = (dir + 1) & 3,
                        _ => cell = cell.step(dir, layout),
                    }
                    push(out, a, cell);
                }
            }
        }
        let first = self.node_at(cell).ok_or(PlannerError::NotOnGraph {
            x: pose.x,
            y: pose.y,
        })?;
        if self.paths.dist(first, to) == UNREACHABLE {
            out.clear();
            return Err(PlannerError::Unreachable { from: first, to });
        }
        out.start = Some(Pose {
            x: pose.x,
            y: pose.y,
            dir: pose.dir & 3,
        });
        out.world_after = world;
        self.append_route(first, dir, to, out);
        Ok(out.actions.len())
    }
}

#[inline]
fn push(out: &mut Route, a: u8, cell: CellIdx) {
    out.actions.push(a);
    out.cells.push(cell);
}

/// Refuses layouts whose world changes route replay cannot track.
fn check_layout(layout: &Layout) -> Result<(), PlannerError> {
    let keys = layout
        .cells
        .iter()
        .filter(|&&c| c == Object::Key as u8)
        .count();
    let doors = layout
        .cells
        .iter()
        .filter(|&&c| Object::from_code(c).is_some_and(Object::is_door))
        .count();
    let unsupported = |message| {
        Err(PlannerError::UnsupportedLayout {
            layout: layout.name.clone(),
            message,
        })
    };
    if keys > 1 {
        return unsupported(format!("{keys} keys; route replay tracks one"));
    }
    if doors > MAX_DOORS {
        return unsupported(format!("{doors} doors; at most {MAX_DOORS} are supported"));
    }
    Ok(())
}

/// For every pose, the first action of a shortest turn-and-move path to a
/// node, through cells the agent can stand on at the start of an episode
/// (floor, open doors; the exit only as a node), by a breadth-first search
/// backwards from all node poses.
fn approach_table(world: &EdgeWorld) -> Vec<u8> {
    let layout = world.layout();
    let poses = layout.cells.len() * 4;
    let enterable = |c: CellIdx| match Object::from_code(layout.cells[c.index()]) {
        Some(Object::Floor | Object::DoorOpen) => true,
        Some(Object::Exit) => world.node_at(c).is_some(),
        _ => false,
    };
    // Forward transitions of every pose, inverted into predecessor lists.
    let mut preds: Vec<Vec<(u32, u8)>> = vec![Vec::new(); poses];
    for c in 0..layout.cells.len() as u32 {
        let cell = CellIdx(c);
        if layout.cells[cell.index()] == Object::Wall as u8 || world.node_at(cell).is_some() {
            continue;
        }
        for dir in 0..4u8 {
            let from = c * 4 + dir as u32;
            preds[(c * 4 + ((dir + 3) & 3) as u32) as usize].push((from, action::LEFT));
            preds[(c * 4 + ((dir + 1) & 3) as u32) as usize].push((from, action::RIGHT));
            let front = cell.step(dir, layout);
            if enterable(front) {
                preds[(front.0 * 4 + dir as u32) as usize].push((from, action::FORWARD));
            }
        }
    }
    let mut table = vec![NO_APPROACH; poses];
    let mut queue = std::collections::VecDeque::new();
    for n in world.nodes() {
        for dir in 0..4 {
            table[n.index() * 4 + dir] = AT_NODE;
            queue.push_back(n.0 * 4 + dir as u32);
        }
    }
    while let Some(v) = queue.pop_front() {
        for &(u, a) in &preds[v as usize] {
            if table[u as usize] == NO_APPROACH {
                table[u as usize] = a;
                queue.push_back(u);
            }
        }
    }
    table
}

// ---------------------------------------------------------------- files --

/// Format tag of saved graphs.
pub const GRAPH_FORMAT: &str = "worldgraph.world_graph.v1";

/// The JSON document of a saved graph.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GraphFile {
    format: String,
    layout_name: String,
    width: usize,
    height: usize,
    /// The layout in its file format, one string per row.
    layout: Vec<String>,
    config: PlannerConfig,
    nodes: Vec<NodeRecord>,
    edges: Vec<EdgeRecord>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct NodeRecord {
    id: NodeId,
    x: u16,
    y: u16,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EdgeRecord {
    from: NodeId,
    to: NodeId,
    weight: u32,
    start_dir: u8,
    actions: Vec<u8>,
    cells: Vec<CellIdx>,
}

impl WorldGraph {
    /// The graph as pretty JSON: format tag, layout (name and rows),
    /// configuration, nodes `{id, x, y}`, edges with weight, start facing,
    /// actions and cells. The route tables are not stored: they are
    /// recomputed on load.
    pub fn to_json(&self) -> String {
        let l = self.layout();
        let file = GraphFile {
            format: GRAPH_FORMAT.to_string(),
            layout_name: l.name.clone(),
            width: l.width,
            height: l.height,
            layout: l.to_text().lines().map(str::to_string).collect(),
            config: self.config.clone(),
            nodes: self
                .nodes()
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    let (x, y) = c.xy(l.width);
                    NodeRecord {
                        id: NodeId(i as u16),
                        x,
                        y,
                    }
                })
                .collect(),
            edges: self
                .edges
                .iter()
                .map(|e| EdgeRecord {
                    from: e.from,
                    to: e.to,
                    weight: e.weight(),
                    start_dir: e.start_dir,
                    actions: e.actions.clone(),
                    cells: e.cells.clone(),
                })
                .collect(),
        };
        serde_json::to_string_pretty(&file)
            .expect("invariant: the graph file serialises (plain data, string keys)")
    }

    /// Reads a graph from [`WorldGraph::to_json`]'s format; `source` names
    /// the input in errors. Everything is checked: the layout is parsed and
    /// validated, node ids must be `0..n` in order, weights must equal the
    /// path lengths, and every edge path is replayed in the simulator.
    pub fn from_json(source: &str, text: &str) -> Result<WorldGraph, PlannerError> {
        let file: GraphFile = serde_json::from_str(text).map_err(|e| PlannerError::Json {
            path: source.to_string(),
            source: e,
        })?;
        let invalid = |message: String| PlannerError::InvalidGraph {
            source_name: source.to_string(),
            message,
        };
        if file.format != GRAPH_FORMAT {
            return Err(invalid(format!(
                "format {:?}, expected {GRAPH_FORMAT:?}",
                file.format
            )));
        }
        let layout = Layout::parse(&file.layout_name, &(file.layout.join("\n") + "\n"))?;
        if (layout.width, layout.height) != (file.width, file.height) {
            return Err(invalid(format!(
                "the layout is {}x{} but the file says {}x{}",
                layout.width, layout.height, file.width, file.height
            )));
        }
        let mut nodes = Vec::with_capacity(file.nodes.len());
        for (i, n) in file.nodes.iter().enumerate() {
            if n.id.index() != i {
                return Err(invalid(format!("node {i} has id {}", n.id)));
            }
            if n.x as usize >= layout.width || n.y as usize >= layout.height {
                return Err(PlannerError::OutOfGrid {
                    x: n.x.into(),
                    y: n.y.into(),
                    width: layout.width,
                    height: layout.height,
                });
            }
            nodes.push(CellIdx::from_xy(n.x as usize, n.y as usize, layout.width));
        }
        let mut edges = Vec::with_capacity(file.edges.len());
        for e in file.edges {
            if e.weight as usize != e.actions.len() {
                return Err(invalid(format!(
                    "edge {} -> {} has weight {} but {} actions",
                    e.from,
                    e.to,
                    e.weight,
                    e.actions.len()
                )));
            }
            edges.push(EdgePath {
                from: e.from,
                to: e.to,
                start_dir: e.start_dir,
                actions: e.actions,
                cells: e.cells,
            });
        }
        file.config.validate()?;
        WorldGraph::from_parts(&layout, &file.config, &nodes, edges, source)
    }

    /// Saves [`WorldGraph::to_json`] atomically (write, fsync, rename).
    pub fn save(&self, path: &Path) -> Result<(), PlannerError> {
        Ok(sim::render::write_atomic(path, self.to_json().as_bytes())?)
    }

    /// Loads a graph saved by [`WorldGraph::save`].
    pub fn load(path: &Path) -> Result<WorldGraph, PlannerError> {
        let text = std::fs::read_to_string(path).map_err(|source| PlannerError::Io {
            path: path.display().to_string(),
            source,
        })?;
        WorldGraph::from_json(&path.display().to_string(), &text)
    }

    // ------------------------------------------------------------ picture --

    /// Colours of [`WorldGraph::render`]'s edges: the lightest edge's (dark
    /// blue) and the heaviest's (light blue); the others lie between.
    pub const EDGE_COLOURS: (Rgb, Rgb) = ([20, 50, 170], [150, 175, 225]);
    /// Colour of [`WorldGraph::render`]'s node discs (on a white ring).
    pub const NODE_COLOUR: Rgb = [200, 30, 110];

    /// The maze with the graph drawn on it, `px` pixels per cell: each edge
    /// along its path, through the cells it visits (dark for light edges,
    /// pale for heavy ones; every segment is offset to the left of its
    /// direction and the last ends in an arrow head, so `p → q` and `q → p`
    /// are told apart), nodes as discs.
    pub fn render(&self, px: usize) -> Canvas {
        let l = self.layout();
        let px = px.max(4);
        let mut canvas = Canvas::new(l.width * px, l.height * px, [255, 255, 255]);
        draw_grid(&mut canvas, &l.cells, l.width, 0, 0, px);
        let s = px as f32;
        let centre = |c: CellIdx| {
            let (x, y) = c.xy(l.width);
            ((x as f32 + 0.5) * s, (y as f32 + 0.5) * s)
        };
        let (wmin, wmax) = self.edges.iter().fold((u32::MAX, 0), |(lo, hi), e| {
            (lo.min(e.weight()), hi.max(e.weight()))
        });
        for e in &self.edges {
            let t = if wmax > wmin {
                (e.weight() - wmin) as f32 / (wmax - wmin) as f32
            } else {
                0.0
            };
            let colour = lerp(Self::EDGE_COLOURS.0, Self::EDGE_COLOURS.1, t);
            // The cells the path passes, each once in a row (turns stay).
            let mut cells = vec![self.nodes()[e.from.index()]];
            for &c in &e.cells {
                if cells.last() != Some(&c) {
                    cells.push(c);
                }
            }
            let points: Vec<(f32, f32)> = cells.iter().map(|&c| centre(c)).collect();
            for (k, pair) in points.windows(2).enumerate() {
                let (a, b) = (pair[0], pair[1]);
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                let len = (dx * dx + dy * dy).sqrt().max(1e-3);
                let (ux, uy) = (dx / len, dy / len);
                let off = (uy * s * 0.12, -ux * s * 0.12);
                let (a, b) = ((a.0 + off.0, a.1 + off.1), (b.0 + off.0, b.1 + off.1));
                canvas.line(a, b, (s * 0.08).max(1.0), colour, 0.8);
                if k + 2 == points.len() {
                    let tip = (b.0 - ux * s * 0.3, b.1 - uy * s * 0.3);
                    let base = (tip.0 - ux * s * 0.3, tip.1 - uy * s * 0.3);
                    let side = (-uy * s * 0.14, ux * s * 0.14);
                    canvas.fill_triangle(
                        [
                            tip,
                            (base.0 + side.0, base.1 + side.1),
                            (base.0 - side.0, base.1 - side.1),
                        ],
                        colour,
                        0.9,
                    );
                }
            }
        }
        for &c in self.nodes() {
            let (x, y) = centre(c);
            canvas.fill_disc(x, y, s * 0.3, [255, 255, 255], 1.0);
            canvas.fill_disc(x, y, s * 0.24, Self::NODE_COLOUR, 1.0);
        }
        canvas
    }

    /// Writes [`WorldGraph::render`] as a PNG, atomically.
    pub fn save_png(&self, path: &Path, px: usize) -> Result<(), PlannerError> {
        Ok(self.render(px).save_png(path)?)
    }
}

pub(crate) fn lerp(a: Rgb, b: Rgb, t: f32) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    [0, 1, 2].map(|i| (a[i] as f32 + (b[i] as f32 - a[i] as f32) * t).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::CandidateSet;
    use proptest::prelude::*;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use sim::{AutoReset, BallSpawn, Env, EnvConfig, Maze};

    fn cfg(candidates: CandidateSet, seed: u64) -> PlannerConfig {
        PlannerConfig {
            candidates,
            seed,
            walks_per_node: 256,
            walk_len: 200,
            ..PlannerConfig::default()
        }
    }

    /// A fresh simulator in the graph's walk rules, episode-long, no reset.
    fn fresh_env(g: &WorldGraph) -> Env {
        let c = EnvConfig {
            task: g.config().walk_task(),
            max_steps: u32::MAX,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::Off,
        };
        Env::new(g.layout().clone(), c, 0, 0)
    }

    /// Replays `route` in `env` (already at the route's start) and checks
    /// that every action leads to the route's cell, that the route's nodes
    /// are passed in order, and that it ends on `target`.
    fn replay(g: &WorldGraph, env: &mut Env, route: &Route, target: NodeId) -> Result<(), String> {
        let w = g.layout().width;
        let mut passed = Vec::new();
        if let Some(n) = g.node_at(CellIdx(env.cell() as u32)) {
            passed.push(n);
        }
        for (i, (&a, &c)) in route.actions().iter().zip(route.cells()).enumerate() {
            env.step_meta(a);
            let at = CellIdx::of_pose(env.pose(), w);
            if at != c {
                return Err(format!(
                    "action {i} ({}) leads to {at}, the route says {c}",
                    action::NAMES[a as usize]
                ));
            }
            if let Some(n) = g.node_at(at)
                && passed.last() != Some(&n)
            {
                passed.push(n);
            }
        }
        let end = CellIdx(env.cell() as u32);
        if end != g.nodes()[target.index()] {
            return Err(format!("the route ends on {end}, not on {target}"));
        }
        // Every node of the route is passed, in order (walks may cross their
        // own start node, so `passed` can hold more).
        let mut it = passed.iter();
        if !route.nodes().iter().all(|n| it.any(|p| p == n)) {
            return Err(format!(
                "nodes {:?} not passed in order {:?}",
                route.nodes(),
                passed
            ));
        }
        Ok(())
    }

    /// Reference distances: Dijkstra over the graph's edges from `src`.
    fn dijkstra(g: &WorldGraph, src: NodeId) -> Vec<u32> {
        let mut dist = vec![UNREACHABLE; g.num_nodes()];
        let mut heap = std::collections::BinaryHeap::new();
        dist[src.index()] = 0;
        heap.push(std::cmp::Reverse((0u32, src.0)));
        while let Some(std::cmp::Reverse((d, v))) = heap.pop() {
            if d > dist[v as usize] {
                continue;
            }
            for e in g.edges().iter().filter(|e| e.from.0 == v) {
                let nd = d + e.weight();
                if nd < dist[e.to.index()] {
                    dist[e.to.index()] = nd;
                    heap.push(std::cmp::Reverse((nd, e.to.0)));
                }
            }
        }
        dist
    }

    /// A random enclosed layout (`seed`-determined): walls, closed and open
    /// doors, sometimes a locked door with its key, the start and an exit
    /// reachable from it.
    fn random_layout(seed: u64) -> Layout {
        for attempt in 0.. {
            let mut rng = SmallRng::seed_from_u64(sim::env_seed(seed, attempt));
            let (w, h) = (rng.random_range(5..=12usize), rng.random_range(5..=10usize));
            let mut g = vec![b'#'; w * h];
            for y in 1..h - 1 {
                for x in 1..w - 1 {
                    g[y * w + x] = match rng.random_range(0..100) {
                        0..25 => b'#',
                        25..29 => b'C',
                        29..31 => b'O',
                        _ => b'.',
                    };
                }
            }
            let floor: Vec<usize> = (0..w * h).filter(|&i| g[i] == b'.').collect();
            if floor.len() < 6 {
                continue;
            }
            let start = floor[rng.random_range(0..floor.len())];
            // Cells reachable from the start through anything but walls.
            let mut seen = vec![false; w * h];
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(i) = stack.pop() {
                for j in [i + 1, i - 1, i + w, i - w] {
                    if g[j] != b'#' && !seen[j] {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
            let reach: Vec<usize> = floor
                .iter()
                .copied()
                .filter(|&i| seen[i] && i != start)
                .collect();
            if reach.len() < 5 {
                continue;
            }
            g[reach[rng.random_range(0..reach.len())]] = b'E';
            if rng.random_bool(0.5) {
                let spots: Vec<usize> = reach.iter().copied().filter(|&i| g[i] == b'.').collect();
                if spots.len() >= 4 {
                    let k = spots[rng.random_range(0..spots.len())];
                    let d = spots[rng.random_range(0..spots.len())];
                    if k != d {
                        g[k] = b'K';
                        g[d] = b'D';
                    }
                }
            }
            g[start] = b"<>^v"[rng.random_range(0..4)];
            let text: String = g
                .chunks(w)
                .map(|row| String::from_utf8_lossy(row).into_owned() + "\n")
                .collect();
            if let Ok(l) = Layout::parse(&format!("random-{seed}"), &text)
                && crate::pivotal::v_all(&l).len() >= 5
            {
                return l;
            }
        }
        unreachable!("the attempt loop only ends by returning")
    }

    fn check_graph(g: &WorldGraph) -> Result<(), TestCaseError> {
        let n = g.num_nodes();
        let mut route = Route::default();
        for a in 0..n {
            let a = NodeId(a as u16);
            let reference = dijkstra(g, a);
            for b in 0..n {
                let b = NodeId(b as u16);
                let d = g.distance(a, b);
                prop_assert_eq!(d, reference[b.index()], "DP vs Dijkstra {} -> {}", a, b);
                for k in 0..n {
                    let k = NodeId(k as u16);
                    let (ak, kb) = (g.distance(a, k), g.distance(k, b));
                    if ak != UNREACHABLE && kb != UNREACHABLE {
                        prop_assert!(d <= ak + kb, "triangle {} {} {}", a, k, b);
                    }
                }
                let facing = ((a.0 as usize + 3 * b.0 as usize) % 4) as u8;
                match g.route_into(a, facing, b, &mut route) {
                    Ok(len) => {
                        prop_assert!(d != UNREACHABLE);
                        prop_assert_eq!(len, route.len());
                        let hops = route.nodes().len() - 1;
                        prop_assert!(
                            len <= d as usize + 2 * hops,
                            "{} actions for distance {} over {} hops",
                            len,
                            d,
                            hops
                        );
                        let mut env = fresh_env(g);
                        env.teleport(route.start().expect("a route has a start"));
                        replay(g, &mut env, &route, b).map_err(|e| {
                            TestCaseError::fail(format!("{}: {a} -> {b}: {e}", g.layout().name))
                        })?;
                    }
                    Err(PlannerError::Unreachable { .. }) => prop_assert_eq!(d, UNREACHABLE),
                    Err(e) => return Err(TestCaseError::fail(e.to_string())),
                }
            }
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, rng_seed: proptest::test_runner::RngSeed::Fixed(3), ..ProptestConfig::default() })]

        /// On random layouts with doors and keys, with edges from walks or
        /// from the exhaustive search: DP distances equal Dijkstra over the
        /// same edges, the triangle inequality holds, and every route
        /// replays in a fresh simulator onto its target.
        #[test]
        fn random_layouts_dp_matches_reference_and_routes_execute(seed in any::<u64>(), k in 2usize..10, exhaustive in any::<bool>()) {
            let layout = random_layout(seed);
            let k = k.min(crate::pivotal::v_all(&layout).len());
            let edge_search = if exhaustive { crate::EdgeSearch::Exhaustive } else { crate::EdgeSearch::RandomWalks };
            let c = PlannerConfig { edge_search, ..cfg(CandidateSet::Random { k }, seed) };
            let g = WorldGraph::build(&layout, &c, &[]).map_err(|e| TestCaseError::fail(e.to_string()))?;
            check_graph(&g)?;
        }

        /// Routes chained in one simulator (each from where the previous
        /// one ended, in the world it left) keep executing, and routes from
        /// arbitrary poses reach their target.
        #[test]
        fn chained_and_pose_routes_execute(seed in any::<u64>()) {
            let layout = random_layout(seed);
            let k = 6.min(crate::pivotal::v_all(&layout).len());
            let g = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k }, seed), &[]).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let mut rng = SmallRng::seed_from_u64(seed);
            let mut route = Route::with_capacity(512, 32);
            let mut env = fresh_env(&g);
            let mut world = g.initial_world();
            let mut at = NodeId(0);
            env.teleport(g.nodes()[0].pose(layout.width, 0));
            for _ in 0..12 {
                let to = NodeId(rng.random_range(0..k) as u16);
                if g.distance(at, to) == UNREACHABLE {
                    continue;
                }
                g.route_in_world_into(at, env.pose().dir, to, world, &mut route).map_err(|e| TestCaseError::fail(e.to_string()))?;
                replay(&g, &mut env, &route, to).map_err(|e| TestCaseError::fail(format!("chained {at} -> {to}: {e}")))?;
                prop_assert_eq!(g.observe_world(env.grid(), env.carrying().map_or(sim::EnvMeta::CARRYING_NOTHING, |o| o as u8)), route.world_after());
                world = route.world_after();
                at = to;
            }
            for cell in crate::pivotal::v_all(&layout) {
                let pose = cell.pose(layout.width, rng.random_range(0..4));
                let to = NodeId(rng.random_range(0..k) as u16);
                match g.route_from_pose_into(pose, to, g.initial_world(), &mut route) {
                    Ok(_) => {
                        let mut env = fresh_env(&g);
                        env.teleport(pose);
                        prop_assert_eq!(route.start(), Some(pose));
                        replay(&g, &mut env, &route, to).map_err(|e| TestCaseError::fail(format!("from {pose:?} to {to}: {e}")))?;
                    }
                    Err(PlannerError::Unreachable { .. } | PlannerError::NotOnGraph { .. }) => {}
                    Err(e) => return Err(TestCaseError::fail(e.to_string())),
                }
            }
        }
    }

    #[test]
    fn embedded_mazes_give_executable_routes() {
        for (maze, door_key) in [
            (Maze::Small, true),
            (Maze::Medium, false),
            (Maze::Large, true),
        ] {
            let layout = maze.layout(door_key);
            let g = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 24 }, 1), &[])
                .expect("graph");
            assert!(
                g.edges().len() >= 24,
                "{}: only {} edges",
                layout.name,
                g.edges().len()
            );
            check_graph(&g).expect("routes execute");
        }
    }

    #[test]
    fn v_all_edges_join_neighbouring_cells_with_one_move() {
        let layout = Maze::Small.layout(false);
        let g = WorldGraph::build(&layout, &cfg(CandidateSet::All, 0), &[]).expect("graph");
        for e in g.edges() {
            assert_eq!(e.actions, vec![action::FORWARD], "{} -> {}", e.from, e.to);
        }
        // Every move between neighbouring floor cells was found.
        let expected: usize = g
            .nodes()
            .iter()
            .filter(|c| layout.cells[c.index()] != Object::Exit as u8)
            .map(|&c| {
                (0..4)
                    .filter(|&d| g.node_at(c.step(d, &layout)).is_some())
                    .count()
            })
            .sum();
        assert_eq!(g.edges().len(), expected);
    }

    #[test]
    fn locked_door_blocks_every_edge_without_the_key() {
        // The Door-Key maze with the key removed (the layout stays valid:
        // doors count as passable for validation).
        let text = Maze::Small.text(true).replace('K', ".");
        let layout = Layout::parse("small-doorkey-nokey", &text).expect("valid");
        let door = CellIdx(
            layout
                .cells
                .iter()
                .position(|&c| c == Object::DoorLocked as u8)
                .expect("locked door") as u32,
        );
        let g = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 30 }, 4), &[])
            .expect("graph");
        assert!(!g.edges().is_empty());
        for e in g.edges() {
            assert!(
                !e.cells.contains(&door),
                "{} -> {} crosses the locked door",
                e.from,
                e.to
            );
        }
        // Nodes on the two sides of the door are not connected.
        let exit = layout
            .cells
            .iter()
            .position(|&c| c == Object::Exit as u8)
            .expect("exit");
        let blocked = {
            let mut l = layout.clone();
            l.cells[door.index()] = Object::Wall as u8;
            l.reachable_from(exit)
        };
        for (a, &ca) in g.nodes().iter().enumerate() {
            for (b, &cb) in g.nodes().iter().enumerate() {
                if blocked[ca.index()] != blocked[cb.index()] {
                    assert_eq!(g.distance(NodeId(a as u16), NodeId(b as u16)), UNREACHABLE);
                }
            }
        }
        // With the key next to the door, an edge goes through it, picking the key up.
        let layout =
            Layout::parse("t", "#########\n#.>..D.E#\n#K#######\n#########\n").expect("valid");
        let nodes = [
            CellIdx::from_xy(2, 1, layout.width),
            CellIdx::from_xy(6, 1, layout.width),
        ];
        let g = WorldGraph::build(
            &layout,
            &PlannerConfig {
                candidates: CandidateSet::Given,
                walks_per_node: 4096,
                ..cfg(CandidateSet::Given, 2)
            },
            &nodes,
        )
        .expect("graph");
        let e = g
            .edge(NodeId(0), NodeId(1))
            .expect("edge through the unlocked door");
        assert!(e.actions.contains(&action::PICKUP) && e.actions.contains(&action::TOGGLE));
        assert!(
            g.edge(NodeId(1), NodeId(0)).is_none(),
            "from the far side the door is locked"
        );
        let mut route = Route::default();
        g.route_into(NodeId(0), 3, NodeId(1), &mut route)
            .expect("route");
        let mut env = fresh_env(&g);
        env.teleport(route.start().expect("start"));
        replay(&g, &mut env, &route, NodeId(1)).expect("executable");
        assert!(route.world_after().carrying_key && route.world_after().open_doors == 1);
    }

    #[test]
    fn refinement_accepts_only_shorter_valid_paths() {
        let layout = Maze::Small.layout(false);
        let raw = PlannerConfig {
            shorten: false,
            ..cfg(CandidateSet::Random { k: 10 }, 3)
        };
        let mut g = WorldGraph::build(&layout, &raw, &[]).expect("graph");
        let exact = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 10 }, 3), &[])
            .expect("graph");
        // Longer or broken proposals are refused.
        assert_eq!(
            g.refine_edges(|e| Some(EdgePath {
                actions: [e.actions.clone(), vec![action::LEFT]].concat(),
                cells: [e.cells.clone(), vec![*e.cells.last().expect("path")]].concat(),
                ..e.clone()
            })),
            0
        );
        let nodes = g.nodes().to_vec();
        assert_eq!(
            g.refine_edges(|e| Some(EdgePath {
                actions: vec![action::LEFT],
                cells: vec![nodes[e.to.index()]],
                ..e.clone()
            })),
            0
        );
        // The exact paths (a stand-in for π_g) are taken where shorter.
        let before: u32 = g.edges().iter().map(EdgePath::weight).sum();
        let changed = g.refine_edges(|e| exact.edge(e.from, e.to).cloned());
        let after: u32 = g.edges().iter().map(EdgePath::weight).sum();
        assert!(
            changed > 0 && after < before,
            "{changed} edges, {before} -> {after}"
        );
        for a in 0..g.num_nodes() as u16 {
            for b in 0..g.num_nodes() as u16 {
                assert_eq!(
                    g.distance(NodeId(a), NodeId(b)),
                    dijkstra(&g, NodeId(a))[b as usize]
                );
            }
        }
    }

    #[test]
    fn loop_erasure_cuts_detours_and_keeps_paths_valid() {
        let layout = Maze::Small.layout(true);
        let g = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 10 }, 5), &[])
            .expect("graph");
        for e in g.edges() {
            // A hesitating follower: turns on the spot before every forward
            // move, and a full turn at the start.
            let mut actions = vec![action::LEFT; 4];
            let mut cells = vec![g.nodes()[e.from.index()]; 4];
            let mut here = g.nodes()[e.from.index()];
            for (&a, &c) in e.actions.iter().zip(&e.cells) {
                if a == action::FORWARD {
                    actions.extend([action::LEFT, action::RIGHT]);
                    cells.extend([here, here]);
                }
                actions.push(a);
                cells.push(c);
                here = c;
            }
            let detour = EdgePath {
                actions,
                cells,
                ..e.clone()
            };
            check_edge_path(&g.world, &detour).expect("the detour is a valid path");
            // The edges are exact shortest paths, so erasing the loops gives
            // back exactly the edge.
            assert_eq!(&g.loop_erased(&detour), e);
            assert_eq!(&g.loop_erased(e), e, "a path without loops is kept");
        }
    }

    #[test]
    fn json_round_trip_and_atomic_save() {
        let layout = Maze::Small.layout(true);
        let g = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 12 }, 9), &[])
            .expect("graph");
        let dir = std::env::temp_dir().join(format!("planner-json-{}", std::process::id()));
        let path = dir.join("graph.json");
        g.save(&path).expect("save");
        let back = WorldGraph::load(&path).expect("load");
        assert_eq!(back.nodes(), g.nodes());
        assert_eq!(back.edges(), g.edges());
        assert_eq!(back.config(), g.config());
        assert_eq!(back.layout(), g.layout());
        assert_eq!(back.shortest_paths(), g.shortest_paths());
        assert_eq!(back.to_json(), g.to_json());
        g.save_png(&dir.join("graph.png"), 16).expect("png");
        let png = std::fs::read(dir.join("graph.png")).expect("png written");
        assert_eq!(&png[1..4], b"PNG");
        std::fs::remove_dir_all(&dir).expect("clean up");

        // Tampered files are refused with a reason.
        let json = g.to_json();
        let v: serde_json::Value = serde_json::from_str(&json).expect("json");
        let with = |f: &dyn Fn(&mut serde_json::Value)| {
            let mut v = v.clone();
            f(&mut v);
            WorldGraph::from_json("g.json", &v.to_string())
                .expect_err("must be refused")
                .to_string()
        };
        assert!(with(&|v| v["edges"][0]["weight"] = 999.into()).contains("weight"));
        assert!(with(&|v| v["edges"][0]["actions"][0] = 6.into()).contains("edge"));
        assert!(with(&|v| v["nodes"][0]["id"] = 5.into()).contains("has id"));
        assert!(with(&|v| v["format"] = "other".into()).contains("format"));
        let dup = with(&|v| {
            let (x, y) = (v["nodes"][0]["x"].clone(), v["nodes"][0]["y"].clone());
            v["nodes"][1]["x"] = x;
            v["nodes"][1]["y"] = y;
        });
        assert!(dup.contains("twice"), "{dup}");
        let e = WorldGraph::from_json("g.json", "{")
            .expect_err("truncated")
            .to_string();
        assert!(e.starts_with("g.json"), "{e}");
    }

    #[test]
    fn unknown_nodes_and_unreachable_pairs_are_errors() {
        let layout = Layout::parse("t", "#######\n#>.D.E#\n#######\n").expect("valid");
        let nodes = [
            CellIdx::from_xy(2, 1, layout.width),
            CellIdx::from_xy(4, 1, layout.width),
        ];
        let g = WorldGraph::build(&layout, &cfg(CandidateSet::Given, 0), &nodes).expect("graph");
        let mut r = Route::default();
        assert!(matches!(
            g.route_into(NodeId(0), 0, NodeId(1), &mut r),
            Err(PlannerError::Unreachable { .. })
        ));
        assert!(matches!(
            g.route_into(NodeId(0), 0, NodeId(2), &mut r),
            Err(PlannerError::UnknownNode { .. })
        ));
        assert!(r.is_empty() && r.start().is_none());
        assert_eq!(
            g.route_into(NodeId(1), 2, NodeId(1), &mut r)
                .expect("trivial route"),
            0
        );
        assert_eq!(r.nodes(), &[NodeId(1)]);
        let e = g
            .route_into(NodeId(0), 0, NodeId(1), &mut r)
            .expect_err("unreachable");
        assert_eq!(e.route_status(), shm_schemas::RouteStatus::Unreachable);
        let e = g
            .route_from_pose_into(
                Pose { x: 0, y: 0, dir: 0 },
                NodeId(0),
                g.initial_world(),
                &mut r,
            )
            .expect_err("a wall");
        assert_eq!(e.route_status(), shm_schemas::RouteStatus::StartNotOnGraph);
        // Wire copy: fits or writes nothing.
        g.route_from_pose_into(
            Pose { x: 1, y: 1, dir: 2 },
            NodeId(0),
            g.initial_world(),
            &mut r,
        )
        .expect("route");
        // Turn around (two turns either way), then one step onto node 0.
        assert_eq!(r.len(), 3);
        assert!(
            r.actions()[0] == r.actions()[1]
                && r.actions()[0] != action::FORWARD
                && r.actions()[2] == action::FORWARD
        );
        let (mut p, mut c, mut a) = ([7u16; 4], [7u32; 4], [7u8; 4]);
        assert_eq!(r.write_wire(&mut p, &mut c, &mut a), Some((1, 3)));
        assert_eq!(
            (p[0], &c[..3], &a[..3]),
            (0, &[8u32, 8, 9][..], r.actions())
        );
        assert_eq!(r.write_wire(&mut p, &mut c[..2], &mut a), None);
        let two_keys = Layout::parse("k", "#######\n#>KK.E#\n#######\n").expect("valid");
        assert!(matches!(
            WorldGraph::build(&two_keys, &cfg(CandidateSet::All, 0), &[]),
            Err(PlannerError::UnsupportedLayout { .. })
        ));
    }
}
