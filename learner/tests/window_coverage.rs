//! Every free cell of every embedded maze can be a narrow goal of the
//! Wide-then-Narrow Manager (Shang et al. 2019, section 4.2: `g_n` lies in
//! the `N×N` window around `g_w ∈ V`) under each candidate set the agent
//! can use: `V_p` of the committed discovery runs, `V_rand` as `train`
//! draws it, and `V_all`, with the automatic window side.

use std::path::PathBuf;

use learner::hrl::wide_narrow::{self, Coverage};
use learner::hrl::{AgentConfig, AgentKind, Candidates, HrlAgent, WorldGraphInputs};
use planner::{CandidateSet, CellIdx, PlannerConfig, WorldGraph};
use sim::{Layout, Maze, Task};

/// The pivotal cells `[x, y]` of a committed discovery run.
fn discovered_cells(maze: Maze, seed: u64) -> Vec<[usize; 2]> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../results/pivotal")
        .join(maze.name())
        .join(format!("discover/seed-{seed}.json"));
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    serde_json::from_value(v["summary"]["pivotal_cells"].clone())
        .unwrap_or_else(|e| panic!("{}: summary.pivotal_cells: {e}", path.display()))
}

/// `V_p` on `layout`: the discovered cells the agent can stand on there
/// (on a Door-Key layout the key and the locked door drop out, as in
/// `train`'s `world_graph_for`).
fn v_p(layout: &Layout, maze: Maze, seed: u64) -> Vec<CellIdx> {
    let cells: Vec<u32> = discovered_cells(maze, seed)
        .iter()
        .map(|&[x, y]| layout.cell_index(x, y) as u32)
        .collect();
    planner::pivotal::nodes_from_cells(layout, &cells)
}

fn task_of(door_key: bool) -> Task {
    if door_key {
        Task::DoorKey
    } else {
        Task::MultiGoal
    }
}

/// A WN agent over `candidates` with the automatic window side, `graph`
/// holding `V` (for `V_rand` and `V_p`).
fn agent(
    layout: &Layout,
    door_key: bool,
    candidates: Candidates,
    graph: Option<WorldGraph>,
) -> HrlAgent {
    let cfg = AgentConfig {
        kind: AgentKind::WideNarrow,
        candidates,
        envs: 1,
        window: 0,
        ..AgentConfig::default()
    };
    let inputs = WorldGraphInputs { graph, gcp: None };
    HrlAgent::new(&cfg, layout, task_of(door_key), Some(inputs), 0).expect("agent")
}

/// A graph over `nodes` (edges play no part in which cells are goals).
fn graph_over(layout: &Layout, door_key: bool, nodes: &[CellIdx]) -> WorldGraph {
    let cfg = PlannerConfig {
        candidates: CandidateSet::Given,
        task: task_of(door_key),
        ..PlannerConfig::default()
    };
    WorldGraph::from_parts(layout, &cfg, nodes, Vec::new(), "v_p").expect("graph")
}

/// `V_rand` of `k` cells as the agent gets it: a world graph built over
/// `CandidateSet::Random` (the same cells `train` draws with
/// `planner::pivotal::v_rand` for a run of that seed).
fn v_rand_graph(layout: &Layout, door_key: bool, k: usize, seed: u64) -> WorldGraph {
    let cfg = PlannerConfig {
        candidates: CandidateSet::Random { k },
        seed,
        task: task_of(door_key),
        // Edges play no part here; short walks keep the test quick.
        walks_per_node: 4,
        walk_len: 64,
        ..PlannerConfig::default()
    };
    let g = WorldGraph::build(layout, &cfg, &[]).expect("V_rand graph");
    assert_eq!(
        g.nodes(),
        planner::pivotal::v_rand(layout, k, seed)
            .expect("v_rand")
            .as_slice(),
        "the graph's nodes are the cells train draws"
    );
    g
}

