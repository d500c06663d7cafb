//! `worldgraph discover`: stage 1 of the paper (world graph discovery) on a
//! maze, in process or as the pipeline's processes, resumable, ending with
//! the world graph, pictures and a summary.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use learner::batch_env::{BatchEnvironment, InProcess};
use learner::discovery::{DiscoveryConfig, RoundStats};
use learner::edge_refinement::RefinementStats;
use learner::run::artefact::read_discovery_config;
use learner::run::dir;
use learner::run::discovery_run::{DiscoveryRun, DiscoverySpec};
use serde::Serialize;
use sim::{Layout, Maze, Task};

use crate::chart::{LineChart, Series, XScale};
use crate::pipeline::{Pipeline, Role, world_words};
use crate::shutdown::teardown;
use crate::world_args::WorldArgs;
use crate::world_graph_picture::{graph_picture, pivotal_picture};

/// `discover` options.
#[derive(Debug, Clone, Args)]
pub struct DiscoverArgs {
    /// Embedded maze: small, medium or large (the default is `train`'s and
    /// the demo's).
    #[arg(long, default_value = "small", conflicts_with = "layout")]
    pub maze: Maze,
    /// A layout file instead of an embedded maze.
    #[arg(long)]
    pub layout: Option<PathBuf>,
    /// Seed of the environments and of the models [default: 0, or the
    /// --config file's `seed`].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Run directory (checkpoints, graph, pictures): new, empty, or a
    /// discover run, which resumes from it (any other directory is refused
    /// untouched) [default: runs/discover-<maze>-<seed>].
    #[arg(long = "run", alias = "run-dir")]
    pub run_dir: Option<PathBuf>,
    /// Environments stepped in parallel (at most 1024).
    #[arg(long, default_value_t = 32)]
    pub envs: usize,
    /// Most rounds of the loop (the budget) [default: 30, or the --config file's].
    #[arg(long)]
    pub rounds: Option<u32>,
    /// Rounds without accuracy improvement before stopping, once `min_rounds`
    /// (12) are done [default: 4, or the --config file's].
    #[arg(long)]
    pub patience: Option<u32>,
    /// `π_g` A2C iterations per round (0: random walks only, and the edges
    /// keep the walks' paths) [default: 100, or the --config file's].
    #[arg(long)]
    pub gcp_iters: Option<u32>,
    /// A TOML file of discovery settings (any subset of `DiscoveryConfig`;
    /// an unknown key is an error). The resolved settings are written to
    /// `<run>/config.toml` with digests of the layout and the settings; a
    /// resumed run must match them (a larger --rounds or --patience is a
    /// continuation).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Run as the pipeline's processes: the environments in a sim process,
    /// the loop in this (learner) process, the graph's edges walked by a
    /// planner process (and refined by π_g here).
    #[arg(long)]
    pub pipeline: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `discover` reports (also `discovery.json` in the run directory).
#[derive(Debug, Serialize)]
pub struct DiscoverySummary {
    /// Maze.
    pub maze: String,
    /// Seed.
    pub seed: u64,
    /// Transport.
    pub transport: String,
    /// Rounds run.
    pub rounds: u32,
    /// Pivotal states `V_p`.
    pub pivotal_states: usize,
    /// Edges of the world graph.
    pub edges: usize,
    /// Node pairs with a path / all ordered pairs.
    pub connected_pairs: f64,
    /// Passages of the maze (doorways and 1-wide corridors between rooms,
    /// [`planner::structure`]).
    pub passages: usize,
    /// Rooms of the maze.
    pub rooms: usize,
    /// Share of the passages with a pivotal state on or next to them.
    pub passage_share: f64,
    /// The same for random cells as many as `V_p` (mean of
    /// [`RANDOM_DRAWS`] draws): the chance level.
    pub passage_share_random: f64,
    /// Share of the rooms holding a pivotal state.
    pub room_share: f64,
    /// The same for random cells (mean of [`RANDOM_DRAWS`] draws).
    pub room_share_random: f64,
    /// Routing through the world graph over `V_p` as built (walks, then
    /// `π_g`'s refinement): route actions over shortest-path actions,
    /// mean over [`ROUTE_PAIRS`] random pairs of cells.
    pub route_stretch: f64,
    /// The same graph's nodes with exact shortest edges (the planner's
    /// search), as `V_rand` gets below: the node sets compared alone.
    pub route_stretch_exact: f64,
    /// Graphs over `V_rand` of the same size with exact shortest edges
    /// (granted every advantage, as in the paper's comparison), mean
    /// stretch over [`RANDOM_GRAPHS`] draws.
    pub route_stretch_random: f64,
    /// Fraction of the pairs the `V_p` graph routes at all.
    pub routed: f64,
    /// The same for the `V_rand` graphs (mean).
    pub routed_random: f64,
    /// Latent model's reconstruction accuracy in the last round.
    pub reconstruction_accuracy: f64,
    /// `π_g` greedy success rate on goals within 10 steps.
    pub gcp_success_within_10: f64,
    /// Environment steps taken.
    pub env_steps: u64,
    /// Seconds of the discovery loop (this invocation plus resumed ones).
    pub wall_seconds: f64,
    /// Training throughput: env-steps per second of the loop.
    pub train_steps_per_sec: f64,
    /// Edges whose random-walk path is longer than the shortest possible.
    pub edges_improvable: usize,
    /// Edges whose random-walk path `π_g` shortened (section 3.3).
    pub edges_refined_by_gcp: usize,
    /// Sum of the edge weights as the random walks found them.
    pub edge_weight_walks: u64,
    /// Sum of the edge weights after `π_g`'s refinement (the graph's).
    pub edge_weight_refined: u64,
    /// Sum of the exact shortest edge weights (the floor of any refinement).
    pub edge_weight_shortest: u64,
    /// The pivotal cells, most pivotal first.
    pub pivotal_cells: Vec<[u16; 2]>,
}

fn world(a: &DiscoverArgs, seed: u64) -> WorldArgs {
    WorldArgs {
        maze: a.maze,
        layout: a.layout.clone(),
        task: Task::MultiGoal,
        seed,
        // Long episodes and no random balls: discovery explores a fixed,
        // deterministic maze (recorded paths must replay exactly).
        max_steps: Some(100_000),
        balls: Some(0),
    }
}

/// The most environments a batch may have: the pipeline's limit, which
/// `train` and `discover` keep in process too.
const MAX_ENVS: usize = shm_schemas::MAX_ENVS;

/// Opens the discovery run of `a` (`--run`, or `runs/discover-<maze>-<seed>`):
/// new, or resumed ([`DiscoveryRun::open`] checks that it is the same run).
fn open_run(
    a: &DiscoverArgs,
    layout: &Layout,
    cfg: DiscoveryConfig,
    num_actions: usize,
) -> anyhow::Result<DiscoveryRun> {
    let dir = a.run_dir.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!("discover-{}-{}", layout.name, cfg.seed))
    });
    // The --config file may sit in the run directory: it is the run's own.
    let own_files: Vec<String> = a
        .config
        .as_deref()
        .and_then(|c| dir::name_in(&dir, c))
        .into_iter()
        .chain(["lock".to_string()])
        .collect();
    DiscoveryRun::open(DiscoverySpec {
        dir,
        layout: layout.clone(),
        envs: a.envs,
        config: cfg,
        num_actions,
        own_files,
        version: env!("CARGO_PKG_VERSION").to_string(),
        commit: env!("WORLDGRAPH_BUILD_COMMIT").to_string(),
    })
}

