//! `dear watch`: one line of live statistics per second (see [`super::stats`]).

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use dear_client::{Client, ReceiveError};

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

/// How often a client whose channel was corrupted tries to connect again (the daemon makes a
/// damaged service again within about two seconds).
const RECONNECT: Duration = Duration::from_millis(500);

pub fn run(args: &WatchArgs) -> anyhow::Result<()> {
    let stop = StopFlag::install()?;
    // `None` while the channel is being made again after a corruption (issue 34): a watch
    // keeps its lines coming (frames 0 meanwhile) instead of exiting.
    let mut client = Some(Client::connect(&args.service)?);
    let mut next_connect = Instant::now();
    let mut out = std::io::stdout().lock();
    let mut window = Window::default();
    let mut lines = 0u64;
    let mut window_start = Instant::now();
    let mut next_line = window_start + Duration::from_secs(1);
    while !stop.is_set() && args.count_seconds.is_none_or(|n| lines < n) {
        let wait = next_line
            .saturating_duration_since(Instant::now())
            .min(POLL);
        let Some(connected) = client.as_ref() else {
            std::thread::sleep(wait);
            if Instant::now() >= next_connect {
                match Client::connect(&args.service) {
                    Ok(c) => {
                        tracing::warn!(service = %args.service, "connected again");
                        client = Some(c);
                    }
                    Err(e) => {
                        tracing::debug!(error = %e, "not connected yet");
                        next_connect = Instant::now() + RECONNECT;
                    }
                }
            }
            if !write_line_if_due(
                args,
                &mut out,
                &mut window,
                &mut window_start,
                &mut next_line,
                &mut lines,
            )? {
                return Ok(());
            }
            continue;
        };
        match connected.wait(wait) {
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
            // Another process wrote into this client's shared records: this channel is
            // lost, the service is not. Connect again and go on counting.
            Err(e @ ReceiveError::Corrupted { .. }) => {
                tracing::warn!(error = %e, "connecting again");
                client = None;
                next_connect = Instant::now() + RECONNECT;
            }
            Err(e) => return Err(e.into()),
        }
        if !write_line_if_due(
            args,
            &mut out,
            &mut window,
            &mut window_start,
            &mut next_line,
            &mut lines,
        )? {
            return Ok(());
        }
    }
    Ok(())
}

/// Writes the window's line when its second is over, and counts it in `lines`. `Ok(false)`
/// when stdout is closed (`dear watch | head`), which ends the command quietly; `Err` only when
/// the report cannot be encoded.
fn write_line_if_due(
    args: &WatchArgs,
    out: &mut impl Write,
    window: &mut Window,
    window_start: &mut Instant,
    next_line: &mut Instant,
    lines: &mut u64,
) -> anyhow::Result<bool> {
    let now = Instant::now();
    if now < *next_line {
        return Ok(true);
    }
    let report = window.report(now - *window_start);
    let line = if args.json {
        serde_json::to_string(&report).context("cannot encode the statistics as JSON")?
    } else {
        report.to_string()
    };
    if writeln!(out, "{line}").and_then(|()| out.flush()).is_err() {
        return Ok(false);
    }
    *lines += 1;
    *window_start = now;
    // Keep a steady cadence, but never try to catch up with missed seconds.
    *next_line = (*next_line + Duration::from_secs(1)).max(now + Duration::from_millis(500));
    Ok(true)
}
