//! Tests of the world graph: construction, routes, refinement, files.

use super::*;
use crate::config::CandidateSet;
use crate::shortest_path::UNREACHABLE;
use proptest::prelude::*;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use sim::{AutoReset, BallSpawn, Env, EnvConfig, Maze};
use sim::{Pose, action};

fn cfg(candidates: CandidateSet, seed: u64) -> PlannerConfig {
    PlannerConfig {
        candidates,
        seed,
        walks_per_node: 256,
        walk_len: 200,
        ..PlannerConfig::default()
    }
}

/// A fresh simulator in the graph's walk rules, episode-long, no reset.
fn fresh_env(g: &WorldGraph) -> Env {
    let c = EnvConfig {
        task: g.config().walk_task(),
        max_steps: u32::MAX,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::Off,
    };
    Env::new(g.layout().clone(), c, 0, 0)
}

/// Replays `route` in `env` (already at the route's start) and checks
/// that every action leads to the route's cell, that the route's nodes
/// are passed in order, and that it ends on `target`.
fn replay(g: &WorldGraph, env: &mut Env, route: &Route, target: NodeId) -> Result<(), String> {
    let w = g.layout().width;
    let mut passed = Vec::new();
    if let Some(n) = g.node_at(CellIdx(env.cell() as u32)) {
        passed.push(n);
    }
    for (i, (&a, &c)) in route.actions().iter().zip(route.cells()).enumerate() {
        env.step_meta(a);
        let at = CellIdx::of_pose(env.pose(), w);
        if at != c {
            return Err(format!(
                "action {i} ({}) leads to {at}, the route says {c}",
                action::NAMES[a as usize]
            ));
        }
        if let Some(n) = g.node_at(at)
            && passed.last() != Some(&n)
        {
            passed.push(n);
        }
    }
    let end = CellIdx(env.cell() as u32);
    if end != g.nodes()[target.index()] {
        return Err(format!("the route ends on {end}, not on {target}"));
    }
    // Every node of the route is passed, in order (walks may cross their
    // own start node, so `passed` can hold more).
    let mut it = passed.iter();
    if !route.nodes().iter().all(|n| it.any(|p| p == n)) {
        return Err(format!(
            "nodes {:?} not passed in order {:?}",
            route.nodes(),
            passed
        ));
    }
    Ok(())
}

/// Reference distances: Dijkstra over the graph's edges from `src`.
fn dijkstra(g: &WorldGraph, src: NodeId) -> Vec<u32> {
    let mut dist = vec![UNREACHABLE; g.num_nodes()];
    let mut heap = std::collections::BinaryHeap::new();
    dist[src.index()] = 0;
    heap.push(std::cmp::Reverse((0u32, src.0)));
    while let Some(std::cmp::Reverse((d, v))) = heap.pop() {
        if d > dist[v as usize] {
            continue;
        }
        for e in g.edges().iter().filter(|e| e.from.0 == v) {
            let nd = d + e.weight();
            if nd < dist[e.to.index()] {
                dist[e.to.index()] = nd;
                heap.push(std::cmp::Reverse((nd, e.to.0)));
            }
        }
    }
    dist
}

/// A random enclosed layout (`seed`-determined): walls, closed and open
/// doors, sometimes a locked door with its key, the start and an exit
/// reachable from it.
fn random_layout(seed: u64) -> Layout {
    for attempt in 0.. {
        let mut rng = SmallRng::seed_from_u64(sim::env_seed(seed, attempt));
        let (w, h) = (rng.random_range(5..=12usize), rng.random_range(5..=10usize));
        let mut g = vec![b'#'; w * h];
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                g[y * w + x] = match rng.random_range(0..100) {
                    0..25 => b'#',
                    25..29 => b'C',
                    29..31 => b'O',
                    _ => b'.',
                };
            }
        }
        let floor: Vec<usize> = (0..w * h).filter(|&i| g[i] == b'.').collect();
        if floor.len() < 6 {
            continue;
        }
        let start = floor[rng.random_range(0..floor.len())];
        // Cells reachable from the start through anything but walls.
        let mut seen = vec![false; w * h];
        let mut stack = vec![start];
        seen[start] = true;
        while let Some(i) = stack.pop() {
            for j in [i + 1, i - 1, i + w, i - w] {
                if g[j] != b'#' && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        let reach: Vec<usize> = floor
            .iter()
            .copied()
            .filter(|&i| seen[i] && i != start)
            .collect();
        if reach.len() < 5 {
            continue;
        }
        g[reach[rng.random_range(0..reach.len())]] = b'E';
        if rng.random_bool(0.5) {
            let spots: Vec<usize> = reach.iter().copied().filter(|&i| g[i] == b'.').collect();
            if spots.len() >= 4 {
                let k = spots[rng.random_range(0..spots.len())];
                let d = spots[rng.random_range(0..spots.len())];
                if k != d {
                    g[k] = b'K';
                    g[d] = b'D';
                }
            }
        }
        g[start] = b"<>^v"[rng.random_range(0..4)];
        let text: String = g
            .chunks(w)
            .map(|row| String::from_utf8_lossy(row).into_owned() + "\n")
            .collect();
        if let Ok(l) = Layout::parse(&format!("random-{seed}"), &text)
            && crate::pivotal::v_all(&l).len() >= 5
        {
            return l;
        }
    }
    unreachable!("the attempt loop only ends by returning")
}

