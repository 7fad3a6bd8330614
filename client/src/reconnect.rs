//! A client that keeps its stream across a restarted daemon and a damaged channel: what an
//! application that runs for days wants instead of handling [`ReceiveError::Corrupted`] and
//! silent channels itself (issue 34; `dear watch`, `record` and `dump` use it).
//!
//! A [`Client`]'s channel can end for reasons that are not the application's:
//! - another process of the service's group wrote into this client's shared records: the SDK
//!   says so once ([`ReceiveError::Corrupted`]) and nothing more arrives through that channel
//!   (deard makes a damaged service again within about two seconds);
//! - some writes break a channel silently (a connection overwritten whole, every byte `0xff`,
//!   looks like an empty queue and the daemon's end gives up on it), and a daemon that was
//!   restarted (systemd after a crash, an upgrade) serves a new service the old channel does
//!   not reach: nothing arrives and nothing is reported.
//!
//! [`ReconnectingClient`] drops a corrupted channel, and one that delivered nothing for its
//! stall time ([`DEFAULT_STALL`]), and connects again every [`RECONNECT_INTERVAL`] until it
//! can; meanwhile its waits return `Ok(None)` after their timeout, as on an idle stream. On a
//! healthy but idle service that costs a reconnection every stall time and loses nothing. What
//! happened is kept as [`ChannelEvent`]s for the application to log ([`ReconnectingClient::take_events`]).

use std::time::{Duration, Instant};

use crate::frame::Frame;
use crate::subscriber::{Client, ConnectError, ReceiveError};

/// How often a lost channel is connected again.
pub const RECONNECT_INTERVAL: Duration = Duration::from_millis(500);
/// How long a channel may deliver nothing before it is connected again, by default (see the
/// module docs): ten frame periods of a 3 fps stream.
pub const DEFAULT_STALL: Duration = Duration::from_secs(3);
/// Events kept until [`ReconnectingClient::take_events`] (the oldest are dropped beyond it).
const MAX_EVENTS: usize = 64;

/// What happened to a [`ReconnectingClient`]'s channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ChannelEvent {
    /// The channel was dropped; it is connected again every [`RECONNECT_INTERVAL`].
    Lost {
        /// Why: the corruption report, or how long nothing arrived.
        reason: String,
    },
    /// A new channel to the service.
    Connected,
}

/// A [`Client`] that connects again after its channel was corrupted or stalled (see the
/// module docs).
pub struct ReconnectingClient {
    service: String,
    /// `None` while the channel is being made again.
    client: Option<Client>,
    stall: Duration,
    next_connect: Instant,
    /// When the channel last delivered a frame, or was connected.
    last_frame: Instant,
    reconnects: u64,
    events: Vec<ChannelEvent>,
}

impl ReconnectingClient {
    /// Connects to `service`; a first connection that fails is the caller's error, as with
    /// [`Client::connect`] (a daemon that is not running yet is not a failure: frames arrive
    /// once it publishes).
    ///
    /// # Errors
    /// As [`Client::connect`].
    pub fn connect(service: &str) -> Result<Self, ConnectError> {
        Ok(ReconnectingClient {
            service: service.to_string(),
            client: Some(Client::connect(service)?),
            stall: DEFAULT_STALL,
            next_connect: Instant::now(),
            last_frame: Instant::now(),
            reconnects: 0,
            events: Vec::new(),
        })
    }

    /// Sets how long the channel may deliver nothing before it is connected again: longer
    /// than the stream's slowest frame interval (default [`DEFAULT_STALL`]).
    pub fn set_stall_timeout(&mut self, stall: Duration) {
        self.stall = stall;
    }

    /// The service's name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// As [`Client::wait`]; a corrupted channel, or one that delivered nothing for the stall
    /// time, is dropped (a [`ChannelEvent::Lost`]; this returns `Ok(None)` at once) and
    /// connected again every [`RECONNECT_INTERVAL`]; meanwhile waits last `timeout` and return
    /// `Ok(None)`, unless a new channel delivers a frame first.
    ///
    /// # Errors
    /// Every error of [`Client::wait`] but [`ReceiveError::Corrupted`].
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<Frame>, ReceiveError> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.client.is_none() {
                self.try_connect();
            }
            let now = Instant::now();
            let left = deadline.saturating_duration_since(now);
            let Some(client) = self.client.as_ref() else {
                if left.is_zero() {
                    return Ok(None);
                }
                let retry = self.next_connect.saturating_duration_since(now);
                std::thread::sleep(left.min(retry.max(Duration::from_millis(1))));
                continue;
            };
            return match client.wait(left) {
                Err(e @ ReceiveError::Corrupted { .. }) => {
                    self.drop_channel(e.to_string());
                    Ok(None)
                }
                Ok(None) if self.last_frame.elapsed() >= self.stall => {
                    let reason = format!(
                        "no frame from {:?} for {:.1} s",
                        self.service,
                        self.last_frame.elapsed().as_secs_f64()
                    );
                    self.drop_channel(reason);
                    Ok(None)
                }
                Ok(Some(frame)) => {
                    self.last_frame = Instant::now();
                    Ok(Some(frame))
                }
                other => other,
            };
        }
    }

    /// Whether a channel is open now (`false` between a loss and the next connection).
    pub fn is_connected(&self) -> bool {
        self.client.is_some()
    }

    /// How many times the channel was connected again.
    pub fn reconnects(&self) -> u64 {
        self.reconnects
    }

    /// The events since the last call, oldest first (at most the last 64).
    pub fn take_events(&mut self) -> Vec<ChannelEvent> {
        std::mem::take(&mut self.events)
    }

    fn event(&mut self, event: ChannelEvent) {
        if self.events.len() == MAX_EVENTS {
            self.events.remove(0);
        }
        self.events.push(event);
    }

    fn drop_channel(&mut self, reason: String) {
        self.client = None;
        // Not at once: deard takes a second or two to make a damaged service again.
        self.next_connect = Instant::now() + RECONNECT_INTERVAL;
        self.event(ChannelEvent::Lost { reason });
    }

    fn try_connect(&mut self) {
        if Instant::now() < self.next_connect {
            return;
        }
        match Client::connect(&self.service) {
            Ok(client) => {
                self.client = Some(client);
                self.last_frame = Instant::now();
                self.reconnects += 1;
                self.event(ChannelEvent::Connected);
            }
            Err(_) => self.next_connect = Instant::now() + RECONNECT_INTERVAL,
        }
    }
}
