//! [`PipelineNode`]: one process's node of a run, and the one
//! open-with-retry every channel goes through.

use std::fmt::Debug;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::config::Config;
use iceoryx2::node::CleanupState;
use iceoryx2::prelude::*;

use super::DEFAULT_RETRY_TIMEOUT;
use super::diagnose::{Class, Expectation, OpenError, PortCreateError, classify_port, diagnose};
use super::files::harden_shm_permissions;
use super::names::{RunName, config_prefix, service_name};
use crate::{Channel, ShmError};

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

/// A node of one run: the entry point of every process
/// (`PipelineNode::<ipc::Service>::new(&run_config(&run)?, run, "sim")`).
/// Opens the run's channels with the pipeline's QoS, retrying transient
/// errors and diagnosing mismatches.
#[derive(Debug)]
pub struct PipelineNode<S: Service> {
    pub(super) node: Node<S>,
    pub(super) run: RunName,
    retry_timeout: Duration,
    /// `"<task>/<actions>"` ([`PipelineNode::with_task`]).
    task: Option<String>,
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
            task: None,
            opened: AtomicBool::new(false),
        })
    }

    /// Sets how long transient errors are retried (default [`DEFAULT_RETRY_TIMEOUT`]).
    pub fn with_retry_timeout(mut self, timeout: Duration) -> PipelineNode<S> {
        self.retry_timeout = timeout;
        self
    }

    /// Makes the task (its name and number of actions) part of the obs
    /// and act services' identity (attribute `wg.task`): a learner or
    /// planner of another task is refused at open with
    /// [`crate::SchemaError::Task`] instead of exchanging batches it
    /// misreads. Every process of a run must set it, or none.
    pub fn with_task(mut self, task: &str, num_actions: usize) -> PipelineNode<S> {
        self.task = Some(format!("{task}/{num_actions}"));
        self
    }

    /// The `wg.task` attribute this node requires, if any.
    pub(super) fn task_attr(&self) -> Option<(&'static str, String)> {
        self.task.clone().map(|t| (super::ATTR_TASK, t))
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
    pub(super) fn retry<T, E: Debug>(
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

    pub(super) fn mark_opened(&self) {
        self.opened.store(true, Ordering::Relaxed);
    }

    pub(super) fn open_failed<E: Debug>(
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

    pub(super) fn create_port<T, E: PortCreateError>(
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

    /// Opens (or creates) the channel `exp.channel` of this node's run with
    /// `open`, the channel's builder with its QoS: retries transient
    /// refusals, cleans up dead nodes when the node table is full, and turns
    /// an incompatible service into the [`crate::SchemaError`] that names the
    /// difference. The one open-with-retry of every channel.
    pub(super) fn open_service<F, E: OpenError>(
        &self,
        exp: &Expectation,
        mut open: impl FnMut(&Node<S>, &ServiceName, &AttributeVerifier) -> Result<F, E>,
    ) -> Result<(ServiceName, F), ShmError> {
        let name = service_name(&self.run, exp.channel)?;
        let verifier = exp.verifier()?;
        self.mark_opened();
        let factory = self
            .retry(
                "open service",
                name.as_str(),
                || open(&self.node, &name, &verifier),
                E::class,
            )
            .map_err(|f| self.open_failed(&name, E::pattern(), exp, f))?;
        Ok((name, factory))
    }
}

pub(super) fn ipc_err(op: &'static str, channel: Channel, e: impl Debug) -> ShmError {
    ShmError::Ipc {
        op,
        service: channel.suffix().to_owned(),
        detail: format!("{e:?}"),
    }
}
