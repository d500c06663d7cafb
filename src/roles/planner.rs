//! The planner process: reads the same observation stream as the learner
//! (visitation counts, so a user can see coverage), owns the world graph
//! (section 3.3), answers route requests by request-response and
//! publishes graph snapshots for readers that join late.
//!
//! The planner never stalls the simulator: it is a passive reader of the
//! observation stream (safe overflow; when it falls behind it skips batches
//! and counts them), it idles with short sleeps instead of spinning so the
//! sim and the learner keep the cores, and it is attached to the stream only
//! [`COVERAGE_WINDOW`] of every [`COVERAGE_PERIOD`] (each subscriber costs
//! the sim work on every publish).
//!
//! The graph is saved to `<run dir>/graph.json` (atomically) with a PNG of
//! the maze, its nodes and edges; a restarted planner loads it instead of
//! rebuilding.
//!
//! Hot-loop histogram: `route_service` (request received → response sent).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use iceoryx2::prelude::ipc;
use planner::{CandidateSet, Coverage, NodeId, PlannerConfig, PlannerError, Route, WorldGraph};
use serde::Serialize;
use shm_schemas::service::PipelineNode;
use shm_schemas::{GraphEdge, ObsShape, RouteStatus, SeqEvent, SeqTracker};
use sim::{Layout, Pose};

use super::{
    EXIT_PEER_DIED, OnPeerDeath, PLANNER_NODE, PeerEvent, PeerWatch, RunArgs, RunCtx, SIM_NODE,
    config_exit,
};
use crate::latency::Latencies;
use crate::world_args::WorldArgs;

/// How the world graph's nodes are chosen.
#[derive(Debug, Clone, Args)]
pub struct GraphArgs {
    /// `V_rand`: this many random free cells as nodes (ignored with --node-file).
    #[arg(long, default_value_t = 32)]
    pub nodes: usize,
    /// Read the nodes from a file (JSON list of [x, y] or one "x,y" per line).
    #[arg(long)]
    pub node_file: Option<PathBuf>,
    /// Random walks from each node when discovering edges.
    #[arg(long, default_value_t = 512)]
    pub walks_per_node: u32,
    /// Most actions per random walk (long enough to connect sparse V_rand
    /// nodes across the large maze).
    #[arg(long, default_value_t = 512)]
    pub walk_len: u32,
    /// Seed of V_rand and of the walks (default: the world seed).
    #[arg(long)]
    pub graph_seed: Option<u64>,
    /// Keep the random walks' edge paths as found instead of shortening
    /// each by an exact search (`discover` shortens them with π_g instead,
    /// as the paper does).
    #[arg(long)]
    pub no_shorten: bool,
}

impl GraphArgs {
    /// The planner configuration these arguments describe.
    pub fn config(&self, world: &WorldArgs) -> PlannerConfig {
        PlannerConfig {
            candidates: match &self.node_file {
                Some(p) => CandidateSet::File {
                    path: p.display().to_string(),
                },
                None => CandidateSet::Random { k: self.nodes },
            },
            seed: self.graph_seed.unwrap_or(world.seed),
            walks_per_node: self.walks_per_node,
            walk_len: self.walk_len,
            shorten: !self.no_shorten,
            task: world.task,
            ..PlannerConfig::default()
        }
    }
}

/// `planner serve` options.
#[derive(Debug, Clone, Args)]
pub struct PlannerServeArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[command(flatten)]
    pub run: RunArgs,
    #[command(flatten)]
    pub graph: GraphArgs,
    /// Environments in the sim's batch (must match the sim's).
    #[arg(long, default_value_t = 256)]
    pub envs: usize,
    /// Slices the sim publishes its batch in (must match the sim's).
    #[arg(long, default_value_t = 2)]
    pub slices: usize,
}

/// The planner reads the observation stream in windows: attached for
/// [`COVERAGE_WINDOW`] of every `COVERAGE_PERIOD`. Every subscriber costs the
/// sim work on each publish (delivery into its queue and, for a reader that
/// lags as this one does by design, taking back the batch its full queue
/// drops), so windows cost the sim less than a planner attached all the
/// time (measured in `docs/implementation_details.md`, "Pipeline
/// throughput"); the coverage picture is a sample of the same stream.
pub const COVERAGE_PERIOD: Duration = Duration::from_secs(1);
/// See [`COVERAGE_PERIOD`].
pub const COVERAGE_WINDOW: Duration = Duration::from_millis(50);

/// What the planner reports at exit (`planner.report.json`).
#[derive(Debug, Serialize)]
pub struct PlannerReport {
    /// Nodes of the graph.
    pub nodes: usize,
    /// Edges of the graph.
    pub edges: usize,
    /// Whether the graph was loaded from the run directory.
    pub graph_loaded: bool,
    /// Observation batches read.
    pub batches_read: u64,
    /// Batches skipped while busy or detached (by design: the planner never
    /// slows the sim; see [`COVERAGE_PERIOD`]).
    pub batches_skipped: u64,
    /// Cells visited at least once.
    pub cells_visited: usize,
    /// Route requests answered.
    pub routes_answered: u64,
    /// Route service time p50 (µs).
    pub route_service_p50_us: f64,
    /// Route service time p99 (µs).
    pub route_service_p99_us: f64,
    /// Why the loop ended.
    pub stopped_by: String,
}