fn check_graph(g: &WorldGraph) -> Result<(), TestCaseError> {
    let n = g.num_nodes();
    let mut route = Route::default();
    for a in 0..n {
        let a = NodeId(a as u16);
        let reference = dijkstra(g, a);
        for b in 0..n {
            let b = NodeId(b as u16);
            let d = g.distance(a, b);
            prop_assert_eq!(d, reference[b.index()], "DP vs Dijkstra {} -> {}", a, b);
            for k in 0..n {
                let k = NodeId(k as u16);
                let (ak, kb) = (g.distance(a, k), g.distance(k, b));
                if ak != UNREACHABLE && kb != UNREACHABLE {
                    prop_assert!(d <= ak + kb, "triangle {} {} {}", a, k, b);
                }
            }
            let facing = ((a.0 as usize + 3 * b.0 as usize) % 4) as u8;
            match g.route_into(a, facing, b, &mut route) {
                Ok(len) => {
                    prop_assert!(d != UNREACHABLE);
                    prop_assert_eq!(len, route.len());
                    let hops = route.nodes().len() - 1;
                    prop_assert!(
                        len <= d as usize + 2 * hops,
                        "{} actions for distance {} over {} hops",
                        len,
                        d,
                        hops
                    );
                    let mut env = fresh_env(g);
                    env.teleport(route.start().expect("a route has a start"));
                    replay(g, &mut env, &route, b).map_err(|e| {
                        TestCaseError::fail(format!("{}: {a} -> {b}: {e}", g.layout().name))
                    })?;
                }
                Err(PlannerError::Unreachable { .. }) => prop_assert_eq!(d, UNREACHABLE),
                Err(e) => return Err(TestCaseError::fail(e.to_string())),
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, rng_seed: proptest::test_runner::RngSeed::Fixed(3), ..ProptestConfig::default() })]

    /// On random layouts with doors and keys, with edges from walks or
    /// from the exhaustive search: DP distances equal Dijkstra over the
    /// same edges, the triangle inequality holds, and every route
    /// replays in a fresh simulator onto its target.
    #[test]
    fn random_layouts_dp_matches_reference_and_routes_execute(seed in any::<u64>(), k in 2usize..10, exhaustive in any::<bool>()) {
        let layout = random_layout(seed);
        let k = k.min(crate::pivotal::v_all(&layout).len());
        let edge_search = if exhaustive { crate::EdgeSearch::Exhaustive } else { crate::EdgeSearch::RandomWalks };
        let c = PlannerConfig { edge_search, ..cfg(CandidateSet::Random { k }, seed) };
        let g = WorldGraph::build(&layout, &c, &[]).map_err(|e| TestCaseError::fail(e.to_string()))?;
        check_graph(&g)?;
    }

    /// Routes chained in one simulator (each from where the previous
    /// one ended, in the world it left) keep executing, and routes from
    /// arbitrary poses reach their target.
    #[test]
    fn chained_and_pose_routes_execute(seed in any::<u64>()) {
        let layout = random_layout(seed);
        let k = 6.min(crate::pivotal::v_all(&layout).len());
        let g = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k }, seed), &[]).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut route = Route::with_capacity(512, 32);
        let mut env = fresh_env(&g);
        let mut world = g.initial_world();
        let mut at = NodeId(0);
        env.teleport(g.nodes()[0].pose(layout.width, 0));
        for _ in 0..12 {
            let to = NodeId(rng.random_range(0..k) as u16);
            if g.distance(at, to) == UNREACHABLE {
                continue;
            }
            g.route_in_world_into(at, env.pose().dir, to, world, &mut route).map_err(|e| TestCaseError::fail(e.to_string()))?;
            replay(&g, &mut env, &route, to).map_err(|e| TestCaseError::fail(format!("chained {at} -> {to}: {e}")))?;
            prop_assert_eq!(g.observe_world(env.grid(), env.carrying().map_or(sim::EnvMeta::CARRYING_NOTHING, |o| o as u8)), route.world_after());
            world = route.world_after();
            at = to;
        }
        for cell in crate::pivotal::v_all(&layout) {
            let pose = cell.pose(layout.width, rng.random_range(0..4));
            let to = NodeId(rng.random_range(0..k) as u16);
            match g.route_from_pose_into(pose, to, g.initial_world(), &mut route) {
                Ok(_) => {
                    let mut env = fresh_env(&g);
                    env.teleport(pose);
                    prop_assert_eq!(route.start(), Some(pose));
                    replay(&g, &mut env, &route, to).map_err(|e| TestCaseError::fail(format!("from {pose:?} to {to}: {e}")))?;
                }
                Err(PlannerError::Unreachable { .. } | PlannerError::NotOnGraph { .. }) => {}
                Err(e) => return Err(TestCaseError::fail(e.to_string())),
            }
        }
    }
}

