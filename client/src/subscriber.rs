//! Connecting to a frame service and waiting for frames.

use std::time::{Duration, Instant};

use dear_proto::service::{frame_event_service, frame_service};
use dear_proto::transport::{create_root, node_config, NodeConfigError, RootError};
use dear_proto::Transport;
use dear_proto::{EventServiceError, FrameHeader, FrameServiceError};
use iceoryx2::node::NodeCreationFailure;
use iceoryx2::port::listener::{Listener, ListenerCreateError, ListenerWaitError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;

use crate::frame::{Frame, FrameError};

/// Why [`Client::connect`] failed. Every variant names the service; the iceoryx2 error is
/// the [`source`](std::error::Error::source).
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// `root` is iceoryx2's root directory this process used ([`node_config`]): a client
    /// that cannot write there (another user's service) fails here.
    #[error("cannot connect to {service:?}: cannot create an iceoryx2 node under {root}")]
    Node {
        service: String,
        root: String,
        #[source]
        source: NodeCreationFailure,
    },
    /// `DEAR_IOX2_ROOT` is set to something that cannot be iceoryx2's root.
    #[error("cannot connect to {service:?}")]
    Root {
        service: String,
        #[source]
        source: NodeConfigError,
    },
    /// The root directory is missing and cannot be made: typically a user outside the
    /// service's group (it cannot enter `/run/deard`).
    #[error("cannot connect to {service:?}")]
    RootDirectory {
        service: String,
        #[source]
        source: RootError,
    },
    /// A bad service name, or the service exists with another contract (QoS, header type).
    #[error("cannot connect to {service:?}")]
    FrameService {
        service: String,
        #[source]
        source: FrameServiceError,
    },
    #[error("cannot connect to {service:?}")]
    EventService {
        service: String,
        #[source]
        source: EventServiceError,
    },
    /// Every subscriber slot of the service is taken.
    #[error("cannot connect to {service:?}: it already has its maximum of {max} subscribers (a service serves at most {max} client processes at once; `dear list` shows them; one ends when its process exits)", max = dear_proto::service::QOS_MAX_SUBSCRIBERS)]
    SubscriberLimit {
        service: String,
        #[source]
        source: SubscriberCreateError,
    },
    #[error("cannot connect to {service:?}: cannot create a subscriber")]
    Subscriber {
        service: String,
        #[source]
        source: SubscriberCreateError,
    },
    #[error("cannot connect to {service:?}: cannot create a listener for its frame events")]
    Listener {
        service: String,
        #[source]
        source: ListenerCreateError,
    },
}

/// Why receiving a frame ([`Client::try_receive`], [`Client::wait`]) failed.
#[derive(Debug, thiserror::Error)]
pub enum ReceiveError {
    #[error("receiving from {service:?} failed")]
    Receive {
        service: String,
        #[source]
        source: iceoryx2::port::ReceiveError,
    },
    /// Waiting for the daemon's frame event failed (a signal only from
    /// [`Client::wait_interruptible`]; [`Client::wait`] returns early instead).
    #[error("waiting for a frame from {service:?} failed")]
    Wait {
        service: String,
        #[source]
        source: ListenerWaitError,
    },
    /// A sample arrived but is not a valid frame; it was dropped. Not fatal: the next one may
    /// be fine (`dear watch` counts these).
    #[error("frame from {service:?} rejected")]
    BadFrame {
        service: String,
        #[source]
        source: FrameError,
    },
}

