//! The iceoryx2 wiring of the pipeline: service names, isolated configs,
//! nodes, the QoS of each channel, opening with retry and mismatch
//! diagnosis, typed port wrappers, and cleanup, one file per concern:
//! `names` (run and service names, configs), `files` (shared-memory
//! files, permissions, dead-node cleanup, teardown), `diagnose` (how an
//! iceoryx2 refusal is retried or explained), `node` ([`PipelineNode`] and
//! its one open-with-retry), and one file per channel (`obs`, `act`,
//! `route`, `graph`) with its QoS and typed ports.
//!
//! ## Names
//!
//! A run `R` ([`RunName`]) uses the services `wg/R/obs`, `wg/R/act`,
//! `wg/R/route` and `wg/R/graph` ([`Channel`], [`service_name`]) and the
//! iceoryx2 prefix `wg_R_` ([`RunName::prefix`], [`run_config`]), so every
//! file it creates (`/dev/shm/wg_R_*`, `/tmp/iceoryx2/**/wg_R_*`) is its own
//! and can be found and removed at teardown ([`teardown_run`]). Tests use
//! [`isolated_config`] with a unique prefix to run in parallel.
//!
//! ## Who opens what
//!
//! Every process opens every service with `open_or_create` and the same QoS
//! (one function per channel here), so start order does not matter. The
//! schema version and the run's shape are part of the service's identity:
//! the user-header / payload type names carry the version
//! (`wg.ObsHeader.v3`: iceoryx2 itself refuses another version with
//! `IncompatibleTypes`), and service *attributes* carry
//! `wg.schema_version`, `wg.num_envs`, `wg.grid` (`"WxH"`) and, for nodes
//! that run a task, `wg.task` (`"doorkey/6"`: task and action count), which
//! `open_or_create_with_attributes` verifies (`IncompatibleAttributes`).
//! When iceoryx2 refuses, [`PipelineNode`] reads the existing service's
//! static description (`Service::details`) and turns the refusal into a
//! [`SchemaError`] that names the difference ("observation batch schema v2
//! on the wire, this process speaks v3", "grid 25x19 expected, publisher
//! sends 13x13"). Every received sample's header is checked again
//! (version, run, shape), so garbage never reaches a view.
//!
//! ## QoS, overflow and backpressure
//!
//! | channel | pattern | publishers / subscribers | history | buffer | overflow |
//! |---|---|---|---|---|---|
//! | obs | pub/sub `[u64]` + `ObsHeader`, `Static` | 1 / 3 (learner, planner, one spare) | K | 4 | safe overflow |
//! | act | pub/sub `[u8]` + `ActHeader`, `Static` | 1 / 2 (sim, one spare) | 0 | 4 | safe overflow |
//! | route | req/resp, fixed size | 1 server / 3 clients, 32 active requests each | – | 1 response | no fire-and-forget |
//! | graph | pub/sub `[u32]` + `GraphHeader`, `PowerOfTwo` | 1 / 4 | 1 | 1 | safe overflow (latest only) |
//!
//! The sim ↔ learner loop is lossless **by protocol**, not by
//! backpressure. The simulator's batch is published as `K` slices
//! ([`crate::ObsShape::sliced`], `K ≤ MAX_SLICES = 4`; `K = 1` is plain
//! lock-step), sample `k` holding slice `k mod K`: the sim publishes sample
//! `k + K` only after it received action batch `k`, which the learner sends
//! after it received sample `k`. So the learner never has more than `K`
//! unread samples in its buffer of 4 and safe overflow can never discard
//! one of them. With `K = 2` the sim steps one half of its batch while the
//! learner chooses the other half's actions (double-buffered sampling), so
//! the round trip hides behind a step. Safe overflow (rather than blocking backpressure) is chosen so
//! that a slow or stuck *planner*, a passive reader of the same stream,
//! can never stall the simulator: the planner loses the oldest batches
//! instead and sees the gap in `seq` ([`crate::SeqTracker`]). History `K`
//! lets a restarted learner pick up the sample the sim is waiting on.
//! One publisher per stream: a second simulator for the same run is
//! refused (`ExceedsMaxSupportedPublishers`); a crashed one's slot is
//! reclaimed by dead-node cleanup, which port creation here triggers and
//! retries.
//!
//! Chunks pre-allocated per obs publisher: `3 × (4 + 2) + K + 2 ≤ 24`, each
//! `ObsShape::payload_bytes()` plus 110 bytes of headers (at most 12 MB for
//! 1024 envs on the 25×19 maze). The route server pre-allocates
//! `clients × 2 × active × (buffer 1 + borrowed 1 + loaned 1) = 576`
//! responses of 10.8 kB (6.3 MB).
//!
//! ## Permissions
//!
//! iceoryx2 creates its shared memory with owner-only permissions, except
//! the per-prefix `…global_mgmt` segment, which it creates world
//! read-writable; [`create_node`] tightens that one to `0600`. The
//! `dev_permissions` feature stays off.

