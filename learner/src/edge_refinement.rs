//! Edge refinement by the goal-conditioned policy (Shang et al. 2019,
//! arXiv:1907.00664, section 3.3, "Edge Connections"):
//!
//! > We then collect the shortest such actionable paths as the edge paths.
//! > Each path is further refined by `π_g` if feasible.
//!
//! For every edge `s_p → s_q` of the world graph, `π_g` is followed greedily
//! from `s_p` (in the layout's initial world, once from each of the four
//! facings) with `s_q` as its goal, for at most [`rollout_budget`] actions.
//! A rollout that stands on `s_q` without touching a third pivotal state
//! or ending the episode has its loops cut out
//! ([`WorldGraph::loop_erased`]: a greedy policy may turn back and forth on
//! its way) and is that edge's proposal when it is shorter than the edge's
//! path; the shortest proposal (ties: the lowest facing) is handed to
//! [`WorldGraph::refine_edges`],
//! which replays it in the simulator before it replaces the path and then
//! rebuilds the all-pairs shortest paths. Edges `π_g` cannot shorten keep
//! the random walk's path: "if feasible".
//!
//! The rollouts are batched (one environment per edge and facing) and the
//! actions are `π_g`'s argmax, so the result is a function of the weights
//! and the graph alone. [`RefinementStats::weight_shortest`] reports the
//! floor no refinement can go below (the exact shortest edge paths), so a
//! user sees how much of the possible shortening `π_g` achieved.

use std::collections::HashMap;

use planner::{CellIdx, EdgePath, NodeId, WorldGraph};
use serde::Serialize;
use sim::{EnvMeta, flags};

use crate::batch_env::ObsView;
use crate::error::LearnerError;
use crate::gcp::GoalConditionedPolicy;

/// Rollouts per `π_g` forward pass (bounds the one-hot batch's memory:
/// 256 × channels × cells floats).
const CHUNK: usize = 256;

/// What a refinement did.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct RefinementStats {
    /// Edges of the graph.
    pub edges: usize,
    /// Edges whose random-walk path is longer than the shortest possible.
    pub improvable: usize,
    /// `π_g` rollouts run (four facings per edge of weight 2 or more).
    pub rollouts: usize,
    /// Rollouts that reached their target node within their budget.
    pub reached: usize,
    /// Edges whose path `π_g` shortened.
    pub refined: usize,
    /// Sum of the edge weights before refinement (the random walks' paths).
    pub weight_walks: u64,
    /// Sum of the edge weights after refinement.
    pub weight_refined: u64,
    /// Sum of the exact shortest edge weights: the floor of any refinement.
    pub weight_shortest: u64,
}

/// One rollout: edge `edge`, started facing `dir`, at most `budget` actions.
#[derive(Debug, Clone, Copy)]
struct Query {
    edge: usize,
    dir: u8,
    budget: usize,
}

/// Refines the edges of `graph` with `π_g` (module docs) and returns what
/// changed.
pub fn refine_with_gcp(
    graph: &mut WorldGraph,
    gcp: &mut GoalConditionedPolicy,
) -> Result<RefinementStats, LearnerError> {
    let shortest: Vec<u32> = graph
        .edges()
        .iter()
        .map(|e| {
            graph
                .shortest_edge_weight(e.from, e.to)
                .unwrap_or(e.weight())
        })
        .collect();
    let mut stats = RefinementStats {
        edges: graph.edges().len(),
        improvable: graph
            .edges()
            .iter()
            .zip(&shortest)
            .filter(|(e, s)| e.weight() > **s)
            .count(),
        weight_walks: total_weight(graph),
        weight_shortest: shortest.iter().map(|&w| u64::from(w)).sum(),
        ..RefinementStats::default()
    };
    let queries: Vec<Query> = graph
        .edges()
        .iter()
        .enumerate()
        .filter(|(_, e)| e.weight() >= 2)
        .flat_map(|(edge, e)| {
            (0..4).map(move |dir| Query {
                edge,
                dir,
                budget: rollout_budget(e.weight()),
            })
        })
        .collect();
    stats.rollouts = queries.len();
    let mut best: HashMap<(NodeId, NodeId), EdgePath> = HashMap::new();
    for chunk in queries.chunks(CHUNK) {
        for reached in follow(graph, gcp, chunk)?.into_iter().flatten() {
            stats.reached += 1;
            let proposal = graph.loop_erased(&reached);
            let key = (proposal.from, proposal.to);
            match best.get(&key) {
                Some(b) if b.weight() <= proposal.weight() => {}
                _ => {
                    best.insert(key, proposal);
                }
            }
        }
    }
    stats.refined = graph.refine_edges(|e| best.get(&(e.from, e.to)).cloned());
    stats.weight_refined = total_weight(graph);
    Ok(stats)
}

