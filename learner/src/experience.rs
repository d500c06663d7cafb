//! The agent's experience of the maze's dynamics, and the routes it knows
//! through it (Shang et al. 2019, section 3.2: "the agent can
//! straightforwardly document and reuse the paths" it took).
//!
//! [`Experience`] books every transition the agent observed during
//! discovery — pose, action → pose, from its random walks, its path
//! replays and `π_g`'s episodes — and nothing else: no map is consulted.
//! World graph discovery runs in a deterministic world (the simulator),
//! so a sequence of observed transitions is a trajectory the agent can
//! execute again, action for action.
//!
//! Two uses:
//! - [`Experience::shortest_paths_from`]: the shortest known action path
//!   from the start to each cell, which the walks replay to reach pivotal
//!   states (`DiscoveryConfig::shortest_known_paths`);
//! - [`KnownRoutes::chain`]: **goal chains**, trajectories that reach
//!   several goals in turn, each along a shortest known route with its ties
//!   broken at random. This is what a trained `π_g` produces (section 3.2:
//!   `π_g` reaches goals; its trajectories train the latent model, section
//!   3.1), and what the latent model needs to find pivotal states: a
//!   shortest turn-and-move route has as few turns as it can, so inside a
//!   room its two ends pin it down, and what they do not pin down is where
//!   it crosses into the next room (`learner/tests/pivotal_doorways.rs`).
//!   On this machine's budget `π_g` reaches goals within a room only
//!   (docs/implementation_details.md, "Pivotal states"), so the loop takes
//!   these routes from the experience it has instead of waiting for `π_g`
//!   to learn them (`DiscoveryConfig::goal_chains`).

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};

use rand::Rng;
use rand::rngs::SmallRng;
use serde::{Deserialize, Serialize};

use crate::vae::{AgentPose, Trajectory};

/// Every transition observed so far: `transition_key` of (pose, action)
/// → the pose it led to as `(cell, direction, carried)`. Serialised as that
/// map (the checkpoint's `experience` field).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Experience {
    transitions: BTreeMap<u64, (u32, u8, u8)>,
}

/// The key of (pose, action): the pose's cell, direction and carried
/// object, then the action, one per byte but the cell. Keys of one pose are
/// contiguous, in action order.
fn transition_key(pose: AgentPose, action: u8) -> u64 {
    (u64::from(pose.cell) << 24)
        | (u64::from(pose.direction) << 16)
        | (u64::from(pose.carried) << 8)
        | u64::from(action)
}

impl Experience {
    /// Books that `action` took the agent from `before` to `after` (the
    /// first observation stands: the world is deterministic).
    pub fn observe(&mut self, before: AgentPose, action: u8, after: AgentPose) {
        self.transitions
            .entry(transition_key(before, action))
            .or_insert((after.cell, after.direction, after.carried));
    }

    /// Books every step of `t`.
    pub fn observe_trajectory(&mut self, t: &Trajectory) {
        for (k, &a) in t.actions.iter().enumerate() {
            self.observe(t.states[k], a, t.states[k + 1]);
        }
    }

    /// Transitions observed.
    pub fn len(&self) -> usize {
        self.transitions.len()
    }

    /// True before anything was observed.
    pub fn is_empty(&self) -> bool {
        self.transitions.is_empty()
    }