/// Runs `worldgraph discover`.
pub fn run(a: DiscoverArgs) -> anyhow::Result<std::process::ExitCode> {
    let cfg = resolved_config(&a)?;
    anyhow::ensure!(
        (1..=MAX_ENVS).contains(&a.envs),
        "--envs {}: from 1 to {MAX_ENVS} environments",
        a.envs
    );
    let seed = cfg.seed;
    let w = world(&a, seed);
    let (layout, env_cfg) = w.build()?;
    // One world graph per maze serves every task on it: it is found on the
    // maze's structure, doors passable and no key (a Door-Key layout's
    // door is refused at run time only while it is closed).
    let layout = layout.structural();
    let mut run = open_run(&a, &layout, cfg, env_cfg.task.num_actions())?;
    if let Some(rounds) = run.resumed_after() {
        eprintln!(
            "discover: resuming {} after round {rounds}",
            run.dir().display()
        );
    }
    let mut transport = Transport::open(&a, &w, &layout, env_cfg, seed, run.dir())?;
    discover_rounds(&mut run, transport.env.as_mut())?;
    let gcp_success = run
        .discovery_mut()
        .evaluate_gcp(transport.env.as_mut(), 10, 200)?;
    let transport_name = transport.name;
    transport.close()?;

    // The world graph over V_p: built here, or by the planner process.
    let (cells, pivotal_file) = run.write_pivotal_states()?;
    let (graph, refinement) = if a.pipeline {
        // Edges walked by the planner process, then each path shortened
        // by π_g where it reaches the next node faster.
        let mut g = build_graph_in_planner(&a, &w, run.dir(), &pivotal_file)?;
        let stats = run.discovery_mut().refine_graph(&mut g)?;
        (g, stats)
    } else {
        run.discovery_mut().build_graph(Task::MultiGoal)?
    };
    run.save_world_graph(&graph)?;
    let summary = summarise(
        &run,
        &graph,
        &refinement,
        gcp_success,
        transport_name,
        cells,
    )?;
    let dir = run.dir();
    sim::atomic_file::write_atomic(
        &dir.join("discovery.json"),
        &serde_json::to_vec_pretty(&summary)?,
    )?;
    save_pictures(&run, &graph, seed)?;
    if a.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print_summary(&summary, run.dir());
    }
    if let Some(w) = untrained_pi_g_warning(summary.gcp_success_within_10) {
        eprintln!("{w}");
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// `π_g`'s greedy success on goals within 10 steps below which it is
/// taken not to have learnt (what an untrained `π_g` scores, and what a
/// longer budget gives on each maze: `docs/findings.md`, stage 1).
const PI_G_LEARNT: f64 = 0.5;

/// A warning when `π_g`, with greedy success `success` on goals within 10
/// steps, has not learnt to reach them: stage 2 initialises its Worker
/// and Manager from it (section 4.4) and steers stochastic traversals
/// with it.
fn untrained_pi_g_warning(success: f64) -> Option<String> {
    (success < PI_G_LEARNT).then(|| {
        format!(
            "warning: pi_g reaches {:.0}% of the goals within 10 steps: it has not learnt to \
             navigate, and stage 2 initialised from it starts with a Worker that rarely reaches \
             its goals. Start its goals near and train it longer (--config \
             experiments/discover-pi-g-curriculum.toml; docs/findings.md, stage 1, has what each \
             maze needs)",
            100.0 * success
        )
    })
}

/// The discovery settings: the `--config` file's (or the defaults), each
/// flag given overriding it; a flag not given keeps the file's value.
fn resolved_config(a: &DiscoverArgs) -> anyhow::Result<DiscoveryConfig> {
    let mut cfg: DiscoveryConfig = match &a.config {
        Some(p) => read_discovery_config(p)?,
        None => DiscoveryConfig::default(),
    };
    if let Some(s) = a.seed {
        cfg.seed = s;
    }
    if let Some(r) = a.rounds {
        cfg.max_rounds = r;
    }
    if let Some(p) = a.patience {
        cfg.patience = p;
    }
    if let Some(g) = a.gcp_iters {
        cfg.gcp_iters_per_round = g;
    }
    Ok(cfg)
}

/// Where the discovery's environments run: in this process, or in a sim
/// process of the pipeline (`--pipeline`), which [`Transport::close`]
/// stops and tears down.
struct Transport {
    env: Box<dyn BatchEnvironment>,
    pipeline: Option<(Pipeline, String)>,
    /// As the summary names it.
    name: &'static str,
}

impl Transport {
    fn open(
        a: &DiscoverArgs,
        w: &WorldArgs,
        layout: &Layout,
        env_cfg: sim::EnvConfig,
        seed: u64,
        dir: &Path,
    ) -> anyhow::Result<Transport> {
        if a.pipeline {
            let run_name = format!("discover-{}", std::process::id());
            let (env, p) = crate::pipeline::spawn_sim_env(w, a.envs, &run_name, dir)?;
            Ok(Transport {
                env: Box::new(env),
                pipeline: Some((p, run_name)),
                name: "pipeline",
            })
        } else {
            Ok(Transport {
                env: Box::new(InProcess::new(layout.clone(), env_cfg, a.envs, seed, 1)?),
                pipeline: None,
                name: "in-process",
            })
        }
    }

    fn close(self) -> anyhow::Result<()> {
        drop(self.env);
        if let Some((mut p, run_name)) = self.pipeline {
            p.stop_all(Duration::from_secs(3));
            teardown(&run_name)?;
        }
        Ok(())
    }
}

/// The loop's remaining rounds, with a progress bar (a line per round on a
/// non-terminal stderr: a log file, CI).
fn discover_rounds(run: &mut DiscoveryRun, env: &mut dyn BatchEnvironment) -> anyhow::Result<()> {
    let total = run.discovery().config().max_rounds as u64;
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "discover {bar:30} round {pos}/{len} {elapsed_precise} {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.set_position(run.discovery().rounds_done() as u64);
    while !run.finished() {
        let s = run.round(env)?;
        let done = run.discovery().rounds_done();
        bar.set_position(done as u64);
        let line = format!(
            "acc {:.3}  π_g {:.2}  |V_p| {}  cells {}",
            s.reconstruction_accuracy, s.gcp_success, s.pivotal_states, s.cells_visited
        );
        if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            eprintln!("discover: round {done}/{total}  {line}");
        }
        bar.set_message(line);
    }
    bar.finish_and_clear();
    Ok(())
}

