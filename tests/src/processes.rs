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
    pub fn start(service: &str, args: &[&str], log: &Path) -> Daemon {
        let log_file = File::create(log).expect("daemon log file");
        let child = Command::new(binary("deard"))
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

/// One frame as a probe saw it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Seen {
    pub frame_id: u64,
    pub skipped: u64,
    pub dropped: u64,
    pub sha256: String,
    /// `FrameHeader::flags`.
    pub flags: u32,
    /// The model bundle named in the header, `-` for none.
    pub bundle: String,
}

impl Probe {
    /// Starts a probe expecting `count` frames and waits until it has subscribed.
    pub fn start(service: &str, count: usize) -> Probe {
        let mut child = Command::new(binary("dear-probe"))
            .args([
                "--service",
                service,
                "--count",
                &count.to_string(),
                "--timeout-s",
                "60",
            ])
            .stdout(Stdio::piped())
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

    /// The next frame line, waiting up to `timeout`.
    pub fn next(&self, timeout: Duration) -> Option<Seen> {
        let line = self.lines.recv_timeout(timeout).ok()?;
        let parts: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(parts.len(), 7, "bad probe line {line:?}");
        assert_eq!(parts[0], "frame");
        Some(Seen {
            frame_id: parts[1].parse().unwrap(),
            skipped: parts[2].parse().unwrap(),
            dropped: parts[3].parse().unwrap(),
            sha256: parts[4].to_string(),
            flags: u32::from_str_radix(parts[5], 16).unwrap(),
            bundle: parts[6].to_string(),
        })
    }

    /// Collects `n` frames, failing the test if they do not all come within `timeout` each.
    pub fn take(&self, n: usize, timeout: Duration) -> Vec<Seen> {
        (0..n)
            .map(|i| {
                self.next(timeout)
                    .unwrap_or_else(|| panic!("probe got only {i} of {n} frames"))
            })
            .collect()
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
