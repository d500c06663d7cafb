//! Errors of the planner crate.

use crate::ids::NodeId;

/// Everything that can go wrong building, querying, saving or loading a
/// world graph.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlannerError {
    /// A configuration value is out of range (checked once by
    /// [`crate::PlannerConfig::validate`]).
    #[error("invalid planner configuration: {field}: {message}")]
    Config {
        /// The offending field.
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// A node-list file (or string) could not be parsed; `line` is 1-based,
    /// 0 when the error concerns the whole input.
    #[error("{source_name}:{line}: {message}")]
    NodeList {
        /// File name (or another description of the input).
        source_name: String,
        /// 1-based line, 0 if not tied to a line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A candidate cell lies outside the grid.
    #[error("cell ({x}, {y}) is outside the {width}x{height} grid")]
    OutOfGrid {
        /// Column.
        x: i64,
        /// Row.
        y: i64,
        /// Grid width.
        width: usize,
        /// Grid height.
        height: usize,
    },
    /// A candidate cell is one the agent cannot stand on at the start of an
    /// episode (a wall, key, ball, closed or locked door, lava, or a cell cut
    /// off from the agent's start).
    #[error("cell ({x}, {y}) holds {object} and cannot be a node: the agent cannot stand there")]
    NotStandable {
        /// Column.
        x: u16,
        /// Row.
        y: u16,
        /// What the cell holds (object name, or "an unreachable cell").
        object: String,
    },
    /// The same cell was given twice as a node.
    #[error("cell ({x}, {y}) is listed twice as a node")]
    DuplicateNode {
        /// Column.
        x: u16,
        /// Row.
        y: u16,
    },
    /// More random nodes (`V_rand`) were asked for than there are cells.
    #[error(
        "asked for {requested} random nodes but the maze has only {available} cells an agent can stand on"
    )]
    NotEnoughCells {
        /// Nodes asked for.
        requested: usize,
        /// Cells available.
        available: usize,
    },
    /// The node count exceeds what [`NodeId`] and the wire format can name.
    #[error("{count} nodes; at most {max} are supported")]
    TooManyNodes {
        /// Nodes given.
        count: usize,
        /// The limit ([`crate::MAX_NODES`]).
        max: usize,
    },
    /// The layout has a feature route replay cannot track (more than one key,
    /// or more than 64 doors; see [`crate::edges`]).
    #[error("layout {layout}: {message}")]
    UnsupportedLayout {
        /// Layout name.
        layout: String,
        /// What is not supported.
        message: String,
    },
    /// A node id that is not in the graph.
    #[error("{node} is not a node of this graph ({num_nodes} nodes)")]
    UnknownNode {
        /// The id asked for.
        node: NodeId,
        /// Nodes in the graph.
        num_nodes: usize,
    },
    /// The graph has no path between the two nodes.
    #[error("no route from {from} to {to} in the world graph")]
    Unreachable {
        /// Start node.
        from: NodeId,
        /// Target node.
        to: NodeId,
    },
    /// A pose from which no node can be reached (route queries from an
    /// arbitrary pose).
    #[error("no node can be reached from ({x}, {y})")]
    NotOnGraph {
        /// Column.
        x: u16,
        /// Row.
        y: u16,
    },
    /// A saved graph is inconsistent (edges naming missing nodes, paths that
    /// do not match their endpoints, ...).
    #[error("{source_name}: invalid world graph: {message}")]
    InvalidGraph {
        /// File name.
        source_name: String,
        /// What is inconsistent.
        message: String,
    },
    /// Reading a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A JSON document could not be read or written.
    #[error("{path}: {source}")]
    Json {
        /// The file.
        path: String,
        /// The cause.
        #[source]
        source: serde_json::Error,
    },
    /// The layout stored in a saved graph was refused.
    #[error(transparent)]
    Layout(#[from] sim::LayoutError),
    /// Writing a file or a picture failed in the simulator's writer.
    #[error(transparent)]
    Sim(#[from] sim::SimError),
}

impl PlannerError {
    /// The route-response status a route service answers for this error:
    /// [`PlannerError::Unreachable`] → `Unreachable`,
    /// [`PlannerError::UnknownNode`] → `UnknownTarget`,
    /// [`PlannerError::NotOnGraph`] → `StartNotOnGraph`, anything else →
    /// `BadRequest`.
    pub fn route_status(&self) -> shm_schemas::RouteStatus {
        use shm_schemas::RouteStatus;
        match self {
            PlannerError::Unreachable { .. } => RouteStatus::Unreachable,
            PlannerError::UnknownNode { .. } => RouteStatus::UnknownTarget,
            PlannerError::NotOnGraph { .. } => RouteStatus::StartNotOnGraph,
            _ => RouteStatus::BadRequest,
        }
    }
}
