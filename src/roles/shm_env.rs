//! The shared-memory client of the pipeline: a [`BatchEnvironment`] whose
//! environments live in the sim process (README.md, "The pipeline").
//!
//! Observation batches are read **in place**: [`ShmEnv::observe`] borrows the
//! received iceoryx2 sample, and the chunk goes back to the simulator when the
//! next batch replaces it. Action batch `k` answers observation sample `k`.
//! Each slice of the batch is lock-step: the simulator publishes a slice's
//! next sample only after receiving the actions for its last one, so no
//! sample is ever lost between the two. With one slice (`discover
//! --pipeline`, `train --pipeline`) the whole batch is lock-step; with `K`
//! slices (`learner serve`) up to `K` samples await their actions at once,
//! and sample `k` holds slice `k mod K`.
//!
//! While waiting, the client watches the sim's iceoryx2 node: when the sim
//! process is gone (dead node, or no node at all) for longer than
//! [`ShmEnvOptions::peer_timeout`], [`ShmEnv::step`] returns
//! [`EnvError::PeerGone`], so the caller can say so and either wait for a
//! restart ([`ShmEnv::wait_for_peer`]) or exit.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::config::Config;
use iceoryx2::prelude::Service;
use shm_schemas::service::{
    ActPublisher, ObsSample, ObsSubscriber, PipelineNode, RunName, list_nodes,
};
use shm_schemas::{Backoff, ObsShape, SeqEvent, SeqTracker};

use learner::batch_env::{BatchEnvironment, EnvError, ObsView};

/// Settings of the client.
#[derive(Debug, Clone)]
pub struct ShmEnvOptions {
    /// iceoryx2 node name of this process.
    pub node_name: String,
    /// Node name of the simulator process to watch.
    pub sim_node_name: String,
    /// How long the sim may be missing before [`EnvError::PeerGone`].
    pub peer_timeout: Duration,
    /// How long to wait for the first batch when connecting.
    pub connect_timeout: Duration,
    /// Set by a signal handler to stop waiting.
    pub stop: Option<Arc<AtomicBool>>,
    /// The task this process runs ([`sim::Task::name`]): with it, a sim of
    /// another task is refused at connect ([`PipelineNode::with_task`]).
    pub task: Option<String>,
}

impl Default for ShmEnvOptions {
    fn default() -> Self {
        ShmEnvOptions {
            node_name: "learner".into(),
            sim_node_name: "sim".into(),
            peer_timeout: Duration::from_millis(500),
            connect_timeout: Duration::from_secs(30),
            stop: None,
            task: None,
        }
    }
}

/// Lost / reordered / restart accounting of the observation stream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct StreamStats {
    /// Batches received.
    pub received: u64,
    /// Batches skipped (a gap in sequence numbers within one sim lifetime).
    pub lost: u64,
    /// Batches that arrived with a sequence number below the expected one.
    pub reordered: u64,
    /// Times the simulator started over (sequence back to 0).
    pub sim_restarts: u64,
}

/// The pipeline's shared-memory batch environment.
pub struct ShmEnv<S: Service> {
    node: PipelineNode<S>,
    config: Config,
    obs: ObsSubscriber<S>,
    act: ActPublisher<S>,
    current: Option<ObsSample<S>>,
    shape: ObsShape,
    num_actions: usize,
    opts: ShmEnvOptions,
    tracker: SeqTracker,
    stats: StreamStats,
    last_latency_ns: u64,
}

