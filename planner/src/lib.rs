//! # planner — the world graph and its traversal
//!
//! Implements the graph side of Shang et al. 2019, *Learning World Graphs to
//! Accelerate Hierarchical Reinforcement Learning* (arXiv:1907.00664),
//! section 3.3 ("Edge Connections") and section 4.3 ("Using World Graph
//! Edges for Traversal"):
//!
//! 1. **Nodes** ([`pivotal`]): pivotal states `V_p`, or a comparison set —
//!    `V_all` (every cell), `V_rand` (random cells), a list from a file.
//! 2. **Edges** ([`edges`]): random walks in the simulator from each node;
//!    `s_p → s_q` when a walk reaches `s_q` without touching a third node;
//!    the shortest such path is kept, its action count is the edge weight.
//!    Paths are then refined: by `π_g` through [`WorldGraph::refine_edges`]
//!    (the learner's `edge_refinement`, with [`edges::loop_erase`]), or,
//!    without a learned policy, by an exact search
//!    ([`edges::shorten_edge`]). Doors, keys and one-way effects are the
//!    simulator's own.
//! 3. **Traversal** ([`shortest_path`], [`world_graph`]): all-pairs
//!    shortest paths by dynamic programming (Floyd–Warshall with a
//!    next-hop table) and routes — nodes, cells and executable actions —
//!    written into caller buffers.
//!
//! [`structure`] finds a maze's passages and rooms and measures how a node
//! set covers them and how well a graph routes (`V_p` against `V_rand`).
//! [`Coverage`] counts visited cells from observation batches. Everything
//! here is pure: the iceoryx2 route service only turns requests into calls
//! of [`WorldGraph::route_from_pose_into`] and friends.
//!
//! ## Calling it
//! - Build: [`WorldGraph::build`]`(&layout, &cfg, given)`; nodes come from
//!   [`PlannerConfig::candidates`] (`V_rand`, `V_all`, a file, or `given`,
//!   e.g. the learner's pivotal states through
//!   [`pivotal::nodes_from_cells`]).
//! - Query: keep one [`Route`] per caller ([`Route::with_capacity`]) and call
//!   [`WorldGraph::route_into`] (node to node) or
//!   [`WorldGraph::route_from_pose_into`] (any pose to a node, with the
//!   observed [`RouteWorld`] from [`WorldGraph::observe_world`]); copy the
//!   answer into a wire response with [`Route::write_wire`] and map errors
//!   with [`PlannerError::route_status`].
//! - Persist: [`WorldGraph::save`] / [`WorldGraph::load`] (JSON, atomic),
//!   [`WorldGraph::save_png`], [`Coverage::save_png`].
//! - Measure: [`WorldGraph::rebuild_shortest_paths`] and the route queries
//!   are what `bench planner` times.
//!
//! ```
//! use planner::{CandidateSet, PlannerConfig, Route, WorldGraph};
//! let layout = sim::Maze::Small.layout(false);
//! let cfg = PlannerConfig { candidates: CandidateSet::Random { k: 8 }, walks_per_node: 64, ..Default::default() };
//! let graph = WorldGraph::build(&layout, &cfg, &[]).unwrap();
//! let mut route = Route::with_capacity(256, 16);
//! let (a, b) = (planner::NodeId(0), planner::NodeId(7));
//! if graph.distance(a, b) != planner::UNREACHABLE {
//!     let n = graph.route_into(a, 0, b, &mut route).unwrap();
//!     assert_eq!(route.nodes().last(), Some(&b));
//!     assert_eq!(n, route.actions().len());
//! }
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod config;
pub mod coverage;
pub mod edges;
mod error;
mod ids;
pub mod pivotal;
pub mod shortest_path;
pub mod structure;
pub mod world_graph;

pub use config::{CandidateSet, EdgeSearch, MAX_NODES, PlannerConfig};
pub use coverage::Coverage;
pub use edges::{EdgePath, EdgeWorld};
pub use error::PlannerError;
pub use ids::{CellIdx, NodeId};
pub use shortest_path::{ShortestPaths, UNREACHABLE};
pub use structure::{MazeStructure, RoutingQuality, StructureCoverage, routing_quality};
pub use world_graph::{Route, RouteWorld, WorldGraph};
