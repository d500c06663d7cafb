//! All-pairs shortest paths over the world graph's edge weights by dynamic
//! programming (Shang et al. 2019, arXiv:1907.00664, sections 3.3 and 4.2:
//! "traversal between pivotal states are planned basing on the weight
//! information using dynamic programming").
//!
//! Floyd–Warshall: after round `k`, `dist[i][j]` is the shortest distance
//! from `i` to `j` using only intermediate nodes `< k`:
//!
//! ```text
//! dist[i][j] ← min(dist[i][j], dist[i][k] + dist[k][j])
//! next[i][j] ← next[i][k]      when the minimum changes
//! ```
//!
//! `next[i][j]` is the first hop on a shortest path from `i` to `j`, so a
//! route is read off hop by hop without search. Row `k` does not change in
//! round `k` (`dist[k][k] = 0`), so the rows of a round are updated in
//! parallel; each row's result depends only on its own values and row `k`,
//! so the tables do not depend on the thread count. Only strict
//! improvements replace an entry: ties keep the earlier path.
//!
//! Works on plain data (node count and `(from, to, weight)` triples); the
//! world graph owns the edges and their paths.

use rayon::prelude::*;

use crate::ids::NodeId;

/// Distance of a pair with no path (`u32::MAX`): the wire format's constant
/// itself ([`shm_schemas::UNREACHABLE`]), so planner tables and route
/// responses cannot drift apart.
pub use shm_schemas::UNREACHABLE;

/// `next` entry of a pair with no path.
const NO_HOP: u16 = u16::MAX;

/// Below this many nodes a round is cheaper than rayon's fork-join.
const PARALLEL_MIN_NODES: usize = 128;

/// The all-pairs distance and next-hop tables, row-major `n × n`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ShortestPaths {
    n: usize,
    dist: Vec<u32>,
    next: Vec<u16>,
}

impl ShortestPaths {
    /// Runs Floyd–Warshall over `n` nodes and the directed, weighted
    /// `edges` `(from, to, weight)`. Self-loops are ignored; of parallel
    /// edges the lightest counts. `n` must be below `u16::MAX`.
    pub fn floyd_warshall(
        n: usize,
        edges: impl IntoIterator<Item = (NodeId, NodeId, u32)>,
    ) -> ShortestPaths {
        debug_assert!(n < NO_HOP as usize);
        let mut dist = vec![UNREACHABLE; n * n];
        let mut next = vec![NO_HOP; n * n];
        for i in 0..n {
            dist[i * n + i] = 0;
            next[i * n + i] = i as u16;
        }
        for (a, b, w) in edges {
            let (a, b) = (a.index(), b.index());
            if a != b && a < n && b < n && w < dist[a * n + b] {
                dist[a * n + b] = w;
                next[a * n + b] = b as u16;
            }
        }
        let mut row_k = vec![0u32; n];
        for k in 0..n {
            row_k.copy_from_slice(&dist[k * n..(k + 1) * n]);
            let relax = |(drow, nrow): (&mut [u32], &mut [u16])| {
                let dik = drow[k];
                if dik == UNREACHABLE {
                    return;
                }
                let hop = nrow[k];
                for ((d, nx), &dkj) in drow.iter_mut().zip(nrow.iter_mut()).zip(&row_k) {
                    let cand = dik.saturating_add(dkj);
                    if cand < *d {
                        *d = cand;
                        *nx = hop;
                    }
                }
            };
            if n >= PARALLEL_MIN_NODES {
                dist.par_chunks_mut(n)
                    .zip(next.par_chunks_mut(n))
                    .for_each(relax);
            } else {
                dist.chunks_mut(n).zip(next.chunks_mut(n)).for_each(relax);
            }
        }
        ShortestPaths { n, dist, next }
    }

    /// Number of nodes.
    #[inline]
    pub fn num_nodes(&self) -> usize {
        self.n
    }

    /// Shortest distance from `a` to `b` (sum of edge weights), or
    /// [`UNREACHABLE`]. Ids out of range are unreachable.
    #[inline]
    pub fn dist(&self, a: NodeId, b: NodeId) -> u32 {
        if a.index() < self.n && b.index() < self.n {
            self.dist[a.index() * self.n + b.index()]
        } else {
            UNREACHABLE
        }
    }

    /// First hop after `a` on a shortest path to `b` (`b` itself when the
    /// edge is direct, `a` when `a == b`), or `None` when unreachable.
    #[inline]
    pub fn next_hop(&self, a: NodeId, b: NodeId) -> Option<NodeId> {
        if a.index() >= self.n || b.index() >= self.n {
            return None;
        }
        let h = self.next[a.index() * self.n + b.index()];
        (h != NO_HOP).then_some(NodeId(h))
    }