#[test]
fn embedded_mazes_give_executable_routes() {
    for (maze, door_key) in [
        (Maze::Small, true),
        (Maze::Medium, false),
        (Maze::Large, true),
    ] {
        let layout = maze.layout(door_key);
        let g = WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 24 }, 1), &[])
            .expect("graph");
        assert!(
            g.edges().len() >= 24,
            "{}: only {} edges",
            layout.name,
            g.edges().len()
        );
        check_graph(&g).expect("routes execute");
    }
}

#[test]
fn v_all_edges_join_neighbouring_cells_with_one_move() {
    let layout = Maze::Small.layout(false);
    let g = WorldGraph::build(&layout, &cfg(CandidateSet::All, 0), &[]).expect("graph");
    for e in g.edges() {
        assert_eq!(e.actions, vec![action::FORWARD], "{} -> {}", e.from, e.to);
    }
    // Every move between neighbouring floor cells was found.
    let expected: usize = g
        .nodes()
        .iter()
        .filter(|c| layout.cells[c.index()] != Object::Exit as u8)
        .map(|&c| {
            (0..4)
                .filter(|&d| g.node_at(c.step(d, &layout)).is_some())
                .count()
        })
        .sum();
    assert_eq!(g.edges().len(), expected);
}

#[test]
fn locked_door_blocks_every_edge_without_the_key() {
    // The Door-Key maze with the key removed (the layout stays valid:
    // doors count as passable for validation).
    let text = Maze::Small.text(true).replace('K', ".");
    let layout = Layout::parse("small-doorkey-nokey", &text).expect("valid");
    let door = CellIdx(
        layout
            .cells
            .iter()
            .position(|&c| c == Object::DoorLocked as u8)
            .expect("locked door") as u32,
    );
    let g =
        WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 30 }, 4), &[]).expect("graph");
    assert!(!g.edges().is_empty());
    for e in g.edges() {
        assert!(
            !e.cells.contains(&door),
            "{} -> {} crosses the locked door",
            e.from,
            e.to
        );
    }
    // Nodes on the two sides of the door are not connected.
    let exit = layout
        .cells
        .iter()
        .position(|&c| c == Object::Exit as u8)
        .expect("exit");
    let blocked = {
        let mut l = layout.clone();
        l.cells[door.index()] = Object::Wall as u8;
        l.reachable_from(exit)
    };
    for (a, &ca) in g.nodes().iter().enumerate() {
        for (b, &cb) in g.nodes().iter().enumerate() {
            if blocked[ca.index()] != blocked[cb.index()] {
                assert_eq!(g.distance(NodeId(a as u16), NodeId(b as u16)), UNREACHABLE);
            }
        }
    }
    // With the key next to the door, an edge goes through it, picking the key up.
    let layout = Layout::parse("t", "#########\n#.>..D.E#\n#K#######\n#########\n").expect("valid");
    let nodes = [
        CellIdx::from_xy(2, 1, layout.width),
        CellIdx::from_xy(6, 1, layout.width),
    ];
    let g = WorldGraph::build(
        &layout,
        &PlannerConfig {
            candidates: CandidateSet::Given,
            walks_per_node: 4096,
            ..cfg(CandidateSet::Given, 2)
        },
        &nodes,
    )
    .expect("graph");
    let e = g
        .edge(NodeId(0), NodeId(1))
        .expect("edge through the unlocked door");
    assert!(e.actions.contains(&action::PICKUP) && e.actions.contains(&action::TOGGLE));
    assert!(
        g.edge(NodeId(1), NodeId(0)).is_none(),
        "from the far side the door is locked"
    );
    let mut route = Route::default();
    g.route_into(NodeId(0), 3, NodeId(1), &mut route)
        .expect("route");
    let mut env = fresh_env(&g);
    env.teleport(route.start().expect("start"));
    replay(&g, &mut env, &route, NodeId(1)).expect("executable");
    assert!(route.world_after().carrying_key && route.world_after().open_doors == 1);
}

