//! Ask the planner for a route: build the world graph of the small maze on
//! 12 random nodes (edges from random walks, section 3.3 of the paper), plan
//! the route between two of them by dynamic programming, and replay its
//! actions in the simulator to see it arrive.
//!
//! `cargo run --release --example plan_route`

use planner::{CandidateSet, NodeId, PlannerConfig, Route, WorldGraph};
use sim::{AutoReset, BallSpawn, Env, EnvConfig, Maze};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let layout = Maze::Small.layout(false);
    let config = PlannerConfig {
        candidates: CandidateSet::Random { k: 12 },
        ..PlannerConfig::default()
    };
    let graph = WorldGraph::build(&layout, &config, &[])?;
    println!(
        "world graph: {} nodes, {} edges",
        graph.num_nodes(),
        graph.edges().len()
    );

    let (from, to) = (NodeId(0), NodeId(graph.num_nodes() as u16 - 1));
    let mut route = Route::with_capacity(1024, 64);
    let actions = graph.route_into(from, 0, to, &mut route)?;
    println!(
        "route {from:?} -> {to:?}: {actions} actions through nodes {:?}",
        route.nodes()
    );

    // Replay it: start on `from` facing right (0), in the walks' rules.
    let walk = EnvConfig {
        task: config.walk_task(),
        max_steps: u32::MAX,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::Off,
    };
    let mut env = Env::new(layout.clone(), walk, 0, 0);
    let start = graph.nodes()[from.index()].pose(layout.width, 0);
    env.teleport(start);
    for &a in route.actions() {
        env.step_meta(a);
    }
    let end = env.pose();
    let target = graph.nodes()[to.index()].pose(layout.width, 0);
    println!(
        "after replaying: agent at ({}, {}), target ({}, {})",
        end.x, end.y, target.x, target.y
    );
    Ok(())
}
