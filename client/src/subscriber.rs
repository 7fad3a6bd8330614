//! Connecting to a frame service and waiting for frames.

use std::time::{Duration, Instant};

use dear_proto::service::{frame_event_service, frame_service};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::frame::Frame;
use dear_proto::FrameHeader;

/// Errors of the client SDK.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot connect to {service:?}: {message}")]
    Connect { service: String, message: String },
    #[error("receiving from {service:?} failed: {message}")]
    Receive { service: String, message: String },
    #[error("frame from {service:?} rejected: {message}")]
    BadFrame { service: String, message: String },
}

/// A subscription to one `deard` frame service.
pub struct Client {
    service: String,
    node: Node<ipc::Service>,
    subscriber: Subscriber<ipc::Service, [u8], FrameHeader>,
    listener: Listener<ipc::Service>,
}

impl Client {
    /// Subscribes to `service` (e.g. `dear/cam0/frames`). Works whether or not the daemon is
    /// running yet; frames arrive once it publishes.
    pub fn connect(service: &str) -> Result<Self, ClientError> {
        let err = |message: String| ClientError::Connect {
            service: service.to_string(),
            message,
        };
        let node = NodeBuilder::new()
            // The application owns its signals; iceoryx2 must not install handlers of its own.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| err(format!("node: {e:?}")))?;
        // A crashed process may have left ports behind; they would hold queue slots.
        node.try_cleanup_dead_nodes();
        let frames = frame_service(&node, service).map_err(err)?;
        let events = frame_event_service(&node, service).map_err(err)?;
        let subscriber = frames
            .subscriber_builder()
            .create()
            .map_err(|e| err(format!("subscriber: {e:?}")))?;
        let listener = events
            .listener_builder()
            .create()
            .map_err(|e| err(format!("listener: {e:?}")))?;
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
    pub fn try_receive(&self) -> Result<Option<Frame>, ClientError> {
        let sample = self
            .subscriber
            .receive()
            .map_err(|e| ClientError::Receive {
                service: self.service.clone(),
                message: format!("{e:?}"),
            })?;
        match sample {
            None => Ok(None),
            Some(sample) => Frame::new(sample)
                .map(Some)
                .map_err(|message| ClientError::BadFrame {
                    service: self.service.clone(),
                    message,
                }),
        }
    }

    /// Waits up to `timeout` for a frame (event-driven: the thread sleeps until the daemon
    /// announces one). `Ok(None)` on timeout.
    pub fn wait(&self, timeout: Duration) -> Result<Option<Frame>, ClientError> {
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
                .map_err(|e| ClientError::Receive {
                    service: self.service.clone(),
                    message: format!("{e:?}"),
                })?;
        }
    }

    /// Waits without a time limit.
    pub fn wait_forever(&self) -> Result<Frame, ClientError> {
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