/// Any error of the client SDK, for applications that handle connecting and receiving alike.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error(transparent)]
    Connect(#[from] ConnectError),
    #[error(transparent)]
    Receive(#[from] ReceiveError),
}

/// A subscription to one `deard` frame service.
pub struct Client {
    service: String,
    node: Node<Transport>,
    subscriber: Subscriber<Transport, [u8], FrameHeader>,
    listener: Listener<Transport>,
}

impl Client {
    /// Subscribes to `service` (e.g. `dear/cam0/frames`). Works whether or not the daemon is
    /// running yet; frames arrive once it publishes.
    pub fn connect(service: &str) -> Result<Self, ConnectError> {
        let name = || service.to_string();
        // The daemon's iceoryx2 root: $DEAR_IOX2_ROOT, else /dev/shm/dear (node_config).
        let config = node_config().map_err(|source| ConnectError::Root {
            service: name(),
            source,
        })?;
        create_root(&config).map_err(|source| ConnectError::RootDirectory {
            service: name(),
            source,
        })?;
        let node = NodeBuilder::new()
            .config(&config)
            // The application owns its signals; iceoryx2 must not install handlers of its own.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Transport>()
            .map_err(|source| ConnectError::Node {
                service: name(),
                root: config.global.root_path().to_string(),
                source,
            })?;
        // A crashed process may have left ports behind; they would hold queue slots.
        node.try_cleanup_dead_nodes();
        let frames =
            frame_service(&node, service).map_err(|source| ConnectError::FrameService {
                service: name(),
                source,
            })?;
        let events =
            frame_event_service(&node, service).map_err(|source| ConnectError::EventService {
                service: name(),
                source,
            })?;
        let subscriber = frames
            .subscriber_builder()
            .create()
            .map_err(|source| match source {
                SubscriberCreateError::ExceedsMaxSupportedSubscribers => {
                    ConnectError::SubscriberLimit {
                        service: name(),
                        source,
                    }
                }
                source => ConnectError::Subscriber {
                    service: name(),
                    source,
                },
            })?;
        let listener =
            events
                .listener_builder()
                .create()
                .map_err(|source| ConnectError::Listener {
                    service: name(),
                    source,
                })?;
        Ok(Client {
            service: service.to_string(),
            node,
            subscriber,
            listener,
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The next queued frame, if any, without waiting.
    pub fn try_receive(&self) -> Result<Option<Frame>, ReceiveError> {
        let sample = self
            .subscriber
            .receive()
            .map_err(|source| ReceiveError::Receive {
                service: self.service.clone(),
                source,
            })?;
        match sample {
            None => Ok(None),
            Some(sample) => Frame::new(sample)
                .map(Some)
                .map_err(|source| ReceiveError::BadFrame {
                    service: self.service.clone(),
                    source,
                }),
        }
    }

    /// Waits up to `timeout` for a frame (event-driven: the thread sleeps until the daemon
    /// announces one). `Ok(None)` on timeout, and also early when a signal interrupted the
    /// wait: a handler of the application's (Ctrl-C), or a stop and continue (Ctrl-Z then `fg`,
    /// a debugger), which interrupts a waiting thread even with no handler installed. Neither is
    /// a failure of the service: check your own flags and call again.
    pub fn wait(&self, timeout: Duration) -> Result<Option<Frame>, ReceiveError> {
        match self.wait_interruptible(timeout) {
            // A frame that came meanwhile is taken; otherwise the caller gets control back.
            Err(ReceiveError::Wait {
                source: ListenerWaitError::InterruptSignal,
                ..
            }) => self.try_receive(),
            other => other,
        }
    }

    /// [`Client::wait`], except that a signal ends the wait with
    /// [`ReceiveError::Wait`] holding [`ListenerWaitError::InterruptSignal`], for callers that
    /// report it (the C SDK's `DEAR_INTERRUPTED`).
    pub fn wait_interruptible(&self, timeout: Duration) -> Result<Option<Frame>, ReceiveError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(frame) = self.try_receive()? {
                return Ok(Some(frame));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.listener
                .timed_wait(|_| {}, left)
                .map_err(|source| ReceiveError::Wait {
                    service: self.service.clone(),
                    source,
                })?;
        }
    }

    /// Waits without a time limit.
    pub fn wait_forever(&self) -> Result<Frame, ReceiveError> {
        loop {
            if let Some(frame) = self.wait(Duration::from_secs(3600))? {
                return Ok(frame);
            }
        }
    }

    /// Removes resources of processes that died without cleaning up (call now and then in
    /// long-running applications; the daemon does it too).
    pub fn cleanup_dead_peers(&self) {
        self.node.try_cleanup_dead_nodes();
    }
}
