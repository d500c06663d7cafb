//! The iceoryx2 wiring of the pipeline: service names, isolated configs,
//! nodes, the QoS of each channel, opening with retry and mismatch
//! diagnosis, typed port wrappers, and cleanup.
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
//! (`wg.ObsHeader.v2`: iceoryx2 itself refuses another version with
//! `IncompatibleTypes`), and service *attributes* carry
//! `wg.schema_version`, `wg.num_envs` and `wg.grid` (`"WxH"`), which
//! `open_or_create_with_attributes` verifies (`IncompatibleAttributes`).
//! When iceoryx2 refuses, [`PipelineNode`] reads the existing service's
//! static description (`Service::details`) and turns the refusal into a
//! [`SchemaError`] that names the difference ("observation batch schema v1
//! on the wire, this process speaks v2", "grid 25x19 expected, publisher
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
use std::path::{Path as StdPath, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::active_request::ActiveRequest;
use iceoryx2::config::Config;
use iceoryx2::node::{CleanupState, NodeView};
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::response::Response;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeCreateError as PsCreate, PublishSubscribeOpenError as PsOpen,
    PublishSubscribeOpenOrCreateError as PsError,
};
use iceoryx2::service::builder::request_response::{
    RequestResponseCreateError as RrCreate, RequestResponseOpenError as RrOpen,
    RequestResponseOpenOrCreateError as RrError,
};
use iceoryx2::service::port_factory::client::ClientCreateError;
use iceoryx2::service::port_factory::server::ServerCreateError;
use iceoryx2::service::port_factory::{publish_subscribe, request_response};
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as StaticPattern;

use crate::action::check_num_envs;
use crate::graph::{GraphSnapshotMut, check_counts, check_grid};
use crate::raw::{assume_init_response, assume_init_slice, split_slice_sample, type_name_of};
use crate::{
    ActBatch, ActBatchMut, ActHeader, Channel, GraphEdge, GraphHeader, GraphSnapshot, ObsBatch,
    ObsBatchMut, ObsHeader, ObsShape, RouteRequest, RouteResponse, RouteStatus, SCHEMA_VERSION,
    SchemaError, ShmError, monotonic_ns,
};

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

// ---------------------------------------------------------------- names

/// A run's name: `1..=64` characters from `[A-Za-z0-9_.-]`, not starting
/// with `.` (it becomes part of service names and file names).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunName(String);

impl RunName {
    /// Longest accepted name.
    pub const MAX_LEN: usize = 64;

    /// Checks and wraps `name`.
    pub fn new(name: &str) -> Result<RunName, ShmError> {
        let bad = |reason: &str| ShmError::InvalidName {
            what: "run name",
            value: name.to_owned(),
            reason: reason.to_owned(),
        };
        if name.is_empty() || name.len() > Self::MAX_LEN {
            return Err(bad("must have 1 to 64 characters"));
        }
        if name.starts_with('.') {
            return Err(bad("must not start with '.'"));
        }
        if !name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_.-".contains(&b))
        {
            return Err(bad("only letters, digits, '_', '.' and '-' are allowed"));
        }
        Ok(RunName(name.to_owned()))
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The run id written into every header: FNV-1a (64 bit) of the name.
    pub fn id(&self) -> u64 {
        self.0.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
            (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
        })
    }

    /// The run's iceoryx2 prefix, `wg_<name>_`.
    pub fn prefix(&self) -> String {
        format!("{PREFIX_ROOT}{}_", self.0)
    }
}

impl std::fmt::Display for RunName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// `wg/<run>/<channel>` as a string.
pub fn service_name_str(run: &RunName, channel: Channel) -> String {
    format!("{SERVICE_ROOT}/{}/{}", run.as_str(), channel.suffix())
}

/// `wg/<run>/<channel>` as an iceoryx2 service name.
pub fn service_name(run: &RunName, channel: Channel) -> Result<ServiceName, ShmError> {
    let s = service_name_str(run, channel);
    ServiceName::new(&s).map_err(|e| ShmError::InvalidName {
        what: "service name",
        value: s,
        reason: format!("{e:?}"),
    })
}

// ---------------------------------------------------------------- config and nodes

/// A default iceoryx2 config (never a config file found on disk) with the
/// given file prefix: what isolates one run, or one test, from the others.
pub fn isolated_config(prefix: &str) -> Result<Config, ShmError> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|e| ShmError::InvalidName {
        what: "iceoryx2 prefix",
        value: prefix.to_owned(),
        reason: format!("{e:?}"),
    })?;
    Ok(config)
}

/// The config of a run: [`isolated_config`] with [`RunName::prefix`].
pub fn run_config(run: &RunName) -> Result<Config, ShmError> {
    isolated_config(&run.prefix())
}

/// The prefix of `config` as a string.
pub fn config_prefix(config: &Config) -> String {
    config.global.prefix.to_string()
}

/// Creates a node with signal handling disabled (the processes own SIGINT
/// and SIGTERM), then tightens the permissions of the prefix's
/// `global_mgmt` segment ([`harden_shm_permissions`]).
pub fn create_node<S: Service>(config: &Config, name: &str) -> Result<Node<S>, ShmError> {
    let node_name = NodeName::new(name).map_err(|e| ShmError::InvalidName {
        what: "node name",
        value: name.to_owned(),
        reason: format!("{e:?}"),
    })?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<S>()
        .map_err(|e| ShmError::Ipc {
            op: "create node",
            service: name.to_owned(),
            detail: format!("{e:?}"),
        })?;
    harden_shm_permissions(&config_prefix(config))?;
    Ok(node)
}

/// Removes group and other permission bits from `/dev/shm/<prefix>*`
/// (iceoryx2 creates the `global_mgmt` segment world read-writable).
/// Returns the files changed.
pub fn harden_shm_permissions(prefix: &str) -> Result<Vec<PathBuf>, ShmError> {
    use std::os::unix::fs::PermissionsExt;
    let mut changed = Vec::new();
    for (path, mode) in shm_files(prefix)? {
        if mode & 0o077 != 0 {
            let perms = std::fs::Permissions::from_mode(mode & 0o700);
            match std::fs::set_permissions(&path, perms) {
                Ok(()) => changed.push(path),
                // Removed meanwhile by a peer's cleanup: nothing to protect.
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => {
                    return Err(ShmError::Io {
                        op: "chmod",
                        path,
                        source,
                    });
                }
            }
        }
    }
    Ok(changed)
}

/// `/dev/shm/<prefix>*` files with their permission bits.
///
/// iceoryx2 names them `<prefix><40 hex digits>` followed by `_` or `.`;
/// only such names count, so the files of run `a_b` are not mistaken for
/// files of run `a` (whose prefix `wg_a_` is a prefix of `wg_a_b_`).
pub fn shm_files(prefix: &str) -> Result<Vec<(PathBuf, u32)>, ShmError> {
    let mut files = files_with_prefix(StdPath::new(SHM_DIR), prefix)?;
    files.retain(|(path, _)| {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        is_iceoryx2_name_after_prefix(name.as_bytes().get(prefix.len()..).unwrap_or_default())
    });
    Ok(files)
}

/// `<40 hex digits>` then `_` or `.`: the hash iceoryx2 puts after the prefix.
fn is_iceoryx2_name_after_prefix(rest: &[u8]) -> bool {
    rest.len() > 40
        && rest[..40].iter().all(u8::is_ascii_hexdigit)
        && matches!(rest[40], b'_' | b'.')
}

