//! The maze's structure, to judge a node set against: its **passages**
//! (doorways and 1-wide corridors between rooms) and its **rooms**, and
//! how well a world graph routes (Shang et al. 2019, section 5, "Benefit of
//! Learned Pivotal States": `V_p` against `V_rand` of the same size).
//!
//! Pure geometry on the layout's initial grid, no learning:
//!
//! - a *narrow* cell is a free cell with walls on both sides along one axis
//!   and free cells on both sides along the other (a dead end is not
//!   narrow); 4-connected narrow cells form a candidate passage;
//! - the *rooms* are the 4-connected components of the free cells once the
//!   candidates are removed; a candidate is a **passage** when it touches
//!   two or more rooms (a notch in a room's wall touches only one and is
//!   given back to its room);
//! - a node set *covers* a passage when a node stands on it or on a free
//!   cell 4-adjacent to it, and a room when a node stands in it.
//!
//! [`MazeStructure::random_coverage`] is the chance level: the mean
//! coverage of many uniform draws of as many cells. [`routing_quality`]
//! measures a world graph as a router: over random pairs of cells, the
//! actions of "walk to the nearest node, follow the graph to the node
//! nearest the target, walk to the target" against the true shortest path
//! (turns count, as in the edge weights).

use std::collections::VecDeque;

use rand::rngs::SmallRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use sim::{Layout, Object, Pose, action};

use crate::ids::{CellIdx, NodeId};
use crate::world_graph::{Route, WorldGraph};

/// `room_of` / `passage_of` entry of a cell that is in none.
const NONE: u32 = u32::MAX;

/// Passages and rooms of a layout (module docs).
#[derive(Debug, Clone)]
pub struct MazeStructure {
    width: usize,
    free: Vec<bool>,
    passages: Vec<Vec<u32>>,
    rooms: Vec<Vec<u32>>,
    passage_of: Vec<u32>,
    room_of: Vec<u32>,
}

/// How much of the structure a node set covers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StructureCoverage {
    /// Fraction of the passages with a node on or next to them.
    pub passage_share: f64,
    /// Fraction of the rooms holding a node.
    pub room_share: f64,
}

/// True for cells an agent can walk on in the initial grid.
fn passable(layout: &Layout, i: usize) -> bool {
    let c = layout.cells[i];
    c != Object::Wall as u8 && c != Object::Lava as u8
}

