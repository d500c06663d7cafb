//! A world graph's file: pretty JSON with a format tag
//! ([`GRAPH_FORMAT`]), the layout, the configuration, the nodes and the
//! edges; the route tables are recomputed on load, and everything read is
//! checked ([`WorldGraph::from_json`]).

use std::path::Path;

use serde::{Deserialize, Serialize};
use sim::Layout;

use super::WorldGraph;
use crate::config::PlannerConfig;
use crate::edges::EdgePath;
use crate::error::PlannerError;
use crate::ids::{CellIdx, NodeId};

/// Format tag of saved graphs.
pub const GRAPH_FORMAT: &str = "worldgraph.world_graph.v1";

/// The JSON document of a saved graph.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GraphFile {
    format: String,
    layout_name: String,
    width: usize,
    height: usize,
    /// The layout in its file format, one string per row.
    layout: Vec<String>,
    config: PlannerConfig,
    nodes: Vec<NodeRecord>,
    edges: Vec<EdgeRecord>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct NodeRecord {
    id: NodeId,
    x: u16,
    y: u16,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EdgeRecord {
    from: NodeId,
    to: NodeId,
    weight: u32,
    start_dir: u8,
    actions: Vec<u8>,
    cells: Vec<CellIdx>,
}

impl WorldGraph {
    /// The graph as pretty JSON: format tag, layout (name and rows),
    /// configuration, nodes `{id, x, y}`, edges with weight, start facing,
    /// actions and cells. The route tables are not stored: they are
    /// recomputed on load.
    pub fn to_json(&self) -> String {
        let l = self.layout();
        let file = GraphFile {
            format: GRAPH_FORMAT.to_string(),
            layout_name: l.name.clone(),
            width: l.width,
            height: l.height,
            layout: l.to_text().lines().map(str::to_string).collect(),
            config: self.config.clone(),
            nodes: self
                .nodes()
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    let (x, y) = c.xy(l.width);
                    NodeRecord {
                        id: NodeId(i as u16),
                        x,
                        y,
                    }
                })
                .collect(),
            edges: self
                .edges
                .iter()
                .map(|e| EdgeRecord {
                    from: e.from,
                    to: e.to,
                    weight: e.weight(),
                    start_dir: e.start_dir,
                    actions: e.actions.clone(),
                    cells: e.cells.clone(),
                })
                .collect(),
        };
        serde_json::to_string_pretty(&file)
            .expect("invariant: the graph file serialises (plain data, string keys)")
    }

    /// Reads a graph from [`WorldGraph::to_json`]'s format; `source` names
    /// the input in errors. Everything is checked: the layout is parsed and
    /// validated, node ids must be `0..n` in order, weights must equal the
    /// path lengths, and every edge path is replayed in the simulator.
    pub fn from_json(source: &str, text: &str) -> Result<WorldGraph, PlannerError> {
        let file: GraphFile = serde_json::from_str(text).map_err(|e| PlannerError::Json {
            path: source.to_string(),
            source: e,
        })?;
        let invalid = |message: String| PlannerError::InvalidGraph {
            source_name: source.to_string(),
            message,
        };
        if file.format != GRAPH_FORMAT {
            return Err(invalid(format!(
                "format {:?}, expected {GRAPH_FORMAT:?}",
                file.format
            )));
        }
        let layout = Layout::parse(&file.layout_name, &(file.layout.join("\n") + "\n"))?;
        if (layout.width, layout.height) != (file.width, file.height) {
            return Err(invalid(format!(
                "the layout is {}x{} but the file says {}x{}",
                layout.width, layout.height, file.width, file.height
            )));
        }
        let mut nodes = Vec::with_capacity(file.nodes.len());
        for (i, n) in file.nodes.iter().enumerate() {
            if n.id.index() != i {
                return Err(invalid(format!("node {i} has id {}", n.id)));
            }
            if n.x as usize >= layout.width || n.y as usize >= layout.height {
                return Err(PlannerError::OutOfGrid {
                    x: n.x.into(),
                    y: n.y.into(),
                    width: layout.width,
                    height: layout.height,
                });
            }
            nodes.push(CellIdx::from_xy(n.x as usize, n.y as usize, layout.width));
        }
        let mut edges = Vec::with_capacity(file.edges.len());
        for e in file.edges {
            if e.weight as usize != e.actions.len() {
                return Err(invalid(format!(
                    "edge {} -> {} has weight {} but {} actions",
                    e.from,
                    e.to,
                    e.weight,
                    e.actions.len()
                )));
            }
            edges.push(EdgePath {
                from: e.from,
                to: e.to,
                start_dir: e.start_dir,
                actions: e.actions,
                cells: e.cells,
            });
        }
        file.config.validate()?;
        WorldGraph::from_parts(&layout, &file.config, &nodes, edges, source)
    }

    /// Saves [`WorldGraph::to_json`] atomically (write, fsync, rename).
    pub fn save(&self, path: &Path) -> Result<(), PlannerError> {
        Ok(sim::atomic_file::write_atomic(
            path,
            self.to_json().as_bytes(),
        )?)
    }

    /// Loads a graph saved by [`WorldGraph::save`].
    pub fn load(path: &Path) -> Result<WorldGraph, PlannerError> {
        let text = std::fs::read_to_string(path).map_err(|source| PlannerError::Io {
            path: path.display().to_string(),
            source,
        })?;
        WorldGraph::from_json(&path.display().to_string(), &text)
    }
}
