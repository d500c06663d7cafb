//! `wg/<run>/graph`: the planner's latest world-graph snapshot.

use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;

use super::diagnose::Expectation;
use super::node::{PipelineNode, ipc_err};
use super::*;
use crate::graph::{GraphSnapshotMut, check_counts, check_grid};
use crate::raw::{assume_init_slice, split_slice_sample, type_name_of};
use crate::{
    Channel, GraphEdge, GraphHeader, GraphSnapshot, SCHEMA_VERSION, ShmError, monotonic_ns,
};

impl<S: Service> PipelineNode<S> {
    pub(super) fn graph_service(
        &self,
        width: u16,
        height: u16,
    ) -> Result<(ServiceName, GraphService<S>), ShmError> {
        let exp = Expectation {
            channel: Channel::Graph,
            types: vec![("user header", type_name_of::<GraphHeader>())],
            attrs: vec![
                (ATTR_SCHEMA_VERSION, SCHEMA_VERSION.to_string()),
                (ATTR_GRID, format!("{width}x{height}")),
            ],
        };
        self.open_service(&exp, |node, name, verifier| {
            node.service_builder(name)
                .publish_subscribe::<[u32]>()
                .user_header::<GraphHeader>()
                .max_publishers(1)
                .max_subscribers(GRAPH_MAX_SUBSCRIBERS)
                .history_size(1)
                .subscriber_max_buffer_size(1)
                .subscriber_max_borrowed_samples(1)
                .enable_safe_overflow(true)
                .open_or_create_with_attributes(verifier)
        })
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
