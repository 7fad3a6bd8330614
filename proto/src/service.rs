//! Service names and the quality-of-service settings every party opens the frame service with.
//!
//! Daemon and clients both call [`frame_service`] (`open_or_create`), so either may start
//! first and a restarted daemon is picked up by running clients. The QoS values are constants of
//! the protocol: a client that asked for different ones would fail to open the service.
//!
//! Overflow policy (documented choice): each subscriber has a queue of
//! [`QOS_SUBSCRIBER_BUFFER`] frames; when it is full the *oldest* frame is overwritten
//! ("safe overflow"), so a slow or stuck subscriber only ever loses its own old frames and never
//! blocks the daemon or other subscribers. Live depth is worth more fresh than complete.

use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::header::{FrameHeader, FORMAT_VERSION, HEADER_SIZE};
use crate::transport::Transport;

/// Frames queued per subscriber before the oldest is overwritten.
pub const QOS_SUBSCRIBER_BUFFER: usize = 2;
/// Frames a subscriber may hold (borrow) at once.
pub const QOS_SUBSCRIBER_BORROWED: usize = 2;
/// Frames a late-joining subscriber receives at once (the latest one).
pub const QOS_HISTORY: usize = 1;
/// Subscribers one daemon serves. Shared memory grows with it: the publisher's data segment
/// holds [`samples_in_shared_memory`] frames (35 with these values: 21.5 MB at 320×240, 86 MB
/// at 640×480), allocated as written (a frame's pages once it has been sent).
pub const QOS_MAX_SUBSCRIBERS: usize = 8;
/// Publishers: one daemon, plus one slot so a restarted daemon can start before the dead
/// instance's port is cleaned up.
pub const QOS_MAX_PUBLISHERS: usize = 2;
/// Nodes (processes) attached to the service.
pub const QOS_MAX_NODES: usize = QOS_MAX_SUBSCRIBERS + QOS_MAX_PUBLISHERS + 4;

/// Frames the publisher's data segment holds: every subscriber's queue and borrowed samples,
/// the history, and the publisher's own loans (iceoryx2 0.10 sizes it so:
/// `max_subscribers · (buffer + borrowed) + history + max_loaned`, with one loan and one
/// sample in flight). Frame size × this is the shared memory one stream can take.
pub const fn samples_in_shared_memory() -> usize {
    QOS_MAX_SUBSCRIBERS * (QOS_SUBSCRIBER_BUFFER + QOS_SUBSCRIBER_BORROWED) + QOS_HISTORY + 2
}

/// Default camera name.
pub const DEFAULT_CAMERA: &str = "cam0";

/// The default frame service of a camera: `dear/<camera>/frames`.
pub fn default_service_name(camera: &str) -> String {
    format!("dear/{camera}/frames")
}

/// Why a service name was refused ([`validate_service_name`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ServiceNameError {
    #[error("service name {name:?} must be 1 to 200 characters")]
    Length { name: String },
    #[error("service name {name:?} contains {found:?}; use letters, digits and / _ - .")]
    Character { name: String, found: char },
    /// Passed our rules but not iceoryx2's (kept as a source so a future iceoryx2 rule is
    /// reported, not swallowed).
    #[error("service name {name:?} is not accepted by iceoryx2")]
    Iceoryx {
        name: String,
        #[source]
        source: ServiceNameRejected,
    },
}

/// iceoryx2's own service-name error.
pub type ServiceNameRejected = iceoryx2::service::service_name::ServiceNameError;

