//! Edges of the world graph by random walks (Shang et al. 2019,
//! arXiv:1907.00664, section 3.3 "Edge Connections"):
//!
//! > we perform random walks from `s_p ∈ V_p` [...] we claim a directed edge
//! > `s_p → s_q` if there exist a random walk trajectory from `s_p` to `s_q`
//! > that does not intersect a third pivotal state. We then collect the
//! > shortest such actionable paths as the edge paths. Each path is further
//! > refined by `π_g` if feasible. The action sequence length of the edge
//! > path [...] defines the weight of the edge.
//!
//! ## Walks
//! A walk runs in the simulator itself ([`sim::Env`], `AutoReset::Off`, no
//! step limit, only the balls drawn in the layout), so its state is the
//! simulator's: pose, door states and carried object, and doors, keys and
//! one-way effects are exactly the simulator's. Each walk starts on its node
//! in the layout's initial world, facing one of the four directions (the
//! walks of a node cycle through them), and picks uniformly among the
//! actions that do something there:
//! `left`, `right`, `forward` when the cell in front can be entered,
//! `pickup` when a key is in front and the hands are empty, `toggle` when a
//! closed door, or a locked door with the key in hand, is in front. The
//! walk policy never closes a door, never picks up a ball and never drops
//! anything: closing or dropping is never needed to reach a place, and
//! without them the world only ever changes one way (doors open, the key is
//! taken, balls are collected), which is what lets edge paths be chained
//! into routes (see [`crate::world_graph`]). A walk ends at the first other
//! node it stands on (the edge), when its episode ends (exit, lava) or
//! after [`crate::PlannerConfig::walk_len`] actions.
//!
//! The recorded path is loop-erased as it grows: when the walk comes back to
//! a state (pose and world) it already passed, the loop is cut out. What is
//! left is still an actionable path from `p` that touches no third node, and
//! it holds no action that changes nothing.
//!
//! ## Shortening
//! [`shorten_edge`] replaces an edge path by an exact shortest one: a
//! breadth-first search over (pose, world) states with the walk policy's
//! actions, from the four facings on `p`, never standing on a third node
//! and never passing through the end of an episode. World graph discovery
//! refines its edges with `π_g` instead, as the paper does (the learner's
//! `edge_refinement`, which turns this off); the exact search serves a
//! planner process given nodes without a learned policy, and `discover`'s
//! report, which compares routes over `π_g`'s edges with routes over exact
//! ones (`route_stretch_exact`).
//!
//! ## Determinism
//! Walks from node `i` draw from their own RNG seeded by `(seed, i)` and run
//! in a fixed order, so the edges do not depend on the number of threads.

use std::collections::HashSet;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sim::{AutoReset, BallSpawn, Env, EnvConfig, EnvMeta, Layout, Object, Task, action, flags};

use crate::config::{EdgeSearch, PlannerConfig};
use crate::ids::{CellIdx, NodeId};

/// One directed edge `from → to` with the path kept for it.
///
/// The path starts on `from`'s cell facing `start_dir`, in the layout's
/// initial world; `actions[i]` is the `i`-th action and `cells[i]` the
/// agent's cell after it. The last cell is `to`'s, and no cell of the path
/// is a third node's.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct EdgePath {
    /// Source node `s_p`.
    pub from: NodeId,
    /// Target node `s_q`.
    pub to: NodeId,
    /// Facing at the start: 0 right, 1 down, 2 left, 3 up.
    pub start_dir: u8,
    /// The actions (MiniGrid numbering).
    pub actions: Vec<u8>,
    /// The agent's cell after each action.
    pub cells: Vec<CellIdx>,
}

impl EdgePath {
    /// The edge weight: the path's action count (section 3.3).
    #[inline]
    pub fn weight(&self) -> u32 {
        self.actions.len() as u32
    }

    /// Facing at the end of the path.
    pub fn end_dir(&self) -> u8 {
        self.actions.iter().fold(self.start_dir, |d, &a| match a {
            action::LEFT => (d + 3) & 3,
            action::RIGHT => (d + 1) & 3,
            _ => d,
        })
    }

