//! # shm_schemas — the wire layout between worldgraph processes
//!
//! The only crate that knows how the sim, learner and planner processes of
//! worldgraph (Shang et al. 2019, "Learning World Graphs to Accelerate
//! Hierarchical Reinforcement Learning", arXiv:1907.00664) lay out the data
//! they share over iceoryx2 shared memory (README.md, "The pipeline"):
//!
//! ```text
//!   sim ── wg/<run>/obs  (ObsHeader + [EnvMeta; N] + N×H×W cells + N×H×W final cells) ──► learner, planner
//!   sim ◄─ wg/<run>/act  (ActHeader + N action bytes) ─────────────── learner
//!   learner ── wg/<run>/route (RouteRequest → RouteResponse) ──► planner
//!   planner ── wg/<run>/graph (GraphHeader + nodes + edges, latest only) ──► learner, viewers
//! ```
//!
//! - [`ObsHeader`]: the observation batch. [`EnvMeta`] is the
//!   per-environment record (with the pose a step's action led to, before
//!   any auto-reset); [`ObsShape`] the run's batch and grid size;
//!   [`ObsBatchMut`] splits a loaned sample into `(&mut ObsHeader,
//!   &mut [EnvMeta], cells, final cells)` so the simulator steps straight
//!   into shared memory; [`ObsBatch`] is the zero-copy read view. The final
//!   cells hold the grid an episode ended on, for the steps that ended one.
//! - [`ActHeader`], [`ActBatch`], [`ActBatchMut`]: the action batch.
//! - [`RouteRequest`], [`RouteResponse`], [`RouteStatus`]: route queries.
//! - [`GraphHeader`], [`GraphEdge`], [`GraphSnapshot`]: graph snapshots.
//! - [`SchemaError`]: what a process gets, instead of garbage, when the
//!   other end speaks another schema version or another shape;
//!   [`ShmError`] wraps it with the transport's own failures.
//! - [`service`]: names (`wg/<run>/obs`, ...), isolated configs, QoS, the
//!   typed ports ([`service::PipelineNode`] → [`service::ObsPublisher`], ...),
//!   dead-node cleanup and teardown.
//! - [`SeqTracker`]: lost/reordered batch accounting.
//!
//! The transport is the `ipc` feature (on by default): the iceoryx2
//! services, the `ZeroCopySend` derives and the unsafe sample access. The
//! simulator, the planner and the learner depend on this crate with default
//! features off, so they use the wire types without building iceoryx2; the
//! `worldgraph` binary, which runs the processes, turns `ipc` on.
//!
//! Every wire type is `#[repr(C)]`, [`bytemuck::Pod`] (no padding, checked
//! at compile time), `ZeroCopySend` with a versioned type name
//! (`wg.ObsHeader.v3`), with its size asserted at compile time. The only
//! `unsafe` code of the workspace's IPC path lives in one private module
//! (`raw.rs`), each block justified.
//!
//! ```
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # #[cfg(feature = "ipc")] {
//! use iceoryx2::prelude::*;
//! use shm_schemas::service::{PipelineNode, RunName, isolated_config};
//! use shm_schemas::{EnvMeta, ObsShape};
//!
//! let run = RunName::new("doc")?;
//! let config = isolated_config(&format!("wgdoc_{}_", std::process::id()))?;
//! let shape = ObsShape::new(2, 3, 3)?;
//! let sim = PipelineNode::<local::Service>::new(&config, run.clone(), "sim")?;
//! let learner = PipelineNode::<local::Service>::new(&config, run, "learner")?;
//! let publisher = sim.obs_publisher(shape)?;
//! let subscriber = learner.obs_subscriber(shape)?;
//!
//! let mut sample = publisher.loan(0, 0)?;
//! let batch = sample.batch_mut();
//! batch.meta.fill(EnvMeta::EMPTY); // the simulator writes here ...
//! batch.cells.fill(1);             // ... and here, in shared memory
//! sample.send()?;
//!
//! let received = subscriber.receive()?.expect("sent above");
//! assert_eq!(received.batch().cells, &[1; 18]);
//! # }
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

mod action;
mod backoff;
mod error;
mod graph;
mod plan;
#[cfg(feature = "ipc")]
mod raw;
mod seq;
#[cfg(feature = "ipc")]
pub mod service;
mod step;

pub use action::{ActBatch, ActBatchMut, ActHeader, NUM_ACTIONS};
pub use backoff::Backoff;
pub use error::{Channel, SchemaError, ShmError};
pub use graph::{GraphEdge, GraphHeader, GraphSnapshot, GraphSnapshotMut, MAX_EDGES, MAX_PIVOTS};
pub use plan::{
    MAX_ROUTE_LEN, MAX_ROUTE_PIVOTS, NO_PIVOT, RouteRequest, RouteResponse, RouteStatus,
    UNREACHABLE,
};
#[cfg(feature = "ipc")]
pub use raw::monotonic_ns;
pub use seq::{SeqEvent, SeqTracker};
pub use step::{
    CELLS_ALIGN, EnvMeta, MAX_CELLS, MAX_ENVS, MAX_GRID_SIDE, MAX_SLICES, ObsBatch, ObsBatchMut,
    ObsHeader, ObsShape, SENTINEL_BYTE, flags,
};

/// Version of the wire layout. Bumped on any change of a wire type; every
/// type name ends in `.v<SCHEMA_VERSION>` and every header carries it.
pub const SCHEMA_VERSION: u32 = 3;

#[cfg(all(test, feature = "ipc"))]
mod tests {
    use super::*;
    use crate::raw::type_name_of;

    #[test]
    fn every_type_name_carries_the_schema_version() {
        let names = [
            type_name_of::<EnvMeta>(),
            type_name_of::<ObsHeader>(),
            type_name_of::<ActHeader>(),
            type_name_of::<RouteRequest>(),
            type_name_of::<RouteResponse>(),
            type_name_of::<GraphHeader>(),
            type_name_of::<GraphEdge>(),
        ];
        for name in names {
            assert!(name.starts_with("wg."), "{name}");
            assert!(
                name.ends_with(&format!(".v{SCHEMA_VERSION}")),
                "{name} does not end in .v{SCHEMA_VERSION}"
            );
        }
    }
}
