//! `wg/<run>/obs`: the observation stream, sim → learner and planner.

use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;

use super::diagnose::Expectation;
use super::node::{PipelineNode, ipc_err};
use super::*;
use crate::raw::{assume_init_slice, split_slice_sample, type_name_of};
use crate::{
    Channel, ObsBatch, ObsBatchMut, ObsHeader, ObsShape, SCHEMA_VERSION, ShmError, monotonic_ns,
};

impl<S: Service> PipelineNode<S> {
    pub(super) fn obs_service(
        &self,
        shape: &ObsShape,
    ) -> Result<(ServiceName, ObsService<S>), ShmError> {
        let mut exp = Expectation {
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
        exp.attrs.extend(self.task_attr());
        self.open_service(&exp, |node, name, verifier| {
            node.service_builder(name)
                .publish_subscribe::<[u64]>()
                .user_header::<ObsHeader>()
                .max_publishers(1)
                .max_subscribers(OBS_MAX_SUBSCRIBERS)
                .history_size(usize::from(shape.slices))
                .subscriber_max_buffer_size(OBS_BUFFER)
                .subscriber_max_borrowed_samples(OBS_MAX_BORROWED)
                .enable_safe_overflow(true)
                .open_or_create_with_attributes(verifier)
        })
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
}

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
    /// Header, metas, cells and final cells, mutable, over the shared memory.
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