/// Loads the run's saved graph when it fits `layout`, or builds and saves one.
pub fn load_or_build(
    dir: &std::path::Path,
    layout: &Layout,
    cfg: &PlannerConfig,
) -> anyhow::Result<(WorldGraph, bool)> {
    let path = dir.join("graph.json");
    if path.exists() {
        match WorldGraph::load(&path) {
            Ok(g) if g.layout() == layout && g.config() == cfg => return Ok((g, true)),
            Ok(_) => tracing::info!(
                "planner: {} is for another maze or configuration; rebuilding",
                path.display()
            ),
            Err(e) => tracing::warn!("planner: cannot load {}: {e}; rebuilding", path.display()),
        }
    }
    let t0 = Instant::now();
    let graph = WorldGraph::build(layout, cfg, &[]).context("cannot build the world graph")?;
    tracing::info!(
        "planner: built a world graph of {} nodes and {} edges in {:.2?}",
        graph.num_nodes(),
        graph.edges().len(),
        t0.elapsed()
    );
    graph.save(&path)?;
    crate::world_graph_picture::graph_picture(&graph, false).save_png(&dir.join("graph.png"))?;
    Ok((graph, false))
}

fn status_of(e: &PlannerError) -> RouteStatus {
    match e {
        PlannerError::UnknownNode { .. } => RouteStatus::UnknownTarget,
        PlannerError::Unreachable { .. } => RouteStatus::Unreachable,
        PlannerError::NotOnGraph { .. } => RouteStatus::StartNotOnGraph,
        _ => RouteStatus::BadRequest,
    }
}