#[test]
fn refinement_accepts_only_shorter_valid_paths() {
    let layout = Maze::Small.layout(false);
    let raw = PlannerConfig {
        shorten: false,
        ..cfg(CandidateSet::Random { k: 10 }, 3)
    };
    let mut g = WorldGraph::build(&layout, &raw, &[]).expect("graph");
    let exact =
        WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 10 }, 3), &[]).expect("graph");
    // Longer or broken proposals are refused.
    assert_eq!(
        g.refine_edges(|e| Some(EdgePath {
            actions: [e.actions.clone(), vec![action::LEFT]].concat(),
            cells: [e.cells.clone(), vec![*e.cells.last().expect("path")]].concat(),
            ..e.clone()
        })),
        0
    );
    let nodes = g.nodes().to_vec();
    assert_eq!(
        g.refine_edges(|e| Some(EdgePath {
            actions: vec![action::LEFT],
            cells: vec![nodes[e.to.index()]],
            ..e.clone()
        })),
        0
    );
    // The exact paths (a stand-in for π_g) are taken where shorter.
    let before: u32 = g.edges().iter().map(EdgePath::weight).sum();
    let changed = g.refine_edges(|e| exact.edge(e.from, e.to).cloned());
    let after: u32 = g.edges().iter().map(EdgePath::weight).sum();
    assert!(
        changed > 0 && after < before,
        "{changed} edges, {before} -> {after}"
    );
    for a in 0..g.num_nodes() as u16 {
        for b in 0..g.num_nodes() as u16 {
            assert_eq!(
                g.distance(NodeId(a), NodeId(b)),
                dijkstra(&g, NodeId(a))[b as usize]
            );
        }
    }
}

#[test]
fn loop_erasure_cuts_detours_and_keeps_paths_valid() {
    let layout = Maze::Small.layout(true);
    let g =
        WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 10 }, 5), &[]).expect("graph");
    for e in g.edges() {
        // A hesitating follower: turns on the spot before every forward
        // move, and a full turn at the start.
        let mut actions = vec![action::LEFT; 4];
        let mut cells = vec![g.nodes()[e.from.index()]; 4];
        let mut here = g.nodes()[e.from.index()];
        for (&a, &c) in e.actions.iter().zip(&e.cells) {
            if a == action::FORWARD {
                actions.extend([action::LEFT, action::RIGHT]);
                cells.extend([here, here]);
            }
            actions.push(a);
            cells.push(c);
            here = c;
        }
        let detour = EdgePath {
            actions,
            cells,
            ..e.clone()
        };
        check_edge_path(&g.world, &detour).expect("the detour is a valid path");
        // The edges are exact shortest paths, so erasing the loops gives
        // back exactly the edge.
        assert_eq!(&g.loop_erased(&detour), e);
        assert_eq!(&g.loop_erased(e), e, "a path without loops is kept");
    }
}