    /// Writes the nodes of a shortest path `a, …, b` into `out` (cleared
    /// first); false, with `out` empty, when `b` cannot be reached.
    pub fn path_into(&self, a: NodeId, b: NodeId, out: &mut Vec<NodeId>) -> bool {
        out.clear();
        if self.dist(a, b) == UNREACHABLE {
            return false;
        }
        out.push(a);
        let mut cur = a;
        while cur != b {
            match self.next_hop(cur, b) {
                Some(h) => {
                    out.push(h);
                    cur = h;
                }
                None => {
                    out.clear();
                    return false;
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Reference: a breadth-first search over the graph with every edge of
    /// weight `w` subdivided into `w` unit steps (a bucket queue over
    /// distances), from `src`.
    fn bfs_distances(n: usize, edges: &[(NodeId, NodeId, u32)], src: usize) -> Vec<u32> {
        let mut dist = vec![UNREACHABLE; n];
        let mut buckets: Vec<Vec<usize>> = vec![vec![src]];
        dist[src] = 0;
        let mut d = 0usize;
        while d < buckets.len() {
            let frontier = std::mem::take(&mut buckets[d]);
            for v in frontier {
                if dist[v] as usize != d {
                    continue;
                }
                for &(a, b, w) in edges.iter().filter(|e| e.0.index() == v) {
                    let nd = d + w as usize;
                    if a != b && (nd as u32) < dist[b.index()] {
                        dist[b.index()] = nd as u32;
                        if buckets.len() <= nd {
                            buckets.resize(nd + 1, Vec::new());
                        }
                        buckets[nd].push(b.index());
                    }
                }
            }
            d += 1;
        }
        dist
    }

    fn graph() -> impl Strategy<Value = (usize, Vec<(NodeId, NodeId, u32)>)> {
        (1usize..40).prop_flat_map(|n| {
            let edge = (0..n, 0..n, 1u32..20)
                .prop_map(|(a, b, w)| (NodeId(a as u16), NodeId(b as u16), w));
            (Just(n), proptest::collection::vec(edge, 0..n * 4))
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 200, rng_seed: proptest::test_runner::RngSeed::Fixed(11), ..ProptestConfig::default() })]

        #[test]
        fn dp_distances_equal_bfs_on_random_graphs((n, edges) in graph()) {
            let sp = ShortestPaths::floyd_warshall(n, edges.iter().copied());
            for s in 0..n {
                let want = bfs_distances(n, &edges, s);
                for (t, &w) in want.iter().enumerate() {
                    prop_assert_eq!(sp.dist(NodeId(s as u16), NodeId(t as u16)), w, "{} -> {}", s, t);
                }
            }
        }

        #[test]
        fn triangle_inequality_and_paths_sum_to_distances((n, edges) in graph()) {
            let sp = ShortestPaths::floyd_warshall(n, edges.iter().copied());
            let weight = |a: NodeId, b: NodeId| edges.iter().filter(|e| e.0 == a && e.1 == b && a != b).map(|e| e.2).min();
            let mut path = Vec::new();
            for i in 0..n {
                for j in 0..n {
                    let (a, b) = (NodeId(i as u16), NodeId(j as u16));
                    for k in 0..n {
                        let (ik, kj) = (sp.dist(a, NodeId(k as u16)), sp.dist(NodeId(k as u16), b));
                        if ik != UNREACHABLE && kj != UNREACHABLE {
                            prop_assert!(sp.dist(a, b) <= ik + kj);
                        }
                    }
                    let reachable = sp.path_into(a, b, &mut path);
                    prop_assert_eq!(reachable, sp.dist(a, b) != UNREACHABLE);
                    if reachable {
                        prop_assert_eq!(path.first(), Some(&a));
                        prop_assert_eq!(path.last(), Some(&b));
                        let total: u32 = path.windows(2).map(|h| weight(h[0], h[1]).expect("hops are edges")).sum();
                        prop_assert_eq!(total, sp.dist(a, b));
                    }
                }
            }
        }
    }

    #[test]
    fn parallel_rounds_equal_sequential_ones() {
        // 200 nodes takes the rayon branch; compare against a 1-thread pool.
        let n = 200;
        let edges: Vec<(NodeId, NodeId, u32)> = (0..n * 3)
            .map(|i| {
                let r = sim::env_seed(9, i as u64);
                (
                    NodeId((r % n as u64) as u16),
                    NodeId(((r >> 16) % n as u64) as u16),
                    1 + ((r >> 32) % 17) as u32,
                )
            })
            .collect();
        let many = ShortestPaths::floyd_warshall(n, edges.iter().copied());
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| ShortestPaths::floyd_warshall(n, edges.iter().copied()));
        assert_eq!(one, many);
        let want = bfs_distances(n, &edges, 0);
        assert!((0..n).all(|t| many.dist(NodeId(0), NodeId(t as u16)) == want[t]));
    }

    #[test]
    fn unreachable_and_out_of_range_ids() {
        let sp = ShortestPaths::floyd_warshall(3, [(NodeId(0), NodeId(1), 4)]);
        assert_eq!(sp.dist(NodeId(0), NodeId(1)), 4);
        assert_eq!(sp.dist(NodeId(1), NodeId(0)), UNREACHABLE);
        assert_eq!(sp.dist(NodeId(0), NodeId(9)), UNREACHABLE);
        assert_eq!(sp.next_hop(NodeId(2), NodeId(0)), None);
        assert_eq!(sp.next_hop(NodeId(1), NodeId(1)), Some(NodeId(1)));
        let mut p = vec![NodeId(7)];
        assert!(!sp.path_into(NodeId(1), NodeId(0), &mut p));
        assert!(p.is_empty());
    }
}
