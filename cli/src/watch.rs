//! `dear watch`: one line of live statistics per second (see [`super::stats`]).

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use dear_client::ReceiveError;

use super::reconnect::ReconnectingClient;
use super::stats::Window;
use super::StopFlag;

/// How long one wait for a frame may block: bounds the reaction time to Ctrl-C and the
/// lateness of a line when no frames arrive.
const POLL: Duration = Duration::from_millis(100);

#[derive(Debug, Args)]
pub struct WatchArgs {
    /// Frame service to watch.
    #[arg(long, default_value_t = super::default_service(), value_parser = super::parse_service)]
    pub service: String,
    /// Print each second as one JSON object per line instead of text.
    #[arg(long)]
    pub json: bool,
    /// Stop after this many lines (default: until Ctrl-C).
    #[arg(long, value_name = "N")]
    pub count_seconds: Option<u64>,
}

pub fn run(args: &WatchArgs) -> anyhow::Result<()> {
    let stop = StopFlag::install()?;
    // A channel another process corrupts is connected again (issue 34): the lines go on,
    // with no frames meanwhile.
    let mut client = ReconnectingClient::connect(&args.service)?;
    let mut out = std::io::stdout().lock();
    let mut window = Window::default();
    let mut lines = 0u64;
    let mut window_start = Instant::now();
    let mut next_line = window_start + Duration::from_secs(1);
    while !stop.is_set() && args.count_seconds.is_none_or(|n| lines < n) {
        let wait = next_line
            .saturating_duration_since(Instant::now())
            .min(POLL);
        match client.wait(wait) {
            Ok(Some(frame)) => {
                let received = dear_proto::time::monotonic_ns();
                window.push(frame.header(), received);
            }
            Ok(None) => {}
            Err(ReceiveError::BadFrame { source, .. }) => {
                tracing::debug!(error = %source, "frame rejected");
                window.reject();
            }
            // Another user's publisher on the service: its frames are refused and counted.
            Err(e @ ReceiveError::UntrustedPublisher { .. }) => {
                super::warn_untrusted_once(&e);
                window.reject();
            }
            // Ctrl-C interrupts the wait; that is a stop, not a failure.
            Err(_) if stop.is_set() => break,
            Err(e) => return Err(e.into()),
        }
        let now = Instant::now();
        if now >= next_line {
            let report = window.report(now - window_start);
            let line = if args.json {
                serde_json::to_string(&report).context("cannot encode the statistics as JSON")?
            } else {
                report.to_string()
            };
            // A closed pipe (`dear watch | head`) ends the command quietly.
            if writeln!(out, "{line}").and_then(|()| out.flush()).is_err() {
                return Ok(());
            }
            lines += 1;
            window_start = now;
            // Keep a steady cadence, but never try to catch up with missed seconds.
            next_line = (next_line + Duration::from_secs(1)).max(now + Duration::from_millis(500));
        }
    }
    Ok(())
}
