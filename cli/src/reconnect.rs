//! `watch`, `record` and `dump` keep going across a damaged channel and a restarted daemon
//! through the SDK's [`dear_client::ReconnectingClient`]; this wrapper logs what happened to
//! the channel as warnings.

use std::time::Duration;

use dear_client::{ChannelEvent, ConnectError, Frame, ReceiveError};

/// A [`dear_client::ReconnectingClient`] whose channel events are logged.
pub struct ReconnectingClient(dear_client::ReconnectingClient);

impl ReconnectingClient {
    /// As [`dear_client::ReconnectingClient::connect`].
    ///
    /// # Errors
    /// As [`dear_client::Client::connect`].
    pub fn connect(service: &str) -> Result<Self, ConnectError> {
        dear_client::ReconnectingClient::connect(service).map(ReconnectingClient)
    }

    /// As [`dear_client::ReconnectingClient::wait`], logging the channel's events.
    ///
    /// # Errors
    /// As [`dear_client::ReconnectingClient::wait`].
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<Frame>, ReceiveError> {
        let got = self.0.wait(timeout);
        for event in self.0.take_events() {
            match event {
                ChannelEvent::Lost { reason } => {
                    tracing::warn!(error = %reason, "connecting again");
                }
                ChannelEvent::Connected => {
                    tracing::warn!(service = %self.0.service(), "connected again");
                }
            }
        }
        got
    }

    /// How many times the channel was connected again.
    pub fn reconnects(&self) -> u64 {
        self.0.reconnects()
    }
}