/// The run's summary (`discovery.json`): the loop's figures, the world
/// graph's, and `V_p` against random cells on the maze's structure.
fn summarise(
    run: &DiscoveryRun,
    graph: &planner::WorldGraph,
    refinement: &RefinementStats,
    gcp_success: f64,
    transport: &str,
    pivotal_cells: Vec<[u16; 2]>,
) -> anyhow::Result<DiscoverySummary> {
    let layout = run.layout();
    let disc = run.discovery();
    let seed = disc.config().seed;
    let history = disc.history();
    let env_steps: u64 = history.iter().map(|h| h.env_steps).sum();
    let loop_seconds: f64 = history.iter().map(|h| h.seconds).sum();
    let reconstruction_accuracy = history.last().map_or(0.0, |h| h.reconstruction_accuracy);
    let pivotal = disc.pivotal_states();
    let structure = StructureReport::measure(
        layout,
        pivotal,
        graph,
        &disc.graph_config(Task::MultiGoal),
        seed,
    )?;
    Ok(DiscoverySummary {
        maze: layout.name.clone(),
        seed,
        transport: transport.into(),
        rounds: disc.rounds_done(),
        pivotal_states: pivotal.len(),
        edges: graph.edges().len(),
        connected_pairs: connected_pairs(graph),
        passages: structure.passages,
        rooms: structure.rooms,
        passage_share: structure.pivotal.passage_share,
        passage_share_random: structure.random.passage_share,
        room_share: structure.pivotal.room_share,
        room_share_random: structure.random.room_share,
        route_stretch: structure.routing.mean_stretch,
        route_stretch_exact: structure.routing_exact.mean_stretch,
        route_stretch_random: structure.routing_random.mean_stretch,
        routed: structure.routing.routed,
        routed_random: structure.routing_random.routed,
        reconstruction_accuracy,
        gcp_success_within_10: gcp_success,
        env_steps,
        wall_seconds: loop_seconds,
        train_steps_per_sec: env_steps as f64 / loop_seconds.max(1e-9),
        edges_improvable: refinement.improvable,
        edges_refined_by_gcp: refinement.refined,
        edge_weight_walks: refinement.weight_walks,
        edge_weight_refined: refinement.weight_refined,
        edge_weight_shortest: refinement.weight_shortest,
        pivotal_cells,
    })
}