/// Most actions a rollout along an edge of weight `w` may take: twice the
/// edge's length and at least 16 more, since loop erasure can shorten what
/// `π_g` walked (a greedy policy that hesitates still finds the way).
pub fn rollout_budget(w: u32) -> usize {
    (2 * w as usize).max(w as usize + 16)
}

fn total_weight(graph: &WorldGraph) -> u64 {
    graph.edges().iter().map(|e| u64::from(e.weight())).sum()
}

/// How a rollout stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Running,
    Reached,
    Failed,
}

/// Follows `π_g` greedily for each query, all in one batch; returns each
/// rollout's path when it reached its target node within its budget.
fn follow(
    graph: &WorldGraph,
    gcp: &mut GoalConditionedPolicy,
    queries: &[Query],
) -> Result<Vec<Option<EdgePath>>, LearnerError> {
    let layout = graph.layout();
    let (width, height) = (layout.width, layout.height);
    let hw = width * height;
    let n = queries.len();
    let mut envs = vec![graph.walk_env().clone(); n];
    let mut cells = vec![0u8; n * hw];
    let mut meta = vec![EnvMeta::EMPTY; n];
    let mut goals = Vec::with_capacity(n);
    let mut paths: Vec<EdgePath> = Vec::with_capacity(n);
    for (i, q) in queries.iter().enumerate() {
        let e = &graph.edges()[q.edge];
        envs[i].teleport(graph.nodes()[e.from.index()].pose(width, q.dir));
        envs[i].observe(&mut cells[i * hw..(i + 1) * hw], &mut meta[i]);
        goals.push(graph.nodes()[e.to.index()].0);
        paths.push(EdgePath {
            from: e.from,
            to: e.to,
            start_dir: q.dir,
            actions: Vec::with_capacity(q.budget),
            cells: Vec::with_capacity(q.budget),
        });
    }
    let mut finals = vec![0u8; cells.len()];
    let mut outcome = vec![Outcome::Running; n];
    let mut state = gcp.network().zero_state(n as i64);
    while outcome.contains(&Outcome::Running) {
        let obs = ObsView {
            seq: 0,
            cells: &cells,
            final_cells: &[],
            meta: &meta,
            width,
            height,
        };
        let (actions, next) = gcp.greedy_step(&obs, &goals, &state)?;
        state = next;
        for (i, q) in queries.iter().enumerate() {
            if outcome[i] != Outcome::Running {
                continue;
            }
            let a = actions[i];
            envs[i].step(
                a,
                &mut cells[i * hw..(i + 1) * hw],
                &mut finals[i * hw..(i + 1) * hw],
                &mut meta[i],
            );
            let m = meta[i];
            let cell = CellIdx(m.end_cell(width) as u32);
            let path = &mut paths[i];
            path.actions.push(a);
            path.cells.push(cell);
            outcome[i] = match graph.node_at(cell) {
                Some(node) if node == path.to => Outcome::Reached,
                Some(node) if node != path.from => Outcome::Failed,
                _ if m.flags & flags::TERMINATED != 0 => Outcome::Failed,
                _ if path.actions.len() >= q.budget => Outcome::Failed,
                _ => Outcome::Running,
            };
        }
    }
    Ok(paths
        .into_iter()
        .zip(outcome)
        .map(|(p, o)| (o == Outcome::Reached).then_some(p))
        .collect())
}
