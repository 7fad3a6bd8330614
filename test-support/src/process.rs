//! Child processes of a test: names that do not collide, signals, waiting for an exit, reading
//! output line by line.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, ExitStatus, Output};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

/// How often the waits here look again.
pub const POLL: Duration = Duration::from_millis(20);

/// A service name per test and test process (`dear-test/<pid>/<test>/frames`), so tests and
/// concurrent test runs never share a service.
pub fn unique_service(test: &str) -> String {
    format!("dear-test/{}/{test}/frames", std::process::id())
}

/// Sends signal `sig` (`libc::SIGTERM`, `libc::SIGKILL`, `libc::SIGSTOP`, …) to `child`;
/// panics if it cannot be sent (the child was already reaped).
#[track_caller]
pub fn signal(child: &Child, sig: i32) {
    let pid = i32::try_from(child.id()).expect("a pid fits in pid_t");
    // SAFETY: kill(2) takes plain integers and touches no memory of this process; the pid is
    // our own child's.
    let sent = unsafe { libc::kill(pid, sig) };
    assert_eq!(
        sent,
        0,
        "kill({pid}, {sig}): {}",
        std::io::Error::last_os_error()
    );
}

/// The exit status of `child`, waiting up to `timeout` for it; `None` if it still runs.
pub fn wait_exit(child: &mut Child, timeout: Duration) -> Option<ExitStatus> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        if Instant::now() >= deadline {
            return None;
        }
        thread::sleep(POLL);
    }
}

/// Waits up to `timeout` for `child` (spawned with piped stdout and stderr) to exit and returns
/// its output; if it still runs then, kills it and panics naming `what` with its standard
/// error. `between` runs at each look (a test publisher sending its next frame, say).
#[track_caller]
pub fn output_within(
    mut child: Child,
    what: &str,
    timeout: Duration,
    mut between: impl FnMut(),
) -> Output {
    let deadline = Instant::now() + timeout;
    while child.try_wait().expect("try_wait").is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let out = child.wait_with_output().expect("the killed child's output");
            panic!(
                "{what} still running after {timeout:?}; stderr: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        between();
        thread::sleep(POLL);
    }
    child.wait_with_output().expect("the child's output")
}

/// The lines of `stream` (a child's piped stdout) as they come, read by a thread of their own;
/// the channel closes at the end of the stream.
pub fn lines(stream: impl Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        for line in BufReader::new(stream).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// Polls `done` until it holds; panics naming `what` (with `context()`, a log say) after
/// `timeout`.
#[track_caller]
pub fn wait_until(
    what: &str,
    timeout: Duration,
    mut done: impl FnMut() -> bool,
    context: impl Fn() -> String,
) {
    let deadline = Instant::now() + timeout;
    while !done() {
        assert!(
            Instant::now() < deadline,
            "waited {timeout:?} for {what}, in vain:\n{}",
            context()
        );
        thread::sleep(POLL);
    }
}