fn files_with_prefix(dir: &StdPath, prefix: &str) -> Result<Vec<(PathBuf, u32)>, ShmError> {
    use std::os::unix::fs::PermissionsExt;
    let entries = std::fs::read_dir(dir).map_err(|source| ShmError::Io {
        op: "list",
        path: dir.to_owned(),
        source,
    })?;
    let mut out = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        if !name.to_string_lossy().starts_with(prefix) {
            continue;
        }
        if let Ok(meta) = entry.metadata() {
            out.push((entry.path(), meta.permissions().mode() & 0o7777));
        }
    }
    out.sort();
    Ok(out)
}

// ---------------------------------------------------------------- cleanup

/// One node found by [`list_nodes`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeSummary {
    /// Node name (empty when its details could not be read).
    pub name: String,
    /// Process id.
    pub pid: i64,
    /// Executable name.
    pub executable: String,
    /// Whether the owning process is alive.
    pub alive: bool,
}

/// The nodes registered under `config`'s prefix, alive and dead
/// (inaccessible or undefined ones are skipped).
pub fn list_nodes<S: Service>(config: &Config) -> Result<Vec<NodeSummary>, ShmError> {
    let mut out = Vec::new();
    Node::<S>::list(config, |state| {
        let (view_details, alive) = match &state {
            NodeState::Alive(v) => (v.details().clone(), true),
            NodeState::Dead(v) => (v.details().clone(), false),
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => {
                return CallbackProgression::Continue;
            }
        };
        let (name, pid, executable) = match view_details {
            Some(d) => (
                d.name().to_string(),
                d.process_id().value() as i64,
                d.executable().to_string(),
            ),
            None => (String::new(), -1, String::new()),
        };
        out.push(NodeSummary {
            name,
            pid,
            executable,
            alive,
        });
        CallbackProgression::Continue
    })
    .map_err(|e| ShmError::Ipc {
        op: "list nodes",
        service: config_prefix(config),
        detail: format!("{e:?}"),
    })?;
    Ok(out)
}

/// The dead nodes under `config`'s prefix (a crashed or killed process).
pub fn list_dead_nodes<S: Service>(config: &Config) -> Result<Vec<NodeSummary>, ShmError> {
    Ok(list_nodes::<S>(config)?
        .into_iter()
        .filter(|n| !n.alive)
        .collect())
}

/// Removes the stale resources of every dead node under `config`'s prefix
/// (what a start-up should do after a killed run). Waits up to `timeout`
/// per node for a concurrent cleaner.
pub fn cleanup_dead_nodes<S: Service>(
    config: &Config,
    timeout: Duration,
) -> Result<CleanupState, ShmError> {
    let mut dead = Vec::new();
    Node::<S>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| ShmError::Ipc {
        op: "list nodes",
        service: config_prefix(config),
        detail: format!("{e:?}"),
    })?;
    let mut state = CleanupState {
        cleanups: 0,
        failed_cleanups: 0,
    };
    for view in dead {
        match view.blocking_remove_stale_resources(timeout) {
            Ok(()) => state.cleanups += 1,
            Err(_) => state.failed_cleanups += 1,
        }
    }
    Ok(state)
}

/// Removes the `/dev/shm/<prefix>*global_mgmt` segments iceoryx2 leaves
/// behind after a clean exit (one per prefix and iceoryx2 version). Only
/// these are touched: removing live service segments by hand corrupts
/// services (iceoryx2 issue #601). Returns the files removed.
pub fn remove_global_mgmt(prefix: &str) -> Result<Vec<PathBuf>, ShmError> {
    let mut removed = Vec::new();
    for (path, _) in shm_files(prefix)? {
        if !path.to_string_lossy().ends_with("global_mgmt") {
            continue;
        }
        match std::fs::remove_file(&path) {
            Ok(()) => removed.push(path),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(source) => {
                return Err(ShmError::Io {
                    op: "remove",
                    path,
                    source,
                });
            }
        }
    }
    Ok(removed)
}

/// Teardown of a run (or a test prefix): refuses while a node is alive,
/// cleans up dead nodes, then removes the leftover `global_mgmt` segments.
/// Returns the shared-memory files still present afterwards (empty after
/// a clean shutdown).
pub fn teardown_run<S: Service>(config: &Config) -> Result<Vec<PathBuf>, ShmError> {
    let prefix = config_prefix(config);
    let alive = list_nodes::<S>(config)?.iter().filter(|n| n.alive).count();
    if alive > 0 {
        return Err(ShmError::StillInUse { prefix, alive });
    }
    cleanup_dead_nodes::<S>(config, Duration::from_secs(1))?;
    remove_global_mgmt(&prefix)?;
    Ok(shm_files(&prefix)?.into_iter().map(|(p, _)| p).collect())
}

// ---------------------------------------------------------------- retry and diagnosis

/// How an iceoryx2 error is handled by the retry loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    /// Retry after a back-off.
    Transient,
    /// Clean up dead nodes, then retry.
    Cleanup,
    /// The service exists but differs: diagnose.
    Incompatible,
    /// Give up.
    Fatal,
}

fn classify_ps(e: &PsError) -> Class {
    match e {
        PsError::SystemInFlux => Class::Transient,
        PsError::PublishSubscribeOpenError(o) => match o {
            PsOpen::DoesNotExist
            | PsOpen::IsMarkedForDestruction
            | PsOpen::ServiceInCorruptedState
            | PsOpen::HangsInCreation => Class::Transient,
            PsOpen::ExceedsMaxNumberOfNodes => Class::Cleanup,
            PsOpen::IncompatibleTypes
            | PsOpen::IncompatibleAttributes
            | PsOpen::IncompatibleMessagingPattern
            | PsOpen::IncompatibleOverflowBehavior
            | PsOpen::DoesNotSupportRequestedMinBufferSize
            | PsOpen::DoesNotSupportRequestedMinHistorySize
            | PsOpen::DoesNotSupportRequestedMinSubscriberBorrowedSamples
            | PsOpen::DoesNotSupportRequestedAmountOfPublishers
            | PsOpen::DoesNotSupportRequestedAmountOfSubscribers
            | PsOpen::DoesNotSupportRequestedAmountOfNodes => Class::Incompatible,
            _ => Class::Fatal,
        },
        PsError::PublishSubscribeCreateError(c) => match c {
            PsCreate::AlreadyExists
            | PsCreate::IsBeingCreatedByAnotherInstance
            | PsCreate::HangsInCreation
            | PsCreate::ServiceInCorruptedState => Class::Transient,
            _ => Class::Fatal,
        },
    }
}

