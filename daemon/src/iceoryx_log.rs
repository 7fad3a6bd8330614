//! iceoryx2's own log, forwarded into the daemon's (tracing, target `iceoryx2`).
//!
//! iceoryx2 reports some failures only in its log: a client whose connection cannot be
//! established ("Unable to establish connection to new receiver" — a client of another user,
//! a full root directory) is a warning there and nothing else. Its default logger writes to
//! stderr on its own, with the complete `Debug` dump of the port as the message's origin (one
//! warning was 6 KB), and the daemon kept it at errors only. Forwarded, its warnings reach the
//! journal with the daemon's own lines, filtered by the same `[runtime] log` / `RUST_LOG`.

use iceoryx2_log::{Log, LogLevel};

/// The level iceoryx2 logs at unless `IOX2_LOG_LEVEL` says otherwise.
pub const DEFAULT_LEVEL: LogLevel = LogLevel::Warn;

/// Longest origin kept: the type name and the start of its fields, not the whole dump.
const ORIGIN_CHARS: usize = 80;

/// Forwards each iceoryx2 record to `tracing` under the target `iceoryx2`.
pub struct TracingLog;

impl Log for TracingLog {
    fn log(&self, level: LogLevel, origin: core::fmt::Arguments, message: core::fmt::Arguments) {
        let origin = short_origin(&origin.to_string());
        match level {
            LogLevel::Trace => tracing::trace!(target: "iceoryx2", origin, "{message}"),
            LogLevel::Debug => tracing::debug!(target: "iceoryx2", origin, "{message}"),
            LogLevel::Info => tracing::info!(target: "iceoryx2", origin, "{message}"),
            LogLevel::Warn => tracing::warn!(target: "iceoryx2", origin, "{message}"),
            LogLevel::Error | LogLevel::Fatal => {
                tracing::error!(target: "iceoryx2", origin, "{message}")
            }
        }
    }
}

/// The origin up to the first `{` or `(` (the type name), at most [`ORIGIN_CHARS`].
fn short_origin(origin: &str) -> String {
    let head = origin
        .split(['{', '('])
        .next()
        .unwrap_or_default()
        .trim()
        .trim_matches('"');
    head.chars().take(ORIGIN_CHARS).collect()
}

/// Installs [`TracingLog`] as iceoryx2's logger at [`DEFAULT_LEVEL`] (or `IOX2_LOG_LEVEL`).
///
/// iceoryx2's global configuration is loaded first, with its log at errors: the daemon ships no
/// iceoryx2 config file on purpose (`dear_proto::transport` sets what it needs), and the
/// warning that one was not found would otherwise open every start.
pub fn install() {
    iceoryx2_log::set_log_level(LogLevel::Error);
    let _ = iceoryx2::config::Config::global_config();
    // `false` only when a logger was installed before (a second call): keep that one.
    let _ = iceoryx2_log::set_logger(&TracingLog);
    iceoryx2::prelude::set_log_level_from_env_or(DEFAULT_LEVEL);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_origin_is_cut_to_its_type_name() {
        let dump = format!("Receiver {{ connections: {} }}", "x".repeat(6000));
        assert_eq!(short_origin(&dump), "Receiver");
        assert_eq!(
            short_origin("Config::global_config()"),
            "Config::global_config"
        );
        assert_eq!(short_origin(&"a".repeat(500)).len(), ORIGIN_CHARS);
    }
}
