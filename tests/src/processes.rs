//! Starting and stopping the real binaries (`deard`, `dear-probe`) and reading their output.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::Duration;

/// The directory holding the workspace's binaries (`target/<profile>`), found from the running
/// test executable (`target/<profile>/deps/<test>`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("current exe");
    let deps = exe.parent().expect("deps dir");
    deps.parent().expect("profile dir").to_path_buf()
}

/// Path of a workspace binary; panics with instructions if it was not built.
pub fn binary(name: &str) -> PathBuf {
    let path = bin_dir().join(name);
    assert!(
        path.is_file(),
        "{} not found: build the workspace binaries first (`cargo test --workspace` or `cargo build --workspace`)",
        path.display()
    );
    path
}

/// A unique service name per test and process, so tests can run in parallel.
pub fn unique_service(test: &str) -> String {
    format!("dear-test/{}/{test}/frames", std::process::id())
}

/// A running `deard`; killed (SIGKILL) on drop if still running.
pub struct Daemon {
    pub child: Child,
    pub log: PathBuf,
}

impl Daemon {
    /// Starts `deard --service <service> <args...>` with its log in `log`.
    pub fn start<S: AsRef<std::ffi::OsStr>>(service: &str, args: &[S], log: &Path) -> Daemon {
        Daemon::start_in(None, service, args, log)
    }

    /// [`Daemon::start`] with `DEAR_IOX2_ROOT` set to `root` (when given).
    pub fn start_in<S: AsRef<std::ffi::OsStr>>(
        root: Option<&Path>,
        service: &str,
        args: &[S],
        log: &Path,
    ) -> Daemon {
        let log_file = File::create(log).expect("daemon log file");
        let mut command = Command::new(binary("deard"));
        if let Some(root) = root {
            command.env(dear_proto::IOX2_ROOT_ENV, root);
        }
        let child = command
            .args(["--service", service, "--stats-interval", "1"])
            .args(args)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(log_file)
            .spawn()
            .expect("spawn deard");
        Daemon {
            child,
            log: log.to_path_buf(),
        }
    }

    /// Sends SIGTERM and waits for the exit status (up to `timeout`).
    pub fn terminate(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        signal(&self.child, libc::SIGTERM);
        wait_timeout(&mut self.child, timeout)
    }

    /// Kills with SIGKILL, as a crash would.
    pub fn crash(&mut self) {
        signal(&self.child, libc::SIGKILL);
        let _ = self.child.wait();
    }

    /// Whether the process is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// The daemon's log so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The first log line containing `needle`, waiting up to `timeout` for it to be written.
    pub fn wait_for_log_line(&self, needle: &str, timeout: Duration) -> Option<String> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if let Some(line) = self.log_text().lines().find(|l| l.contains(needle)) {
                return Some(line.to_string());
            }
            if std::time::Instant::now() >= deadline {
                return None;
            }
            thread::sleep(Duration::from_millis(20));
        }
    }

    /// The counters of the replay, from the `source finished` line `deard` logs when a
    /// non-looping replay has been published (it keeps serving afterwards), waiting up to
    /// `timeout`. Panics with the log if the line does not come.
    pub fn wait_source_finished(&self, timeout: Duration) -> Counts {
        let line = self
            .wait_for_log_line("source finished", timeout)
            .unwrap_or_else(|| panic!("deard did not finish its replay:\n{}", self.log_text()));
        Counts::parse(&line).unwrap_or_else(|| panic!("no counters in {line:?}"))
    }

    /// The final counters, from the `stopped` line `deard` logs as it exits (call after
    /// [`Daemon::terminate`]). Panics with the log if there is none.
    pub fn final_counts(&self) -> Counts {
        let log = self.log_text();
        log.lines()
            .rev()
            .find(|l| l.contains("stopped published="))
            .and_then(Counts::parse)
            .unwrap_or_else(|| panic!("no final statistics in the deard log:\n{log}"))
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.is_running() {
            self.crash();
        }
    }
}

/// A running `dear-probe` whose lines arrive on a channel.
pub struct Probe {
    pub child: Child,
    lines: mpsc::Receiver<String>,
}

/// One frame as a probe saw it (one line of `dear-probe`'s output).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Seen {
    pub frame_id: u64,
    /// `FrameHeader::run_id`: the publisher instance that sent the frame.
    pub run_id: u64,
    /// `FrameHeader::sequence`: samples that publisher instance sent before this one.
    pub sequence: u64,
    pub skipped: u64,
    pub dropped: u64,
    pub sha256: String,
    /// `FrameHeader::flags`.
    pub flags: u32,
    /// The model bundle named in the header, `-` for none.
    pub bundle: String,
}

impl Probe {
    /// Starts a probe expecting `count` frames and waits until it has subscribed. The probe
    /// exits after `count` frames or 300 s, or is killed when dropped.
    pub fn start(service: &str, count: usize) -> Probe {
        Probe::start_with_delay(service, count, Duration::ZERO)
    }

    /// [`Probe::start`] for a slow client: the probe sleeps `delay` after each frame.
    pub fn start_with_delay(service: &str, count: usize, delay: Duration) -> Probe {
        let mut child = Probe::command(service, count, delay)
            .spawn()
            .expect("spawn dear-probe");
        let lines = reader_thread(child.stdout.take().expect("probe stdout"));
        let probe = Probe { child, lines };
        let first = probe
            .lines
            .recv_timeout(Duration::from_secs(30))
            .expect("probe did not start");
        assert_eq!(first, "ready");
        probe
    }

