//! The world-graph snapshot (`wg/<run>/graph`): the planner publishes the
//! current graph (Shang et al. 2019, arXiv:1907.00664, section 3.3: pivotal
//! states as nodes, edges weighted by their action count) to the learner and
//! to viewers.
//!
//! A "latest snapshot" stream (iceoryx2 guide, section 4): pub/sub with
//! history 1 and subscriber buffer 1, so a late joiner gets the current
//! graph and a slow reader only ever sees the newest one. Graphs grow as
//! discovery proceeds, so the payload is a slice with the `PowerOfTwo`
//! allocation strategy rather than a fixed worst-case array.
//!
//! Layout: user header [`GraphHeader`]; payload `[u32]`:
//!
//! ```text
//! [0, num_nodes)                       node i's cell index (y · W + x)
//! [num_nodes, num_nodes + 2·num_edges) num_edges × GraphEdge {from, to, weight}
//! ```

use bytemuck::{Pod, Zeroable};
#[cfg(feature = "ipc")]
use iceoryx2::prelude::ZeroCopySend;

use crate::step::{check_len, check_run, check_version};
use crate::{Channel, SchemaError};
#[cfg(feature = "ipc")]
use crate::{MAX_GRID_SIDE, SCHEMA_VERSION, step::check_range};

/// Most nodes (pivotal states) in a graph: one per cell of the largest grid.
pub const MAX_PIVOTS: usize = crate::MAX_CELLS;
/// Most directed edges in a graph.
pub const MAX_EDGES: usize = 1 << 20;

/// One directed edge `from → to` of the world graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Pod, Zeroable)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("wg.GraphEdge.v3"))]
#[repr(C)]
pub struct GraphEdge {
    /// Source node id.
    pub from: u16,
    /// Target node id.
    pub to: u16,
    /// Action count of the kept path.
    pub weight: u32,
}

/// Header of a graph snapshot (iceoryx2 user header of `wg/<run>/graph`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("wg.GraphHeader.v3"))]
#[repr(C)]
pub struct GraphHeader {
    /// [`SCHEMA_VERSION`] of the writer.
    pub schema_version: u32,
    /// Nodes in the snapshot.
    pub num_nodes: u32,
    /// [`crate::service::RunName::id`] of the run.
    pub run_id: u64,
    /// Version counter of the graph, +1 per change; route responses name
    /// the version that answered them.
    pub graph_version: u64,
    /// `CLOCK_MONOTONIC` time of `send()` in ns.
    pub send_time_ns: u64,
    /// Edges in the snapshot.
    pub num_edges: u32,
    /// Grid width, to turn cell indices into `(x, y)`.
    pub width: u16,
    /// Grid height.
    pub height: u16,
}

impl GraphHeader {
    /// Payload length in `u32` words for the given counts.
    pub const fn payload_words(num_nodes: usize, num_edges: usize) -> usize {
        num_nodes + num_edges * (size_of::<GraphEdge>() / size_of::<u32>())
    }

    /// Checks version, run and grid.
    pub fn check(&self, width: u16, height: u16, run_id: u64) -> Result<(), SchemaError> {
        check_version(Channel::Graph, self.schema_version)?;
        check_run(Channel::Graph, run_id, self.run_id)?;
        if (self.width, self.height) != (width, height) {
            return Err(SchemaError::GridShape {
                channel: Channel::Graph,
                expected: (width, height),
                wire: (self.width, self.height),
            });
        }
        Ok(())
    }
}

/// Checks node and edge counts against [`MAX_PIVOTS`] and [`MAX_EDGES`]
/// (zero is allowed: an empty graph).
pub(crate) fn check_counts(num_nodes: usize, num_edges: usize) -> Result<(), SchemaError> {
    for (what, value, max) in [
        ("num_nodes", num_nodes, MAX_PIVOTS),
        ("num_edges", num_edges, MAX_EDGES),
    ] {
        if value > max {
            return Err(SchemaError::OutOfRange {
                channel: Channel::Graph,
                what,
                value,
                max,
            });
        }
    }
    Ok(())
}

/// Checks a grid size against [`MAX_GRID_SIDE`].
#[cfg(feature = "ipc")]
pub(crate) fn check_grid(
    channel: Channel,
    width: usize,
    height: usize,
) -> Result<(u16, u16), SchemaError> {
    check_range(channel, "width", width, MAX_GRID_SIDE)?;
    check_range(channel, "height", height, MAX_GRID_SIDE)?;
    Ok((width as u16, height as u16))
}

