//! Route queries (`wg/<run>/route`, request-response): the learner asks the
//! planner for a traversal from its current cell to a pivotal state of the
//! world graph (Shang et al. 2019, arXiv:1907.00664, section 3.3: routes are
//! planned by dynamic programming over the graph's edge weights) and gets
//! back the pivotal states on the way, the cells and the actions.
//!
//! Both messages are fixed-size `#[repr(C)]` values (a response is
//! 10 792 bytes), so the service needs no slice sizing; the server writes
//! its answer in place ([`crate::service::RouteCall::respond`]) and only the
//! used prefixes of the arrays are meaningful.

use bytemuck::{Pod, Zeroable};
#[cfg(feature = "ipc")]
use iceoryx2::prelude::ZeroCopySend;

use crate::{Channel, SCHEMA_VERSION, SchemaError};

/// Most pivotal states listed in one route.
pub const MAX_ROUTE_PIVOTS: usize = 256;
/// Most actions (and cells) in one route.
pub const MAX_ROUTE_LEN: usize = 2048;
/// "No path": the distance of an unreachable pair in the planner's
/// all-pairs table, and the value of [`RouteResponse::total_weight`] when
/// there is no route. One constant shared by planner and schema.
pub const UNREACHABLE: u32 = u32::MAX;
/// "No pivotal state" in a `u16` pivot id field.
pub const NO_PIVOT: u16 = u16::MAX;

/// Outcome of a route query ([`RouteResponse::status`] on the wire).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
#[non_exhaustive]
pub enum RouteStatus {
    /// A route was found; pivots, cells and actions are filled.
    Ok = 0,
    /// The graph has no path from the start to the target.
    Unreachable = 1,
    /// `to_pivot` is not a node of the current graph.
    UnknownTarget = 2,
    /// The start cell is not on the graph (not a pivotal state and not
    /// attachable to one).
    StartNotOnGraph = 3,
    /// A route exists but exceeds [`MAX_ROUTE_LEN`] actions or
    /// [`MAX_ROUTE_PIVOTS`] pivots.
    TooLong = 4,
    /// The planner has no graph yet.
    NoGraph = 5,
    /// The request was malformed (schema version, run, fields out of range).
    BadRequest = 6,
}

impl RouteStatus {
    /// Decodes the wire value; `None` for a value this version does not know.
    pub fn from_wire(v: u32) -> Option<RouteStatus> {
        Some(match v {
            0 => RouteStatus::Ok,
            1 => RouteStatus::Unreachable,
            2 => RouteStatus::UnknownTarget,
            3 => RouteStatus::StartNotOnGraph,
            4 => RouteStatus::TooLong,
            5 => RouteStatus::NoGraph,
            6 => RouteStatus::BadRequest,
            _ => return None,
        })
    }
}

/// A route query: from cell `from_cell` facing `from_dir` to pivotal state
/// `to_pivot`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("wg.RouteRequest.v3"))]
#[repr(C)]
pub struct RouteRequest {
    /// Chosen by the client, echoed in the response.
    pub request_id: u64,
    /// [`crate::service::RunName::id`] of the run.
    pub run_id: u64,
    /// [`SCHEMA_VERSION`] of the client.
    pub schema_version: u32,
    /// Environment asking (for the client's bookkeeping and the planner's logs).
    pub env: u32,
    /// Start cell index, `y · W + x`.
    pub from_cell: u32,
    /// Target pivotal state (graph node id).
    pub to_pivot: u16,
    /// Agent facing at the start: 0 right, 1 down, 2 left, 3 up.
    pub from_dir: u8,
    /// Zero; room for flags.
    pub reserved: u8,
}

impl RouteRequest {
    /// A request of this schema version.
    pub fn new(
        request_id: u64,
        run_id: u64,
        env: u32,
        from_cell: u32,
        from_dir: u8,
        to_pivot: u16,
    ) -> RouteRequest {
        RouteRequest {
            request_id,
            run_id,
            schema_version: SCHEMA_VERSION,
            env,
            from_cell,
            to_pivot,
            from_dir,
            reserved: 0,
        }
    }

    /// Checks version and run (the server answers [`RouteStatus::BadRequest`] on error).
    pub fn check(&self, run_id: u64) -> Result<(), SchemaError> {
        crate::step::check_version(Channel::Route, self.schema_version)?;
        crate::step::check_run(Channel::Route, run_id, self.run_id)
    }
}

/// The planner's answer to one [`RouteRequest`].
///
/// `pivots[..num_pivots]` are the pivotal states the route passes, in
/// order, ending with the target; `actions[i]` is the `i`-th action and
/// `cells[i]` the agent's cell after it, for `i < num_actions` (the start
/// cell is the request's `from_cell`). Entries past the counts are stale;
/// use the accessors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("wg.RouteResponse.v3")
)]
#[repr(C)]
pub struct RouteResponse {
    /// The request's `request_id`.
    pub request_id: u64,
    /// [`crate::GraphHeader::graph_version`] of the graph that answered.
    pub graph_version: u64,
    /// [`crate::service::RunName::id`] of the run.
    pub run_id: u64,
    /// [`SCHEMA_VERSION`] of the planner.
    pub schema_version: u32,
    /// A [`RouteStatus`] as `u32`.
    pub status: u32,
    /// Entries of `pivots` in use.
    pub num_pivots: u32,
    /// Entries of `cells` and `actions` in use.
    pub num_actions: u32,
    /// Pivotal states on the route, start to target.
    pub pivots: [u16; MAX_ROUTE_PIVOTS],
    /// Cell after each action, `y · W + x`.
    pub cells: [u32; MAX_ROUTE_LEN],
    /// The actions (MiniGrid numbering).
    pub actions: [u8; MAX_ROUTE_LEN],
}