/// Runs the planner role until stopped; returns the process exit code.
pub fn serve(a: PlannerServeArgs) -> anyhow::Result<std::process::ExitCode> {
    // Everything a restart could not fix is checked first (EXIT_CONFIG).
    let checked = (|| -> anyhow::Result<_> {
        let (layout, _) = a.world.build()?;
        let shape = ObsShape::sliced(a.envs, a.slices, layout.width, layout.height)?;
        let cfg = a.graph.config(&a.world);
        cfg.validate()?;
        if let Some(path) = &a.graph.node_file {
            planner::pivotal::read_node_file(&layout, path)?;
        }
        Ok((RunCtx::new(&a.run, PLANNER_NODE)?, layout, shape, cfg))
    })();
    let (ctx, layout, shape, cfg) = match checked {
        Ok(v) => v,
        Err(e) => return Ok(config_exit("planner", &e)),
    };
    let (graph, graph_loaded) = load_or_build(&ctx.dir, &layout, &cfg)?;
    let nodes: Vec<u32> = graph.nodes().iter().map(|c| c.0).collect();
    let edges: Vec<GraphEdge> = graph
        .edges()
        .iter()
        .map(|e| GraphEdge {
            from: e.from.0,
            to: e.to.0,
            weight: e.weight(),
        })
        .collect();

    let node = PipelineNode::<ipc::Service>::new(&ctx.config, ctx.run.clone(), PLANNER_NODE)?
        .with_task(a.world.task.name(), a.world.task.num_actions());
    node.cleanup_dead_nodes();
    let attach = || {
        node.obs_subscriber(shape)
            .context("planner: cannot open the observation service")
    };
    // Attached at once, so a shape or schema mismatch stops the planner now.
    let mut obs = match node.obs_subscriber(shape) {
        Ok(s) => Some(s),
        Err(shm_schemas::ShmError::Schema(e)) => {
            return Ok(config_exit("planner", &anyhow::Error::new(e)));
        }
        Err(e) => {
            return Err(
                anyhow::Error::new(e).context("planner: cannot open the observation service")
            );
        }
    };
    let mut attached_at = Instant::now();
    let server = node
        .route_server()
        .context("planner: cannot open the route service")?;
    let snapshots = node.graph_publisher(layout.width, layout.height)?;
    let graph_version = 1u64;
    snapshots.publish(graph_version, &nodes, &edges)?;
    eprintln!(
        "planner: run '{}', world graph of {} nodes, {} edges ({}), serving routes",
        ctx.run,
        nodes.len(),
        edges.len(),
        if graph_loaded { "loaded" } else { "built" }
    );

    let mut lat = Latencies::new("planner");
    lat.register("route_service");
    let mut coverage = Coverage::for_layout(&layout);
    let mut seqs = SeqTracker::new();
    let mut sim_watch = PeerWatch::new(SIM_NODE);
    let mut route = Route::with_capacity(shm_schemas::MAX_ROUTE_LEN, shm_schemas::MAX_ROUTE_PIVOTS);
    let mut pivots: Vec<u16> = Vec::with_capacity(shm_schemas::MAX_ROUTE_PIVOTS);
    let mut cells: Vec<u32> = Vec::with_capacity(shm_schemas::MAX_ROUTE_LEN);
    let (mut batches, mut skipped, mut answered) = (0u64, 0u64, 0u64);
    let mut last_activity = Instant::now();
    let mut next_housekeeping = Instant::now();
    let world = graph.initial_world();
    let stopped_by;
    loop {
        // Only route requests count as activity: observation batches arrive
        // every few µs while the pipeline runs, and spinning on them would
        // take a core from the sim or the learner (it cost the pipeline a
        // third of its throughput). Coverage is a sample: the batches
        // buffered when it wakes (every 1 ms) while it is attached.
        let mut busy = false;
        let now = Instant::now();
        if obs.is_some() && now - attached_at >= COVERAGE_WINDOW {
            obs = None;
        } else if obs.is_none() && now - attached_at >= COVERAGE_PERIOD {
            obs = Some(attach()?);
            attached_at = now;
        }
        while let Some(sample) = obs.as_ref().map(|o| o.receive()).transpose()?.flatten() {
            let b = sample.batch();
            coverage.observe(b.meta);
            match seqs.observe(b.header.seq) {
                SeqEvent::Gap { missing } => skipped += missing,
                SeqEvent::Stale { .. } => seqs = SeqTracker::new(), // a restarted sim
                SeqEvent::First | SeqEvent::InOrder => {}
            }
            batches += 1;
        }
        while let Some(call) = server.receive()? {
            let t0 = Instant::now();
            let req = *call.request();
            let pose = Pose {
                x: (req.from_cell as usize % layout.width) as u16,
                y: (req.from_cell as usize / layout.width) as u16,
                dir: req.from_dir & 3,
            };
            match graph.route_from_pose_into(pose, NodeId(req.to_pivot), world, &mut route) {
                Ok(_) => {
                    pivots.clear();
                    pivots.extend(route.nodes().iter().map(|n| n.0));
                    cells.clear();
                    cells.extend(route.cells().iter().map(|c| c.0));
                    call.respond(
                        graph_version,
                        RouteStatus::Ok,
                        &pivots,
                        &cells,
                        route.actions(),
                    )?
                }
                Err(e) => call.respond(graph_version, status_of(&e), &[], &[], &[])?,
            };
            lat.record("route_service", t0.elapsed().as_nanos() as u64);
            answered += 1;
            busy = true;
        }
        let now = Instant::now();
        if busy {
            last_activity = now;
        }
        if now >= next_housekeeping {
            next_housekeeping = now + Duration::from_millis(100);
            if ctx.should_stop() {
                stopped_by = "stop request".to_string();
                break;
            }
            snapshots.update_connections()?;
            ctx.report_on_request(&lat);
            match sim_watch.poll(&ctx) {
                PeerEvent::Died => {
                    eprintln!("planner: the sim is gone (no live '{SIM_NODE}' node)");
                    node.cleanup_dead_nodes();
                    if ctx.on_peer_death == OnPeerDeath::Exit {
                        stopped_by = "sim died".to_string();
                        break;
                    }
                    eprintln!("planner: still serving routes; waiting for a sim to rejoin");
                }
                PeerEvent::Back => eprintln!("planner: a sim rejoined"),
                PeerEvent::Quiet => {}
            }
        }
        // Spin briefly after activity (fast answers to bursts of route
        // requests), then sleep: on 2 cores the sim and the learner spin, and
        // every wake-up of the planner preempts one of them.
        if now - last_activity > Duration::from_micros(300) {
            std::thread::sleep(Duration::from_millis(1));
        } else {
            std::hint::spin_loop();
        }
    }

    drop((obs, server, snapshots, node));
    ctx.tidy();
    coverage.save_png(&layout, &ctx.dir.join("coverage.png"), 24)?;
    let report = PlannerReport {
        nodes: nodes.len(),
        edges: edges.len(),
        graph_loaded,
        batches_read: batches,
        batches_skipped: skipped,
        cells_visited: coverage.visited_cells(),
        routes_answered: answered,
        route_service_p50_us: lat.percentile_us("route_service", 50.0),
        route_service_p99_us: lat.percentile_us("route_service", 99.0),
        stopped_by: stopped_by.clone(),
    };
    ctx.write_json("planner.report.json", &report)?;
    lat.write_reports(&ctx.dir)?;
    eprint!("{}", lat.table());
    eprintln!(
        "planner: read {} batches (skipped {}), {} cells visited, {} routes answered, stopped by {}",
        batches, skipped, report.cells_visited, answered, stopped_by
    );
    Ok(if stopped_by == "sim died" {
        std::process::ExitCode::from(EXIT_PEER_DIED)
    } else {
        std::process::ExitCode::SUCCESS
    })
}