/// Read view of a graph snapshot.
#[derive(Debug, Clone, Copy)]
pub struct GraphSnapshot<'a> {
    /// The header.
    pub header: &'a GraphHeader,
    /// Node `i`'s cell index.
    pub nodes: &'a [u32],
    /// The directed edges.
    pub edges: &'a [GraphEdge],
}

impl<'a> GraphSnapshot<'a> {
    /// Views `payload` after checking `header`.
    pub fn new(
        header: &'a GraphHeader,
        payload: &'a [u32],
        width: u16,
        height: u16,
        run_id: u64,
    ) -> Result<GraphSnapshot<'a>, SchemaError> {
        header.check(width, height, run_id)?;
        let (n, m) = (header.num_nodes as usize, header.num_edges as usize);
        check_counts(n, m)?;
        let words = GraphHeader::payload_words(n, m);
        check_len(Channel::Graph, words * 4, payload.len() * 4)?;
        let (nodes, rest) = payload[..words].split_at(n);
        Ok(GraphSnapshot {
            header,
            nodes,
            edges: bytemuck::cast_slice(rest),
        })
    }
}

/// Write view of a loaned graph snapshot (stale contents: write all).
#[derive(Debug)]
pub struct GraphSnapshotMut<'a> {
    /// The header (counts, run, grid set at loan; set `graph_version`).
    pub header: &'a mut GraphHeader,
    /// Node `i`'s cell index.
    pub nodes: &'a mut [u32],
    /// The directed edges.
    pub edges: &'a mut [GraphEdge],
}

impl<'a> GraphSnapshotMut<'a> {
    /// Views `payload` as `num_nodes` nodes and `num_edges` edges, writing
    /// the counts and version into the header.
    #[cfg(feature = "ipc")]
    pub(crate) fn new(
        header: &'a mut GraphHeader,
        payload: &'a mut [u32],
        num_nodes: usize,
        num_edges: usize,
    ) -> Result<GraphSnapshotMut<'a>, SchemaError> {
        check_counts(num_nodes, num_edges)?;
        let words = GraphHeader::payload_words(num_nodes, num_edges);
        check_len(Channel::Graph, words * 4, payload.len() * 4)?;
        header.schema_version = SCHEMA_VERSION;
        header.num_nodes = num_nodes as u32;
        header.num_edges = num_edges as u32;
        let (nodes, rest) = payload[..words].split_at_mut(num_nodes);
        Ok(GraphSnapshotMut {
            header,
            nodes,
            edges: bytemuck::cast_slice_mut(rest),
        })
    }
}

const _: () = assert!(size_of::<GraphEdge>() == 8);
const _: () = assert!(align_of::<GraphEdge>() == 4);
const _: () = assert!(size_of::<GraphHeader>() == 40);
const _: () = assert!(align_of::<GraphHeader>() == 8);
const _: () = assert!(MAX_PIVOTS <= crate::NO_PIVOT as usize);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snapshot_views() {
        let mut payload = vec![0u32; GraphHeader::payload_words(3, 2)];
        let mut h = GraphHeader {
            run_id: 4,
            width: 13,
            height: 13,
            ..Default::default()
        };
        {
            let g = GraphSnapshotMut::new(&mut h, &mut payload, 3, 2).unwrap();
            g.nodes.copy_from_slice(&[14, 20, 150]);
            g.edges[0] = GraphEdge {
                from: 0,
                to: 1,
                weight: 6,
            };
            g.edges[1] = GraphEdge {
                from: 1,
                to: 2,
                weight: 11,
            };
            g.header.graph_version = 9;
        }
        let g = GraphSnapshot::new(&h, &payload, 13, 13, 4).unwrap();
        assert_eq!(g.nodes, &[14, 20, 150]);
        assert_eq!(
            g.edges[1],
            GraphEdge {
                from: 1,
                to: 2,
                weight: 11
            }
        );
        assert_eq!(g.header.graph_version, 9);
        assert!(matches!(
            GraphSnapshot::new(&h, &payload, 25, 19, 4),
            Err(SchemaError::GridShape { .. })
        ));
        assert!(matches!(
            GraphSnapshot::new(&h, &payload[..5], 13, 13, 4),
            Err(SchemaError::PayloadTooShort { .. })
        ));
        let empty = GraphHeader {
            num_nodes: 0,
            num_edges: 0,
            ..h
        };
        assert!(
            GraphSnapshot::new(&empty, &[], 13, 13, 4)
                .unwrap()
                .nodes
                .is_empty()
        );
    }
}