impl<S: Service> std::fmt::Debug for ShmEnv<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShmEnv")
            .field("shape", &self.shape)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl<S: Service> ShmEnv<S> {
    /// Opens the run's observation and action services for a batch of
    /// `shape` and waits for the first observation batch.
    pub fn connect(
        config: &Config,
        run: RunName,
        shape: ObsShape,
        num_actions: usize,
        opts: ShmEnvOptions,
    ) -> Result<ShmEnv<S>, EnvError> {
        let mut node = PipelineNode::<S>::new(config, run, &opts.node_name)?;
        if let Some(task) = &opts.task {
            node = node.with_task(task, num_actions);
        }
        node.cleanup_dead_nodes();
        let obs = node.obs_subscriber(shape)?;
        let act = node.act_publisher(shape.num_envs as usize)?;
        act.update_connections()?;
        let mut env = ShmEnv {
            node,
            config: config.clone(),
            obs,
            act,
            current: None,
            shape,
            num_actions,
            opts,
            tracker: SeqTracker::new(),
            stats: StreamStats::default(),
            last_latency_ns: 0,
        };
        let deadline = env.opts.connect_timeout;
        env.wait_next(None, deadline)?;
        Ok(env)
    }

    /// Stream accounting so far.
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// One-way latency of the last batch (publisher's send → this receive), ns.
    pub fn last_latency_ns(&self) -> u64 {
        self.last_latency_ns
    }

    /// The iceoryx2 node.
    pub fn node(&self) -> &PipelineNode<S> {
        &self.node
    }

    /// Whether the sim's node is alive now.
    pub fn sim_alive(&self) -> bool {
        list_nodes::<S>(&self.config)
            .map(|nodes| {
                nodes
                    .iter()
                    .any(|n| n.alive && n.name == self.opts.sim_node_name)
            })
            .unwrap_or(false)
    }

    /// After [`EnvError::PeerGone`]: waits (up to `timeout`) until a
    /// restarted simulator publishes a batch, and continues from it.
    pub fn wait_for_peer(&mut self, timeout: Duration) -> Result<(), EnvError> {
        self.current = None;
        self.node.cleanup_dead_nodes();
        // A restarted simulator numbers its batches from 0 again: a new
        // stream, not a reordering of the old one.
        let before = self.tracker.clone();
        self.tracker = SeqTracker::new();
        self.wait_next(None, timeout)?;
        let seq = self.observe().seq;
        if before.expected().is_some_and(|next| seq < next) {
            self.stats.sim_restarts += 1;
        }
        Ok(())
    }

    fn stopped(&self) -> bool {
        self.opts
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
    }

    /// Spins until a batch newer than `after` arrives (`None`: any batch).
    fn wait_next(&mut self, after: Option<u64>, timeout: Duration) -> Result<(), EnvError> {
        let start = Instant::now();
        let mut next_check = start + Duration::from_millis(50);
        let mut missing_since: Option<Instant> = None;
        let mut backoff = Backoff::new();
        let mut polls = 0u32;
        loop {
            if let Some(sample) = self.obs.receive()? {
                let seq = sample.header().seq;
                let restarted = after.is_some_and(|a| seq == 0 && a > 0);
                if let Some(a) = after
                    && seq <= a
                    && !restarted
                {
                    // A stale batch (history of a previous connection): skip it.
                    continue;
                }
                self.last_latency_ns = sample.latency_ns();
                if restarted {
                    self.stats.sim_restarts += 1;
                    self.tracker = SeqTracker::new();
                }
                match self.tracker.observe(seq) {
                    SeqEvent::Gap { missing } => self.stats.lost += missing,
                    SeqEvent::Stale { .. } => self.stats.reordered += 1,
                    SeqEvent::First | SeqEvent::InOrder => {}
                }
                self.stats.received += 1;
                self.current = Some(sample);
                return Ok(());
            }
            backoff.snooze();
            polls = polls.wrapping_add(1);
            if !polls.is_multiple_of(256) {
                continue;
            }
            let now = Instant::now();
            if self.stopped() {
                return Err(EnvError::Interrupted);
            }
            if now >= next_check {
                next_check = now + Duration::from_millis(50);
                if self.sim_alive() {
                    missing_since = None;
                } else {
                    let since = *missing_since.get_or_insert(now);
                    if after.is_some() && now - since >= self.opts.peer_timeout {
                        return Err(EnvError::PeerGone {
                            peer: "sim",
                            detail: format!(
                                "no live '{}' node for {:?}",
                                self.opts.sim_node_name,
                                now - since
                            ),
                        });
                    }
                }
                if now - start >= timeout {
                    return Err(EnvError::PeerGone {
                        peer: "sim",
                        detail: format!("no observation batch within {timeout:?}"),
                    });
                }
            }
        }
    }
}

impl<S: Service> BatchEnvironment for ShmEnv<S> {
    fn num_envs(&self) -> usize {
        self.shape.num_envs as usize
    }
    fn num_actions(&self) -> usize {
        self.num_actions
    }
    fn observe(&self) -> ObsView<'_> {
        let sample = self
            .current
            .as_ref()
            .expect("invariant: connect() received a first batch");
        let b = sample.batch();
        ObsView {
            seq: b.header.seq,
            cells: b.cells,
            final_cells: b.final_cells,
            meta: b.meta,
            width: self.shape.width as usize,
            height: self.shape.height as usize,
        }
    }
    fn step(&mut self, actions: &[u8]) -> Result<(), EnvError> {
        if actions.len() != self.num_envs() {
            return Err(EnvError::ActionCount {
                expected: self.num_envs(),
                got: actions.len(),
            });
        }
        let seq = self
            .current
            .as_ref()
            .map(|s| s.header().seq)
            .expect("invariant: a batch is held");
        // Release the observation chunk before answering, so the simulator
        // never runs out of chunks to loan.
        self.current = None;
        self.act.send_actions(seq, actions)?;
        let timeout = Duration::from_secs(u64::MAX / 4);
        self.wait_next(Some(seq), timeout)
    }
}
