//! Routes over the world graph (the module docs, "Routes"): [`Route`],
//! the buffers a query writes into, [`RouteWorld`], the doors and key a
//! replay depends on, and the queries themselves, from a node
//! ([`WorldGraph::route_into`], [`WorldGraph::route_in_world_into`]) or
//! from any pose ([`WorldGraph::route_from_pose_into`]).

use sim::{Object, Pose, action};

use super::{NO_DOOR, WorldGraph};
use crate::edges::EdgeWorld;
use crate::error::PlannerError;
use crate::ids::{CellIdx, NodeId};
use crate::shortest_path::UNREACHABLE;

/// `approach` entry of a pose on a node.
pub(super) const AT_NODE: u8 = u8::MAX;
/// `approach` entry of a pose from which no node can be reached.
pub(super) const NO_APPROACH: u8 = u8::MAX - 1;

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

impl WorldGraph {
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

/// For every pose, the first action of a shortest turn-and-move path to a
/// node, through cells the agent can stand on at the start of an episode
/// (floor, open doors; the exit only as a node), by a breadth-first search
/// backwards from all node poses.
pub(super) fn approach_table(world: &EdgeWorld) -> Vec<u8> {
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
