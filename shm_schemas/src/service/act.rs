//! `wg/<run>/act`: the action batches, learner → sim.

use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;

use super::diagnose::Expectation;
use super::node::{PipelineNode, ipc_err};
use super::*;
use crate::action::check_num_envs;
use crate::raw::{assume_init_slice, split_slice_sample, type_name_of};
use crate::{ActBatch, ActBatchMut, ActHeader, Channel, SCHEMA_VERSION, ShmError, monotonic_ns};

impl<S: Service> PipelineNode<S> {
    pub(super) fn act_service(
        &self,
        num_envs: u32,
    ) -> Result<(ServiceName, ActService<S>), ShmError> {
        let mut exp = Expectation {
            channel: Channel::Act,
            types: vec![("user header", type_name_of::<ActHeader>())],
            attrs: vec![
                (ATTR_SCHEMA_VERSION, SCHEMA_VERSION.to_string()),
                (ATTR_NUM_ENVS, num_envs.to_string()),
            ],
        };
        exp.attrs.extend(self.task_attr());
        self.open_service(&exp, |node, name, verifier| {
            node.service_builder(name)
                .publish_subscribe::<[u8]>()
                .user_header::<ActHeader>()
                .max_publishers(1)
                .max_subscribers(ACT_MAX_SUBSCRIBERS)
                .history_size(0)
                .subscriber_max_buffer_size(ACT_BUFFER)
                .subscriber_max_borrowed_samples(2)
                .enable_safe_overflow(true)
                .open_or_create_with_attributes(verifier)
        })
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
}

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
    /// waits for it in turn (measured in docs/implementation_details.md,
    /// "Pipeline throughput").
    pub fn prefetch_actions(&self) {
        crate::raw::prefetch(self.actions());
    }
}