#[test]
fn json_round_trip_and_atomic_save() {
    let layout = Maze::Small.layout(true);
    let g =
        WorldGraph::build(&layout, &cfg(CandidateSet::Random { k: 12 }, 9), &[]).expect("graph");
    let dir = std::env::temp_dir().join(format!("planner-json-{}", std::process::id()));
    let path = dir.join("graph.json");
    g.save(&path).expect("save");
    let back = WorldGraph::load(&path).expect("load");
    assert_eq!(back.nodes(), g.nodes());
    assert_eq!(back.edges(), g.edges());
    assert_eq!(back.config(), g.config());
    assert_eq!(back.layout(), g.layout());
    assert_eq!(back.shortest_paths(), g.shortest_paths());
    assert_eq!(back.to_json(), g.to_json());
    g.save_png(&dir.join("graph.png"), 16).expect("png");
    let png = std::fs::read(dir.join("graph.png")).expect("png written");
    assert_eq!(&png[1..4], b"PNG");
    std::fs::remove_dir_all(&dir).expect("clean up");

    // Tampered files are refused with a reason.
    let json = g.to_json();
    let v: serde_json::Value = serde_json::from_str(&json).expect("json");
    let with = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut v = v.clone();
        f(&mut v);
        WorldGraph::from_json("g.json", &v.to_string())
            .expect_err("must be refused")
            .to_string()
    };
    assert!(with(&|v| v["edges"][0]["weight"] = 999.into()).contains("weight"));
    assert!(with(&|v| v["edges"][0]["actions"][0] = 6.into()).contains("edge"));
    assert!(with(&|v| v["nodes"][0]["id"] = 5.into()).contains("has id"));
    assert!(with(&|v| v["format"] = "other".into()).contains("format"));
    let dup = with(&|v| {
        let (x, y) = (v["nodes"][0]["x"].clone(), v["nodes"][0]["y"].clone());
        v["nodes"][1]["x"] = x;
        v["nodes"][1]["y"] = y;
    });
    assert!(dup.contains("twice"), "{dup}");
    let e = WorldGraph::from_json("g.json", "{")
        .expect_err("truncated")
        .to_string();
    assert!(e.starts_with("g.json"), "{e}");
}

#[test]
fn unknown_nodes_and_unreachable_pairs_are_errors() {
    let layout = Layout::parse("t", "#######\n#>.D.E#\n#######\n").expect("valid");
    let nodes = [
        CellIdx::from_xy(2, 1, layout.width),
        CellIdx::from_xy(4, 1, layout.width),
    ];
    let g = WorldGraph::build(&layout, &cfg(CandidateSet::Given, 0), &nodes).expect("graph");
    let mut r = Route::default();
    assert!(matches!(
        g.route_into(NodeId(0), 0, NodeId(1), &mut r),
        Err(PlannerError::Unreachable { .. })
    ));
    assert!(matches!(
        g.route_into(NodeId(0), 0, NodeId(2), &mut r),
        Err(PlannerError::UnknownNode { .. })
    ));
    assert!(r.is_empty() && r.start().is_none());
    assert_eq!(
        g.route_into(NodeId(1), 2, NodeId(1), &mut r)
            .expect("trivial route"),
        0
    );
    assert_eq!(r.nodes(), &[NodeId(1)]);
    let e = g
        .route_into(NodeId(0), 0, NodeId(1), &mut r)
        .expect_err("unreachable");
    assert_eq!(e.route_status(), shm_schemas::RouteStatus::Unreachable);
    let e = g
        .route_from_pose_into(
            Pose { x: 0, y: 0, dir: 0 },
            NodeId(0),
            g.initial_world(),
            &mut r,
        )
        .expect_err("a wall");
    assert_eq!(e.route_status(), shm_schemas::RouteStatus::StartNotOnGraph);
    // Wire copy: fits or writes nothing.
    g.route_from_pose_into(
        Pose { x: 1, y: 1, dir: 2 },
        NodeId(0),
        g.initial_world(),
        &mut r,
    )
    .expect("route");
    // Turn around (two turns either way), then one step onto node 0.
    assert_eq!(r.len(), 3);
    assert!(
        r.actions()[0] == r.actions()[1]
            && r.actions()[0] != action::FORWARD
            && r.actions()[2] == action::FORWARD
    );
    let (mut p, mut c, mut a) = ([7u16; 4], [7u32; 4], [7u8; 4]);
    assert_eq!(r.write_wire(&mut p, &mut c, &mut a), Some((1, 3)));
    assert_eq!(
        (p[0], &c[..3], &a[..3]),
        (0, &[8u32, 8, 9][..], r.actions())
    );
    assert_eq!(r.write_wire(&mut p, &mut c[..2], &mut a), None);
    let two_keys = Layout::parse("k", "#######\n#>KK.E#\n#######\n").expect("valid");
    assert!(matches!(
        WorldGraph::build(&two_keys, &cfg(CandidateSet::All, 0), &[]),
        Err(PlannerError::UnsupportedLayout { .. })
    ));
}