fn classify_rr(e: &RrError) -> Class {
    match e {
        RrError::SystemInFlux => Class::Transient,
        RrError::RequestResponseOpenError(o) => match o {
            RrOpen::DoesNotExist
            | RrOpen::IsMarkedForDestruction
            | RrOpen::ServiceInCorruptedState
            | RrOpen::HangsInCreation => Class::Transient,
            RrOpen::ExceedsMaxNumberOfNodes => Class::Cleanup,
            RrOpen::IncompatibleRequestOrResponseType
            | RrOpen::IncompatibleAttributes
            | RrOpen::IncompatibleMessagingPattern
            | RrOpen::IncompatibleOverflowBehaviorForRequests
            | RrOpen::IncompatibleOverflowBehaviorForResponses
            | RrOpen::IncompatibleBehaviorForFireAndForgetRequests
            | RrOpen::DoesNotSupportRequestedAmountOfClientRequestLoans
            | RrOpen::DoesNotSupportRequestedAmountOfActiveRequestsPerClient
            | RrOpen::DoesNotSupportRequestedResponseBufferSize
            | RrOpen::DoesNotSupportRequestedAmountOfServers
            | RrOpen::DoesNotSupportRequestedAmountOfClients
            | RrOpen::DoesNotSupportRequestedAmountOfNodes
            | RrOpen::DoesNotSupportRequestedAmountOfBorrowedResponsesPerPendingResponse => {
                Class::Incompatible
            }
            _ => Class::Fatal,
        },
        RrError::RequestResponseCreateError(c) => match c {
            RrCreate::AlreadyExists
            | RrCreate::IsBeingCreatedByAnotherInstance
            | RrCreate::HangsInCreation
            | RrCreate::ServiceInCorruptedState => Class::Transient,
            _ => Class::Fatal,
        },
    }
}

/// Port creation: a full port table usually holds a dead process's port
/// until dead-node cleanup runs (iceoryx2 FAQ), so clean up and retry.
trait PortCreateError: Debug {
    fn table_full(&self) -> bool;
}
impl PortCreateError for PublisherCreateError {
    fn table_full(&self) -> bool {
        matches!(self, PublisherCreateError::ExceedsMaxSupportedPublishers)
    }
}
impl PortCreateError for SubscriberCreateError {
    fn table_full(&self) -> bool {
        matches!(self, SubscriberCreateError::ExceedsMaxSupportedSubscribers)
    }
}
impl PortCreateError for ServerCreateError {
    fn table_full(&self) -> bool {
        matches!(self, ServerCreateError::ExceedsMaxSupportedServers)
    }
}
impl PortCreateError for ClientCreateError {
    fn table_full(&self) -> bool {
        matches!(self, ClientCreateError::ExceedsMaxSupportedClients)
    }
}

fn classify_port<E: PortCreateError>(e: &E) -> Class {
    if e.table_full() {
        Class::Cleanup
    } else {
        Class::Fatal
    }
}

/// What this process expects of a service, for diagnosing a refusal.
struct Expectation {
    channel: Channel,
    /// `(role, our type name)`; role is "user header", "request", "response".
    types: Vec<(&'static str, String)>,
    /// Required attributes.
    attrs: Vec<(&'static str, String)>,
}

impl Expectation {
    fn verifier(&self) -> Result<AttributeVerifier, ShmError> {
        let mut v = AttributeVerifier::new();
        for (k, val) in &self.attrs {
            let key = (*k).try_into().map_err(|e| attr_error(k, e))?;
            let value = val.as_str().try_into().map_err(|e| attr_error(val, e))?;
            v = v.require(&key, &value).map_err(|e| attr_error(k, e))?;
        }
        Ok(v)
    }
}

fn attr_error(value: &str, e: impl Debug) -> ShmError {
    ShmError::InvalidName {
        what: "service attribute",
        value: value.to_owned(),
        reason: format!("{e:?}"),
    }
}

/// Splits `"wg.ObsHeader.v3"` into `("wg.ObsHeader", 3)`.
fn split_version(name: &str) -> Option<(&str, u32)> {
    let (base, v) = name.rsplit_once(".v")?;
    Some((base, v.parse().ok()?))
}

fn parse_grid(v: &str) -> Option<(u16, u16)> {
    let (w, h) = v.split_once('x')?;
    Some((w.parse().ok()?, h.parse().ok()?))
}

/// Reads the existing service's description and names the difference.
fn diagnose<S: Service>(
    config: &Config,
    name: &ServiceName,
    pattern: MessagingPattern,
    exp: &Expectation,
    reason: String,
) -> SchemaError {
    let channel = exp.channel;
    let details = match S::details(name, config, pattern) {
        Ok(Some(d)) => d,
        other => {
            return SchemaError::Incompatible {
                channel,
                reason,
                wire: format!("service description unavailable ({other:?})"),
            };
        }
    };
    let wire_types: Vec<(&'static str, String)> = match details.static_details.messaging_pattern() {
        StaticPattern::PublishSubscribe(ps) => {
            vec![(
                "user header",
                ps.message_type_details()
                    .user_header
                    .type_name()
                    .to_string(),
            )]
        }
        StaticPattern::RequestResponse(rr) => vec![
            (
                "request",
                rr.request_message_type_details()
                    .payload
                    .type_name()
                    .to_string(),
            ),
            (
                "response",
                rr.response_message_type_details()
                    .payload
                    .type_name()
                    .to_string(),
            ),
        ],
        _ => Vec::new(),
    };
    let wire_attrs: Vec<(String, String)> = details
        .static_details
        .attributes()
        .iter()
        .map(|a| (a.key().to_string(), a.value().to_string()))
        .collect();

    for (role, ours) in &exp.types {
        let Some((_, wire)) = wire_types.iter().find(|(r, _)| r == role) else {
            continue;
        };
        if wire == ours {
            continue;
        }
        return match (split_version(wire), split_version(ours)) {
            (Some((wb, wv)), Some((ob, ov))) if wb == ob => SchemaError::SchemaVersion {
                channel,
                wire: wv,
                ours: ov,
            },
            _ => SchemaError::WireType {
                channel,
                wire: wire.clone(),
                ours: ours.clone(),
            },
        };
    }
    for (key, ours) in &exp.attrs {
        let wire = wire_attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str());
        let Some(wire) = wire else {
            return SchemaError::Incompatible {
                channel,
                reason: format!("{reason}: attribute {key} missing on the wire"),
                wire: format!("{wire_attrs:?}"),
            };
        };
        if wire == ours {
            continue;
        }
        let mismatch =
            match *key {
                ATTR_SCHEMA_VERSION => wire.parse().ok().zip(ours.parse().ok()).map(|(w, o)| {
                    SchemaError::SchemaVersion {
                        channel,
                        wire: w,
                        ours: o,
                    }
                }),
                ATTR_GRID => {
                    parse_grid(wire)
                        .zip(parse_grid(ours))
                        .map(|(w, o)| SchemaError::GridShape {
                            channel,
                            expected: o,
                            wire: w,
                        })
                }
                ATTR_SLICES => {
                    wire.parse()
                        .ok()
                        .zip(ours.parse().ok())
                        .map(|(w, o)| SchemaError::Slices {
                            channel,
                            expected: o,
                            wire: w,
                        })
                }
                ATTR_NUM_ENVS => {
                    wire.parse()
                        .ok()
                        .zip(ours.parse().ok())
                        .map(|(w, o)| SchemaError::BatchSize {
                            channel,
                            expected: o,
                            wire: w,
                        })
                }
                _ => None,
            };
        return mismatch.unwrap_or_else(|| SchemaError::Incompatible {
            channel,
            reason: format!("{reason}: attribute {key} = {wire:?}, expected {ours:?}"),
            wire: format!("{wire_attrs:?}"),
        });
    }
    SchemaError::Incompatible {
        channel,
        reason,
        wire: format!("types {wire_types:?}, attributes {wire_attrs:?}"),
    }
}

// ---------------------------------------------------------------- the node

/// A node of one run: the entry point of every process
/// (`PipelineNode::<ipc::Service>::new(&run_config(&run)?, run, "sim")`).
/// Opens the run's channels with the pipeline's QoS, retrying transient
/// errors and diagnosing mismatches.
#[derive(Debug)]
pub struct PipelineNode<S: Service> {
    node: Node<S>,
    run: RunName,
    retry_timeout: Duration,
    /// Set once this node opened any of the run's services.
    opened: AtomicBool,
}

impl<S: Service> PipelineNode<S> {
    /// Creates the node `node_name` for `run` under `config` (see [`create_node`]).
    pub fn new(
        config: &Config,
        run: RunName,
        node_name: &str,
    ) -> Result<PipelineNode<S>, ShmError> {
        Ok(PipelineNode {
            node: create_node(config, node_name)?,
            run,
            retry_timeout: DEFAULT_RETRY_TIMEOUT,
            opened: AtomicBool::new(false),
        })
    }