/// Ordered node pairs with a path over all ordered pairs.
fn connected_pairs(graph: &planner::WorldGraph) -> f64 {
    let n = graph.num_nodes();
    if n < 2 {
        return 0.0;
    }
    let connected = (0..n)
        .flat_map(|i| (0..n).map(move |j| (i, j)))
        .filter(|&(i, j)| {
            i != j
                && graph.distance(planner::NodeId(i as u16), planner::NodeId(j as u16))
                    != planner::UNREACHABLE
        })
        .count();
    connected as f64 / (n * (n - 1)) as f64
}

/// The pivotal states on the maze, the world graph, and the loop's curves.
fn save_pictures(run: &DiscoveryRun, graph: &planner::WorldGraph, seed: u64) -> anyhow::Result<()> {
    let dir = run.dir().to_path_buf();
    let layout = run.layout().clone();
    let disc = run.discovery();
    pivotal_picture(
        &layout,
        &disc.prior_means(),
        disc.pivotal_states(),
        graph,
        seed,
    )
    .save_png(&dir.join("pivotal.png"))?;
    graph_picture(graph, true).save_png(&dir.join("graph.png"))?;
    curves(disc.history())
        .render(900, 520)
        .save_png(&dir.join("discovery_curves.png"))?;
    Ok(())
}