impl MazeStructure {
    /// Finds the passages and rooms of `layout` (cells reachable from the
    /// start only).
    pub fn new(layout: &Layout) -> MazeStructure {
        let (w, h) = (layout.width, layout.height);
        let reach = layout
            .reachable_from(layout.cell_index(layout.start.x as usize, layout.start.y as usize));
        let free: Vec<bool> = (0..w * h)
            .map(|i| reach[i] && passable(layout, i))
            .collect();
        let open = |x: i64, y: i64| {
            x >= 0
                && y >= 0
                && (x as usize) < w
                && (y as usize) < h
                && free[y as usize * w + x as usize]
        };
        let narrow: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                free[i]
                    && ((!open(x - 1, y) && !open(x + 1, y) && open(x, y - 1) && open(x, y + 1))
                        || (!open(x, y - 1) && !open(x, y + 1) && open(x - 1, y) && open(x + 1, y)))
            })
            .collect();
        let candidates = components(w, h, |i| narrow[i]);
        let mut in_candidate = vec![false; w * h];
        for c in &candidates {
            for &i in c {
                in_candidate[i as usize] = true;
            }
        }
        let rooms_of = |skip: &[bool]| components(w, h, |i| free[i] && !skip[i]);
        let first_rooms = rooms_of(&in_candidate);
        let mut room_of = vec![NONE; w * h];
        for (r, cells) in first_rooms.iter().enumerate() {
            for &i in cells {
                room_of[i as usize] = r as u32;
            }
        }
        let touching = |cells: &[u32], room_of: &[u32]| {
            let mut rooms: Vec<u32> = cells
                .iter()
                .flat_map(|&i| neighbours(w, h, i as usize))
                .map(|j| room_of[j])
                .filter(|&r| r != NONE)
                .collect();
            rooms.sort_unstable();
            rooms.dedup();
            rooms.len()
        };
        let passages: Vec<Vec<u32>> = candidates
            .into_iter()
            .filter(|c| touching(c, &room_of) >= 2)
            .collect();
        let mut passage_of = vec![NONE; w * h];
        for (p, cells) in passages.iter().enumerate() {
            for &i in cells {
                passage_of[i as usize] = p as u32;
            }
        }
        // Notches touching one room are part of it: recompute the rooms with
        // only the passages removed.
        let in_passage: Vec<bool> = passage_of.iter().map(|&p| p != NONE).collect();
        let rooms = rooms_of(&in_passage);
        let mut room_of = vec![NONE; w * h];
        for (r, cells) in rooms.iter().enumerate() {
            for &i in cells {
                room_of[i as usize] = r as u32;
            }
        }
        MazeStructure {
            width: w,
            free,
            passages,
            rooms,
            passage_of,
            room_of,
        }
    }

    /// The passages, each as its cells in index order.
    pub fn passages(&self) -> &[Vec<u32>] {
        &self.passages
    }

    /// The rooms, each as its cells in index order.
    pub fn rooms(&self) -> &[Vec<u32>] {
        &self.rooms
    }

    /// Cells of the rooms and passages (the free cells reachable from the start).
    pub fn free_cells(&self) -> Vec<u32> {
        (0..self.free.len() as u32)
            .filter(|&i| self.free[i as usize])
            .collect()
    }

    /// The passage `cell` lies on, if any.
    pub fn passage_of(&self, cell: u32) -> Option<usize> {
        self.passage_of
            .get(cell as usize)
            .filter(|&&p| p != NONE)
            .map(|&p| p as usize)
    }

    /// The room `cell` lies in, if any.
    pub fn room_of(&self, cell: u32) -> Option<usize> {
        self.room_of
            .get(cell as usize)
            .filter(|&&r| r != NONE)
            .map(|&r| r as usize)
    }

    /// The passages `cell` is on or next to (4-adjacent).
    fn passages_near(&self, cell: u32, out: &mut Vec<usize>) {
        out.clear();
        let h = self.free.len() / self.width;
        let i = cell as usize;
        if i >= self.free.len() {
            return;
        }
        for j in std::iter::once(i).chain(neighbours(self.width, h, i)) {
            if let Some(p) = self.passage_of(j as u32)
                && !out.contains(&p)
            {
                out.push(p);
            }
        }
    }

    /// The share of passages and rooms `nodes` (cell indices) cover.
    pub fn coverage(&self, nodes: &[u32]) -> StructureCoverage {
        let mut passage_hit = vec![false; self.passages.len()];
        let mut room_hit = vec![false; self.rooms.len()];
        let mut near = Vec::new();
        for &c in nodes {
            self.passages_near(c, &mut near);
            for &p in &near {
                passage_hit[p] = true;
            }
            if let Some(r) = self.room_of(c) {
                room_hit[r] = true;
            }
        }
        let share = |hits: &[bool]| {
            if hits.is_empty() {
                1.0
            } else {
                hits.iter().filter(|&&h| h).count() as f64 / hits.len() as f64
            }
        };
        StructureCoverage {
            passage_share: share(&passage_hit),
            room_share: share(&room_hit),
        }
    }

    /// The chance level of [`Self::coverage`]: its mean over `draws` sets
    /// of `k` distinct free cells drawn uniformly with `seed`.
    pub fn random_coverage(&self, k: usize, draws: usize, seed: u64) -> StructureCoverage {
        let mut cells = self.free_cells();
        let k = k.min(cells.len());
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut passages, mut rooms) = (0.0, 0.0);
        for _ in 0..draws.max(1) {
            let (chosen, _) = cells.partial_shuffle(&mut rng, k);
            let c = self.coverage(chosen);
            passages += c.passage_share;
            rooms += c.room_share;
        }
        let n = draws.max(1) as f64;
        StructureCoverage {
            passage_share: passages / n,
            room_share: rooms / n,
        }
    }

    /// Text picture: `#` wall, `P` passage cell, `a`–`z` rooms (cycling),
    /// `*` a node of `nodes`. For test and log output.
    pub fn ascii(&self, nodes: &[u32]) -> String {
        let mut s = String::new();
        for (i, &free) in self.free.iter().enumerate() {
            let ch = if nodes.contains(&(i as u32)) {
                '*'
            } else if !free {
                '#'
            } else if self.passage_of(i as u32).is_some() {
                'P'
            } else {
                self.room_of(i as u32)
                    .map_or('?', |r| char::from(b'a' + (r % 26) as u8))
            };
            s.push(ch);
            if (i + 1) % self.width == 0 {
                s.push('\n');
            }
        }
        s
    }
}