    /// True when the path changes the world (opens a door or picks up the
    /// key): replaying it after such a change needs the bookkeeping of
    /// [`crate::world_graph::RouteWorld`].
    pub fn changes_world(&self) -> bool {
        self.actions
            .iter()
            .any(|&a| a == action::PICKUP || a == action::TOGGLE)
    }
}

/// `node_of_cell` entry of a cell that is no node.
pub(crate) const NO_NODE: u16 = u16::MAX;
/// Index of the "nothing carried" entry in the carried-object hash table.
const CARRY_SLOTS: usize = sim::object::NUM_OBJECTS + 1;

/// The maze as the walks see it: the simulator in the layout's initial
/// world, which cells are nodes, and a Zobrist table that names a world
/// (grid plus carried object) by a 64-bit hash.
#[derive(Debug, Clone)]
pub struct EdgeWorld {
    template: Env,
    nodes: Vec<CellIdx>,
    node_of_cell: Vec<u16>,
    zobrist: Vec<u64>,
    multigoal: bool,
}

impl EdgeWorld {
    /// The walk world of `layout` with nodes at `nodes` (checked by
    /// [`crate::pivotal::check_nodes`] beforehand) and the rules of `task`.
    pub fn new(layout: &Layout, nodes: &[CellIdx], task: Task) -> EdgeWorld {
        let cfg = EnvConfig {
            task,
            max_steps: u32::MAX,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::Off,
        };
        let template = Env::new(layout.clone(), cfg, 0, 0);
        let mut node_of_cell = vec![NO_NODE; layout.cells.len()];
        for (i, c) in nodes.iter().enumerate() {
            node_of_cell[c.index()] = i as u16;
        }
        let slots = layout.cells.len() * sim::object::NUM_OBJECTS + CARRY_SLOTS;
        let zobrist = (0..slots as u64)
            .map(|i| sim::env_seed(0x5a0b_7157, i))
            .collect();
        EdgeWorld {
            template,
            nodes: nodes.to_vec(),
            node_of_cell,
            zobrist,
            multigoal: task.is_multigoal(),
        }
    }

    /// The simulator in the layout's initial world.
    pub fn template(&self) -> &Env {
        &self.template
    }

    /// The layout.
    pub fn layout(&self) -> &Layout {
        self.template.layout()
    }

    /// The node cells.
    pub fn nodes(&self) -> &[CellIdx] {
        &self.nodes
    }

    /// The node standing on `cell`, if any.
    #[inline]
    pub fn node_at(&self, cell: CellIdx) -> Option<NodeId> {
        self.node_of_cell
            .get(cell.index())
            .copied()
            .filter(|&n| n != NO_NODE)
            .map(NodeId)
    }

    #[inline]
    fn z_cell(&self, cell: usize, code: u8) -> u64 {
        self.zobrist[cell * sim::object::NUM_OBJECTS + code as usize]
    }

    #[inline]
    fn z_carry(&self, carrying: u8) -> u64 {
        let slot = if carrying == EnvMeta::CARRYING_NOTHING {
            0
        } else {
            carrying as usize + 1
        };
        self.zobrist
            [self.layout().cells.len() * sim::object::NUM_OBJECTS + slot.min(CARRY_SLOTS - 1)]
    }

    /// Hash of the initial world.
    fn initial_hash(&self) -> u64 {
        let cells = self
            .template
            .grid()
            .iter()
            .enumerate()
            .fold(0, |h, (i, &c)| h ^ self.z_cell(i, c));
        cells ^ self.z_carry(EnvMeta::CARRYING_NOTHING)
    }

