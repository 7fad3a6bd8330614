//! A client that outlives a corrupted channel (issue 34): when another process of the
//! service's group writes into this client's shared records, the SDK says so once
//! ([`ReceiveError::Corrupted`]) and nothing more arrives through that [`Client`]; the service
//! itself goes on (deard makes a damaged service again within about two seconds). `watch`,
//! `record` and `dump` keep going through [`ReconnectingClient`] instead of ending.
//!
//! Some writes break a channel silently: a connection overwritten whole (every byte `0xff`)
//! has queue positions that look like an empty queue, and the daemon's end gives up on it, so
//! nothing arrives and nothing is reported. A channel that delivers nothing for [`STALL`] is
//! therefore connected again too; on a healthy but idle service that costs a reconnection
//! every few seconds and loses nothing.

use std::time::{Duration, Instant};

use dear_client::{Client, ConnectError, Frame, ReceiveError};

/// How often a lost channel is connected again.
const RECONNECT: Duration = Duration::from_millis(500);
/// How long a channel may deliver nothing before it is connected again (see the module docs).
pub const STALL: Duration = Duration::from_secs(3);

/// A [`Client`] that connects again after its channel was corrupted.
pub struct ReconnectingClient {
    service: String,
    /// `None` while the channel is being made again.
    client: Option<Client>,
    next_connect: Instant,
    /// When the channel last delivered a frame, or was connected.
    last_frame: Instant,
    reconnects: u64,
}

impl ReconnectingClient {
    /// Connects to `service`; a first connection that fails is the caller's error, as with
    /// [`Client::connect`].
    ///
    /// # Errors
    /// As [`Client::connect`].
    pub fn connect(service: &str) -> Result<Self, ConnectError> {
        Ok(ReconnectingClient {
            service: service.to_string(),
            client: Some(Client::connect(service)?),
            next_connect: Instant::now(),
            last_frame: Instant::now(),
            reconnects: 0,
        })
    }

    /// As [`Client::wait`]; a corrupted channel, or one that delivered nothing for
    /// [`STALL`], is dropped, said on stderr (as a warning) and connected again every 0.5 s,
    /// and meanwhile this waits `timeout` and returns `Ok(None)`.
    ///
    /// # Errors
    /// Every error of [`Client::wait`] but [`ReceiveError::Corrupted`].
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<Frame>, ReceiveError> {
        let Some(client) = self.client.as_ref() else {
            std::thread::sleep(timeout);
            self.try_connect();
            return Ok(None);
        };
        match client.wait(timeout) {
            Err(e @ ReceiveError::Corrupted { .. }) => {
                tracing::warn!(error = %e, "connecting again");
                self.drop_channel();
                Ok(None)
            }
            Ok(None) if self.last_frame.elapsed() >= STALL => {
                tracing::warn!(service = %self.service, seconds = STALL.as_secs(), "no frame through this channel for a while: connecting again");
                self.drop_channel();
                Ok(None)
            }
            Ok(Some(frame)) => {
                self.last_frame = Instant::now();
                Ok(Some(frame))
            }
            other => other,
        }
    }

    fn drop_channel(&mut self) {
        self.client = None;
        self.next_connect = Instant::now() + RECONNECT;
    }

    /// How many times the channel was connected again.
    pub fn reconnects(&self) -> u64 {
        self.reconnects
    }

    fn try_connect(&mut self) {
        if Instant::now() < self.next_connect {
            return;
        }
        match Client::connect(&self.service) {
            Ok(client) => {
                tracing::warn!(service = %self.service, "connected again");
                self.client = Some(client);
                self.last_frame = Instant::now();
                self.reconnects += 1;
            }
            Err(e) => {
                tracing::debug!(error = %e, "not connected yet");
                self.next_connect = Instant::now() + RECONNECT;
            }
        }
    }
}