    /// Sets how long transient errors are retried (default [`DEFAULT_RETRY_TIMEOUT`]).
    pub fn with_retry_timeout(mut self, timeout: Duration) -> PipelineNode<S> {
        self.retry_timeout = timeout;
        self
    }

    /// The iceoryx2 node (for events, WaitSets, listing).
    pub fn node(&self) -> &Node<S> {
        &self.node
    }

    /// The run.
    pub fn run(&self) -> &RunName {
        &self.run
    }

    /// Removes stale resources of dead nodes under this node's prefix.
    pub fn cleanup_dead_nodes(&self) -> CleanupState {
        self.node.try_cleanup_dead_nodes()
    }

    /// Last resort after a crash *during service creation* left a service
    /// that can no longer be opened (`ServiceInCorruptedState` or
    /// `HangsInCreation` until the retry budget runs out, iceoryx2 issue
    /// #1584): removes the run's four services by force. Refused with
    /// [`ShmError::StillInUse`] while any other node of the prefix is alive;
    /// call it at start-up, before this node opens any port. Returns the
    /// number of services removed.
    pub fn force_remove_stale_services(&self) -> Result<usize, ShmError> {
        if self.opened.load(Ordering::Relaxed) {
            return Err(ShmError::Ipc {
                op: "force remove services",
                service: self.run.to_string(),
                detail: "this node already opened services of the run; call it first thing".into(),
            });
        }
        let mut services = Vec::new();
        for channel in Channel::ALL {
            let pattern = if channel == Channel::Route {
                MessagingPattern::RequestResponse
            } else {
                MessagingPattern::PublishSubscribe
            };
            services.push((service_name(&self.run, channel)?, pattern));
        }
        match crate::raw::force_remove_services(&self.node, &services) {
            Ok(Ok(n)) => Ok(n),
            Ok(Err(detail)) => Err(ShmError::Ipc {
                op: "force remove services",
                service: self.run.to_string(),
                detail,
            }),
            Err(alive) => Err(ShmError::StillInUse {
                prefix: config_prefix(self.node.config()),
                alive,
            }),
        }
    }

    /// Runs `f` until it succeeds, a non-transient error occurs, or the retry
    /// budget is spent; back-off doubles from 1 ms to 64 ms.
    fn retry<T, E: Debug>(
        &self,
        op: &'static str,
        service: &str,
        mut f: impl FnMut() -> Result<T, E>,
        classify: impl Fn(&E) -> Class,
    ) -> Result<T, Result<(E, Class), ShmError>> {
        let start = Instant::now();
        let mut delay = Duration::from_millis(1);
        loop {
            let e = match f() {
                Ok(v) => return Ok(v),
                Err(e) => e,
            };
            let class = classify(&e);
            match class {
                Class::Transient => {}
                Class::Cleanup => {
                    self.node.try_cleanup_dead_nodes();
                }
                Class::Incompatible | Class::Fatal => return Err(Ok((e, class))),
            }
            if start.elapsed() >= self.retry_timeout {
                return Err(Err(ShmError::Timeout {
                    op,
                    service: service.to_owned(),
                    waited: start.elapsed(),
                    last: format!("{e:?}"),
                }));
            }
            std::thread::sleep(delay);
            delay = (delay * 2).min(Duration::from_millis(64));
        }
    }

    fn mark_opened(&self) {
        self.opened.store(true, Ordering::Relaxed);
    }

    fn open_failed<E: Debug>(
        &self,
        name: &ServiceName,
        pattern: MessagingPattern,
        exp: &Expectation,
        fail: Result<(E, Class), ShmError>,
    ) -> ShmError {
        match fail {
            Ok((e, Class::Incompatible)) => {
                diagnose::<S>(self.node.config(), name, pattern, exp, format!("{e:?}")).into()
            }
            Ok((e, _)) => ShmError::Ipc {
                op: "open service",
                service: name.to_string(),
                detail: format!("{e:?}"),
            },
            Err(e) => e,
        }
    }

    fn create_port<T, E: PortCreateError>(
        &self,
        op: &'static str,
        name: &ServiceName,
        f: impl FnMut() -> Result<T, E>,
    ) -> Result<T, ShmError> {
        self.retry(op, name.as_str(), f, classify_port)
            .map_err(|fail| match fail {
                Ok((e, _)) => ShmError::Ipc {
                    op,
                    service: name.to_string(),
                    detail: format!("{e:?}"),
                },
                Err(e) => e,
            })
    }

    // ------------------------------------------------------------ obs

    fn obs_service(&self, shape: &ObsShape) -> Result<(ServiceName, ObsService<S>), ShmError> {
        let name = service_name(&self.run, Channel::Obs)?;
        let exp = Expectation {
            channel: Channel::Obs,
            types: vec![("user header", type_name_of::<ObsHeader>())],
            attrs: vec![
                (ATTR_SCHEMA_VERSION, SCHEMA_VERSION.to_string()),
                // Slices first: another slicing also changes the per-sample
                // batch size, and the slicing is the cause to name.
                (ATTR_SLICES, shape.slices.to_string()),
                (ATTR_NUM_ENVS, shape.num_envs.to_string()),
                (ATTR_GRID, shape.grid_attr()),
            ],
        };
        let verifier = exp.verifier()?;
        self.mark_opened();
        let factory = self
            .retry(
                "open service",
                name.as_str(),
                || {
                    self.node
                        .service_builder(&name)
                        .publish_subscribe::<[u64]>()
                        .user_header::<ObsHeader>()
                        .max_publishers(1)
                        .max_subscribers(OBS_MAX_SUBSCRIBERS)
                        .history_size(usize::from(shape.slices))
                        .subscriber_max_buffer_size(OBS_BUFFER)
                        .subscriber_max_borrowed_samples(OBS_MAX_BORROWED)
                        .enable_safe_overflow(true)
                        .open_or_create_with_attributes(&verifier)
                },
                classify_ps,
            )
            .map_err(|f| self.open_failed(&name, MessagingPattern::PublishSubscribe, &exp, f))?;
        Ok((name, factory))
    }

