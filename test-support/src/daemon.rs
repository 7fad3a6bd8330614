//! A running `deard`: its log in a file, waits on its log lines and on the counters of its
//! statistics lines, stopping it as systemd or a crash would.

use std::ffi::OsStr;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use crate::process::{self, POLL};

/// A running `deard` whose standard error (its log) goes to a file; killed with SIGKILL on drop
/// if a test left it running.
pub struct Daemon {
    pub child: Child,
    /// The log file.
    pub log: PathBuf,
    /// The directory holding `log` when the daemon made it ([`Daemon::spawn_logging_to_temp`]).
    _log_dir: Option<tempfile::TempDir>,
}

impl Daemon {
    /// Spawns `command` (a `deard` command line the test built: binary, service, source) with
    /// its standard error written to `log`, standard output discarded, and `RUST_LOG=info`
    /// unless the command sets `RUST_LOG` itself.
    pub fn spawn(mut command: Command, log: &Path) -> Daemon {
        let log_file = File::create(log)
            .unwrap_or_else(|e| panic!("cannot create the log {}: {e}", log.display()));
        if !command
            .get_envs()
            .any(|(key, _)| key == OsStr::new("RUST_LOG"))
        {
            command.env("RUST_LOG", "info");
        }
        let child = command
            .stdout(Stdio::null())
            .stderr(log_file)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot spawn {:?}: {e}", command.get_program()));
        Daemon {
            child,
            log: log.to_path_buf(),
            _log_dir: None,
        }
    }

    /// [`Daemon::spawn`] with the log in a temporary directory of its own, removed with the
    /// daemon.
    pub fn spawn_logging_to_temp(command: Command) -> Daemon {
        let dir = tempfile::tempdir().expect("a temporary directory for the log");
        let mut daemon = Daemon::spawn(command, &dir.path().join("deard.log"));
        daemon._log_dir = Some(dir);
        daemon
    }

    /// The log so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The first log line containing `needle`, waiting up to `timeout` for it; `None` if it
    /// does not come.
    pub fn wait_for_log_line(&self, needle: &str, timeout: Duration) -> Option<String> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(line) = self.log_text().lines().find(|l| l.contains(needle)) {
                return Some(line.to_string());
            }
            if Instant::now() >= deadline {
                return None;
            }
            thread::sleep(POLL);
        }
    }

    /// Waits until the log contains `needle` and returns the first line with it; panics with
    /// the log if the daemon exits first or `timeout` passes.
    #[track_caller]
    pub fn wait_for_log(&mut self, needle: &str, timeout: Duration) -> String {
        self.wait_for_logged(&format!("a line with {needle:?}"), timeout, |log| {
            log.lines().find(|l| l.contains(needle)).map(str::to_string)
        })
    }

    /// Waits for a log line whose counters ([`Counts`]: a statistics line, `source finished`,
    /// `stopped`) satisfy `reached`, and returns them; panics naming `what` with the log if the
    /// daemon exits first or `timeout` passes. For a statistics line within the wait, start
    /// the daemon with a short `--stats-interval`.
    #[track_caller]
    pub fn wait_for_counts(
        &mut self,
        what: &str,
        timeout: Duration,
        reached: impl Fn(&Counts) -> bool,
    ) -> Counts {
        self.wait_for_logged(&format!("counters that show {what}"), timeout, |log| {
            log.lines().filter_map(Counts::parse).find(|c| reached(c))
        })
    }

    /// Polls the log until `find` finds something in it, and returns that; panics naming
    /// `what` with the log if the daemon exits first (after one last look: it may have logged
    /// it as it exited) or `timeout` passes.
    #[track_caller]
    fn wait_for_logged<T>(
        &mut self,
        what: &str,
        timeout: Duration,
        find: impl Fn(&str) -> Option<T>,
    ) -> T {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(found) = find(&self.log_text()) {
                return found;
            }
            if let Ok(Some(status)) = self.child.try_wait() {
                if let Some(found) = find(&self.log_text()) {
                    return found;
                }
                panic!(
                    "deard exited ({status}) before logging {what}:\n{}",
                    self.log_text()
                );
            }
            assert!(
                Instant::now() < deadline,
                "deard did not log {what} within {timeout:?}:\n{}",
                self.log_text()
            );
            thread::sleep(POLL);
        }
    }

    /// The counters of the replay, from the `source finished` line `deard` logs when a
    /// non-looping replay has been published (it keeps serving afterwards), waiting up to
    /// `timeout`. Panics with the log if the line does not come.
    #[track_caller]
    pub fn wait_source_finished(&self, timeout: Duration) -> Counts {
        let line = self
            .wait_for_log_line("source finished", timeout)
            .unwrap_or_else(|| panic!("deard did not finish its replay:\n{}", self.log_text()));
        Counts::parse(&line).unwrap_or_else(|| panic!("no counters in {line:?}"))
    }

    /// The final counters, from the `stopped` line `deard` logs as it exits (call after
    /// [`Daemon::terminate`]). Panics with the log if there is none.
    #[track_caller]
    pub fn final_counts(&self) -> Counts {
        let log = self.log_text();
        log.lines()
            .rev()
            .find(|l| l.contains("stopped published="))
            .and_then(Counts::parse)
            .unwrap_or_else(|| panic!("no final statistics in the deard log:\n{log}"))
    }

    /// Sends signal `sig` (`libc::SIGTERM`, …).
    #[track_caller]
    pub fn signal(&self, sig: i32) {
        process::signal(&self.child, sig);
    }

    /// Sends SIGTERM (systemd's stop) and waits up to `timeout` for the exit status.
    pub fn terminate(&mut self, timeout: Duration) -> Option<ExitStatus> {
        self.signal(libc::SIGTERM);
        self.wait(timeout)
    }

    /// Kills with SIGKILL, as a crash would, and reaps it.
    pub fn crash(&mut self) {
        self.signal(libc::SIGKILL);
        let _ = self.child.wait();
    }

    /// The exit status, waiting up to `timeout` for it; `None` if it still runs.
    pub fn wait(&mut self, timeout: Duration) -> Option<ExitStatus> {
        process::wait_exit(&mut self.child, timeout)
    }

    /// Whether the process is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.is_running() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Counters from a `deard` log line (`published=… skipped=… dropped=…`, as `deard` logs them
/// when stderr is not a terminal): the statistics lines, `source finished` and `stopped`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    /// Samples sent (`FrameHeader::sequence` of the last one + 1 when no send failed).
    pub published: u64,
    /// Input frames refused as bad.
    pub skipped: u64,
    /// Input frames the capture queue dropped because processing fell behind.
    pub dropped: u64,
}

impl Counts {
    /// The counters of a log line, `None` if it lacks one of them.
    pub fn parse(line: &str) -> Option<Counts> {
        let field = |key: &str| -> Option<u64> {
            line.split_whitespace()
                .find_map(|word| word.strip_prefix(key)?.strip_prefix('='))?
                .parse()
                .ok()
        };
        Some(Counts {
            published: field("published")?,
            skipped: field("skipped")?,
            dropped: field("dropped")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::Counts;

    #[test]
    fn counts_are_read_from_a_statistics_line_and_not_from_other_lines() {
        let line = "2026-11-27T07:00:00Z  INFO deard::run: 30.0 fps published=12 skipped=3 dropped=0 network_rejected=0";
        assert_eq!(
            Counts::parse(line),
            Some(Counts {
                published: 12,
                skipped: 3,
                dropped: 0
            })
        );
        assert_eq!(Counts::parse("INFO deard::run: serving"), None);
        assert_eq!(Counts::parse("published=1 skipped=x dropped=0"), None);
    }
}