/// Has a planner process build the world graph over `V_p` (`--node-file`)
/// and save it into the run directory, then loads it.
fn build_graph_in_planner(
    a: &DiscoverArgs,
    w: &WorldArgs,
    dir: &Path,
    nodes: &Path,
) -> anyhow::Result<planner::WorldGraph> {
    let run = format!("discover-graph-{}", std::process::id());
    let _ = std::fs::remove_file(dir.join("graph.json"));
    let mut words = vec!["planner".to_string(), "serve".into()];
    words.extend(world_words(w));
    words.extend([
        "--run".into(),
        run.clone(),
        "--run-dir".into(),
        dir.display().to_string(),
    ]);
    words.extend([
        "--envs".into(),
        a.envs.to_string(),
        "--slices".into(),
        "1".into(),
        "--node-file".into(),
        nodes.display().to_string(),
        // The learner shortens the edges with π_g afterwards.
        "--no-shorten".into(),
    ]);
    words.extend(["--duration".into(), "0.5".into()]);
    let mut p = Pipeline::new(vec![(Role::Planner, words)], Some(dir))?;
    p.spawn(Role::Planner)?;
    let until = Instant::now() + Duration::from_secs(300);
    while p.any_running() && Instant::now() < until {
        p.poll_exited();
        std::thread::sleep(Duration::from_millis(50));
    }
    p.stop_all(Duration::from_secs(3));
    teardown(&run)?;
    planner::WorldGraph::load(&dir.join("graph.json")).with_context(|| {
        format!(
            "the planner did not save a graph; see {}/planner.log",
            dir.display()
        )
    })
}

/// Random node sets drawn for the coverage's chance level.
pub const RANDOM_DRAWS: usize = 1000;
/// `V_rand` graphs built for the routing's chance level.
pub const RANDOM_GRAPHS: usize = 5;
/// Random pairs of cells routed per graph.
pub const ROUTE_PAIRS: usize = 500;

/// `V_p` against `V_rand` on the maze's structure (section 5,
/// "Benefit of Learned Pivotal States").
struct StructureReport {
    passages: usize,
    rooms: usize,
    pivotal: planner::StructureCoverage,
    random: planner::StructureCoverage,
    routing: planner::RoutingQuality,
    routing_exact: planner::RoutingQuality,
    routing_random: planner::RoutingQuality,
}