    /// The simulator's end of `wg/<run>/obs`, sized exactly for `shape`.
    pub fn obs_publisher(&self, shape: ObsShape) -> Result<ObsPublisher<S>, ShmError> {
        let (name, service) = self.obs_service(&shape)?;
        let publisher = self.create_port("create publisher", &name, || {
            service
                .publisher_builder()
                .initial_max_slice_len(shape.payload_words())
                .allocation_strategy(AllocationStrategy::Static)
                .max_loaned_samples(OBS_MAX_LOANS)
                .create()
                .map_err(|e: PublisherCreateError| e)
        })?;
        let publisher = ObsPublisher {
            publisher,
            _service: service,
            shape,
            run_id: self.run.id(),
        };
        publisher.update_connections()?;
        Ok(publisher)
    }

    /// A reader of `wg/<run>/obs` expecting `shape` (the learner, the planner).
    pub fn obs_subscriber(&self, shape: ObsShape) -> Result<ObsSubscriber<S>, ShmError> {
        let (name, service) = self.obs_service(&shape)?;
        let subscriber = self.create_port("create subscriber", &name, || {
            service
                .subscriber_builder()
                .buffer_size(OBS_BUFFER)
                .create()
                .map_err(|e: SubscriberCreateError| e)
        })?;
        Ok(ObsSubscriber {
            subscriber,
            _service: service,
            shape,
            run_id: self.run.id(),
        })
    }

    // ------------------------------------------------------------ act

    fn act_service(&self, num_envs: u32) -> Result<(ServiceName, ActService<S>), ShmError> {
        let name = service_name(&self.run, Channel::Act)?;
        let exp = Expectation {
            channel: Channel::Act,
            types: vec![("user header", type_name_of::<ActHeader>())],
            attrs: vec![
                (ATTR_SCHEMA_VERSION, SCHEMA_VERSION.to_string()),
                (ATTR_NUM_ENVS, num_envs.to_string()),
            ],
        };
        let verifier = exp.verifier()?;
        self.mark_opened();
        let factory = self
            .retry(
                "open service",
                name.as_str(),
                || {
                    self.node
                        .service_builder(&name)
                        .publish_subscribe::<[u8]>()
                        .user_header::<ActHeader>()
                        .max_publishers(1)
                        .max_subscribers(ACT_MAX_SUBSCRIBERS)
                        .history_size(0)
                        .subscriber_max_buffer_size(ACT_BUFFER)
                        .subscriber_max_borrowed_samples(2)
                        .enable_safe_overflow(true)
                        .open_or_create_with_attributes(&verifier)
                },
                classify_ps,
            )
            .map_err(|f| self.open_failed(&name, MessagingPattern::PublishSubscribe, &exp, f))?;
        Ok((name, factory))
    }

    /// The learner's end of `wg/<run>/act` for batches of `num_envs`.
    pub fn act_publisher(&self, num_envs: usize) -> Result<ActPublisher<S>, ShmError> {
        let n = check_num_envs(num_envs)?;
        let (name, service) = self.act_service(n)?;
        let publisher = self.create_port("create publisher", &name, || {
            service
                .publisher_builder()
                .initial_max_slice_len(num_envs)
                .allocation_strategy(AllocationStrategy::Static)
                .max_loaned_samples(2)
                .create()
                .map_err(|e: PublisherCreateError| e)
        })?;
        let publisher = ActPublisher {
            publisher,
            _service: service,
            num_envs: n,
            run_id: self.run.id(),
        };
        publisher.update_connections()?;
        Ok(publisher)
    }

    /// The simulator's reader of `wg/<run>/act` for batches of `num_envs`.
    pub fn act_subscriber(&self, num_envs: usize) -> Result<ActSubscriber<S>, ShmError> {
        let n = check_num_envs(num_envs)?;
        let (name, service) = self.act_service(n)?;
        let subscriber = self.create_port("create subscriber", &name, || {
            service
                .subscriber_builder()
                .buffer_size(ACT_BUFFER)
                .create()
                .map_err(|e: SubscriberCreateError| e)
        })?;
        Ok(ActSubscriber {
            subscriber,
            _service: service,
            num_envs: n,
            run_id: self.run.id(),
        })
    }

    // ------------------------------------------------------------ route

    fn route_service(&self) -> Result<(ServiceName, RouteService<S>), ShmError> {
        let name = service_name(&self.run, Channel::Route)?;
        let exp = Expectation {
            channel: Channel::Route,
            types: vec![
                ("request", type_name_of::<RouteRequest>()),
                ("response", type_name_of::<RouteResponse>()),
            ],
            attrs: vec![(ATTR_SCHEMA_VERSION, SCHEMA_VERSION.to_string())],
        };
        let verifier = exp.verifier()?;
        self.mark_opened();
        let factory = self
            .retry(
                "open service",
                name.as_str(),
                || {
                    self.node
                        .service_builder(&name)
                        .request_response::<RouteRequest, RouteResponse>()
                        .max_servers(1)
                        .max_clients(ROUTE_MAX_CLIENTS)
                        .max_active_requests_per_client(ROUTE_MAX_ACTIVE_REQUESTS)
                        .max_response_buffer_size(1)
                        .max_borrowed_responses_per_pending_response(1)
                        .enable_fire_and_forget_requests(false)
                        .open_or_create_with_attributes(&verifier)
                },
                classify_rr,
            )
            .map_err(|f| self.open_failed(&name, MessagingPattern::RequestResponse, &exp, f))?;
        Ok((name, factory))
    }

    /// The planner's end of `wg/<run>/route`.
    pub fn route_server(&self) -> Result<RouteServer<S>, ShmError> {
        let (name, service) = self.route_service()?;
        let server = self.create_port("create server", &name, || {
            service
                .server_builder()
                .max_loaned_responses_per_request(1)
                .create()
                .map_err(|e: ServerCreateError| e)
        })?;
        Ok(RouteServer {
            server,
            _service: service,
            run_id: self.run.id(),
        })
    }

    /// A client of `wg/<run>/route` (the learner).
    pub fn route_client(&self) -> Result<RouteClient<S>, ShmError> {
        let (name, service) = self.route_service()?;
        let client = self.create_port("create client", &name, || {
            service
                .client_builder()
                .create()
                .map_err(|e: ClientCreateError| e)
        })?;
        Ok(RouteClient {
            client,
            _service: service,
            run_id: self.run.id(),
            next_id: AtomicU64::new(1),
        })
    }

    // ------------------------------------------------------------ graph

    fn graph_service(
        &self,
        width: u16,
        height: u16,
    ) -> Result<(ServiceName, GraphService<S>), ShmError> {
        let name = service_name(&self.run, Channel::Graph)?;
        let exp = Expectation {
            channel: Channel::Graph,
            types: vec![("user header", type_name_of::<GraphHeader>())],
            attrs: vec![
                (ATTR_SCHEMA_VERSION, SCHEMA_VERSION.to_string()),
                (ATTR_GRID, format!("{width}x{height}")),
            ],
        };
        let verifier = exp.verifier()?;
        self.mark_opened();
        let factory = self
            .retry(
                "open service",
                name.as_str(),
                || {
                    self.node
                        .service_builder(&name)
                        .publish_subscribe::<[u32]>()
                        .user_header::<GraphHeader>()
                        .max_publishers(1)
                        .max_subscribers(GRAPH_MAX_SUBSCRIBERS)
                        .history_size(1)
                        .subscriber_max_buffer_size(1)
                        .subscriber_max_borrowed_samples(1)
                        .enable_safe_overflow(true)
                        .open_or_create_with_attributes(&verifier)
                },
                classify_ps,
            )
            .map_err(|f| self.open_failed(&name, MessagingPattern::PublishSubscribe, &exp, f))?;
        Ok((name, factory))
    }

