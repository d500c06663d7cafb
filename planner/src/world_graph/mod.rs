//! The world graph `G_w` (Shang et al. 2019, arXiv:1907.00664, sections 3
//! and 4.2): nodes are pivotal states (or another candidate set), edges the
//! paths found by random walks ([`crate::edges`]), and traversal between
//! nodes follows the all-pairs shortest paths of
//! [`crate::shortest_path`].
//!
//! ## Routes
//! A route from node `A` to node `B` is the chain of edges on a shortest
//! path, each edge's recorded actions replayed in turn (section 4.3,
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
//!
//! ## Files
//! - this one: building the graph ([`WorldGraph::build`],
//!   [`WorldGraph::from_parts`]), refining its edges
//!   ([`WorldGraph::refine_edges`]), the route tables and the accessors;
//! - `routes.rs`: [`Route`], [`RouteWorld`] and the route queries;
//! - `file.rs`: the JSON file of a graph ([`WorldGraph::save`],
//!   [`WorldGraph::load`]);
//! - `picture.rs`: the graph drawn on its maze ([`WorldGraph::render`]);
//! - `tests.rs`: the tests.

mod file;
mod picture;
mod routes;
#[cfg(test)]
mod tests;

use sim::{Env, Layout, Object};

pub use self::file::GRAPH_FORMAT;
pub(crate) use self::picture::lerp;
use self::routes::approach_table;
pub use self::routes::{Route, RouteWorld};
use crate::config::PlannerConfig;
use crate::edges::{EdgePath, EdgeWorld, check_edge_path, discover_edges};
use crate::error::PlannerError;
use crate::ids::{CellIdx, NodeId};
use crate::pivotal::{candidates, check_nodes};
use crate::shortest_path::ShortestPaths;

/// `edge_of` entry of a pair without an edge.
const NO_EDGE: u32 = u32::MAX;
/// `door_slot` entry of a cell that is no door.
const NO_DOOR: u8 = u8::MAX;
/// Most doors a layout may have: door states are tracked in a `u64`.
pub const MAX_DOORS: usize = 64;

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
    /// node, [`routes::AT_NODE`] or [`routes::NO_APPROACH`].
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

    /// Refines edge paths (section 3.3: "each path is further refined
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
    /// [`crate::UNREACHABLE`].
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