    /// The observed outcomes of the actions taken in `pose`, in action order.
    fn successors(&self, pose: AgentPose) -> impl Iterator<Item = (u8, AgentPose)> + '_ {
        let from = transition_key(pose, 0);
        self.transitions
            .range(from..from + 256)
            .map(|(&key, &(cell, direction, carried))| {
                (
                    (key & 0xff) as u8,
                    AgentPose {
                        cell,
                        direction,
                        carried,
                    },
                )
            })
    }

    /// The shortest known action path from `start` to each cell reached
    /// (any facing; not the start's own cell): breadth-first over poses,
    /// actions in ascending order, so the result is a function of the
    /// experience alone.
    pub fn shortest_paths_from(&self, start: AgentPose) -> BTreeMap<u32, Vec<u8>> {
        let mut parent: HashMap<AgentPose, (AgentPose, u8)> = HashMap::new();
        let mut seen = HashSet::from([start]);
        let mut queue = VecDeque::from([start]);
        let mut paths = BTreeMap::new();
        let mut reached_cells = HashSet::from([start.cell]);
        while let Some(p) = queue.pop_front() {
            for (a, q) in self.successors(p) {
                if !seen.insert(q) {
                    continue;
                }
                parent.insert(q, (p, a));
                queue.push_back(q);
                if reached_cells.insert(q.cell) {
                    // The first pose of a cell reached is one of its nearest.
                    let mut path = Vec::new();
                    let mut at = q;
                    while let Some(&(before, a)) = parent.get(&at) {
                        path.push(a);
                        at = before;
                    }
                    path.reverse();
                    paths.insert(q.cell, path);
                }
            }
        }
        paths
    }

    /// The experience as a graph over poses, for route queries.
    pub fn routes(&self) -> KnownRoutes {
        let mut poses: Vec<AgentPose> = Vec::new();
        let mut index: HashMap<AgentPose, usize> = HashMap::new();
        let mut id = |p: AgentPose, poses: &mut Vec<AgentPose>| {
            *index.entry(p).or_insert_with(|| {
                poses.push(p);
                poses.len() - 1
            })
        };
        let mut edges = Vec::with_capacity(self.transitions.len());
        for (&key, &(cell, direction, carried)) in &self.transitions {
            let from = AgentPose {
                cell: (key >> 24) as u32,
                direction: ((key >> 16) & 0xff) as u8,
                carried: ((key >> 8) & 0xff) as u8,
            };
            let to = AgentPose {
                cell,
                direction,
                carried,
            };
            if from == to {
                // A step into a wall: no route uses it.
                continue;
            }
            let (i, j) = (id(from, &mut poses), id(to, &mut poses));
            edges.push((i, (key & 0xff) as u8, j));
        }
        let mut next = vec![Vec::new(); poses.len()];
        let mut prev = vec![Vec::new(); poses.len()];
        for (i, a, j) in edges {
            next[i].push(j);
            prev[j].push((a, i));
        }
        KnownRoutes { poses, next, prev }
    }
}

/// How far the goals of a [`KnownRoutes::chain`] lie, and how many.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChainShape {
    /// Goals reached in turn.
    pub legs: usize,
    /// Fewest actions from one goal (or the start) to the next, along the
    /// shortest known route.
    pub min_actions: u32,
    /// Most actions from one goal to the next.
    pub max_actions: u32,
}

/// The observed transitions as a graph over poses ([`Experience::routes`]).
#[derive(Debug, Clone)]
pub struct KnownRoutes {
    poses: Vec<AgentPose>,
    /// Poses one observed action leads to.
    next: Vec<Vec<usize>>,
    /// (action, pose) pairs that lead here.
    prev: Vec<Vec<(u8, usize)>>,
}

impl KnownRoutes {
    /// Poses the agent has been in (and moved from or to).
    pub fn num_poses(&self) -> usize {
        self.poses.len()
    }

    /// Actions from pose `from` to every pose along known transitions
    /// (`u32::MAX` where no known route leads).
    fn distances_from(&self, from: usize) -> Vec<u32> {
        let mut dist = vec![u32::MAX; self.poses.len()];
        dist[from] = 0;
        let mut queue = VecDeque::from([from]);
        while let Some(p) = queue.pop_front() {
            for &q in &self.next[p] {
                if dist[q] == u32::MAX {
                    dist[q] = dist[p] + 1;
                    queue.push_back(q);
                }
            }
        }
        dist
    }

