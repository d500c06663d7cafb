//! `worldgraph bench planner`: route-query latency through the all-pairs
//! dynamic-programming tables (section 3.3), against a Dijkstra search
//! per query on the same edge graph measured in the same run, and the time
//! to rebuild all-pairs shortest paths (Floyd–Warshall).

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::time::Instant;

use clap::Args;
use planner::{CandidateSet, NodeId, PlannerConfig, Route, UNREACHABLE, WorldGraph};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use sim::{Maze, Task};

use crate::latency::Latencies;

/// `bench planner` options.
#[derive(Debug, Clone, Args)]
pub struct BenchPlannerArgs {
    /// Nodes of the world graph (`V_rand`).
    #[arg(long, default_value_t = 500)]
    pub nodes: usize,
    /// Maze (the large one has room for 500 nodes).
    #[arg(long, default_value = "large")]
    pub maze: Maze,
    /// Route queries to time (random node pairs with a path).
    #[arg(long, default_value_t = 200_000)]
    pub queries: usize,
    /// Seed of the graph and of the query pairs.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Figures of `bench planner`.
#[derive(Debug, Serialize)]
pub struct PlannerBenchReport {
    /// Nodes.
    pub nodes: usize,
    /// Edges.
    pub edges: usize,
    /// Seconds to build the graph (walks + shortening + DP).
    pub build_seconds: f64,
    /// Median time to rebuild all-pairs shortest paths (ms).
    pub rebuild_ms: f64,
    /// DP route query p50 (µs), full route (nodes, cells, actions).
    pub route_p50_us: f64,
    /// DP route query p99 (µs).
    pub route_p99_us: f64,
    /// DP route query p99.9 (µs).
    pub route_p999_us: f64,
    /// Dijkstra-per-query baseline p50 (µs), node path only.
    pub dijkstra_p50_us: f64,
    /// Dijkstra baseline p99 (µs).
    pub dijkstra_p99_us: f64,
    /// `dijkstra_p50 / route_p50`.
    pub speedup_p50: f64,
}

/// Node path by Dijkstra over the edge list (the baseline).
fn dijkstra(
    adj: &[Vec<(u16, u32)>],
    a: usize,
    b: usize,
    dist: &mut [u32],
    prev: &mut [u16],
    path: &mut Vec<u16>,
) -> bool {
    dist.fill(UNREACHABLE);
    dist[a] = 0;
    let mut heap = BinaryHeap::new();
    heap.push(Reverse((0u32, a as u16)));
    while let Some(Reverse((d, u))) = heap.pop() {
        let u = u as usize;
        if u == b {
            break;
        }
        if d > dist[u] {
            continue;
        }
        for &(v, w) in &adj[u] {
            let nd = d + w;
            if nd < dist[v as usize] {
                dist[v as usize] = nd;
                prev[v as usize] = u as u16;
                heap.push(Reverse((nd, v)));
            }
        }
    }
    path.clear();
    if dist[b] == UNREACHABLE {
        return false;
    }
    let mut v = b;
    while v != a {
        path.push(v as u16);
        v = prev[v] as usize;
    }
    path.push(a as u16);
    true
}

/// Runs the benchmark.
pub fn run(a: BenchPlannerArgs) -> anyhow::Result<std::process::ExitCode> {
    let (mut graph, build_seconds) = build_graph(&a)?;
    let rebuild_ms = median_rebuild_ms(&mut graph);
    let pairs = query_pairs(&graph, &a);
    anyhow::ensure!(!pairs.is_empty(), "no connected node pairs in this graph");
    let lat = time_queries(&graph, &pairs);
    let r = PlannerBenchReport {
        nodes: graph.num_nodes(),
        edges: graph.edges().len(),
        build_seconds,
        rebuild_ms,
        route_p50_us: lat.percentile_us("dp_route", 50.0),
        route_p99_us: lat.percentile_us("dp_route", 99.0),
        route_p999_us: lat.percentile_us("dp_route", 99.9),
        dijkstra_p50_us: lat.percentile_us("dijkstra_baseline", 50.0),
        dijkstra_p99_us: lat.percentile_us("dijkstra_baseline", 99.0),
        speedup_p50: lat.percentile_us("dijkstra_baseline", 50.0)
            / lat.percentile_us("dp_route", 50.0),
    };
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        print_table(&a, &r, &lat);
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// The world graph of `--nodes` random nodes on `--maze`, and the seconds
/// its build took (walks, shortening and the all-pairs tables).
fn build_graph(a: &BenchPlannerArgs) -> anyhow::Result<(WorldGraph, f64)> {
    let layout = a.maze.layout(false);
    let free = layout.free_cells().len();
    anyhow::ensure!(
        a.nodes >= 2 && a.nodes <= free,
        "--nodes must be in 2..={free} for the {} maze",
        a.maze
    );
    let cfg = PlannerConfig {
        candidates: CandidateSet::Random { k: a.nodes },
        seed: a.seed,
        walks_per_node: 128,
        walk_len: 64,
        shorten: true,
        task: Task::MultiGoal,
        ..PlannerConfig::default()
    };
    let t0 = Instant::now();
    let graph = WorldGraph::build(&layout, &cfg, &[])?;
    Ok((graph, t0.elapsed().as_secs_f64()))
}

/// Median of 5 rebuilds of the all-pairs shortest paths (ms).
fn median_rebuild_ms(graph: &mut WorldGraph) -> f64 {
    let mut rebuilds = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        graph.rebuild_shortest_paths();
        rebuilds.push(t.elapsed().as_secs_f64() * 1e3);
    }
    rebuilds.sort_by(f64::total_cmp);
    rebuilds[rebuilds.len() / 2]
}

/// `--queries` random pairs of distinct nodes with a path between them
/// (at most a million).
fn query_pairs(graph: &WorldGraph, a: &BenchPlannerArgs) -> Vec<(usize, usize)> {
    let n = graph.num_nodes();
    let mut rng = SmallRng::seed_from_u64(a.seed ^ 0xbe4c);
    std::iter::repeat_with(|| (rng.random_range(0..n), rng.random_range(0..n)))
        .filter(|&(x, y)| {
            x != y && graph.distance(NodeId(x as u16), NodeId(y as u16)) != UNREACHABLE
        })
        .take(a.queries.min(1_000_000))
        .collect()
}

/// Times every pair's DP route (`dp_route`), then every pair's Dijkstra
/// node path on the graph's edge list (`dijkstra_baseline`).
fn time_queries(graph: &WorldGraph, pairs: &[(usize, usize)]) -> Latencies {
    let mut lat = Latencies::new("planner");
    let mut route = Route::with_capacity(shm_schemas::MAX_ROUTE_LEN, shm_schemas::MAX_ROUTE_PIVOTS);
    for (i, &(x, y)) in pairs.iter().enumerate() {
        let t = Instant::now();
        let r = graph.route_into(
            NodeId(x as u16),
            (i % 4) as u8,
            NodeId(y as u16),
            &mut route,
        );
        lat.record("dp_route", t.elapsed().as_nanos() as u64);
        std::hint::black_box(r.ok());
    }
    let n = graph.num_nodes();
    let mut adj = vec![Vec::new(); n];
    for e in graph.edges() {
        adj[e.from.index()].push((e.to.0, e.weight()));
    }
    let (mut dist, mut prev, mut path) = (vec![0u32; n], vec![0u16; n], Vec::with_capacity(n));
    for &(x, y) in pairs {
        let t = Instant::now();
        let ok = dijkstra(&adj, x, y, &mut dist, &mut prev, &mut path);
        lat.record("dijkstra_baseline", t.elapsed().as_nanos() as u64);
        std::hint::black_box(ok);
    }
    lat
}

/// Prints the `bench planner` table.
fn print_table(a: &BenchPlannerArgs, r: &PlannerBenchReport, lat: &Latencies) {
    println!(
        "bench planner: {} maze, {} nodes, {} edges, graph built in {:.2} s",
        a.maze, r.nodes, r.edges, r.build_seconds
    );
    println!(
        "  all-pairs shortest paths rebuild (Floyd-Warshall): {:.2} ms (median of 5)",
        r.rebuild_ms
    );
    print!("{}", lat.table());
    println!(
        "  DP route (nodes+cells+actions) vs Dijkstra node path, p50 speed-up: {:.1}x",
        r.speedup_p50
    );
}