    /// The command that starts a probe (stdout piped), for a test to add to: the root
    /// (`DEAR_IOX2_ROOT`), another user.
    pub fn command(service: &str, count: usize, delay: Duration) -> Command {
        let mut command = Command::new(binary("dear-probe"));
        command
            .args([
                "--service",
                service,
                "--count",
                &count.to_string(),
                "--timeout-s",
                "300",
                "--delay-ms",
                &delay.as_millis().to_string(),
            ])
            .stdout(Stdio::piped());
        command
    }

    /// Starts the probe `command` made ([`Probe::command`]) and waits until it has subscribed;
    /// panics with its standard error if it does not.
    pub fn spawn(mut command: Command) -> Probe {
        let mut child = command
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn dear-probe");
        let lines = reader_thread(child.stdout.take().expect("probe stdout"));
        let mut probe = Probe { child, lines };
        if let Ok(first) = probe.lines.recv_timeout(Duration::from_secs(30)) {
            assert_eq!(first, "ready");
            return probe;
        }
        let _ = probe.child.kill();
        let mut err = String::new();
        if let Some(mut stderr) = probe.child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut stderr, &mut err);
        }
        panic!("probe did not start: {err}");
    }

    /// The next frame line, waiting up to `timeout`.
    pub fn next(&self, timeout: Duration) -> Option<Seen> {
        let line = self.lines.recv_timeout(timeout).ok()?;
        Some(parse_frame_line(&line))
    }

    /// Collects frames until `done` holds for the frames so far (checked after each frame) or
    /// no frame arrives for `quiet`, and returns them. For streams that may lose frames: the
    /// frame service overwrites a slow subscriber's oldest samples, so a test cannot wait for a
    /// number of frames; it waits for the frame that ends the stream (the newest sample is
    /// never overwritten, so the publisher's last one always arrives) and then checks what came
    /// against what the publisher says it sent. `quiet` only ends a stream that is broken.
    pub fn collect_until(
        &self,
        mut done: impl FnMut(&[Seen]) -> bool,
        quiet: Duration,
    ) -> Vec<Seen> {
        let mut seen = Vec::new();
        while let Some(s) = self.next(quiet) {
            seen.push(s);
            if done(&seen) {
                break;
            }
        }
        seen
    }

    /// Kills the probe with SIGKILL (a client crash).
    pub fn crash(&mut self) {
        signal(&self.child, libc::SIGKILL);
        let _ = self.child.wait();
    }

    /// Waits for the probe to exit and returns whether it succeeded.
    pub fn finish(&mut self, timeout: Duration) -> bool {
        wait_timeout(&mut self.child, timeout)
            .map(|s| s.success())
            .unwrap_or(false)
    }
}

impl Drop for Probe {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            self.crash();
        }
    }
}

/// Parses one frame line of `dear-probe` (format in its doc comment); panics on anything else.
pub fn parse_frame_line(line: &str) -> Seen {
    let parts: Vec<&str> = line.split_whitespace().collect();
    assert!(
        parts.len() == 9 && parts[0] == "frame",
        "bad probe line {line:?}"
    );
    let number = |i: usize| -> u64 {
        parts[i]
            .parse()
            .unwrap_or_else(|e| panic!("field {i} of probe line {line:?}: {e}"))
    };
    Seen {
        frame_id: number(1),
        run_id: u64::from_str_radix(parts[2], 16)
            .unwrap_or_else(|e| panic!("run id of probe line {line:?}: {e}")),
        sequence: number(3),
        skipped: number(4),
        dropped: number(5),
        sha256: parts[6].to_string(),
        flags: u32::from_str_radix(parts[7], 16)
            .unwrap_or_else(|e| panic!("flags of probe line {line:?}: {e}")),
        bundle: parts[8].to_string(),
    }
}

/// The frames of `seen` split where the `run_id` changes: one slice per stretch of frames from
/// one publisher instance, in the order received.
pub fn split_runs(seen: &[Seen]) -> Vec<&[Seen]> {
    seen.chunk_by(|a, b| a.run_id == b.run_id).collect()
}

/// Samples of one run a client lost, from the sequence numbers it received: those before the
/// first received (a run starts at 0) and in every gap. With the frames received this
/// accounts for every sample up to the last received one (`received + lost = last + 1`).
/// Panics unless `frames` is one run with strictly increasing sequence numbers.
pub fn lost_by_sequence(frames: &[Seen]) -> u64 {
    let Some(first) = frames.first() else {
        return 0;
    };
    let mut lost = first.sequence;
    for pair in frames.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        assert_eq!(a.run_id, b.run_id, "one run at a time");
        assert!(
            b.sequence > a.sequence,
            "sequence {} after {} in run {:016x}: reordered or duplicated",
            b.sequence,
            a.sequence,
            a.run_id
        );
        lost += b.sequence - a.sequence - 1;
    }
    lost
}

/// Counters from a `deard` statistics line (`published=… skipped=… dropped=…`, as `deard` logs
/// them when stderr is not a terminal).
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

fn reader_thread(stdout: ChildStdout) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            match line {
                Ok(line) => {
                    if tx.send(line).is_err() {
                        break;
                    }
                }
                Err(_) => break,
            }
        }
    });
    rx
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: sending a signal to our own child's pid has no memory-safety implications.
    unsafe {
        libc::kill(child.id() as i32, sig);
    }
}

fn wait_timeout(child: &mut Child, timeout: Duration) -> Option<std::process::ExitStatus> {
    let deadline = std::time::Instant::now() + timeout;
    loop {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        if std::time::Instant::now() >= deadline {
            return None;
        }
        thread::sleep(Duration::from_millis(20));
    }
}