    /// The planner's end of `wg/<run>/graph` for a `width × height` maze.
    pub fn graph_publisher(
        &self,
        width: usize,
        height: usize,
    ) -> Result<GraphPublisher<S>, ShmError> {
        let (w, h) = check_grid(Channel::Graph, width, height)?;
        let (name, service) = self.graph_service(w, h)?;
        let publisher = self.create_port("create publisher", &name, || {
            service
                .publisher_builder()
                .initial_max_slice_len(GRAPH_INITIAL_WORDS)
                .allocation_strategy(AllocationStrategy::PowerOfTwo)
                .max_loaned_samples(1)
                .create()
                .map_err(|e: PublisherCreateError| e)
        })?;
        Ok(GraphPublisher {
            publisher,
            _service: service,
            width: w,
            height: h,
            run_id: self.run.id(),
        })
    }

    /// A reader of `wg/<run>/graph` (learner, viewers); gets the latest
    /// snapshot on joining, after the publisher's next send or
    /// `update_connections`.
    pub fn graph_subscriber(
        &self,
        width: usize,
        height: usize,
    ) -> Result<GraphSubscriber<S>, ShmError> {
        let (w, h) = check_grid(Channel::Graph, width, height)?;
        let (name, service) = self.graph_service(w, h)?;
        let subscriber = self.create_port("create subscriber", &name, || {
            service
                .subscriber_builder()
                .buffer_size(1)
                .create()
                .map_err(|e: SubscriberCreateError| e)
        })?;
        Ok(GraphSubscriber {
            subscriber,
            _service: service,
            width: w,
            height: h,
            run_id: self.run.id(),
        })
    }
}

fn ipc_err(op: &'static str, channel: Channel, e: impl Debug) -> ShmError {
    ShmError::Ipc {
        op,
        service: channel.suffix().to_owned(),
        detail: format!("{e:?}"),
    }
}

// ---------------------------------------------------------------- obs ports

/// The simulator's observation publisher.
#[derive(Debug)]
pub struct ObsPublisher<S: Service> {
    publisher: Publisher<S, [u64], ObsHeader>,
    _service: ObsService<S>,
    shape: ObsShape,
    run_id: u64,
}

impl<S: Service> ObsPublisher<S> {
    /// The batch shape.
    pub fn shape(&self) -> ObsShape {
        self.shape
    }

    /// Loans a sample for batch `seq` at simulator step `step`: the header is
    /// filled, metas and cells are stale and must all be written (debug
    /// builds fill them with [`crate::SENTINEL_BYTE`]).
    pub fn loan(&self, seq: u64, step: u64) -> Result<ObsSampleMut<S>, ShmError> {
        let uninit = self
            .publisher
            .loan_slice_uninit(self.shape.payload_words())
            .map_err(|e| ipc_err("loan", Channel::Obs, e))?;
        let mut sample = assume_init_slice(uninit);
        *sample.user_header_mut() = ObsHeader {
            seq,
            step,
            slice: (seq % u64::from(self.shape.slices)) as u16,
            ..ObsHeader::new(&self.shape, self.run_id)
        };
        if cfg!(debug_assertions) {
            sample
                .payload_mut()
                .fill(u64::from_ne_bytes([crate::SENTINEL_BYTE; 8]));
        }
        Ok(ObsSampleMut {
            sample,
            shape: self.shape,
        })
    }

    /// Connects subscribers that joined since the last send and delivers
    /// the history (the last batch) to them. iceoryx2 has no background
    /// thread: call this periodically while waiting for an action batch,
    /// so a learner that (re)joins receives the batch the sim waits on.
    pub fn update_connections(&self) -> Result<(), ShmError> {
        self.publisher
            .update_connections()
            .map_err(|e| ipc_err("update connections", Channel::Obs, e))
    }
}

/// A loaned observation sample, written in place, then [`send`](Self::send).
#[derive(Debug)]
pub struct ObsSampleMut<S: Service> {
    sample: SampleMut<S, [u64], ObsHeader>,
    shape: ObsShape,
}

impl<S: Service> ObsSampleMut<S> {
    /// `(&mut ObsHeader, &mut [EnvMeta], &mut [u8])` over the shared memory.
    pub fn batch_mut(&mut self) -> ObsBatchMut<'_> {
        let shape = self.shape;
        let (header, payload) = split_slice_sample(&mut self.sample);
        ObsBatchMut::new(header, payload, &shape)
            .expect("invariant: the sample was loaned with the shape's length")
    }

    /// The header.
    pub fn header(&self) -> &ObsHeader {
        self.sample.user_header()
    }

    /// Stamps `send_time_ns` and publishes; returns the number of
    /// subscribers reached.
    pub fn send(self) -> Result<usize, ShmError> {
        self.send_stamped().map(|(subscribers, _)| subscribers)
    }

    /// [`send`](Self::send), also returning the stamped `send_time_ns`
    /// ([`monotonic_ns`]), so a caller that times its loop needs no second
    /// clock read.
    pub fn send_stamped(mut self) -> Result<(usize, u64), ShmError> {
        let t = monotonic_ns();
        self.sample.user_header_mut().send_time_ns = t;
        let subscribers = self
            .sample
            .send()
            .map_err(|e| ipc_err("send", Channel::Obs, e))?;
        Ok((subscribers, t))
    }
}

/// A reader of observation batches.
#[derive(Debug)]
pub struct ObsSubscriber<S: Service> {
    subscriber: Subscriber<S, [u64], ObsHeader>,
    _service: ObsService<S>,
    shape: ObsShape,
    run_id: u64,
}

impl<S: Service> ObsSubscriber<S> {
    /// The expected batch shape.
    pub fn shape(&self) -> ObsShape {
        self.shape
    }

    /// The next batch, if any (non-blocking). A batch whose header does not
    /// match this process's shape, run or schema is an `Err` (and released).
    pub fn receive(&self) -> Result<Option<ObsSample<S>>, ShmError> {
        let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| ipc_err("receive", Channel::Obs, e))?
        else {
            return Ok(None);
        };
        ObsBatch::new(
            sample.user_header(),
            sample.payload(),
            &self.shape,
            self.run_id,
        )?;
        Ok(Some(ObsSample {
            sample,
            shape: self.shape,
            run_id: self.run_id,
        }))
    }
}

/// A received observation batch, read in place; dropping it releases the chunk.
#[derive(Debug)]
pub struct ObsSample<S: Service> {
    sample: Sample<S, [u64], ObsHeader>,
    shape: ObsShape,
    run_id: u64,
}

impl<S: Service> ObsSample<S> {
    /// The batch: header, metas, cells, borrowed from shared memory.
    pub fn batch(&self) -> ObsBatch<'_> {
        ObsBatch::new(
            self.sample.user_header(),
            self.sample.payload(),
            &self.shape,
            self.run_id,
        )
        .expect("invariant: checked in ObsSubscriber::receive")
    }

    /// The header.
    pub fn header(&self) -> &ObsHeader {
        self.sample.user_header()
    }

    /// One-way latency from the publisher's `send()` to now, in ns.
    pub fn latency_ns(&self) -> u64 {
        monotonic_ns().saturating_sub(self.header().send_time_ns)
    }
}

// ---------------------------------------------------------------- act ports

