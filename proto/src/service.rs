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
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::header::{FrameHeader, PAYLOAD_ALIGNMENT};

/// Frames queued per subscriber before the oldest is overwritten.
pub const QOS_SUBSCRIBER_BUFFER: usize = 2;
/// Frames a subscriber may hold (borrow) at once.
pub const QOS_SUBSCRIBER_BORROWED: usize = 2;
/// Frames a late-joining subscriber receives at once (the latest one).
pub const QOS_HISTORY: usize = 1;
/// Subscribers one daemon serves. Shared memory grows with it: about
/// `(QOS_MAX_SUBSCRIBERS · (BUFFER + BORROWED) + 3) · frame size` (86 MB at 640×480).
pub const QOS_MAX_SUBSCRIBERS: usize = 8;
/// Publishers: one daemon, plus one slot so a restarted daemon can start before the dead
/// instance's port is cleaned up.
pub const QOS_MAX_PUBLISHERS: usize = 2;
/// Nodes (processes) attached to the service.
pub const QOS_MAX_NODES: usize = QOS_MAX_SUBSCRIBERS + QOS_MAX_PUBLISHERS + 4;

/// Default camera name.
pub const DEFAULT_CAMERA: &str = "cam0";

/// The default frame service of a camera: `dear/<camera>/frames`.
pub fn default_service_name(camera: &str) -> String {
    format!("dear/{camera}/frames")
}

/// Checks a service name: non-empty, at most 200 bytes, ASCII letters, digits and `/_-.`.
pub fn validate_service_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > 200 {
        return Err(format!("service name {name:?} must be 1 to 200 characters"));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || "/_-.".contains(*c)))
    {
        return Err(format!(
            "service name {name:?} contains {c:?}; use letters, digits and / _ - ."
        ));
    }
    Ok(())
}

/// The publish-subscribe port factory of the frame service.
pub type FrameService = publish_subscribe::PortFactory<ipc::Service, [u8], FrameHeader>;
/// The event port factory that announces new frames.
pub type FrameEventService = event::PortFactory<ipc::Service>;

/// Opens (or creates) the frame service `name` with the protocol's QoS.
pub fn frame_service(node: &Node<ipc::Service>, name: &str) -> Result<FrameService, String> {
    validate_service_name(name)?;
    let service_name: ServiceName = name
        .try_into()
        .map_err(|e| format!("service name {name:?}: {e:?}"))?;
    node.service_builder(&service_name)
        .publish_subscribe::<[u8]>()
        .user_header::<FrameHeader>()
        .payload_alignment(Alignment::new(PAYLOAD_ALIGNMENT).expect("power of two"))
        .enable_safe_overflow(true)
        .subscriber_max_buffer_size(QOS_SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(QOS_SUBSCRIBER_BORROWED)
        .history_size(QOS_HISTORY)
        .max_subscribers(QOS_MAX_SUBSCRIBERS)
        .max_publishers(QOS_MAX_PUBLISHERS)
        .max_nodes(QOS_MAX_NODES)
        .open_or_create()
        .map_err(|e| format!("cannot open or create the frame service {name:?}: {e:?}"))
}

/// Opens (or creates) the event service that announces each new frame of `name`.
pub fn frame_event_service(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<FrameEventService, String> {
    validate_service_name(name)?;
    let service_name: ServiceName = name
        .try_into()
        .map_err(|e| format!("service name {name:?}: {e:?}"))?;
    node.service_builder(&service_name)
        .event()
        .max_listeners(QOS_MAX_SUBSCRIBERS)
        .max_notifiers(QOS_MAX_PUBLISHERS)
        .max_nodes(QOS_MAX_NODES)
        .open_or_create()
        .map_err(|e| format!("cannot open or create the event service {name:?}: {e:?}"))
}
