//! Starting the real binaries of the end-to-end tests (`deard`, `dear-probe`) and reading the
//! probe's output. The daemon handle, its log waits and counters are the workspace's
//! ([`dear_test_support::daemon`]).

use std::ffi::OsStr;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use dear_test_support::paths::binary;
use dear_test_support::process::{lines, signal, wait_exit};

/// The command line of the workspace's `deard` serving `service` with a statistics line every
/// second and `args` after that, for [`dear_test_support::daemon::Daemon::spawn`].
pub fn deard<S: AsRef<OsStr>>(service: &str, args: &[S]) -> Command {
    let mut command = Command::new(binary("deard"));
    command
        .args(["--service", service, "--stats-interval", "1"])
        .args(args);
    command
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
        let lines = lines(child.stdout.take().expect("probe stdout"));
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
        let lines = lines(child.stdout.take().expect("probe stdout"));
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
        wait_exit(&mut self.child, timeout)
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