impl StructureReport {
    fn measure(
        layout: &Layout,
        pivotal: &[u32],
        graph: &planner::WorldGraph,
        graph_cfg: &planner::PlannerConfig,
        seed: u64,
    ) -> anyhow::Result<StructureReport> {
        let s = planner::MazeStructure::new(layout);
        let route_seed = sim::env_seed(seed, 0x0052_4f55_5445); // "ROUTE"
        let exact = planner::PlannerConfig {
            shorten: true,
            ..graph_cfg.clone()
        };
        let nodes = planner::pivotal::nodes_from_cells(layout, pivotal);
        let exact_graph = planner::WorldGraph::build(layout, &exact, &nodes)?;
        let (mut stretch, mut routed) = (0.0, 0.0);
        for k in 0..RANDOM_GRAPHS {
            let cells =
                planner::pivotal::v_rand(layout, nodes.len(), sim::env_seed(seed, k as u64))?;
            let g = planner::WorldGraph::build(layout, &exact, &cells)?;
            let q = planner::routing_quality(&g, ROUTE_PAIRS, route_seed);
            stretch += q.mean_stretch / RANDOM_GRAPHS as f64;
            routed += q.routed / RANDOM_GRAPHS as f64;
        }
        Ok(StructureReport {
            passages: s.passages().len(),
            rooms: s.rooms().len(),
            pivotal: s.coverage(pivotal),
            random: s.random_coverage(
                pivotal.len(),
                RANDOM_DRAWS,
                sim::env_seed(seed, 0x0052_414e),
            ),
            routing: planner::routing_quality(graph, ROUTE_PAIRS, route_seed),
            routing_exact: planner::routing_quality(&exact_graph, ROUTE_PAIRS, route_seed),
            routing_random: planner::RoutingQuality {
                mean_stretch: stretch,
                routed,
                pairs: ROUTE_PAIRS,
            },
        })
    }
}

fn curves(history: &[RoundStats]) -> LineChart {
    let series = |name: &str, f: fn(&RoundStats) -> f64| Series {
        name: name.into(),
        points: history.iter().map(|h| (h.round as f64, f(h))).collect(),
    };
    LineChart {
        title: "world graph discovery".into(),
        x_label: "round".into(),
        y_label: "fraction".into(),
        series: vec![
            series("reconstruction accuracy", |h| h.reconstruction_accuracy),
            series("pi_g goal success", |h| h.gcp_success),
            series("kept states", |h| h.kept_fraction),
        ],
        x_scale: XScale::Count,
    }
}

fn print_summary(s: &DiscoverySummary, dir: &Path) {
    println!(
        "world graph discovery: {} maze, seed {}, {} ({})",
        s.maze,
        s.seed,
        s.transport,
        dir.display()
    );
    println!("  {:<44} {:>12}", "figure", "value");
    let rows: Vec<(&str, String)> = vec![
        ("rounds", s.rounds.to_string()),
        ("pivotal states |V_p|", s.pivotal_states.to_string()),
        ("world graph edges", s.edges.to_string()),
        (
            "  shortened by pi_g / could be shorter",
            format!("{} / {}", s.edges_refined_by_gcp, s.edges_improvable),
        ),
        (
            "  total weight: walks -> pi_g (shortest)",
            format!(
                "{} -> {} ({})",
                s.edge_weight_walks, s.edge_weight_refined, s.edge_weight_shortest
            ),
        ),
        (
            "connected node pairs",
            format!("{:.1}%", 100.0 * s.connected_pairs),
        ),
        (
            "passages with a pivotal state on or next to",
            format!(
                "{:.0}% (random {:.0}%) of {}",
                100.0 * s.passage_share,
                100.0 * s.passage_share_random,
                s.passages
            ),
        ),
        (
            "rooms holding a pivotal state",
            format!(
                "{:.0}% (random {:.0}%) of {}",
                100.0 * s.room_share,
                100.0 * s.room_share_random,
                s.rooms
            ),
        ),
        (
            "route / shortest: V_p graph (exact edges)",
            format!("{:.3} ({:.3})", s.route_stretch, s.route_stretch_exact),
        ),
        (
            "  V_rand graphs, exact edges",
            format!("{:.3}", s.route_stretch_random),
        ),
        (
            "reconstruction accuracy",
            format!("{:.3}", s.reconstruction_accuracy),
        ),
        (
            "pi_g success, goals within 10 steps",
            format!("{:.1}%", 100.0 * s.gcp_success_within_10),
        ),
        ("env steps", s.env_steps.to_string()),
        ("wall time (s)", format!("{:.1}", s.wall_seconds)),
        (
            "training throughput (env-steps/s)",
            format!("{:.0}", s.train_steps_per_sec),
        ),
    ];
    for (k, v) in rows {
        println!("  {k:<44} {v:>12}");
    }
    println!(
        "  pictures: pivotal.png (prior mean, V_p, edges), graph.png (edges along their paths, passages in green), discovery_curves.png"
    );
}