/// Why the frame service could not be opened or created ([`frame_service`]).
#[derive(Debug, thiserror::Error)]
pub enum FrameServiceError {
    #[error(transparent)]
    Name(#[from] ServiceNameError),
    /// The service exists with another user header or payload type: made by a daemon or
    /// client of another frame format (format 2's header had 192 bytes, format 3's 256).
    #[error(
        "cannot open the frame service {name:?}: it exists with another frame header type, so \
         the process that made it (a deard or client still running) speaks another frame format \
         than this one's format {FORMAT_VERSION} (`DearFrameHeader` of {HEADER_SIZE} bytes; \
         format 2 had 192): update the older of the two (docs/protocol.md, \"Frame layout\")"
    )]
    OtherFormat {
        name: String,
        #[source]
        source: PublishSubscribeOpenOrCreateError,
    },
    /// Typically: the service exists with other QoS, or the shared memory is not accessible.
    #[error("cannot open or create the frame service {name:?} (if it exists, another process made it with other QoS or types than this protocol's: docs/protocol.md, \"Frame layout\")")]
    OpenOrCreate {
        name: String,
        #[source]
        source: PublishSubscribeOpenOrCreateError,
    },
}

/// Why the event service could not be opened or created ([`frame_event_service`]).
#[derive(Debug, thiserror::Error)]
pub enum EventServiceError {
    #[error(transparent)]
    Name(#[from] ServiceNameError),
    #[error("cannot open or create the event service {name:?}")]
    OpenOrCreate {
        name: String,
        #[source]
        source: EventOpenOrCreateError,
    },
}

/// Checks a service name: non-empty, at most 200 bytes, ASCII letters, digits and `/_-.`.
pub fn validate_service_name(name: &str) -> Result<(), ServiceNameError> {
    if name.is_empty() || name.len() > 200 {
        return Err(ServiceNameError::Length {
            name: name.to_string(),
        });
    }
    if let Some(found) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || "/_-.".contains(*c)))
    {
        return Err(ServiceNameError::Character {
            name: name.to_string(),
            found,
        });
    }
    Ok(())
}

/// The iceoryx2 name of a valid service name.
fn service_name(name: &str) -> Result<ServiceName, ServiceNameError> {
    validate_service_name(name)?;
    name.try_into().map_err(|source| ServiceNameError::Iceoryx {
        name: name.to_string(),
        source,
    })
}

/// The publish-subscribe port factory of the frame service.
pub type FrameService = publish_subscribe::PortFactory<Transport, [u8], FrameHeader>;
/// The event port factory that announces new frames.
pub type FrameEventService = event::PortFactory<Transport>;

/// Opens (or creates) the frame service `name` with the protocol's QoS.
pub fn frame_service(
    node: &Node<Transport>,
    name: &str,
) -> Result<FrameService, FrameServiceError> {
    let service_name = service_name(name)?;
    node.service_builder(&service_name)
        .publish_subscribe::<[u8]>()
        .user_header::<FrameHeader>()
        .enable_safe_overflow(true)
        .subscriber_max_buffer_size(QOS_SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(QOS_SUBSCRIBER_BORROWED)
        .history_size(QOS_HISTORY)
        .max_subscribers(QOS_MAX_SUBSCRIBERS)
        .max_publishers(QOS_MAX_PUBLISHERS)
        .max_nodes(QOS_MAX_NODES)
        .open_or_create()
        .map_err(|source| {
            let name = name.to_string();
            match source {
                PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    PublishSubscribeOpenError::IncompatibleTypes,
                ) => FrameServiceError::OtherFormat { name, source },
                source => FrameServiceError::OpenOrCreate { name, source },
            }
        })
}

/// Opens (or creates) the event service that announces each new frame of `name`.
pub fn frame_event_service(
    node: &Node<Transport>,
    name: &str,
) -> Result<FrameEventService, EventServiceError> {
    let service_name = service_name(name)?;
    node.service_builder(&service_name)
        .event()
        .max_listeners(QOS_MAX_SUBSCRIBERS)
        .max_notifiers(QOS_MAX_PUBLISHERS)
        .max_nodes(QOS_MAX_NODES)
        .open_or_create()
        .map_err(|source| EventServiceError::OpenOrCreate {
            name: name.to_string(),
            source,
        })
}