    /// Writes the walk policy's actions available in `env`'s state into
    /// `out`; returns how many (always ≥ 2: the turns).
    #[inline]
    fn effective_actions(&self, env: &Env, out: &mut [u8; 5]) -> usize {
        let pose = env.pose();
        let front = CellIdx::of_pose(pose, self.layout().width).step(pose.dir, self.layout());
        let obj = Object::from_code(env.grid()[front.index()]).unwrap_or(Object::Wall);
        let carrying = env.carrying();
        out[0] = action::LEFT;
        out[1] = action::RIGHT;
        let mut n = 2;
        if obj.can_overlap() || (obj == Object::Ball && self.multigoal) {
            out[n] = action::FORWARD;
            n += 1;
        }
        if obj == Object::Key && carrying.is_none() {
            out[n] = action::PICKUP;
            n += 1;
        }
        if obj == Object::DoorClosed || (obj == Object::DoorLocked && carrying == Some(Object::Key))
        {
            out[n] = action::TOGGLE;
            n += 1;
        }
        n
    }

    /// Applies `a` to `env` and returns the step record and the new world
    /// hash (only the cell in front and the carried object can change).
    #[inline]
    fn step(&self, env: &mut Env, a: u8, hash: u64) -> (EnvMeta, u64) {
        let pose = env.pose();
        let front = CellIdx::of_pose(pose, self.layout().width)
            .step(pose.dir, self.layout())
            .index();
        let (before, carried) = (env.grid()[front], carry_code(env));
        let meta = env.step_meta(a);
        let after = env.grid()[front];
        let mut h = hash;
        if after != before {
            h ^= self.z_cell(front, before) ^ self.z_cell(front, after);
        }
        if meta.carrying != carried {
            h ^= self.z_carry(carried) ^ self.z_carry(meta.carrying);
        }
        (meta, h)
    }

    #[inline]
    fn pose_id(&self, meta: &EnvMeta) -> u32 {
        (meta.y as u32 * self.layout().width as u32 + meta.x as u32) * 4 + meta.dir as u32
    }
}

#[inline]
fn carry_code(env: &Env) -> u8 {
    env.carrying()
        .map_or(EnvMeta::CARRYING_NOTHING, |o| o as u8)
}

/// A path from a start state that cuts its loops as it grows (module
/// docs): `states[0]` is the start, `actions[i]` leads from `states[i]` to
/// `states[i + 1]`, whose cell is `cells[i]`; a state is `(pose id, world
/// hash)`. When a pushed state is one the path already holds, the loop
/// back to it is dropped. Only the latest state of each pose is looked up,
/// which finds every loop when the world changes one way only (the walks);
/// a path that undoes a change (closes a door it opened) keeps that loop,
/// which leaves it valid, only longer.
struct LoopErasedPath {
    states: Vec<(u32, u64)>,
    actions: Vec<u8>,
    cells: Vec<CellIdx>,
    /// Per pose: index into `states` where it was last pushed (checked
    /// against `states` before use, so stale entries are harmless).
    slot: Vec<u32>,
}

impl LoopErasedPath {
    fn new(world: &EdgeWorld) -> LoopErasedPath {
        LoopErasedPath {
            states: Vec::new(),
            actions: Vec::new(),
            cells: Vec::new(),
            slot: vec![u32::MAX; world.layout().cells.len() * 4],
        }
    }

    /// Starts over at `start`.
    fn start(&mut self, start: (u32, u64)) {
        self.states.clear();
        self.actions.clear();
        self.cells.clear();
        self.slot[start.0 as usize] = 0;
        self.states.push(start);
    }

    /// `a` led to `state`.
    fn push(&mut self, a: u8, state: (u32, u64)) {
        let j = self.slot[state.0 as usize] as usize;
        if j < self.states.len() && self.states[j] == state {
            // Back to a state the path already passed: erase the loop.
            self.states.truncate(j + 1);
            self.actions.truncate(j);
            self.cells.truncate(j);
        } else {
            self.slot[state.0 as usize] = self.states.len() as u32;
            self.states.push(state);
            self.actions.push(a);
            self.cells.push(CellIdx(state.0 / 4));
        }
    }
}

/// Reusable buffers of one thread's walks.
struct WalkScratch {
    env: Env,
    dirty: bool,
    /// The current walk's loop-erased path.
    path: LoopErasedPath,
}

impl WalkScratch {
    fn new(world: &EdgeWorld) -> WalkScratch {
        WalkScratch {
            env: world.template.clone(),
            dirty: false,
            path: LoopErasedPath::new(world),
        }
    }
}