/// The learner's action publisher.
#[derive(Debug)]
pub struct ActPublisher<S: Service> {
    publisher: Publisher<S, [u8], ActHeader>,
    _service: ActService<S>,
    num_envs: u32,
    run_id: u64,
}

impl<S: Service> ActPublisher<S> {
    /// Loans a sample answering observation batch `seq` (actions stale:
    /// write all `N`).
    pub fn loan(&self, seq: u64) -> Result<ActSampleMut<S>, ShmError> {
        let uninit = self
            .publisher
            .loan_slice_uninit(self.num_envs as usize)
            .map_err(|e| ipc_err("loan", Channel::Act, e))?;
        let mut sample = assume_init_slice(uninit);
        *sample.user_header_mut() = ActHeader::new(self.num_envs, self.run_id, seq);
        Ok(ActSampleMut { sample })
    }

    /// Copies `actions` into a loaned sample and sends it.
    pub fn send_actions(&self, seq: u64, actions: &[u8]) -> Result<usize, ShmError> {
        crate::step::check_len(Channel::Act, self.num_envs as usize, actions.len())?;
        let mut s = self.loan(seq)?;
        s.batch_mut()
            .actions
            .copy_from_slice(&actions[..self.num_envs as usize]);
        s.send()
    }

    /// Connects subscribers that joined since the last send.
    pub fn update_connections(&self) -> Result<(), ShmError> {
        self.publisher
            .update_connections()
            .map_err(|e| ipc_err("update connections", Channel::Act, e))
    }
}

/// A loaned action sample.
#[derive(Debug)]
pub struct ActSampleMut<S: Service> {
    sample: SampleMut<S, [u8], ActHeader>,
}

impl<S: Service> ActSampleMut<S> {
    /// Header and `N` action bytes over the shared memory.
    pub fn batch_mut(&mut self) -> ActBatchMut<'_> {
        let (header, actions) = split_slice_sample(&mut self.sample);
        ActBatchMut { header, actions }
    }

    /// Stamps `send_time_ns` and publishes.
    pub fn send(mut self) -> Result<usize, ShmError> {
        self.sample.user_header_mut().send_time_ns = monotonic_ns();
        self.sample
            .send()
            .map_err(|e| ipc_err("send", Channel::Act, e))
    }
}

/// The simulator's reader of action batches.
#[derive(Debug)]
pub struct ActSubscriber<S: Service> {
    subscriber: Subscriber<S, [u8], ActHeader>,
    _service: ActService<S>,
    num_envs: u32,
    run_id: u64,
}

impl<S: Service> ActSubscriber<S> {
    /// The next action batch, if any (checked like [`ObsSubscriber::receive`]).
    pub fn receive(&self) -> Result<Option<ActSample<S>>, ShmError> {
        let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| ipc_err("receive", Channel::Act, e))?
        else {
            return Ok(None);
        };
        ActBatch::new(
            sample.user_header(),
            sample.payload(),
            self.num_envs,
            self.run_id,
        )?;
        Ok(Some(ActSample {
            sample,
            num_envs: self.num_envs,
        }))
    }
}

/// A received action batch.
#[derive(Debug)]
pub struct ActSample<S: Service> {
    sample: Sample<S, [u8], ActHeader>,
    num_envs: u32,
}

impl<S: Service> ActSample<S> {
    /// The header.
    pub fn header(&self) -> &ActHeader {
        self.sample.user_header()
    }
    /// The `N` actions.
    pub fn actions(&self) -> &[u8] {
        &self.sample.payload()[..self.num_envs as usize]
    }
    /// Starts loading the actions' cache lines, which the learner wrote on
    /// the other core, all at once: otherwise a step reaching each line
    /// waits for it in turn (paired runs on 2 vCPUs: 0.3–2.8 % of the sim's
    /// cycle saved, 8 of 8; docs/implementation_details.md).
    pub fn prefetch_actions(&self) {
        crate::raw::prefetch(self.actions());
    }
}

// ---------------------------------------------------------------- route ports

/// The planner's route server.
#[derive(Debug)]
pub struct RouteServer<S: Service> {
    server: Server<S, RouteRequest, (), RouteResponse, ()>,
    _service: RouteService<S>,
    run_id: u64,
}

impl<S: Service> RouteServer<S> {
    /// The next request, if any. A request of another schema version or run
    /// is answered with [`RouteStatus::BadRequest`] here and reported as `Err`.
    pub fn receive(&self) -> Result<Option<RouteCall<S>>, ShmError> {
        let Some(active) = self
            .server
            .receive()
            .map_err(|e| ipc_err("receive", Channel::Route, e))?
        else {
            return Ok(None);
        };
        let call = RouteCall { active };
        if let Err(e) = call.request().check(self.run_id) {
            call.respond(0, RouteStatus::BadRequest, &[], &[], &[])?;
            return Err(e.into());
        }
        Ok(Some(call))
    }
}

/// One received route request; answer it with [`respond`](Self::respond).
#[derive(Debug)]
pub struct RouteCall<S: Service> {
    active: ActiveRequest<S, RouteRequest, (), RouteResponse, ()>,
}

impl<S: Service> RouteCall<S> {
    /// The request.
    pub fn request(&self) -> &RouteRequest {
        self.active.payload()
    }

    /// Whether the client still waits for the answer.
    pub fn is_connected(&self) -> bool {
        self.active.is_connected()
    }

    /// Writes the answer in place in shared memory and sends it. Returns
    /// the status actually sent: [`RouteStatus::TooLong`] when the route
    /// does not fit [`crate::MAX_ROUTE_LEN`] / [`crate::MAX_ROUTE_PIVOTS`].
    pub fn respond(
        self,
        graph_version: u64,
        status: RouteStatus,
        pivots: &[u16],
        cells: &[u32],
        actions: &[u8],
    ) -> Result<RouteStatus, ShmError> {
        let request = *self.request();
        let uninit = self
            .active
            .loan_uninit()
            .map_err(|e| ipc_err("loan response", Channel::Route, e))?;
        let mut response = assume_init_response(uninit);
        let filled =
            response
                .payload_mut()
                .fill(&request, graph_version, status, pivots, cells, actions);
        let sent = response
            .payload()
            .status()
            .unwrap_or(RouteStatus::BadRequest);
        response
            .send()
            .map_err(|e| ipc_err("send response", Channel::Route, e))?;
        match filled {
            Ok(()) => Ok(sent),
            Err(SchemaError::OutOfRange { .. }) => Ok(RouteStatus::TooLong),
            Err(e) => Err(e.into()),
        }
    }
}

/// The learner's route client. At most [`ROUTE_MAX_ACTIVE_REQUESTS`]
/// requests may be pending at once (more: `Err` from
/// [`request`](Self::request)); dropping a [`PendingRoute`] frees its slot
/// and withdraws the request (a request withdrawn before the planner
/// received it is never delivered).
#[derive(Debug)]
pub struct RouteClient<S: Service> {
    client: Client<S, RouteRequest, (), RouteResponse, ()>,
    _service: RouteService<S>,
    run_id: u64,
    next_id: AtomicU64,
}

