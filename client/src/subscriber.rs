//! Connecting to a frame service and waiting for frames.

use std::os::unix::fs::MetadataExt;
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
    /// A sample came from a publisher that does not belong to the owner of the iceoryx2 root
    /// (the daemon's user, or root): another user of the service's group published on the
    /// service first. The sample was dropped.
    #[error("a frame from {service:?} was published by uid {uid} (pid {pid}), not by the owner of the iceoryx2 root {} (uid {owner}) or root: another user's process publishes on this service; its frames are refused", root.display())]
    UntrustedPublisher {
        service: String,
        uid: u32,
        pid: String,
        owner: u32,
        root: std::path::PathBuf,
    },
    /// Issue 34: the shared records of this client's channel from the daemon were found
    /// overwritten (by another process of the service's group, or a buggy one): the queue
    /// named a sample outside the daemon's frames, or the record's layout changed. Nothing
    /// more arrives through this [`Client`]: connect again ([`Client::connect`]; the daemon
    /// makes a damaged service again within about two seconds).
    #[error("the channel from {service:?} to this client was corrupted: another process wrote into its shared records (the transport's *.connection / *.dynamic files); nothing more can be received through it: connect again")]
    Corrupted {
        service: String,
        #[source]
        source: iceoryx2::port::ReceiveError,
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
    /// To look up which node published a sample.
    frames: dear_proto::FrameService,
    /// The iceoryx2 root and its owner: the user whose publishers are trusted (with root).
    root: std::path::PathBuf,
    root_owner: u32,
    /// The last publisher found to be trusted (its port id).
    trusted: std::cell::Cell<Option<u128>>,
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
        let root = create_root(&config).map_err(|source| ConnectError::RootDirectory {
            service: name(),
            source,
        })?;
        let root_owner = std::fs::metadata(&root).map(|m| m.uid()).unwrap_or(0);
        // Issue 34: another process of the service's group can truncate this client's shared
        // records while they are mapped; an access to the lost pages then reads zeros (the
        // record is refused as corrupted, `ReceiveError::Corrupted`) instead of killing this
        // process with SIGBUS. Faults anywhere else keep the application's disposition. Not
        // fatal when it cannot be installed: only that attack is not survived.
        let _ = dear_proto::transport::survive_truncated_records();
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
            frames,
            root,
            root_owner,
            trusted: std::cell::Cell::new(None),
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The next queued frame, if any, without waiting. A frame from a publisher of another user
    /// than the root's owner (or root) is refused ([`ReceiveError::UntrustedPublisher`]).
    pub fn try_receive(&self) -> Result<Option<Frame>, ReceiveError> {
        let sample = self.subscriber.receive().map_err(|source| match source {
            iceoryx2::port::ReceiveError::ConnectionCorrupted => ReceiveError::Corrupted {
                service: self.service.clone(),
                source,
            },
            source => ReceiveError::Receive {
                service: self.service.clone(),
                source,
            },
        })?;
        let Some(sample) = sample else {
            return Ok(None);
        };
        self.check_publisher(sample.header().publisher_id())?;
        Frame::new(sample)
            .map(Some)
            .map_err(|source| ReceiveError::BadFrame {
                service: self.service.clone(),
                source,
            })
    }

    /// Whether `publisher` runs as the owner of the iceoryx2 root or as root: the owner of its
    /// node's directory (`<root>/nodes/<node id>`, made by the publishing process). Issue 34:
    /// a member of the service's group who started a publisher on the service before the
    /// daemon had its frames received by every client. A publisher that has already left the
    /// service cannot be checked; its last samples are accepted.
    fn check_publisher(
        &self,
        publisher: iceoryx2::identifiers::UniquePublisherId,
    ) -> Result<(), ReceiveError> {
        if self.trusted.get() == Some(publisher.value()) {
            return Ok(());
        }
        let mut node = None;
        self.frames.dynamic_config().list_publishers(|details| {
            if details.publisher_id == publisher {
                node = Some(details.node_id);
                return CallbackProgression::Stop;
            }
            CallbackProgression::Continue
        });
        let untrusted = |uid: u32, pid: String| ReceiveError::UntrustedPublisher {
            service: self.service.clone(),
            uid,
            pid,
            owner: self.root_owner,
            root: self.root.clone(),
        };
        // Gone from the service since (a daemon that was stopped or crashed): its last samples
        // cannot be checked and are accepted, so a client sees a daemon's run to its end.
        let Some(node) = node else {
            return Ok(());
        };
        let pid = node
            .pid::<Transport>()
            .map(|p| p.value().to_string())
            .unwrap_or_else(|_| "unknown".into());
        let dir = self.root.join("nodes").join(node.value().to_string());
        let uid = std::fs::symlink_metadata(&dir)
            .map(|m| m.uid())
            .unwrap_or(u32::MAX);
        if uid == self.root_owner || uid == 0 {
            self.trusted.set(Some(publisher.value()));
            return Ok(());
        }
        Err(untrusted(uid, pid))
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
