//! `wg/<run>/route`: route queries, learner → planner → learner.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::active_request::ActiveRequest;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use iceoryx2::response::Response;
use iceoryx2::service::port_factory::client::ClientCreateError;
use iceoryx2::service::port_factory::server::ServerCreateError;

use super::diagnose::Expectation;
use super::node::{PipelineNode, ipc_err};
use super::*;
use crate::raw::{assume_init_response, type_name_of};
use crate::{
    Channel, RouteRequest, RouteResponse, RouteStatus, SCHEMA_VERSION, SchemaError, ShmError,
};

impl<S: Service> PipelineNode<S> {
    pub(super) fn route_service(&self) -> Result<(ServiceName, RouteService<S>), ShmError> {
        let exp = Expectation {
            channel: Channel::Route,
            types: vec![
                ("request", type_name_of::<RouteRequest>()),
                ("response", type_name_of::<RouteResponse>()),
            ],
            attrs: vec![(ATTR_SCHEMA_VERSION, SCHEMA_VERSION.to_string())],
        };
        self.open_service(&exp, |node, name, verifier| {
            node.service_builder(name)
                .request_response::<RouteRequest, RouteResponse>()
                .max_servers(1)
                .max_clients(ROUTE_MAX_CLIENTS)
                .max_active_requests_per_client(ROUTE_MAX_ACTIVE_REQUESTS)
                .max_response_buffer_size(1)
                .max_borrowed_responses_per_pending_response(1)
                .enable_fire_and_forget_requests(false)
                .open_or_create_with_attributes(verifier)
        })
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
}

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