impl<S: Service> RouteClient<S> {
    /// Sends a request for a route from `from_cell` facing `from_dir` to
    /// pivotal state `to_pivot`, on behalf of environment `env`.
    pub fn request(
        &self,
        env: u32,
        from_cell: u32,
        from_dir: u8,
        to_pivot: u16,
    ) -> Result<PendingRoute<S>, ShmError> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let request = RouteRequest::new(id, self.run_id, env, from_cell, from_dir, to_pivot);
        let pending = self
            .client
            .send_copy(request)
            .map_err(|e| ipc_err("send request", Channel::Route, e))?;
        Ok(PendingRoute { pending, request })
    }
}

/// A request in flight; dropping it withdraws the request.
#[derive(Debug)]
pub struct PendingRoute<S: Service> {
    pending: PendingResponse<S, RouteRequest, (), RouteResponse, ()>,
    request: RouteRequest,
}

impl<S: Service> PendingRoute<S> {
    /// The request sent.
    pub fn request(&self) -> &RouteRequest {
        &self.request
    }

    /// Whether the server still holds the request (false: it will never answer).
    pub fn is_connected(&self) -> bool {
        self.pending.is_connected()
    }

    /// The answer, if it arrived (non-blocking); checked against the request.
    pub fn try_receive(&self) -> Result<Option<RouteReply<S>>, ShmError> {
        let Some(response) = self
            .pending
            .receive()
            .map_err(|e| ipc_err("receive response", Channel::Route, e))?
        else {
            return Ok(None);
        };
        response.payload().check(&self.request)?;
        Ok(Some(RouteReply { response }))
    }

    /// Polls until the answer arrives, the server drops the request, or
    /// `timeout` passes (spinning, then yielding).
    pub fn wait(&self, timeout: Duration) -> Result<RouteReply<S>, ShmError> {
        let start = Instant::now();
        let mut spins = 0u32;
        loop {
            if let Some(reply) = self.try_receive()? {
                return Ok(reply);
            }
            if !self.is_connected() {
                // A response may have been sent just before the disconnect.
                if let Some(reply) = self.try_receive()? {
                    return Ok(reply);
                }
                return Err(ShmError::Ipc {
                    op: "wait for route",
                    service: Channel::Route.suffix().to_owned(),
                    detail: "server dropped the request".into(),
                });
            }
            if start.elapsed() >= timeout {
                return Err(ShmError::Timeout {
                    op: "wait for route",
                    service: Channel::Route.suffix().to_owned(),
                    waited: start.elapsed(),
                    last: "no response".into(),
                });
            }
            spins += 1;
            if spins > 1000 {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
        }
    }
}

/// A received route, read in place.
#[derive(Debug)]
pub struct RouteReply<S: Service> {
    response: Response<S, RouteResponse, ()>,
}

impl<S: Service> RouteReply<S> {
    /// The response.
    pub fn response(&self) -> &RouteResponse {
        self.response.payload()
    }
}

impl<S: Service> std::ops::Deref for RouteReply<S> {
    type Target = RouteResponse;
    fn deref(&self) -> &RouteResponse {
        self.response()
    }
}

// ---------------------------------------------------------------- graph ports

/// The planner's graph-snapshot publisher.
#[derive(Debug)]
pub struct GraphPublisher<S: Service> {
    publisher: Publisher<S, [u32], GraphHeader>,
    _service: GraphService<S>,
    width: u16,
    height: u16,
    run_id: u64,
}

impl<S: Service> GraphPublisher<S> {
    /// Loans a snapshot of `num_nodes` nodes and `num_edges` edges to fill in place.
    pub fn loan(&self, num_nodes: usize, num_edges: usize) -> Result<GraphSampleMut<S>, ShmError> {
        check_counts(num_nodes, num_edges)?;
        let words = GraphHeader::payload_words(num_nodes, num_edges);
        let uninit = self
            .publisher
            .loan_slice_uninit(words)
            .map_err(|e| ipc_err("loan", Channel::Graph, e))?;
        let mut sample = assume_init_slice(uninit);
        *sample.user_header_mut() = GraphHeader {
            run_id: self.run_id,
            width: self.width,
            height: self.height,
            ..GraphHeader::default()
        };
        Ok(GraphSampleMut {
            sample,
            num_nodes,
            num_edges,
        })
    }

    /// Copies `nodes` and `edges` into a snapshot of `graph_version` and sends it.
    pub fn publish(
        &self,
        graph_version: u64,
        nodes: &[u32],
        edges: &[GraphEdge],
    ) -> Result<usize, ShmError> {
        let mut s = self.loan(nodes.len(), edges.len())?;
        let g = s.snapshot_mut();
        g.header.graph_version = graph_version;
        g.nodes.copy_from_slice(nodes);
        g.edges.copy_from_slice(edges);
        s.send()
    }

    /// Delivers the latest snapshot to subscribers that joined since the
    /// last send; call it periodically (iceoryx2 has no background thread).
    pub fn update_connections(&self) -> Result<(), ShmError> {
        self.publisher
            .update_connections()
            .map_err(|e| ipc_err("update connections", Channel::Graph, e))
    }
}

/// A loaned graph snapshot.
#[derive(Debug)]
pub struct GraphSampleMut<S: Service> {
    sample: SampleMut<S, [u32], GraphHeader>,
    num_nodes: usize,
    num_edges: usize,
}

impl<S: Service> GraphSampleMut<S> {
    /// Header, nodes and edges over the shared memory.
    pub fn snapshot_mut(&mut self) -> GraphSnapshotMut<'_> {
        let (n, m) = (self.num_nodes, self.num_edges);
        let (header, payload) = split_slice_sample(&mut self.sample);
        GraphSnapshotMut::new(header, payload, n, m)
            .expect("invariant: loaned with the counts' length")
    }

    /// Stamps `send_time_ns` and publishes.
    pub fn send(mut self) -> Result<usize, ShmError> {
        self.sample.user_header_mut().send_time_ns = monotonic_ns();
        self.sample
            .send()
            .map_err(|e| ipc_err("send", Channel::Graph, e))
    }
}

/// A reader of graph snapshots.
#[derive(Debug)]
pub struct GraphSubscriber<S: Service> {
    subscriber: Subscriber<S, [u32], GraphHeader>,
    _service: GraphService<S>,
    width: u16,
    height: u16,
    run_id: u64,
}

impl<S: Service> GraphSubscriber<S> {
    /// The newest snapshot, if one arrived since the last call.
    pub fn receive(&self) -> Result<Option<GraphSample<S>>, ShmError> {
        let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| ipc_err("receive", Channel::Graph, e))?
        else {
            return Ok(None);
        };
        GraphSnapshot::new(
            sample.user_header(),
            sample.payload(),
            self.width,
            self.height,
            self.run_id,
        )?;
        Ok(Some(GraphSample {
            sample,
            width: self.width,
            height: self.height,
            run_id: self.run_id,
        }))
    }
}

/// A received graph snapshot, read in place.
#[derive(Debug)]
pub struct GraphSample<S: Service> {
    sample: Sample<S, [u32], GraphHeader>,
    width: u16,
    height: u16,
    run_id: u64,
}

impl<S: Service> GraphSample<S> {
    /// Header, nodes and edges.
    pub fn snapshot(&self) -> GraphSnapshot<'_> {
        GraphSnapshot::new(
            self.sample.user_header(),
            self.sample.payload(),
            self.width,
            self.height,
            self.run_id,
        )
        .expect("invariant: checked in GraphSubscriber::receive")
    }
}

#[cfg(test)]
#[path = "service_tests.rs"]
mod tests;