    /// A goal chain from a random known pose: `shape.legs` goals in turn,
    /// each a cell drawn uniformly among those whose shortest known route
    /// from where the agent stands takes `min_actions..=max_actions`
    /// actions, reached along a shortest known route with ties broken at
    /// random. Stops early where no cell lies in range; `None` when not
    /// even the first leg can be drawn.
    pub fn chain(&self, shape: ChainShape, rng: &mut SmallRng) -> Option<Trajectory> {
        if self.poses.is_empty() {
            return None;
        }
        let mut at = rng.random_range(0..self.poses.len());
        let mut states = vec![self.poses[at]];
        let mut actions = Vec::new();
        for _ in 0..shape.legs {
            let dist = self.distances_from(at);
            // Each cell's nearest poses, then the cells in range.
            let mut nearest: BTreeMap<u32, (u32, Vec<usize>)> = BTreeMap::new();
            for (i, &d) in dist.iter().enumerate() {
                if d == u32::MAX || d == 0 {
                    continue;
                }
                let e = nearest
                    .entry(self.poses[i].cell)
                    .or_insert((u32::MAX, Vec::new()));
                if d < e.0 {
                    *e = (d, vec![i]);
                } else if d == e.0 {
                    e.1.push(i);
                }
            }
            let here = self.poses[at].cell;
            let in_range: Vec<&Vec<usize>> = nearest
                .iter()
                .filter(|&(&cell, &(d, _))| {
                    cell != here && (shape.min_actions..=shape.max_actions).contains(&d)
                })
                .map(|(_, (_, ends))| ends)
                .collect();
            if in_range.is_empty() {
                break;
            }
            let ends = in_range[rng.random_range(0..in_range.len())];
            let goal = ends[rng.random_range(0..ends.len())];
            // Back from the goal, a random predecessor one action nearer.
            let mut leg = Vec::with_capacity(dist[goal] as usize);
            let mut q = goal;
            while q != at {
                let before: Vec<&(u8, usize)> = self.prev[q]
                    .iter()
                    .filter(|&&(_, p)| dist[p] != u32::MAX && dist[p] + 1 == dist[q])
                    .collect();
                let &(a, p) = before[rng.random_range(0..before.len())];
                leg.push((a, q));
                q = p;
            }
            for &(a, q) in leg.iter().rev() {
                actions.push(a);
                states.push(self.poses[q]);
            }
            at = goal;
        }
        (!actions.is_empty()).then_some(Trajectory { states, actions })
    }
}

/// Fixtures shared by the tests of the modules that use [`Experience`].
#[cfg(test)]
pub(crate) mod test_support {
    use super::*;
    use sim::action::{FORWARD, LEFT, RIGHT};

    /// A pose carrying nothing.
    pub(crate) fn pose(cell: u32, direction: u8) -> AgentPose {
        AgentPose {
            cell,
            direction,
            carried: 0,
        }
    }

