//! How an iceoryx2 refusal is handled: retried, cleaned up after, or read
//! against the existing service's description and named as a
//! [`SchemaError`].

use std::fmt::Debug;

use iceoryx2::config::Config;
use iceoryx2::port::publisher::PublisherCreateError;
use iceoryx2::port::subscriber::SubscriberCreateError;
use iceoryx2::prelude::*;
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
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as StaticPattern;

use super::{ATTR_GRID, ATTR_NUM_ENVS, ATTR_SCHEMA_VERSION, ATTR_SLICES, ATTR_TASK};
use crate::{Channel, SchemaError, ShmError};

/// How an iceoryx2 error is handled by the retry loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Class {
    /// Retry after a back-off.
    Transient,
    /// Clean up dead nodes, then retry.
    Cleanup,
    /// The service exists but differs: diagnose.
    Incompatible,
    /// Give up.
    Fatal,
}

pub(super) fn classify_ps(e: &PsError) -> Class {
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

pub(super) fn classify_rr(e: &RrError) -> Class {
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
pub(super) trait PortCreateError: Debug {
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

pub(super) fn classify_port<E: PortCreateError>(e: &E) -> Class {
    if e.table_full() {
        Class::Cleanup
    } else {
        Class::Fatal
    }
}

/// What this process expects of a service, for diagnosing a refusal.
pub(super) struct Expectation {
    pub(super) channel: Channel,
    /// `(role, our type name)`; role is "user header", "request", "response".
    pub(super) types: Vec<(&'static str, String)>,
    /// Required attributes.
    pub(super) attrs: Vec<(&'static str, String)>,
}

impl Expectation {
    pub(super) fn verifier(&self) -> Result<AttributeVerifier, ShmError> {
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

/// `"doorkey/6"` → `"doorkey (6 actions)"`.
fn describe_task(attr: &str) -> String {
    match attr.split_once('/') {
        Some((task, n)) => format!("{task} ({n} actions)"),
        None => attr.to_owned(),
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
pub(super) fn diagnose<S: Service>(
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
                // The attribute counts one slice's environments; the user
                // chose the whole batch (`--envs`), and the slicing, checked
                // first, is the same on both ends here.
                ATTR_NUM_ENVS => {
                    let slices: u32 = exp
                        .attrs
                        .iter()
                        .find(|(k, _)| *k == ATTR_SLICES)
                        .and_then(|(_, v)| v.parse().ok())
                        .unwrap_or(1);
                    wire.parse::<u32>()
                        .ok()
                        .zip(ours.parse::<u32>().ok())
                        .map(|(w, o)| SchemaError::BatchSize {
                            channel,
                            expected: o * slices,
                            wire: w * slices,
                        })
                }
                ATTR_TASK => Some(SchemaError::Task {
                    channel,
                    expected: describe_task(ours),
                    wire: describe_task(wire),
                }),
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

/// An `open_or_create` refusal of one messaging pattern: how the retry
/// loop treats it, and which pattern to read the existing service as.
pub(super) trait OpenError: Debug {
    fn class(&self) -> Class;
    fn pattern() -> MessagingPattern;
}

impl OpenError for PsError {
    fn class(&self) -> Class {
        classify_ps(self)
    }
    fn pattern() -> MessagingPattern {
        MessagingPattern::PublishSubscribe
    }
}

impl OpenError for RrError {
    fn class(&self) -> Class {
        classify_rr(self)
    }
    fn pattern() -> MessagingPattern {
        MessagingPattern::RequestResponse
    }
}
