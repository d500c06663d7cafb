//! Errors: [`SchemaError`] when the two ends of a channel disagree on the
//! wire layout, [`ShmError`] for everything the service layer can report.

use std::path::PathBuf;
use std::time::Duration;

/// The four channels of the pipeline (README.md, "The pipeline"). Used in error
/// messages and to build service names ([`crate::service::service_name`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    /// `wg/<run>/obs`: sim → learner, planner ([`crate::ObsHeader`] + cells).
    Obs,
    /// `wg/<run>/act`: learner → sim ([`crate::ActHeader`] + actions).
    Act,
    /// `wg/<run>/route`: learner ⇄ planner ([`crate::RouteRequest`] → [`crate::RouteResponse`]).
    Route,
    /// `wg/<run>/graph`: planner → learner, viewers ([`crate::GraphHeader`] + nodes, edges).
    Graph,
}

impl Channel {
    /// Every channel, in pipeline order.
    pub const ALL: [Channel; 4] = [Channel::Obs, Channel::Act, Channel::Route, Channel::Graph];

    /// Last segment of the service name (`wg/<run>/<suffix>`).
    pub const fn suffix(self) -> &'static str {
        match self {
            Channel::Obs => "obs",
            Channel::Act => "act",
            Channel::Route => "route",
            Channel::Graph => "graph",
        }
    }

    /// What the channel carries, for messages.
    pub const fn describe(self) -> &'static str {
        match self {
            Channel::Obs => "observation batch",
            Channel::Act => "action batch",
            Channel::Route => "route request/response",
            Channel::Graph => "graph snapshot",
        }
    }
}

impl std::fmt::Display for Channel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.describe())
    }
}

/// The two ends of a channel disagree about what is on the wire, or a
/// sample does not match what this process was configured for. Returned
/// instead of ever handing out misinterpreted bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SchemaError {
    /// The peer speaks another schema version (seen in the service's type
    /// names when opening, or in a sample header's `schema_version`).
    #[error("{channel} schema v{wire} on the wire, this process speaks v{ours}")]
    SchemaVersion {
        /// Which channel.
        channel: Channel,
        /// Version found on the wire.
        wire: u32,
        /// [`crate::SCHEMA_VERSION`] of this build.
        ours: u32,
    },
    /// The grid shape differs from the one this process was configured for.
    #[error(
        "{channel}: grid {}x{} expected, publisher sends {}x{}",
        expected.0, expected.1, wire.0, wire.1
    )]
    GridShape {
        /// Which channel.
        channel: Channel,
        /// `(width, height)` this process expects.
        expected: (u16, u16),
        /// `(width, height)` on the wire.
        wire: (u16, u16),
    },
    /// The number of environments per batch differs.
    #[error("{channel}: batch of {expected} environments expected, publisher sends {wire}")]
    BatchSize {
        /// Which channel.
        channel: Channel,
        /// Batch size this process expects.
        expected: u32,
        /// Batch size on the wire.
        wire: u32,
    },
    /// The two ends run different tasks (another reward, another action
    /// set): seen in the service's `wg.task` attribute when opening.
    #[error(
        "{channel}: this process runs task {expected}, the run's {channel} service carries task {wire}"
    )]
    Task {
        /// Which channel.
        channel: Channel,
        /// `<task> (<n> actions)` this process runs.
        expected: String,
        /// `<task> (<n> actions)` of the service.
        wire: String,
    },
    /// A sample belongs to another run (its header's `run_id`).
    #[error("{channel}: sample of run {wire:#018x}, this process belongs to run {expected:#018x}")]
    RunMismatch {
        /// Which channel.
        channel: Channel,
        /// [`crate::service::RunName::id`] of this process's run.
        expected: u64,
        /// `run_id` in the sample.
        wire: u64,
    },
    /// The service carries a type this process does not know at all (not
    /// merely another version of the same type).
    #[error("{channel}: the service carries `{wire}`, this process expects `{ours}`")]
    WireType {
        /// Which channel.
        channel: Channel,
        /// Type name found in the service's static configuration.
        wire: String,
        /// Type name this process uses.
        ours: String,
    },
    /// iceoryx2 refused to connect (`IncompatibleTypes`, `IncompatibleAttributes`
    /// and similar) and the service's description did not reveal a more
    /// specific reason (for instance a type with the same name but another size).
    #[error("{channel}: iceoryx2 refused the service as incompatible ({reason}); wire: {wire}")]
    Incompatible {
        /// Which channel.
        channel: Channel,
        /// The iceoryx2 error.
        reason: String,
        /// What the existing service declares (types and attributes).
        wire: String,
    },
    /// A sample's payload is shorter than its header claims.
    #[error("{channel}: payload holds {got} bytes, the header requires {needed}")]
    PayloadTooShort {
        /// Which channel.
        channel: Channel,
        /// Bytes needed by the header's counts.
        needed: usize,
        /// Bytes in the payload.
        got: usize,
    },
    /// The batch is published in another number of slices.
    #[error(
        "{channel}: batch in {expected} slice(s) expected, publisher sends {wire} \
         (start every process of a run with the same --slices)"
    )]
    Slices {
        /// Which channel.
        channel: Channel,
        /// Slices this process expects.
        expected: u16,
        /// Slices on the wire.
        wire: u16,
    },
    /// The slices do not divide the batch.
    #[error("{channel}: {slices} slices do not divide a batch of {total} environments")]
    SlicesDoNotDivide {
        /// Which channel.
        channel: Channel,
        /// Slices requested.
        slices: usize,
        /// Environments in the batch.
        total: usize,
    },
    /// A shape or count is outside the fixed capacities of the schema.
    #[error("{channel}: {what} = {value} is out of range (at most {max}, and not 0 for sizes)")]
    OutOfRange {
        /// Which channel.
        channel: Channel,
        /// Which quantity.
        what: &'static str,
        /// The offending value.
        value: usize,
        /// The largest allowed value ([`crate::MAX_ENVS`] and friends).
        max: usize,
    },
}