/// One random walk from node `p` facing `dir`; returns the node it reached
/// (its loop-erased path is left in `s`).
fn walk(
    world: &EdgeWorld,
    p: NodeId,
    dir: u8,
    len: u32,
    rng: &mut SmallRng,
    s: &mut WalkScratch,
    h0: u64,
) -> Option<NodeId> {
    if s.dirty {
        s.env = world.template.clone();
        s.dirty = false;
    }
    let width = world.layout().width;
    s.env.teleport(world.nodes[p.index()].pose(width, dir));
    let mut hash = h0;
    s.path
        .start((world.nodes[p.index()].0 * 4 + dir as u32, h0));
    let mut choices = [0u8; 5];
    for _ in 0..len {
        let n = world.effective_actions(&s.env, &mut choices);
        let a = choices[rng.random_range(0..n)];
        let (meta, h) = world.step(&mut s.env, a, hash);
        if h != hash {
            s.dirty = true;
            hash = h;
        }
        let state = (world.pose_id(&meta), hash);
        let cell = CellIdx(state.0 / 4);
        s.path.push(a, state);
        if let Some(q) = world.node_at(cell).filter(|&q| q != p) {
            return Some(q);
        }
        if meta.flags & flags::TERMINATED != 0 {
            return None;
        }
    }
    None
}

/// The edges found by `cfg.walks_per_node` random walks from every node
/// (module docs), one per ordered pair at most, sorted by `(from, to)`,
/// each the shortest path any walk found (ties: the earliest walk); then,
/// when `cfg.shorten` is set, each shortened by [`shorten_edge`]. Nodes on
/// the exit get no outgoing edges: the episode ends there. With
/// [`EdgeSearch::Exhaustive`], the edges of [`exhaustive_edges_from`]
/// instead (every edge the walks could ever find, at its shortest).
pub fn discover_edges(world: &EdgeWorld, cfg: &PlannerConfig) -> Vec<EdgePath> {
    if cfg.edge_search == EdgeSearch::Exhaustive {
        let per_node: Vec<Vec<EdgePath>> = (0..world.nodes.len())
            .into_par_iter()
            .map(|i| exhaustive_edges_from(world, NodeId(i as u16)))
            .collect();
        return per_node.into_iter().flatten().collect();
    }
    let h0 = world.initial_hash();
    let per_node: Vec<Vec<EdgePath>> = (0..world.nodes.len())
        .into_par_iter()
        .map_init(
            || WalkScratch::new(world),
            |s, i| {
                let p = NodeId(i as u16);
                let mut best: Vec<EdgePath> = Vec::new();
                if world.layout().cells[world.nodes[i].index()] == Object::Exit as u8 {
                    return best;
                }
                let mut rng = SmallRng::seed_from_u64(sim::env_seed(cfg.seed, i as u64));
                // A fresh simulator per node bounds its step counter
                // (`PlannerConfig::validate` caps walks × length).
                s.env = world.template.clone();
                s.dirty = false;
                for w in 0..cfg.walks_per_node {
                    let dir = (w % 4) as u8;
                    let Some(q) = walk(world, p, dir, cfg.walk_len, &mut rng, s, h0) else {
                        continue;
                    };
                    match best.iter_mut().find(|e| e.to == q) {
                        Some(e) if e.actions.len() <= s.path.actions.len() => {}
                        Some(e) => {
                            e.start_dir = dir;
                            e.actions.clone_from(&s.path.actions);
                            e.cells.clone_from(&s.path.cells);
                        }
                        None => best.push(EdgePath {
                            from: p,
                            to: q,
                            start_dir: dir,
                            actions: s.path.actions.clone(),
                            cells: s.path.cells.clone(),
                        }),
                    }
                }
                best.sort_unstable_by_key(|e| e.to);
                best
            },
        )
        .collect();
    let edges: Vec<EdgePath> = per_node.into_iter().flatten().collect();
    if cfg.shorten {
        edges.par_iter().map(|e| shorten_edge(world, e)).collect()
    } else {
        edges
    }
}