    /// The 3×2 room of `#####/#>..#/#..E#/#####`: cells 6, 7, 8 on top,
    /// 11, 12, 13 below, with a walk's transitions.
    pub(crate) fn walked() -> Experience {
        let mut e = Experience::default();
        e.observe(pose(6, 0), FORWARD, pose(7, 0));
        e.observe(pose(7, 0), FORWARD, pose(8, 0));
        e.observe(pose(8, 0), RIGHT, pose(8, 1));
        e.observe(pose(8, 1), FORWARD, pose(13, 1));
        // A detour: down first, then along the bottom row.
        e.observe(pose(6, 0), RIGHT, pose(6, 1));
        e.observe(pose(6, 1), FORWARD, pose(11, 1));
        e.observe(pose(11, 1), LEFT, pose(11, 0));
        e.observe(pose(11, 0), FORWARD, pose(12, 0));
        // Seen, but never from a pose the agent can reach from the start.
        e.observe(pose(12, 2), FORWARD, pose(11, 2));
        // Into a wall: no move.
        e.observe(pose(8, 0), FORWARD, pose(8, 0));
        e
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::{pose, walked};
    use super::*;
    use rand::SeedableRng;
    use sim::action::{FORWARD, LEFT, RIGHT};

    #[test]
    fn shortest_known_paths_follow_observed_transitions_only() {
        let paths = walked().shortest_paths_from(pose(6, 0));
        assert_eq!(paths[&13], vec![FORWARD, FORWARD, RIGHT, FORWARD]);
        assert_eq!(paths[&12], vec![RIGHT, FORWARD, LEFT, FORWARD]);
        assert_eq!(paths[&8], vec![FORWARD, FORWARD]);
        assert_eq!(paths[&11], vec![RIGHT, FORWARD]);
        assert!(!paths.contains_key(&6), "no path to the start's own cell");
    }

    #[test]
    fn a_chain_is_a_sequence_of_observed_transitions_along_shortest_routes() {
        let e = walked();
        let routes = e.routes();
        let shape = ChainShape {
            legs: 2,
            min_actions: 1,
            max_actions: 10,
        };
        let mut rng = SmallRng::seed_from_u64(3);
        let mut chains = 0;
        for _ in 0..200 {
            let Some(t) = routes.chain(shape, &mut rng) else {
                continue;
            };
            chains += 1;
            assert_eq!(t.states.len(), t.actions.len() + 1);
            for (k, &a) in t.actions.iter().enumerate() {
                let seen: Vec<_> = e.successors(t.states[k]).collect();
                assert!(
                    seen.contains(&(a, t.states[k + 1])),
                    "step {k} of {t:?} was never observed"
                );
            }
            // From the start pose, the shortest route to cell 13 is the
            // top row: a chain never takes the detour to get there first.
            if t.states[0] == pose(6, 0) && t.states.iter().any(|s| s.cell == 13) {
                let first = t.states.iter().position(|s| s.cell == 13).expect("on it");
                assert_eq!(first, 4, "{t:?}");
            }
        }
        assert!(chains > 100, "{chains} chains of 200 draws");
    }

    #[test]
    fn goals_out_of_range_end_the_chain() {
        let routes = walked().routes();
        let far = ChainShape {
            legs: 3,
            min_actions: 50,
            max_actions: 60,
        };
        let mut rng = SmallRng::seed_from_u64(0);
        assert!((0..50).all(|_| routes.chain(far, &mut rng).is_none()));
        assert!(
            Experience::default()
                .routes()
                .chain(far, &mut rng)
                .is_none()
        );
    }

    #[test]
    fn ties_are_broken_both_ways() {
        // A 2×2 room walked fully. Facing the wall on the left of its
        // top-left cell, the cell behind is three actions away either way
        // round: turn left twice or right twice, then forward.
        let layout = sim::Layout::parse("room", "####\n#>.#\n#.E#\n####\n").expect("layout");
        let w = layout.width as u32;
        let free = [w + 1, w + 2, 2 * w + 1, 2 * w + 2];
        let mut e = Experience::default();
        for &c in &free {
            for d in 0..4u8 {
                e.observe(pose(c, d), LEFT, pose(c, (d + 3) & 3));
                e.observe(pose(c, d), RIGHT, pose(c, (d + 1) & 3));
                let (dx, dy) = sim::Pose::DIR_VEC[d as usize];
                let n = (c as i64 + i64::from(dx) + i64::from(dy) * i64::from(w)) as u32;
                let to = if free.contains(&n) { n } else { c };
                e.observe(pose(c, d), FORWARD, pose(to, d));
            }
        }
        let routes = e.routes();
        let shape = ChainShape {
            legs: 1,
            min_actions: 3,
            max_actions: 3,
        };
        let mut rng = SmallRng::seed_from_u64(1);
        let mut seen = HashSet::new();
        for _ in 0..1000 {
            if let Some(t) = routes.chain(shape, &mut rng)
                && t.states[0] == pose(free[0], 2)
            {
                assert_eq!(t.states.last().expect("non-empty").cell, free[1]);
                seen.insert(t.actions.clone());
            }
        }
        let both = HashSet::from([vec![LEFT, LEFT, FORWARD], vec![RIGHT, RIGHT, FORWARD]]);
        assert_eq!(seen, both);
    }
}