use std::fmt::Debug;

use std::time::Duration;

use iceoryx2::service::port_factory::{publish_subscribe, request_response};

use crate::{ActHeader, GraphHeader, ObsHeader, RouteRequest, RouteResponse};

mod act;
mod diagnose;
mod files;
mod graph;
mod names;
mod node;
mod obs;
mod route;

pub use act::{ActPublisher, ActSample, ActSampleMut, ActSubscriber};
pub use files::{
    NodeSummary, Swept, cleanup_dead_nodes, harden_shm_permissions, list_dead_nodes, list_nodes,
    remove_global_mgmt, shm_files, shm_prefixes, sweep_stale_prefixes, teardown_run,
};
pub use graph::{GraphPublisher, GraphSample, GraphSampleMut, GraphSubscriber};
pub use names::{
    RunName, config_prefix, isolated_config, run_config, service_name, service_name_str,
};
pub use node::{PipelineNode, create_node};
pub use obs::{ObsPublisher, ObsSample, ObsSampleMut, ObsSubscriber};
pub use route::{PendingRoute, RouteCall, RouteClient, RouteReply, RouteServer};

/// First segment of every service name.
pub const SERVICE_ROOT: &str = "wg";
/// Start of every iceoryx2 prefix of a run (`wg_<run>_`).
pub const PREFIX_ROOT: &str = "wg_";
/// Attribute key: the schema version, decimal.
pub const ATTR_SCHEMA_VERSION: &str = "wg.schema_version";
/// Attribute key: environments per batch, decimal.
pub const ATTR_NUM_ENVS: &str = "wg.num_envs";
/// Attribute key: grid size, `"WxH"`.
pub const ATTR_GRID: &str = "wg.grid";
/// Attribute key: slices per observation batch ([`crate::ObsShape::slices`]).
pub const ATTR_SLICES: &str = "wg.slices";
/// Attribute key: the task and its action count, `"<task>/<actions>"`
/// ([`PipelineNode::with_task`]); on the obs and act services.
pub const ATTR_TASK: &str = "wg.task";
/// Default time [`PipelineNode`] keeps retrying transient iceoryx2 errors.
pub const DEFAULT_RETRY_TIMEOUT: Duration = Duration::from_secs(5);
/// Directory of POSIX shared memory on Linux.
pub const SHM_DIR: &str = "/dev/shm";

/// Obs service: subscribers (learner, planner, one spare for a viewer or a
/// restarted process whose predecessor is not yet cleaned up).
pub const OBS_MAX_SUBSCRIBERS: usize = 3;
/// Obs service: per-subscriber queue; ≥ 2 and ≥ [`crate::MAX_SLICES`]
/// keeps the lock-step learner lossless (it has at most one unread sample
/// per slice).
pub const OBS_BUFFER: usize = crate::MAX_SLICES;
/// Obs service: samples a subscriber may hold at once.
pub const OBS_MAX_BORROWED: usize = 2;
/// Obs publisher: samples the simulator may hold loaned at once.
pub const OBS_MAX_LOANS: usize = 2;
/// Act service: subscribers (the sim and one spare).
pub const ACT_MAX_SUBSCRIBERS: usize = 2;
/// Act service: per-subscriber queue (one unread answer per slice at most).
pub const ACT_BUFFER: usize = crate::MAX_SLICES;
/// Route service: clients (the learner, a benchmark or tool, one spare).
pub const ROUTE_MAX_CLIENTS: usize = 3;
/// Route service: outstanding requests per client.
pub const ROUTE_MAX_ACTIVE_REQUESTS: usize = 32;
/// Graph service: subscribers (learner, viewers).
pub const GRAPH_MAX_SUBSCRIBERS: usize = 4;
/// Graph publisher: initial slice capacity in `u32` words (grows by powers of two).
pub const GRAPH_INITIAL_WORDS: usize = 1 << 14;

/// Port factory of `wg/<run>/obs`.
pub type ObsService<S> = publish_subscribe::PortFactory<S, [u64], ObsHeader>;
/// Port factory of `wg/<run>/act`.
pub type ActService<S> = publish_subscribe::PortFactory<S, [u8], ActHeader>;
/// Port factory of `wg/<run>/route`.
pub type RouteService<S> = request_response::PortFactory<S, RouteRequest, (), RouteResponse, ()>;
/// Port factory of `wg/<run>/graph`.
pub type GraphService<S> = publish_subscribe::PortFactory<S, [u32], GraphHeader>;

#[cfg(test)]
mod tests;