/// The edge `from → to` with its path replaced by an exact shortest one
/// (module docs, "Shortening"), or `edge` itself when none is shorter.
/// Ties between facings go to the lowest `start_dir`.
pub fn shorten_edge(world: &EdgeWorld, edge: &EdgePath) -> EdgePath {
    match shortest_edge_path(world, edge.from, edge.to) {
        Some(p) if p.actions.len() <= edge.actions.len() => p,
        _ => edge.clone(),
    }
}

/// Breadth-first search over (pose, world) states for the shortest path
/// from node `from` (any facing, initial world) to node `to` that touches no
/// third node; `None` when there is none.
pub fn shortest_edge_path(world: &EdgeWorld, from: NodeId, to: NodeId) -> Option<EdgePath> {
    if to.index() >= world.nodes.len() {
        return None;
    }
    bfs_edges(world, from, Some(to)).pop()
}

/// Every edge out of `from` with its shortest path: the nodes a search over
/// (pose, world) states reaches without touching a third node, sorted by
/// target. The limit of [`discover_edges`] with unboundedly many walks.
pub fn exhaustive_edges_from(world: &EdgeWorld, from: NodeId) -> Vec<EdgePath> {
    let mut edges = bfs_edges(world, from, None);
    edges.sort_unstable_by_key(|e| e.to);
    edges
}

/// The breadth-first search of [`shortest_edge_path`] and
/// [`exhaustive_edges_from`]: from the four facings on `from` in the initial
/// world, with the walk policy's actions, never expanding a state on
/// another node or at the end of an episode. Each node other than `from`
/// is recorded at its first (shortest) arrival; with `target` set, only
/// that node, and the search stops there. Ties go to the state enqueued
/// first (lowest start facing, then action order).
fn bfs_edges(world: &EdgeWorld, from: NodeId, target: Option<NodeId>) -> Vec<EdgePath> {
    let mut found = Vec::new();
    let width = world.layout().width;
    let Some(&from_cell) = world.nodes.get(from.index()) else {
        return found;
    };
    if world.layout().cells[from_cell.index()] == Object::Exit as u8 {
        return found;
    }
    // Worlds met so far: their hash and an environment in that world.
    let mut worlds: Vec<(u64, Env)> = vec![(world.initial_hash(), world.template.clone())];
    // BFS states: (pose id, world index, parent state, action from parent).
    let mut states: Vec<(u32, u32, u32, u8)> = Vec::new();
    let mut seen: HashSet<(u32, u32)> = HashSet::new();
    let mut reached = vec![false; world.nodes.len()];
    reached[from.index()] = true;
    for dir in 0..4u8 {
        let pid = from_cell.0 * 4 + dir as u32;
        seen.insert((pid, 0));
        states.push((pid, 0, u32::MAX, 0));
    }
    let mut head = 0;
    let mut choices = [0u8; 5];
    while head < states.len() {
        let (pid, wi, _, _) = states[head];
        if let Some(q) = world.node_at(CellIdx(pid / 4)).filter(|&q| q != from) {
            // On another node: an edge (at its shortest), never expanded.
            if !std::mem::replace(&mut reached[q.index()], true) && target.is_none_or(|t| t == q) {
                let (mut actions, mut cells) = (Vec::new(), Vec::new());
                let mut i = head;
                while states[i].2 != u32::MAX {
                    actions.push(states[i].3);
                    cells.push(CellIdx(states[i].0 / 4));
                    i = states[i].2 as usize;
                }
                actions.reverse();
                cells.reverse();
                found.push(EdgePath {
                    from,
                    to: q,
                    start_dir: (states[i].0 % 4) as u8,
                    actions,
                    cells,
                });
                if target.is_some() {
                    return found;
                }
            }
            head += 1;
            continue;
        }
        let pose = CellIdx(pid / 4).pose(width, (pid % 4) as u8);
        let hash = worlds[wi as usize].0;
        let env = &mut worlds[wi as usize].1;
        env.teleport(pose);
        let n = world.effective_actions(env, &mut choices);
        let front = CellIdx(pid / 4).step(pose.dir, world.layout()).index();
        for &a in &choices[..n] {
            // Actions that may change the world step a copy; the others
            // reuse the world's environment (teleported back each time).
            let changes = a == action::PICKUP
                || a == action::TOGGLE
                || (a == action::FORWARD
                    && worlds[wi as usize].1.grid()[front] == Object::Ball as u8);
            let (meta, h, env_after) = if changes {
                let mut e = worlds[wi as usize].1.clone();
                e.teleport(pose);
                let (m, h) = world.step(&mut e, a, hash);
                (m, h, Some(e))
            } else {
                let e = &mut worlds[wi as usize].1;
                e.teleport(pose);
                let (m, h) = world.step(e, a, hash);
                (m, h, None)
            };
            let next = world.pose_id(&meta);
            if meta.flags & flags::TERMINATED != 0 && world.node_at(CellIdx(next / 4)).is_none() {
                continue;
            }
            let nw = match worlds.iter().position(|(wh, _)| *wh == h) {
                Some(k) => k as u32,
                None => {
                    let e = env_after.unwrap_or_else(|| worlds[wi as usize].1.clone());
                    worlds.push((h, e));
                    (worlds.len() - 1) as u32
                }
            };
            if seen.insert((next, nw)) {
                states.push((next, nw, head as u32, a));
            }
        }
        head += 1;
    }
    found
}