/// Errors of the service layer ([`crate::service`]): wrong names, iceoryx2
/// failures, time-outs, and schema mismatches.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ShmError {
    /// The peer's wire layout differs; see [`SchemaError`].
    #[error(transparent)]
    Schema(#[from] SchemaError),
    /// A run name, node name or prefix is not usable in iceoryx2 names.
    #[error("invalid {what} {value:?}: {reason}")]
    InvalidName {
        /// What kind of name.
        what: &'static str,
        /// The name as given.
        value: String,
        /// Why it was refused.
        reason: String,
    },
    /// An iceoryx2 call failed with a non-transient error.
    #[error("{op} on {service}: {detail}")]
    Ipc {
        /// The operation ("open service", "create publisher", "loan", ...).
        op: &'static str,
        /// The service name (or node name).
        service: String,
        /// The iceoryx2 error, `Debug`-formatted.
        detail: String,
    },
    /// A transient iceoryx2 condition did not clear within the retry budget.
    #[error("{op} on {service}: still failing after {waited:?} of retries (last: {last})")]
    Timeout {
        /// The operation retried.
        op: &'static str,
        /// The service name.
        service: String,
        /// How long it was retried.
        waited: Duration,
        /// The last error seen.
        last: String,
    },
    /// Teardown refused because nodes of the run are still alive.
    #[error("{alive} node(s) of prefix {prefix:?} are still alive; not removing shared memory")]
    StillInUse {
        /// The iceoryx2 prefix of the run.
        prefix: String,
        /// Number of live nodes.
        alive: usize,
    },
    /// A file operation during teardown or permission hardening failed.
    #[error("{op} {}: {source}", path.display())]
    Io {
        /// What was attempted.
        op: &'static str,
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
}
