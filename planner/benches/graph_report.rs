//! Figures and pictures of the world graph for a person to read: how much
//! of each embedded maze the default walks connect, the graph and coverage
//! pictures, and rebuild and route-query timings. It prints and writes; it
//! asserts nothing (the tests in `src/` do).
//!
//! `cargo bench -p planner --bench graph_report [-- connectivity|pictures|timing]`
//! (no name: all three). `worldgraph bench planner` measures route queries
//! against a Dijkstra baseline.

use std::time::Instant;

use planner::{CandidateSet, Coverage, NodeId, PlannerConfig, Route, UNREACHABLE, WorldGraph};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use sim::{AutoReset, BallSpawn, Env, EnvConfig, Layout, Maze};

/// The graph of `layout` on `candidates` with the walk budget of the
/// planner's tests (256 walks of 200 steps per node; the default is 512 of
/// 512), which the README's timing table was measured with.
fn build(layout: &Layout, candidates: CandidateSet, seed: u64) -> WorldGraph {
    let budget = PlannerConfig {
        walks_per_node: 256,
        walk_len: 200,
        ..PlannerConfig::default()
    };
    let config = PlannerConfig {
        candidates,
        seed,
        ..budget
    };
    WorldGraph::build(layout, &config, &[]).expect("graph")
}

/// How much of each embedded maze the default walks connect.
fn connectivity() {
    for maze in Maze::ALL {
        for k in [16, 32, 64] {
            let layout = maze.layout(false);
            let t = Instant::now();
            let config = PlannerConfig {
                candidates: CandidateSet::Random { k },
                ..PlannerConfig::default()
            };
            let g = WorldGraph::build(&layout, &config, &[]).expect("graph");
            let n = g.num_nodes();
            let pairs = (0..n * n)
                .filter(|&i| {
                    g.distance(NodeId((i / n) as u16), NodeId((i % n) as u16)) != UNREACHABLE
                })
                .count();
            println!(
                "{} k={k}: {} edges, {:.1}% of pairs connected, built in {:.2?}",
                layout.name,
                g.edges().len(),
                100.0 * pairs as f64 / (n * n) as f64,
                t.elapsed()
            );
        }
    }
}

/// The medium maze's graph and a coverage heat map of random walks (and
/// the same for the small Door-Key maze), written to the temp directory.
fn pictures() {
    let dir = std::env::temp_dir().join("planner-pictures");
    for (maze, dk) in [(Maze::Medium, false), (Maze::Small, true)] {
        let layout = maze.layout(dk);
        let g = build(&layout, CandidateSet::Random { k: 24 }, 1);
        g.save_png(&dir.join(format!("{}-graph.png", layout.name)), 24)
            .expect("png");
        let walk = EnvConfig {
            task: g.config().walk_task(),
            max_steps: u32::MAX,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::Off,
        };
        let mut env = Env::new(layout.clone(), walk, 0, 0);
        let mut cov = Coverage::for_layout(&layout);
        let mut rng = SmallRng::seed_from_u64(0);
        let batch: Vec<_> = (0..20_000)
            .map(|_| env.step_meta(rng.random_range(0..3)))
            .collect();
        cov.observe(&batch);
        cov.save_png(
            &layout,
            &dir.join(format!("{}-coverage.png", layout.name)),
            24,
        )
        .expect("png");
    }
    println!("pictures in {}", dir.display());
}

/// The `times[q]` quantile, in µs.
fn quantile_us(times: &[u64], q: f64) -> f64 {
    times[((times.len() - 1) as f64 * q) as usize] as f64 / 1000.0
}

/// Graph build, all-pairs rebuild and route-query times.
fn timing() {
    for (maze, candidates) in [
        (Maze::Medium, CandidateSet::All),
        (Maze::Large, CandidateSet::Random { k: 500 }),
        (Maze::Large, CandidateSet::Random { k: 32 }),
    ] {
        let layout = maze.layout(false);
        let t = Instant::now();
        let mut g = build(&layout, candidates, 0);
        let build = t.elapsed();
        let t = Instant::now();
        g.rebuild_shortest_paths();
        let rebuild = t.elapsed();
        let n = g.num_nodes();
        let mut rng = SmallRng::seed_from_u64(1);
        let mut route = Route::with_capacity(4096, 1024);
        let mut times = Vec::with_capacity(100_000);
        let mut lens = 0usize;
        for _ in 0..100_000 {
            let (a, b) = (
                NodeId(rng.random_range(0..n) as u16),
                NodeId(rng.random_range(0..n) as u16),
            );
            let t = Instant::now();
            let r = g.route_into(a, 0, b, &mut route);
            times.push(t.elapsed().as_nanos() as u64);
            lens += r.unwrap_or(0);
        }
        times.sort_unstable();
        println!(
            "{}: {n} nodes, {} edges, build {:.2?}, rebuild_shortest_paths {:.2?}, route_into p50 {:.2} us p99 {:.2} us max {:.2} us (mean route {:.0} actions)",
            layout.name,
            g.edges().len(),
            build,
            rebuild,
            quantile_us(&times, 0.5),
            quantile_us(&times, 0.99),
            quantile_us(&times, 1.0),
            lens as f64 / times.len() as f64
        );
        let cells = planner::pivotal::v_all(&layout);
        let mut pose_times = Vec::with_capacity(100_000);
        for _ in 0..100_000 {
            let pose =
                cells[rng.random_range(0..cells.len())].pose(layout.width, rng.random_range(0..4));
            let b = NodeId(rng.random_range(0..n) as u16);
            let t = Instant::now();
            let _ = g.route_from_pose_into(pose, b, g.initial_world(), &mut route);
            pose_times.push(t.elapsed().as_nanos() as u64);
        }
        pose_times.sort_unstable();
        println!(
            "{}: route_from_pose_into p50 {:.2} us p99 {:.2} us",
            layout.name,
            quantile_us(&pose_times, 0.5),
            quantile_us(&pose_times, 0.99)
        );
    }
}

fn main() {
    // `cargo bench` passes `--bench`; any other word picks a report.
    let picked: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let reports: [(&str, fn()); 3] = [
        ("connectivity", connectivity),
        ("pictures", pictures),
        ("timing", timing),
    ];
    for (name, report) in reports {
        if picked.is_empty() || picked.iter().any(|p| p == name) {
            report();
        }
    }
}