/// `edge`'s path with its loops cut out, as the walks cut theirs while
/// they grow (module docs): replayed in the simulator from `from`'s cell
/// facing `start_dir` in the initial world, every return to a (pose, world)
/// state the path already passed drops the actions in between. The result
/// takes the same states in the same order minus the loops, so it is never
/// longer and ends where `edge` ends; its `cells` are the replay's. Used on
/// paths followed by a learned policy, which may turn back and forth. The
/// erasure is the walks' own (`LoopErasedPath`).
pub fn loop_erase(world: &EdgeWorld, edge: &EdgePath) -> EdgePath {
    let start = world.nodes[edge.from.index()];
    let mut env = world.template.clone();
    env.teleport(start.pose(world.layout().width, edge.start_dir));
    let mut hash = world.initial_hash();
    let mut path = LoopErasedPath::new(world);
    path.start((start.0 * 4 + u32::from(edge.start_dir & 3), hash));
    for &a in &edge.actions {
        let (meta, h) = world.step(&mut env, a, hash);
        hash = h;
        path.push(a, (world.pose_id(&meta), hash));
    }
    EdgePath {
        from: edge.from,
        to: edge.to,
        start_dir: edge.start_dir,
        actions: path.actions,
        cells: path.cells,
    }
}

/// Replays `edge`'s path in the simulator from `from`'s cell facing
/// `start_dir` in the initial world and checks it: every action leads to
/// the recorded cell, no cell on the way is a third node, and it ends on
/// `to`. Used on graphs loaded from files. The error says what failed.
pub fn check_edge_path(world: &EdgeWorld, edge: &EdgePath) -> Result<(), String> {
    let n = world.nodes.len();
    if edge.from.index() >= n || edge.to.index() >= n || edge.from == edge.to {
        return Err(format!(
            "edge {} -> {} does not join two distinct nodes of {n}",
            edge.from, edge.to
        ));
    }
    if edge.actions.is_empty() || edge.actions.len() != edge.cells.len() || edge.start_dir > 3 {
        return Err(format!(
            "edge {} -> {}: {} actions, {} cells, start_dir {}",
            edge.from,
            edge.to,
            edge.actions.len(),
            edge.cells.len(),
            edge.start_dir
        ));
    }
    let mut env = world.template.clone();
    env.teleport(world.nodes[edge.from.index()].pose(world.layout().width, edge.start_dir));
    for (i, (&a, &c)) in edge.actions.iter().zip(&edge.cells).enumerate() {
        let meta = env.step_meta(a);
        let cell = CellIdx(world.pose_id(&meta) / 4);
        if cell != c {
            return Err(format!(
                "edge {} -> {}: action {i} leads to {cell}, the path says {c}",
                edge.from, edge.to
            ));
        }
        let last = i + 1 == edge.actions.len();
        match world.node_at(cell) {
            Some(q) if q == edge.to && last => return Ok(()),
            Some(q) if q != edge.from => {
                return Err(format!(
                    "edge {} -> {}: action {i} touches the third node {q}",
                    edge.from, edge.to
                ));
            }
            _ => {}
        }
        if meta.flags & flags::TERMINATED != 0 {
            return Err(format!(
                "edge {} -> {}: the episode ends at action {i}",
                edge.from, edge.to
            ));
        }
    }
    Err(format!(
        "edge {} -> {}: the path does not end on {}",
        edge.from, edge.to, edge.to
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pivotal::check_nodes;

    fn layout(text: &str) -> Layout {
        Layout::parse("t", text).expect("valid layout")
    }

    fn cell(l: &Layout, x: usize, y: usize) -> CellIdx {
        CellIdx::from_xy(x, y, l.width)
    }

    fn cfg(walks: u32) -> PlannerConfig {
        PlannerConfig {
            walks_per_node: walks,
            walk_len: 200,
            ..PlannerConfig::default()
        }
    }

    #[test]
    fn corridor_gives_edges_between_neighbours_only() {
        let l = layout("##########\n#>......E#\n##########\n");
        let nodes =
            check_nodes(&l, &[cell(&l, 1, 1), cell(&l, 4, 1), cell(&l, 7, 1)]).expect("nodes");
        let w = EdgeWorld::new(&l, &nodes, Task::MultiGoal);
        let edges = discover_edges(&w, &cfg(64));
        let pairs: Vec<(u16, u16, u32)> = edges
            .iter()
            .map(|e| (e.from.0, e.to.0, e.weight()))
            .collect();
        // 0↔1 and 1↔2 (3 cells apart: 3 forwards after facing the right way); never 0→2.
        assert_eq!(pairs, vec![(0, 1, 3), (1, 0, 3), (1, 2, 3), (2, 1, 3)]);
        let all = discover_edges(
            &w,
            &PlannerConfig {
                edge_search: EdgeSearch::Exhaustive,
                ..cfg(1)
            },
        );
        let all: Vec<(u16, u16, u32)> =
            all.iter().map(|e| (e.from.0, e.to.0, e.weight())).collect();
        assert_eq!(all, pairs);
        assert!(
            edges
                .iter()
                .all(|e| e.cells.last() == Some(&nodes[e.to.index()]))
        );
    }

    #[test]
    fn closed_door_needs_a_toggle_and_the_path_records_it() {
        let l = layout("#######\n#>.C.E#\n#######\n");
        let nodes = check_nodes(&l, &[cell(&l, 2, 1), cell(&l, 4, 1)]).expect("nodes");
        let w = EdgeWorld::new(&l, &nodes, Task::MultiGoal);
        let edges = discover_edges(&w, &cfg(64));
        let e = edges
            .iter()
            .find(|e| (e.from.0, e.to.0) == (0, 1))
            .expect("edge through the closed door");
        assert_eq!(
            e.actions,
            vec![action::TOGGLE, action::FORWARD, action::FORWARD]
        );
        assert_eq!(e.start_dir, 0);
        assert!(e.changes_world());
    }

    #[test]
    fn locked_door_is_crossed_only_with_the_key() {
        // No key anywhere: no edge through the locked door.
        let l = layout("#######\n#>.D.E#\n#######\n");
        let nodes = check_nodes(&l, &[cell(&l, 2, 1), cell(&l, 4, 1)]).expect("nodes");
        let w = EdgeWorld::new(&l, &nodes, Task::DoorKey);
        assert!(discover_edges(&w, &cfg(256)).is_empty());
        assert!(shortest_edge_path(&w, NodeId(0), NodeId(1)).is_none());
        // The key on the near side: the edge picks it up and unlocks the door.
        let l = layout("#######\n#.>D.E#\n#K#####\n#######\n");
        let nodes = check_nodes(&l, &[cell(&l, 2, 1), cell(&l, 4, 1)]).expect("nodes");
        let w = EdgeWorld::new(&l, &nodes, Task::DoorKey);
        let edges = discover_edges(&w, &cfg(2048));
        let e = edges
            .iter()
            .find(|e| (e.from.0, e.to.0) == (0, 1))
            .expect("edge through the unlocked door");
        assert!(
            e.actions.contains(&action::PICKUP) && e.actions.contains(&action::TOGGLE),
            "{:?}",
            e.actions
        );
        // Nothing leads back: the node beyond the door has a path back only once
        // the door is open, which its walks (from the initial world) never see.
        assert!(!edges.iter().any(|e| (e.from.0, e.to.0) == (1, 0)));
    }

    #[test]
    fn walk_edges_are_exhaustive_edges_with_the_same_weights() {
        for (maze, dk) in [(sim::Maze::Small, true), (sim::Maze::Medium, false)] {
            let l = maze.layout(dk);
            let nodes = crate::pivotal::v_rand(&l, 20, 8).expect("nodes");
            let w = EdgeWorld::new(&l, &nodes, Task::MultiGoal);
            let walks = discover_edges(&w, &cfg(256));
            let all = discover_edges(
                &w,
                &PlannerConfig {
                    edge_search: EdgeSearch::Exhaustive,
                    ..cfg(1)
                },
            );
            // Walks mostly meet the nearest nodes first; the search finds every
            // pair joined by some path around the other nodes.
            assert!(
                !walks.is_empty() && walks.len() <= all.len(),
                "{} of {}",
                walks.len(),
                all.len()
            );
            for e in &walks {
                let x = all
                    .iter()
                    .find(|x| (x.from, x.to) == (e.from, e.to))
                    .expect("a walk edge is a possible edge");
                assert_eq!(x.weight(), e.weight(), "{} -> {}", e.from, e.to);
            }
            for e in &all {
                check_edge_path(&w, e).expect("exhaustive paths replay");
            }
        }
    }

    #[test]
    fn same_seed_same_edges_on_any_thread_count() {
        let l = sim::Maze::Small.layout(true);
        let nodes = crate::pivotal::v_rand(&l, 12, 5).expect("nodes");
        let w = EdgeWorld::new(&l, &nodes, Task::DoorKey);
        for shorten in [false, true] {
            let c = PlannerConfig {
                shorten,
                ..cfg(128)
            };
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .expect("pool")
                .install(|| discover_edges(&w, &c));
            let many = rayon::ThreadPoolBuilder::new()
                .num_threads(4)
                .build()
                .expect("pool")
                .install(|| discover_edges(&w, &c));
            assert_eq!(one, many);
            assert!(!one.is_empty());
            if !shorten {
                // Raw walk paths depend on the seed (shortened ones are exact).
                assert_ne!(
                    one,
                    discover_edges(
                        &w,
                        &PlannerConfig {
                            seed: 1,
                            ..c.clone()
                        }
                    ),
                    "the seed matters"
                );
            }
        }
    }

    #[test]
    fn shortening_never_lengthens_and_matches_bfs() {
        let l = sim::Maze::Small.layout(false);
        let nodes = crate::pivotal::v_rand(&l, 8, 1).expect("nodes");
        let w = EdgeWorld::new(&l, &nodes, Task::MultiGoal);
        let raw = discover_edges(
            &w,
            &PlannerConfig {
                shorten: false,
                ..cfg(256)
            },
        );
        for e in &raw {
            let s = shorten_edge(&w, e);
            assert!(s.weight() <= e.weight());
            assert_eq!((s.from, s.to), (e.from, e.to));
            assert_eq!(
                s.weight(),
                shortest_edge_path(&w, e.from, e.to)
                    .expect("reachable")
                    .weight()
            );
            assert!(
                s.cells[..s.cells.len() - 1]
                    .iter()
                    .all(|&c| w.node_at(c).is_none_or(|n| n == e.from))
            );
        }
    }
}