/// Every free cell (not a wall: `Window::valid`'s rule) within the window
/// of some candidate, checked by Chebyshev distance without the window
/// code.
fn assert_every_free_cell_is_a_narrow_goal(layout: &Layout, candidates: &[u32], side: usize) {
    let r = (side / 2) as i64;
    let xy = |c: usize| ((c % layout.width) as i64, (c / layout.width) as i64);
    for (c, &code) in layout.cells.iter().enumerate() {
        if code == sim::Object::Wall as u8 {
            continue;
        }
        let (x, y) = xy(c);
        assert!(
            candidates.iter().any(|&v| {
                let (vx, vy) = xy(v as usize);
                (x - vx).abs() <= r && (y - vy).abs() <= r
            }),
            "{}: ({x}, {y}) is outside every {side}×{side} window",
            layout.name
        );
    }
}

/// Checks the agent's window: the automatic side is the paper's, widened
/// just enough, and every free cell is covered. Returns the coverage.
fn check(layout: &Layout, a: &HrlAgent, label: &str) -> Coverage {
    let cov = a.window_coverage().expect("WN has a window");
    let paper = AgentConfig::default().window_side(layout.width);
    assert_eq!(
        cov.side,
        wide_narrow::covering_side(paper, a.candidates(), layout),
        "{label}"
    );
    assert!(cov.side >= paper && cov.side % 2 == 1, "{label}: {cov}");
    assert!(cov.is_complete(), "{}, {label}: {cov}", layout.name);
    assert_eq!(cov.covered, cov.free);
    assert_every_free_cell_is_a_narrow_goal(layout, a.candidates(), cov.side);
    let at_paper = wide_narrow::coverage(paper, a.candidates(), layout);
    println!(
        "{:<15} {label:<22} {cov} (at {paper}×{paper}: {} of {})",
        layout.name, at_paper.covered, at_paper.free
    );
    cov
}

#[test]
fn every_free_cell_is_a_possible_narrow_goal_under_every_candidate_set() {
    for maze in Maze::ALL {
        for door_key in [false, true] {
            let layout = maze.layout(door_key);
            for seed in 0..3 {
                let nodes = v_p(&layout, maze, seed);
                let a = agent(
                    &layout,
                    door_key,
                    Candidates::Pivotal,
                    Some(graph_over(&layout, door_key, &nodes)),
                );
                check(&layout, &a, &format!("V_p (discover {seed})"));
            }
            let k = v_p(&layout, maze, 0).len();
            for seed in 0..6 {
                let a = agent(
                    &layout,
                    door_key,
                    Candidates::Random,
                    Some(v_rand_graph(&layout, door_key, k, seed)),
                );
                check(&layout, &a, &format!("V_rand (k {k}, seed {seed})"));
            }
            let a = agent(&layout, door_key, Candidates::All, None);
            let cov = check(&layout, &a, "V_all");
            assert_eq!(
                cov.side,
                AgentConfig::default().window_side(layout.width),
                "V_all needs no widening"
            );
        }
    }
}

/// The premise: under the old fixed side (5 on the small maze) the
/// discovered `V_p` leaves the exit out of every window, so no narrow goal
/// could ever be the exit.
#[test]
fn the_old_fixed_window_missed_the_small_maze_exit_under_v_p() {
    let layout = Maze::Small.layout(false);
    let v: Vec<u32> = v_p(&layout, Maze::Small, 0).iter().map(|c| c.0).collect();
    let old = wide_narrow::coverage(5, &v, &layout);
    assert!(old.uncovered.contains(&[11, 11]), "{old}");
    let exit = layout.cell_index(11, 11);
    assert_eq!(layout.cells[exit], sim::Object::Exit as u8);
    let a = agent(
        &layout,
        false,
        Candidates::Pivotal,
        Some(graph_over(&layout, false, &v_p(&layout, Maze::Small, 0))),
    );
    let new = a.window_coverage().expect("window");
    assert!(new.side > 5 && new.is_complete(), "{new}");
}