fn neighbours(w: usize, h: usize, i: usize) -> impl Iterator<Item = usize> {
    let (x, y) = ((i % w) as i64, (i / w) as i64);
    [(1, 0), (0, 1), (-1, 0), (0, -1)]
        .into_iter()
        .map(move |(dx, dy)| (x + dx, y + dy))
        .filter(move |&(x, y)| x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h)
        .map(move |(x, y)| y as usize * w + x as usize)
}

/// 4-connected components of the cells where `inside` holds, each in
/// index order, ordered by their first cell.
fn components(w: usize, h: usize, inside: impl Fn(usize) -> bool) -> Vec<Vec<u32>> {
    let mut seen = vec![false; w * h];
    let mut out = Vec::new();
    for start in 0..w * h {
        if seen[start] || !inside(start) {
            continue;
        }
        seen[start] = true;
        let mut stack = vec![start];
        let mut cells = Vec::new();
        while let Some(i) = stack.pop() {
            cells.push(i as u32);
            for j in neighbours(w, h, i) {
                if !seen[j] && inside(j) {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        cells.sort_unstable();
        out.push(cells);
    }
    out
}

/// Shortest action counts from one pose to every pose (`cell · 4 + dir`)
/// with turn left, turn right and forward, through passable cells:
/// `u32::MAX` where unreachable.
fn pose_distances(layout: &Layout, from: Pose) -> Vec<u32> {
    let w = layout.width;
    let mut dist = vec![u32::MAX; layout.cells.len() * 4];
    let start = (from.y as usize * w + from.x as usize) * 4 + (from.dir & 3) as usize;
    dist[start] = 0;
    let mut queue = VecDeque::from([start]);
    while let Some(p) = queue.pop_front() {
        let (cell, dir) = (p / 4, (p % 4) as u8);
        let (dx, dy) = Pose::DIR_VEC[dir as usize];
        let (x, y) = ((cell % w) as i32 + dx, (cell / w) as i32 + dy);
        let ahead = (x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < layout.height)
            .then(|| y as usize * w + x as usize)
            .filter(|&j| passable(layout, j));
        let next = [
            Some(cell * 4 + ((dir + 3) & 3) as usize),
            Some(cell * 4 + ((dir + 1) & 3) as usize),
            ahead.map(|j| j * 4 + dir as usize),
        ];
        for q in next.into_iter().flatten() {
            if dist[q] == u32::MAX {
                dist[q] = dist[p] + 1;
                queue.push_back(q);
            }
        }
    }
    dist
}

fn to_cell(dist: &[u32], cell: u32) -> u32 {
    (0..4)
        .map(|d| dist[cell as usize * 4 + d])
        .min()
        .unwrap_or(u32::MAX)
}

/// How well a world graph routes between cells ([`routing_quality`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RoutingQuality {
    /// Mean of route actions / shortest actions over the routed pairs (1 is
    /// perfect).
    pub mean_stretch: f64,
    /// Fraction of the pairs the graph could route at all.
    pub routed: f64,
    /// Pairs drawn.
    pub pairs: usize,
}

/// Routes `pairs` random pairs of distinct free cells (random start facing,
/// drawn with `seed`) through `graph`: from the start to its nearest node
/// ([`WorldGraph::route_from_pose_into`]), along the graph to the node
/// nearest the target (fewest actions from it), then the shortest way to
/// the target. The stretch of a pair is that route's action count over the
/// shortest path's. Pairs the graph cannot route count in
/// [`RoutingQuality::routed`] only.
pub fn routing_quality(graph: &WorldGraph, pairs: usize, seed: u64) -> RoutingQuality {
    let layout = graph.layout();
    let structure = MazeStructure::new(layout);
    let cells = structure.free_cells();
    let w = layout.width;
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut route = Route::with_capacity(1024, 64);
    let (mut sum, mut routed) = (0.0, 0usize);
    let pose_of = |cell: u32, dir: u8| CellIdx(cell).pose(w, dir);
    // Distances into each cell from every node pose, for the last leg.
    let from_node: Vec<[Vec<u32>; 4]> = graph
        .nodes()
        .iter()
        .map(|&n| [0u8, 1, 2, 3].map(|d| pose_distances(layout, pose_of(n.0, d))))
        .collect();
    let mut drawn = 0;
    while drawn < pairs && cells.len() >= 2 {
        let s = cells[rng.random_range(0..cells.len())];
        let t = cells[rng.random_range(0..cells.len())];
        if s == t {
            continue;
        }
        drawn += 1;
        let start = pose_of(s, rng.random_range(0..4));
        let shortest = to_cell(&pose_distances(layout, start), t);
        let nearest = (0..graph.num_nodes()).min_by_key(|&k| {
            (0..4)
                .map(|d| to_cell(&from_node[k][d], t))
                .min()
                .unwrap_or(u32::MAX)
        });
        let Some(b) = nearest else { break };
        if graph
            .route_from_pose_into(start, NodeId(b as u16), graph.initial_world(), &mut route)
            .is_err()
        {
            continue;
        }
        let facing = route.actions().iter().fold(start.dir, |d, &a| match a {
            action::LEFT => (d + 3) & 3,
            action::RIGHT => (d + 1) & 3,
            _ => d,
        });
        let last = to_cell(&from_node[b][facing as usize], t);
        if last == u32::MAX || shortest == 0 || shortest == u32::MAX {
            continue;
        }
        routed += 1;
        sum += (route.len() as u32 + last) as f64 / shortest as f64;
    }
    RoutingQuality {
        mean_stretch: if routed == 0 {
            f64::INFINITY
        } else {
            sum / routed as f64
        },
        routed: routed as f64 / drawn.max(1) as f64,
        pairs: drawn,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::Maze;

    #[test]
    fn small_maze_has_four_doorways_and_four_rooms() {
        let layout = Maze::Small.layout(false);
        let s = MazeStructure::new(&layout);
        let w = layout.width as u32;
        let mut doorways: Vec<u32> = s.passages().iter().map(|p| p[0]).collect();
        doorways.sort_unstable();
        assert!(
            s.passages().iter().all(|p| p.len() == 1),
            "{}",
            s.ascii(&[])
        );
        assert_eq!(doorways, vec![3 * w + 6, 6 * w + 3, 6 * w + 9, 9 * w + 6]);
        assert_eq!(s.rooms().len(), 4, "{}", s.ascii(&[]));
        // A node on a doorway covers it, one next to it too; rooms by cell.
        let c = s.coverage(&[3 * w + 6, 6 * w + 4 + w]);
        assert_eq!(c.passage_share, 0.25);
        let c = s.coverage(&[3 * w + 5, 7 * w + 9, w + 1]);
        assert_eq!((c.passage_share, c.room_share), (0.5, 0.5));
        let all = s.coverage(&s.free_cells());
        assert_eq!((all.passage_share, all.room_share), (1.0, 1.0));
        let chance = s.random_coverage(1, 2000, 1);
        // One cell: on or next to a doorway with probability 12 / 104.
        assert!(
            (chance.passage_share * 4.0 - 12.0 / 104.0).abs() < 0.03,
            "{chance:?}"
        );
    }

    #[test]
    fn large_maze_corridor_is_one_passage() {
        let layout = Maze::Large.layout(false);
        let s = MazeStructure::new(&layout);
        let long: Vec<&Vec<u32>> = s.passages().iter().filter(|p| p.len() > 1).collect();
        assert!(!long.is_empty(), "{}", s.ascii(&[]));
        for p in s.passages() {
            assert!(p.iter().all(|&c| s.room_of(c).is_none()));
        }
    }

    #[test]
    fn a_graph_over_every_cell_routes_almost_optimally() {
        let layout = Maze::Small.layout(false);
        let s = MazeStructure::new(&layout);
        let nodes: Vec<CellIdx> = s.free_cells().into_iter().step_by(3).map(CellIdx).collect();
        let cfg = crate::PlannerConfig {
            candidates: crate::CandidateSet::Given,
            ..Default::default()
        };
        let graph = WorldGraph::build(&layout, &cfg, &nodes).expect("graph builds");
        let q = routing_quality(&graph, 200, 3);
        assert_eq!(q.pairs, 200);
        assert!(q.routed > 0.99, "{q:?}");
        assert!((1.0..1.6).contains(&q.mean_stretch), "{q:?}");
    }
}