impl RouteResponse {
    /// Decoded status (`None` for a status this version does not know).
    pub fn status(&self) -> Option<RouteStatus> {
        RouteStatus::from_wire(self.status)
    }
    /// The pivotal states on the route.
    pub fn pivots(&self) -> &[u16] {
        &self.pivots[..(self.num_pivots as usize).min(MAX_ROUTE_PIVOTS)]
    }
    /// The cells after each action.
    pub fn cells(&self) -> &[u32] {
        &self.cells[..(self.num_actions as usize).min(MAX_ROUTE_LEN)]
    }
    /// The actions.
    pub fn actions(&self) -> &[u8] {
        &self.actions[..(self.num_actions as usize).min(MAX_ROUTE_LEN)]
    }
    /// Total weight of the route (its action count), or [`UNREACHABLE`]
    /// when the status is not `Ok`.
    pub fn total_weight(&self) -> u32 {
        if self.status == RouteStatus::Ok as u32 {
            self.num_actions
        } else {
            UNREACHABLE
        }
    }

    /// Fills the response in place: header fields, then the used prefixes
    /// of the arrays. A route longer than the capacities is not written;
    /// the status becomes [`RouteStatus::TooLong`] and `Err` says so.
    pub fn fill(
        &mut self,
        request: &RouteRequest,
        graph_version: u64,
        status: RouteStatus,
        pivots: &[u16],
        cells: &[u32],
        actions: &[u8],
    ) -> Result<(), SchemaError> {
        self.request_id = request.request_id;
        self.run_id = request.run_id;
        self.graph_version = graph_version;
        self.schema_version = SCHEMA_VERSION;
        self.num_pivots = 0;
        self.num_actions = 0;
        self.status = status as u32;
        if cells.len() != actions.len() {
            self.status = RouteStatus::BadRequest as u32;
            return Err(SchemaError::PayloadTooShort {
                channel: Channel::Route,
                needed: actions.len(),
                got: cells.len(),
            });
        }
        if pivots.len() > MAX_ROUTE_PIVOTS || actions.len() > MAX_ROUTE_LEN {
            self.status = RouteStatus::TooLong as u32;
            let (what, value, max) = if pivots.len() > MAX_ROUTE_PIVOTS {
                ("route pivots", pivots.len(), MAX_ROUTE_PIVOTS)
            } else {
                ("route actions", actions.len(), MAX_ROUTE_LEN)
            };
            return Err(SchemaError::OutOfRange {
                channel: Channel::Route,
                what,
                value,
                max,
            });
        }
        self.pivots[..pivots.len()].copy_from_slice(pivots);
        self.cells[..cells.len()].copy_from_slice(cells);
        self.actions[..actions.len()].copy_from_slice(actions);
        self.num_pivots = pivots.len() as u32;
        self.num_actions = actions.len() as u32;
        Ok(())
    }

    /// Checks version, run and that this answers `request`.
    pub fn check(&self, request: &RouteRequest) -> Result<(), SchemaError> {
        crate::step::check_version(Channel::Route, self.schema_version)?;
        crate::step::check_run(Channel::Route, request.run_id, self.run_id)?;
        if self.request_id != request.request_id {
            return Err(SchemaError::Incompatible {
                channel: Channel::Route,
                reason: format!(
                    "response to request {} received for request {}",
                    self.request_id, request.request_id
                ),
                wire: String::new(),
            });
        }
        Ok(())
    }
}

const _: () = assert!(size_of::<RouteRequest>() == 32);
const _: () = assert!(align_of::<RouteRequest>() == 8);
const _: () = assert!(size_of::<RouteResponse>() == 10_792);
const _: () = assert!(align_of::<RouteResponse>() == 8);
const _: () = assert!(MAX_ROUTE_PIVOTS < NO_PIVOT as usize);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_and_read() {
        let req = RouteRequest::new(5, 1, 0, 14, 0, 3);
        let mut r: Box<RouteResponse> = Box::new(RouteResponse::zeroed());
        r.fill(&req, 2, RouteStatus::Ok, &[0, 3], &[15, 16, 16], &[2, 2, 1])
            .unwrap();
        r.check(&req).unwrap();
        assert_eq!(r.status(), Some(RouteStatus::Ok));
        assert_eq!(r.pivots(), &[0, 3]);
        assert_eq!(r.cells(), &[15, 16, 16]);
        assert_eq!(r.actions(), &[2, 2, 1]);
        assert_eq!(r.total_weight(), 3);

        let long = vec![2u8; MAX_ROUTE_LEN + 1];
        let cells = vec![0u32; MAX_ROUTE_LEN + 1];
        assert!(
            r.fill(&req, 2, RouteStatus::Ok, &[0], &cells, &long)
                .is_err()
        );
        assert_eq!(r.status(), Some(RouteStatus::TooLong));
        assert_eq!(r.total_weight(), UNREACHABLE);
        assert!(r.actions().is_empty());
        for v in 0..7 {
            assert_eq!(RouteStatus::from_wire(v).map(|s| s as u32), Some(v));
        }
        assert_eq!(RouteStatus::from_wire(7), None);
    }
}
