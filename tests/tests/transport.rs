//! Issue 34: the transport's files under attack, by real processes on the real files of a
//! running `deard` (trust model: docs/security.md).
//!
//! Most tests need root, as CI has: they give the iceoryx2 root to a group and run clients
//! and attackers as `nobody` (uid 65534) in it, as a service's apps run in its group. Without
//! root they say so and check nothing.

use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use dear_e2e_tests::processes::{deard, Probe};
use dear_test_support::daemon::Daemon;
use dear_test_support::process::{unique_service, wait_until};
use dear_test_support::scene;

const W: u32 = 160;
const H: u32 = 120;
const WAIT: Duration = Duration::from_secs(30);
/// The group and user the tests' clients run as.
const NOBODY: u32 = 65534;

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

/// Whether this test can run `what` (clients, a publisher) as another user, which only root
/// can; when it cannot, it says so and the test returns without checking anything.
fn can_run_as_another_user(what: &str) -> bool {
    let root = is_root();
    if !root {
        eprintln!("not root: cannot run {what} as another user; not checked");
    }
    root
}

/// A capture to replay and an iceoryx2 root for one test, in a directory every user may enter.
struct Setup {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
    root: PathBuf,
    capture: PathBuf,
}

/// The service's group for the tests that also run without root: `nobody`'s under root (the
/// clients run as `nobody`), else this user's own.
fn clients_group() -> u32 {
    if is_root() {
        NOBODY
    } else {
        // SAFETY: getegid has no preconditions.
        unsafe { libc::getegid() }
    }
}

/// The root is `0770`, its group `group` (the service's group: its members are clients).
fn setup(group: u32) -> Setup {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_path_buf();
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
    let root = dir.join("root");
    std::fs::create_dir(&root).unwrap();
    std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o770)).unwrap();
    std::os::unix::fs::chown(&root, None, Some(group)).unwrap();
    let capture = scene::write_capture(&dir.join("cap"), 10, W, H, scene::factory_calibration());
    Setup {
        capture: capture.root().to_path_buf(),
        _tmp: tmp,
        dir,
        root,
    }
}

impl Setup {
    /// A looping replay, served until the test ends; its transport checks logged
    /// ([`transport_checked`]).
    fn daemon(&self, service: &str, log: &str) -> Daemon {
        let capture = self.capture.to_str().unwrap().to_string();
        let args = ["--refine", "none", "--loop", "--replay", &capture];
        let mut command = deard(service, &args);
        command
            .env(dear_proto::IOX2_ROOT_ENV, &self.root)
            .env("RUST_LOG", "info,deard::publish=debug");
        Daemon::spawn(command, &self.dir.join(log))
    }

    /// [`daemon`](Self::daemon), once it serves (its log shown if it does not).
    fn serving_daemon(&self, service: &str, log: &str) -> Daemon {
        let daemon = self.daemon(service, log);
        daemon
            .wait_for_log_line("serving", WAIT)
            .unwrap_or_else(|| panic!("deard did not serve:\n{}", daemon.log_text()));
        daemon
    }

    /// A client process of this user (the service's own), subscribed.
    fn own_probe(&self, service: &str) -> Probe {
        let mut command = Probe::command(service, 1_000_000, Duration::ZERO);
        command.env(dear_proto::IOX2_ROOT_ENV, &self.root);
        Probe::spawn(command)
    }

    /// A client process as `uid` (with that user's group only), subscribed.
    fn probe(&self, service: &str, uid: u32) -> Probe {
        let mut command = Probe::command(service, 1_000_000, Duration::ZERO);
        command
            .env(dear_proto::IOX2_ROOT_ENV, &self.root)
            .uid(uid)
            .gid(uid);
        Probe::spawn(command)
    }

    /// The files in the root whose names end with `suffix`.
    fn files(&self, suffix: &str) -> Vec<PathBuf> {
        std::fs::read_dir(&self.root)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.to_str().unwrap().ends_with(suffix))
            .collect()
    }
}

/// The run id (16 hex digits) the daemon logged for its publisher instance.
fn run_id_of(daemon: &Daemon) -> String {
    daemon
        .wait_for_log_line("publisher instance", WAIT)
        .unwrap_or_else(|| panic!("no publisher instance:\n{}", daemon.log_text()))
        .split("run_id=")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .to_string()
}

/// Runs `program args` as `nobody` and returns whether it succeeded, and its stderr.
fn as_nobody(program: &str, args: &[&str]) -> (bool, String) {
    let out = Command::new(program)
        .args(args)
        .uid(NOBODY)
        .gid(NOBODY)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Waits until `probe` has received `n` more frames; panics with the daemon's log if not.
fn receives(probe: &Probe, n: usize, daemon: &mut Daemon) {
    for k in 0..n {
        if probe.next(WAIT).is_none() {
            panic!(
                "the client received {k} of {n} frames (daemon running: {}):\n{}",
                daemon.is_running(),
                daemon.log_text()
            );
        }
    }
}

/// Defect 1 (the data segment): a member of the service's group wrote 152 random bytes into
/// the publisher's `*.data` file and the daemon died with a general protection fault;
/// `truncate -s0` killed it with SIGBUS. The segment is now written by the daemon only: the
/// writes are refused, and the member's own client goes on receiving frames (it maps the
/// segment read-only).
#[test]
fn a_client_cannot_write_or_truncate_the_frames() {
    if !can_run_as_another_user("clients") {
        return;
    }
    let s = setup(NOBODY);
    let service = unique_service("data-segment");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    let probe = s.probe(&service, NOBODY);
    receives(&probe, 5, &mut daemon);
    let data = s.files(".data");
    assert!(!data.is_empty(), "no data segment in {}", s.root.display());
    for file in &data {
        let path = file.to_str().unwrap();
        let (ok, err) = as_nobody(
            "dd",
            &[
                "if=/dev/urandom",
                &format!("of={path}"),
                "bs=152",
                "count=1",
                "seek=16",
                "oflag=seek_bytes",
                "conv=notrunc",
            ],
        );
        assert!(!ok && err.contains("Permission denied"), "dd: {err}");
        let (ok, err) = as_nobody("truncate", &["-s0", path]);
        assert!(!ok && err.contains("Permission denied"), "truncate: {err}");
        let mode = std::fs::metadata(file).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o644, "{path}");
    }
    receives(&probe, 20, &mut daemon);
    assert!(daemon.is_running(), "{}", daemon.log_text());
}

/// Defect 9: a user outside the service's group is told so, not `UnableToGenerateUniqueNodeId`
/// or `InsufficientPermissions` (the root `0770` is visible to it but cannot be entered).
#[test]
fn an_outsider_is_asked_whether_it_is_in_the_group() {
    if !can_run_as_another_user("a client") {
        return;
    }
    let s = setup(0);
    let service = unique_service("outsider");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    let mut command = Probe::command(&service, 1, Duration::ZERO);
    let out = command
        .env(dear_proto::IOX2_ROOT_ENV, &s.root)
        .uid(NOBODY)
        .gid(NOBODY)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("is this user in the service's group?")
            && err.contains(s.root.to_str().unwrap()),
        "{err}"
    );
    assert!(daemon.is_running());
}

/// Defect 2: with the daemon stopped, a member replaced `$ROOT/nodes` by a symbolic link, and
/// a root daemon then created a `0777` directory and `0666` files where it pointed. The daemon
/// now removes links from its root before it creates anything there, and says so.
#[test]
fn a_symbolic_link_in_the_root_is_removed_not_followed() {
    let s = setup(clients_group());
    let elsewhere = s.dir.join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    std::os::unix::fs::symlink(&elsewhere, s.root.join("nodes")).unwrap();
    let service = unique_service("symlink");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    let log = daemon.log_text();
    assert!(
        log.contains("removed a symbolic link from the iceoryx2 root") && log.contains("nodes"),
        "{log}"
    );
    assert_eq!(
        std::fs::read_dir(&elsewhere).unwrap().count(),
        0,
        "nothing created where the link pointed"
    );
    assert!(std::fs::symlink_metadata(s.root.join("nodes"))
        .unwrap()
        .is_dir());
    let probe = s.own_probe(&service);
    receives(&probe, 3, &mut daemon);

    // One swapped in while the daemon serves is removed within a second too.
    let link = s.root.join("services").join("iox2_swapped.service");
    std::os::unix::fs::symlink(&elsewhere, &link).unwrap();
    wait_until(
        "deard to remove the symbolic link",
        WAIT,
        || std::fs::symlink_metadata(&link).is_err(),
        || daemon.log_text(),
    );
    let line = daemon
        .wait_for_log_line("iox2_swapped.service", WAIT)
        .unwrap();
    assert!(line.contains("removed a symbolic link"), "{line}");
    receives(&probe, 3, &mut daemon);
}

/// Defect 3 (lock-out): 16 junk bytes in iceoryx2's node counter (`*global_mgmt`) made every
/// later start fail with `UnableToGenerateUniqueNodeId` (the file not named). The daemon
/// repairs it at start, and while it serves, naming the file.
#[test]
fn junk_in_the_node_counter_is_repaired_at_start_and_while_serving() {
    let s = setup(clients_group());
    let service = unique_service("global-mgmt");
    let mut first = s.serving_daemon(&service, "first.log");
    assert!(first.terminate(WAIT).expect("stops").success());
    let counters = s.files(".global_mgmt");
    assert_eq!(counters.len(), 1, "{counters:?}");
    let junk = [0x5Au8; 16];
    std::fs::write(&counters[0], junk).unwrap();

    let mut daemon = s.daemon(&service, "second.log");
    daemon
        .wait_for_log_line("serving", WAIT)
        .unwrap_or_else(|| panic!("deard did not start:\n{}", daemon.log_text()));
    let line = daemon
        .wait_for_log_line("node counter was damaged", WAIT)
        .unwrap();
    assert!(line.contains(counters[0].to_str().unwrap()), "{line}");

    // Again while it serves: repaired within a second, then new clients connect.
    std::fs::write(&counters[0], junk).unwrap();
    wait_until(
        "deard to repair the node counter a second time",
        WAIT,
        || {
            daemon
                .log_text()
                .matches("node counter was damaged")
                .count()
                >= 2
        },
        || daemon.log_text(),
    );
    let probe = s.own_probe(&service);
    receives(&probe, 3, &mut daemon);
}

/// Defect 7: after `rm -rf $ROOT/*` the daemon logged 15 fps forever while no new client
/// could find the service. It now notices within a second, says which file went, makes the
/// service again, and a new client receives frames.
#[test]
fn deleted_transport_files_are_noticed_and_made_again() {
    let s = setup(clients_group());
    let service = unique_service("deleted");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    for entry in std::fs::read_dir(&s.root).unwrap().flatten() {
        let path = entry.path();
        if entry.file_type().unwrap().is_dir() {
            std::fs::remove_dir_all(&path).unwrap();
        } else {
            std::fs::remove_file(&path).unwrap();
        }
    }
    let line = daemon
        .wait_for_log_line("a file of the transport was deleted", WAIT)
        .unwrap_or_else(|| panic!("not noticed:\n{}", daemon.log_text()));
    assert!(line.contains(s.root.to_str().unwrap()), "{line}");
    daemon
        .wait_for_log_line("made the transport's files again", WAIT)
        .unwrap_or_else(|| panic!("not made again:\n{}", daemon.log_text()));
    let probe = s.own_probe(&service);
    receives(&probe, 3, &mut daemon);
}

/// Defect 3 (impersonation): a member of the service's group who published on the service
/// before the daemon made the real one refuse to start, and every client received his frames.
/// Now the daemon serves beside him (saying so, naming his uid), and clients refuse his frames
/// (naming his uid) and receive the daemon's.
#[test]
fn another_users_publisher_neither_locks_out_nor_impersonates_the_daemon() {
    if !can_run_as_another_user("a publisher") {
        return;
    }
    let s = setup(NOBODY);
    let service = unique_service("impostor");
    let _impostor = Impostor::start(&s, &service);

    let mut daemon = s.serving_daemon(&service, "deard.log");
    let warning = daemon
        .wait_for_log_line("another user's process publishes on this service", WAIT)
        .unwrap();
    assert!(warning.contains("uid=65534"), "{warning}");
    let run_id = run_id_of(&daemon);

    let mut probe = s.own_probe(&service);
    for _ in 0..20 {
        let seen = probe.next(WAIT).expect("a frame of the daemon");
        assert_eq!(
            format!("{:016x}", seen.run_id),
            run_id,
            "only the daemon's frames"
        );
    }
    probe.crash();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut probe.child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(
        err.contains("published by uid 65534") && err.contains("its frames are refused"),
        "{err}"
    );
    assert!(daemon.is_running());
}

/// A `dear-impostor` publishing on a service as `nobody` (a member of the service's group in
/// these tests), killed when dropped.
struct Impostor {
    _process: Killed,
}

impl Impostor {
    /// Starts one and waits until it publishes.
    fn start(s: &Setup, service: &str) -> Impostor {
        let mut child = Command::new(dear_test_support::paths::binary("dear-impostor"))
            .arg(service)
            .env(dear_proto::IOX2_ROOT_ENV, &s.root)
            .uid(NOBODY)
            .gid(NOBODY)
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(child.stdout.take().unwrap()),
            &mut line,
        )
        .unwrap();
        let impostor = Impostor {
            _process: Killed(child),
        };
        assert_eq!(line.trim(), "ready");
        impostor
    }
}

/// Defect 3 (lock-out), the rest of it: two members' publishers took both publisher slots of
/// the service before the daemon, and the daemon could not start. Now it makes the service
/// again without them (it owns the root), says so naming them, and serves; clients receive
/// its frames.
#[test]
fn other_users_holding_every_publisher_slot_do_not_lock_the_daemon_out() {
    if !can_run_as_another_user("a publisher") {
        return;
    }
    let s = setup(NOBODY);
    let service = unique_service("lockout");
    let _first = Impostor::start(&s, &service);
    let _second = Impostor::start(&s, &service);

    let mut daemon = s.daemon(&service, "deard.log");
    let taken = daemon
        .wait_for_log_line("hold every publisher slot", WAIT)
        .unwrap_or_else(|| panic!("not noticed:\n{}", daemon.log_text()));
    assert!(taken.contains("uid 65534"), "{taken}");
    daemon
        .wait_for_log_line("serving", WAIT)
        .unwrap_or_else(|| panic!("deard did not serve:\n{}", daemon.log_text()));
    let run_id = run_id_of(&daemon);
    let probe = s.own_probe(&service);
    for _ in 0..10 {
        let seen = probe.next(WAIT).expect("a frame of the daemon");
        assert_eq!(
            format!("{:016x}", seen.run_id),
            run_id,
            "the daemon's frames"
        );
    }
    assert!(daemon.is_running());
}

/// Defect 10: one member of the service's group could take every subscriber slot (16 `dear
/// watch`: 8 served, 8 refused) and keep every other client out. Now the daemon removes a
/// user's subscribers beyond `[service] max_subscribers_per_user` (6 of the 8 slots by
/// default) within a second, naming the user, and another user's client connects and
/// receives.
#[test]
fn one_member_cannot_take_every_subscriber_slot() {
    if !can_run_as_another_user("clients") {
        return;
    }
    let s = setup(NOBODY);
    let service = unique_service("quota");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    // Each probe has subscribed when it is returned.
    let _members: Vec<Probe> = (0..dear_proto::service::QOS_MAX_SUBSCRIBERS)
        .map(|_| s.probe(&service, NOBODY))
        .collect();
    // The daemon removes two of them (at one check, or over two if it checked meanwhile).
    let removed = |log: &str| -> usize {
        log.lines()
            .filter(|l| l.contains("max_subscribers_per_user allows"))
            .filter_map(|l| {
                l.split("removed=")
                    .nth(1)?
                    .split_whitespace()
                    .next()?
                    .parse::<usize>()
                    .ok()
            })
            .sum()
    };
    let deadline = std::time::Instant::now() + WAIT;
    while removed(&daemon.log_text()) < 2 {
        assert!(
            std::time::Instant::now() < deadline && daemon.is_running(),
            "no subscriber removed:\n{}",
            daemon.log_text()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let log = daemon.log_text();
    let line = log
        .lines()
        .find(|l| l.contains("max_subscribers_per_user allows"))
        .unwrap();
    assert!(
        line.contains("uid=65534") && line.contains("limit=6"),
        "{line}"
    );
    // The service's own user's client gets a slot and frames.
    let own = s.own_probe(&service);
    receives(&own, 3, &mut daemon);
    assert!(daemon.is_running());
}

/// A small seeded generator (SplitMix64) for the scribbles: the same seed, the same writes.
struct Scribbler(u64);

impl Scribbler {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }

    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }

    /// One write into `file` of the kind a hostile or buggy client makes: random bytes at a
    /// random place, a few flipped bits, its first page overwritten (the headers), or the
    /// file truncated. Returns what it did; a file that went away meanwhile is skipped.
    fn scribble(&mut self, file: &std::path::Path) -> String {
        use std::os::unix::fs::FileExt;
        let Ok(f) = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(file)
        else {
            return format!("{} gone", file.display());
        };
        let size = f.metadata().map(|m| m.len() as usize).unwrap_or(0);
        if size == 0 {
            return format!("{} empty", file.display());
        }
        let what = match self.below(4) {
            0 => {
                let n = 1 + self.below(256.min(size));
                let at = self.below(size - n + 1);
                f.write_all_at(&self.bytes(n), at as u64).ok();
                format!("{n} random bytes at {at}")
            }
            1 => {
                let flips = 1 + self.below(8);
                for _ in 0..flips {
                    let at = self.below(size) as u64;
                    let mut b = [0u8];
                    if f.read_exact_at(&mut b, at).is_ok() {
                        b[0] ^= 1 << self.below(8);
                        f.write_all_at(&b, at).ok();
                    }
                }
                format!("{flips} bits flipped")
            }
            2 => {
                let n = size.min(4096);
                f.write_all_at(&self.bytes(n), 0).ok();
                format!("its first {n} bytes random")
            }
            _ => {
                let to = self.below(size);
                f.set_len(to as u64).ok();
                format!("truncated to {to} bytes")
            }
        };
        format!("{}: {what}", file.display())
    }
}

/// The number of writes and the seed of a scribbling test: `DEAR_SCRIBBLE_WRITES` (default
/// `writes`) and `DEAR_SCRIBBLE_SEED` (default `seed`), for longer runs by hand.
fn scribble_settings(writes: u64, seed: u64) -> (usize, u64) {
    let env = |name: &str, default: u64| {
        std::env::var(name)
            .ok()
            .map(|v| {
                v.parse::<u64>()
                    .unwrap_or_else(|e| panic!("{name}={v}: {e}"))
            })
            .unwrap_or(default)
    };
    (
        env("DEAR_SCRIBBLE_WRITES", writes) as usize,
        env("DEAR_SCRIBBLE_SEED", seed),
    )
}

/// Receiving client processes (`dear-probe`, as `nobody`) started during a scribbling test, each
/// with its output and standard error in files of the test's directory. Killed when dropped.
struct Clients {
    dir: PathBuf,
    started: usize,
    children: Vec<Client>,
}

struct Client {
    child: std::process::Child,
    out: PathBuf,
    err: PathBuf,
    /// The size of its output (a line per frame) when last looked at.
    seen: u64,
}

impl Client {
    /// The frames it received so far (its output's frame lines).
    fn received(&self) -> usize {
        count_frames(&self.out)
    }
}

/// The frame lines in the output file `out` of a `dear-probe`.
fn count_frames(out: &std::path::Path) -> usize {
    std::fs::read_to_string(out)
        .unwrap_or_default()
        .lines()
        .filter(|l| l.starts_with("frame "))
        .count()
}

impl Clients {
    fn new(dir: &std::path::Path) -> Self {
        Clients {
            dir: dir.to_path_buf(),
            started: 0,
            children: Vec::new(),
        }
    }

    /// Starts one more client of `service` under `root`: it receives until killed.
    fn start(&mut self, root: &std::path::Path, service: &str) {
        let out = self.dir.join(format!("client-{}.out", self.started));
        let err = self.dir.join(format!("client-{}.err", self.started));
        self.started += 1;
        let child = Command::new(dear_test_support::paths::binary("dear-probe"))
            .args([
                "--service",
                service,
                "--count",
                "1000000",
                "--timeout-s",
                "300",
            ])
            .env(dear_proto::IOX2_ROOT_ENV, root)
            .env("RUST_BACKTRACE", "1")
            .uid(NOBODY)
            .gid(NOBODY)
            .stdout(std::fs::File::create(&out).unwrap())
            .stderr(std::fs::File::create(&err).unwrap())
            .spawn()
            .unwrap();
        self.children.push(Client {
            child,
            out,
            err,
            seen: 0,
        });
    }

    /// Stops (SIGKILL, not reported by [`Clients::ended`]) the running clients that received
    /// nothing since the last call: the service they joined was made again by the daemon, or
    /// their records keep them from receiving. The test starts others, which receive.
    fn retire_idle(&mut self) {
        self.children.retain_mut(|c| {
            let size = std::fs::metadata(&c.out).map(|m| m.len()).unwrap_or(0);
            let idle = size == c.seen && matches!(c.child.try_wait(), Ok(None));
            c.seen = size;
            if idle {
                let _ = c.child.kill();
                let _ = c.child.wait();
            }
            !idle
        });
    }

    /// The clients still running.
    fn running(&mut self) -> usize {
        let mut running = 0;
        for c in &mut self.children {
            running += usize::from(matches!(c.child.try_wait(), Ok(None)));
        }
        running
    }

    /// The clients that ended since the last call, each as its exit status and its standard
    /// error (they are forgotten: the test starts others).
    fn ended(&mut self) -> Vec<(std::process::ExitStatus, String)> {
        let mut ended = Vec::new();
        self.children.retain_mut(|c| match c.child.try_wait() {
            Ok(Some(status)) => {
                ended.push((status, std::fs::read_to_string(&c.err).unwrap_or_default()));
                false
            }
            _ => true,
        });
        ended
    }
}

impl Drop for Clients {
    fn drop(&mut self) {
        for c in &mut self.children {
            let _ = c.child.kill();
            let _ = c.child.wait();
        }
    }
}

/// Waits until the daemon has finished every transport check it started before now and two
/// more: damage a client wrote before the call is then acted on (a service made again is made
/// by the second check that sees the damage), and a client connecting afterwards is not cut off
/// by a late repair. Panics with the log if the checks stop.
fn transport_checked(daemon: &Daemon) {
    let checks = || {
        daemon
            .log_text()
            .matches(deard::publish::CHECKING_TRANSPORT)
            .count()
    };
    // The check under way may have read the records before the last write landed; the next
    // one sees the damage, the one after repairs it, and the third starts after that.
    let target = checks() + 3;
    wait_until(
        "the daemon's transport checks after the last write",
        WAIT,
        || checks() >= target,
        || daemon.log_text(),
    );
}

/// After the scribbling stopped, a fresh client receives frames. The daemon notices damaged
/// records within two checks (a second apart) and makes the service again, so the clients start
/// once it has acted on the last write ([`transport_checked`]; a repair that came later cut a
/// client off mid-stream). A client that came meanwhile would be refused by the damaged records
/// or get no frames, and connect again, as after any restart of the service. Each try is a
/// whole client run: 3 frames or a 5 s timeout, a second after the last; then a client
/// receives 10 frames in a row.
fn a_fresh_client_receives(s: &Setup, service: &str, daemon: &mut Daemon) {
    transport_checked(daemon);
    let mut refused = Vec::new();
    let served = (0..10).any(|_| {
        // A client that connects again waits a little first (the daemon checks every second).
        std::thread::sleep(Duration::from_secs(1));
        let out = Command::new(dear_test_support::paths::binary("dear-probe"))
            .args(["--service", service, "--count", "3", "--timeout-s", "5"])
            .env(dear_proto::IOX2_ROOT_ENV, &s.root)
            .uid(NOBODY)
            .gid(NOBODY)
            .output()
            .unwrap();
        refused.push(String::from_utf8_lossy(&out.stderr).into_owned());
        out.status.success()
    });
    assert!(
        served,
        "no fresh client received 3 frames in 10 tries: {refused:#?}\n{}",
        daemon.log_text()
    );
    assert!(daemon.is_running(), "{}", daemon.log_text());
    let fresh = s.probe(service, NOBODY);
    receives(&fresh, 10, daemon);
    assert!(daemon.is_running(), "{}", daemon.log_text());
}

/// Defect 1 (the shared records): a member of the service's group wrote 152 random bytes into a
/// `*.connection` file (the daemon aborted in the publisher's returned-sample handling) or a
/// `*.dynamic` file (it aborted, SIGSEGV in release). Clients must be able to write both, so
/// the patched iceoryx2 (third_party/README.md) checks on the publisher's side every offset,
/// size and index it reads from them, and the daemon makes the service again when a client
/// damaged its records (a truncated one, which raised SIGBUS, is replaced by zero pages). Here,
/// while a client (`nobody`, in the group) receives, 600 seeded writes (random bytes, bit
/// flips, overwritten headers, truncations) go into every such file in turn; the
/// daemon must stay up throughout, and a fresh client must receive frames afterwards. (The
/// clients' side: [`a_client_scribbling_on_the_shared_records_cannot_crash_another_client`].)
#[test]
fn a_client_scribbling_on_the_shared_records_cannot_crash_the_daemon() {
    if !can_run_as_another_user("clients") {
        return;
    }
    // Longer by hand: DEAR_SCRIBBLE_WRITES=20000 DEAR_SCRIBBLE_SEED=7 (docs/security.md).
    let (writes, seed) = scribble_settings(600, 0x34);
    let s = setup(NOBODY);
    let service = unique_service("scribble");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    let victim = s.probe(&service, NOBODY);
    receives(&victim, 5, &mut daemon);
    // The listeners' event states too (`*.event_mgmt`, which the daemon's notifier writes
    // into every frame): before the patch, a write there made the notifier add 1 at an
    // address of the writer's choosing (SIGSEGV in the shared_records harness).
    let records = || {
        [
            s.files(".connection"),
            s.files(".dynamic"),
            s.files(".event_mgmt"),
        ]
        .concat()
    };
    assert!(
        !s.files(".connection").is_empty()
            && !s.files(".dynamic").is_empty()
            && !s.files(".event_mgmt").is_empty(),
        "{:?}",
        records()
    );
    // The files a client must write: a member of the group can.
    for file in records() {
        let (ok, err) = as_nobody("test", &["-w", file.to_str().unwrap()]);
        assert!(ok, "{} not writable by a member: {err}", file.display());
    }
    let mut scribbler = Scribbler(seed);
    let mut kinds = [0usize; 3];
    // Clients that connect again when the daemon made the service again (their old one is
    // gone), or when the last listener went (a client whose channel was damaged leaves):
    // there is always a connection and an event state to scribble on. Killed at the end.
    let mut clients = Clients::new(&s.dir);
    let mut first = Vec::new();
    for i in 0..writes {
        if i % 20 == 19 && (s.files(".connection").is_empty() || s.files(".event_mgmt").is_empty())
        {
            clients.start(&s.root, &service);
        }
        // First half: the clients' own records only, connections and event states (the
        // victim's, then the clients' that came after it died); second half: the service's
        // records too. A client scribbling on those all the time keeps any new client out
        // (it damages each new record), but not the daemon down.
        let files = if i < writes / 2 {
            [s.files(".connection"), s.files(".event_mgmt")].concat()
        } else {
            records()
        };
        if files.is_empty() {
            std::thread::sleep(Duration::from_millis(20));
            continue;
        }
        let file = &files[scribbler.below(files.len())];
        let name = file.to_str().unwrap();
        kinds[if name.ends_with(".dynamic") {
            1
        } else if name.ends_with(".event_mgmt") {
            2
        } else {
            0
        }] += 1;
        let what = scribbler.scribble(file);
        if first.len() < 10 {
            first.push(what.clone());
        }
        // Let a few frames go through the damage.
        std::thread::sleep(Duration::from_millis(10));
        assert!(
            daemon.is_running(),
            "deard died after write {i} of seed {seed} ({what}):\n{}",
            daemon.log_text()
        );
    }
    assert!(
        kinds.iter().all(|&k| k > 0),
        "writes into connections, dynamic records, event states: {kinds:?}; the first: {first:#?}\n{}",
        daemon.log_text()
    );
    eprintln!(
        "seed {seed}: {} writes into connections, {} into the services' records, {} into event states; the daemon made the service again {} times",
        kinds[0],
        kinds[1],
        kinds[2],
        daemon.log_text().matches("a client damaged the service's shared records").count()
    );
    a_fresh_client_receives(&s, &service, &mut daemon);
}

/// Defect 1, the receiving side: a write into a `*.dynamic` or `*.connection` record by one
/// member of the group crashed *other clients* (every subscriber reads both: the queue of
/// offsets the daemon sends into its connection, the list of publishers in the service's
/// record). The patched iceoryx2 (third_party/README.md) checks on the subscriber's side too
/// every offset, position and size it reads from them; a client that finds its channel
/// corrupted gets an error naming it and connects again. Here three clients (`nobody`)
/// receive while 600 seeded writes (random bytes, bit flips, overwritten headers,
/// truncations) go into the clients' connections (first half) and the service's records
/// (second half, with the connections); no client may die by a signal or a panic (one that
/// gives up must say why, and another takes its place), and a fresh client receives frames
/// afterwards.
#[test]
fn a_client_scribbling_on_the_shared_records_cannot_crash_another_client() {
    if !can_run_as_another_user("clients") {
        return;
    }
    let (writes, seed) = scribble_settings(600, 0x35);
    let s = setup(NOBODY);
    let service = unique_service("scribble-clients");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    const CLIENTS: usize = 3;
    let mut clients = Clients::new(&s.dir);
    for _ in 0..CLIENTS {
        clients.start(&s.root, &service);
    }
    // Every client receives before the first write.
    wait_until(
        "a frame received by every client",
        WAIT,
        || clients.children.iter().all(|c| c.received() > 0),
        || daemon.log_text(),
    );
    let mut scribbler = Scribbler(seed);
    let mut kinds = [0usize; 3];
    let mut gave_up = Vec::new();
    for i in 0..writes {
        for (status, err) in clients.ended() {
            use std::os::unix::process::ExitStatusExt;
            assert!(
                status.signal().is_none() && status.code() != Some(101),
                "a client died ({status}) after write {i} of seed {seed}: {err}"
            );
            // Not a crash: it said why (e.g. its channel was corrupted) and exited.
            assert!(err.contains("dear-probe: "), "{status}: {err:?}");
            gave_up.push(err);
        }
        // Clients that stopped receiving make way for new ones (a second or more of writes).
        if i % 100 == 99 {
            clients.retire_idle();
        }
        // One at a time: a client that gives up at once is not replaced in a busy loop.
        if clients.running() < CLIENTS {
            clients.start(&s.root, &service);
        }
        // First half: the clients' own records only, connections (what a receiving client
        // reads most) and event states (which it drains); second half: the service's records
        // too (which keep new clients out while damaged).
        let files = if i < writes / 2 {
            [s.files(".connection"), s.files(".event_mgmt")].concat()
        } else {
            [
                s.files(".connection"),
                s.files(".event_mgmt"),
                s.files(".dynamic"),
            ]
            .concat()
        };
        if files.is_empty() {
            std::thread::sleep(Duration::from_millis(20));
            continue;
        }
        let file = &files[scribbler.below(files.len())];
        let name = file.to_str().unwrap();
        kinds[if name.ends_with(".dynamic") {
            1
        } else if name.ends_with(".event_mgmt") {
            2
        } else {
            0
        }] += 1;
        scribbler.scribble(file);
        // Let a few frames go through the damage.
        std::thread::sleep(Duration::from_millis(10));
    }
    // Every client's end after the last write, before they are killed.
    std::thread::sleep(Duration::from_millis(500));
    for (status, err) in clients.ended() {
        use std::os::unix::process::ExitStatusExt;
        assert!(
            status.signal().is_none() && status.code() != Some(101),
            "a client died ({status}) after the last write of seed {seed}: {err}"
        );
        gave_up.push(err);
    }
    assert!(
        kinds.iter().all(|&k| k > 0),
        "writes into connections, dynamic records, event states: {kinds:?}\n{}",
        daemon.log_text()
    );
    // Frames the clients received meanwhile: they were receiving while the records changed.
    let frames: usize = (0..clients.started)
        .map(|n| count_frames(&s.dir.join(format!("client-{n}.out"))))
        .sum();
    eprintln!(
        "seed {seed}: {} writes into connections, {} into the services' records, {} into event states; {} clients started, {frames} frames received, {} gave up (none crashed; {} of them told their channel was corrupted); the daemon made the service again {} times; the first to give up: {:?}",
        kinds[0],
        kinds[1],
        kinds[2],
        clients.started,
        gave_up.len(),
        gave_up.iter().filter(|e| e.contains("was corrupted")).count(),
        daemon.log_text().matches("a client damaged the service's shared records").count(),
        gave_up.first()
    );
    if std::env::var_os("DEAR_SCRIBBLE_REASONS").is_some() {
        let mut reasons = std::collections::BTreeMap::<String, usize>::new();
        for e in &gave_up {
            let line = e
                .lines()
                .rev()
                .find(|l| l.starts_with("dear-probe: "))
                .unwrap_or("?");
            *reasons.entry(line.chars().take(400).collect()).or_default() += 1;
        }
        eprintln!("{reasons:#?}");
    }
    drop(clients);
    assert!(daemon.is_running(), "{}", daemon.log_text());
    a_fresh_client_receives(&s, &service, &mut daemon);
}

/// Writes into every `*.connection` file (the only subscriber is `client`'s, so all are its
/// channels) for a few seconds, as a hostile or buggy member of the group would: random writes
/// ([`Scribbler`]), then whole records of `0xff` (queue positions that look like an empty
/// queue: the channel breaks without an error). `client` must not end meanwhile; whether a
/// write broke its channel (it then connects again) depends on where the writes land.
fn scribble_on_its_channels(
    s: &Setup,
    client: &mut std::process::Child,
    err: &std::path::Path,
    seed: u64,
) {
    use std::os::unix::fs::FileExt;
    let read = || std::fs::read_to_string(err).unwrap_or_default();
    let mut scribbler = Scribbler(seed);
    for i in 0..400 {
        assert!(
            client.try_wait().unwrap().is_none(),
            "the client ended after {i} writes: {}",
            read()
        );
        for file in s.files(".connection") {
            if i < 300 {
                scribbler.scribble(&file);
            } else if let Ok(f) = std::fs::OpenOptions::new().write(true).open(&file) {
                let size = f.metadata().map(|m| m.len() as usize).unwrap_or(0);
                f.write_all_at(&vec![0xff; size], 0).ok();
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(
        client.try_wait().unwrap().is_none(),
        "the client ended after the writes: {}",
        read()
    );
}

/// A client process killed when the test ends, failed or not (a panicking test would leave it
/// running otherwise).
struct Killed(std::process::Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `dear watch` whose channels another process writes into goes on reporting frames (it
/// connects again when a channel broke), instead of exiting (issue 34).
#[test]
fn dear_watch_keeps_reporting_while_its_channels_are_written_into() {
    let s = setup(clients_group());
    let service = unique_service("watch-reconnect");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    let (out, err) = (s.dir.join("watch.out"), s.dir.join("watch.err"));
    let mut watch = Killed(
        Command::new(dear_test_support::paths::binary("dear"))
            .args(["watch", "--json", "--service", &service])
            .env(dear_proto::IOX2_ROOT_ENV, &s.root)
            .stdout(std::fs::File::create(&out).unwrap())
            .stderr(std::fs::File::create(&err).unwrap())
            .spawn()
            .unwrap(),
    );
    let frames_per_line = |text: &str| -> Vec<u64> {
        text.lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .map(|v| v["frames"].as_u64().unwrap())
            .collect()
    };
    let read = |p: &PathBuf| std::fs::read_to_string(p).unwrap_or_default();
    wait_until(
        "a line with frames",
        WAIT,
        || frames_per_line(&read(&out)).iter().any(|&n| n > 0),
        || read(&err),
    );
    scribble_on_its_channels(&s, &mut watch.0, &err, 0x77);
    let lines_then = frames_per_line(&read(&out)).len();
    wait_until(
        "a line with frames after the writes",
        WAIT,
        || {
            frames_per_line(&read(&out))
                .iter()
                .skip(lines_then + 1)
                .any(|&n| n > 0)
        },
        || format!("{}\n{}", read(&err), daemon.log_text()),
    );
    assert!(
        watch.0.try_wait().unwrap().is_none(),
        "dear watch ended: {}",
        read(&err)
    );
    assert!(daemon.is_running(), "{}", daemon.log_text());
}

/// `dear record` goes on recording through the same writes (the same reconnecting client as
/// `dear watch`), its last line says how often it connected again, and Ctrl-C ends it
/// normally, as a recording without a limit is ended.
#[test]
fn dear_record_keeps_recording_while_its_channels_are_written_into() {
    let s = setup(clients_group());
    let service = unique_service("record-reconnect");
    let mut daemon = s.serving_daemon(&service, "deard.log");
    let mcap = s.dir.join("rec.mcap");
    let (out, err) = (s.dir.join("record.out"), s.dir.join("record.err"));
    let mut record = Killed(
        Command::new(dear_test_support::paths::binary("dear"))
            .args(["record", "--service", &service, "--mcap"])
            .arg(&mcap)
            .env(dear_proto::IOX2_ROOT_ENV, &s.root)
            .stdout(std::fs::File::create(&out).unwrap())
            .stderr(std::fs::File::create(&err).unwrap())
            .spawn()
            .unwrap(),
    );
    let read = |p: &PathBuf| std::fs::read_to_string(p).unwrap_or_default();
    // Frames are being written (the MCAP grows past its 1 MiB write buffer) before the channel
    // is corrupted.
    wait_until(
        "frames in the recording",
        WAIT,
        || std::fs::metadata(&mcap).is_ok_and(|m| m.len() > 0),
        || read(&err),
    );
    scribble_on_its_channels(&s, &mut record.0, &err, 0x78);
    // Frames after the writes (through a new channel if one broke), then Ctrl-C: how a
    // recording without a limit ends. Its MCAP keeps growing when frames arrive.
    let size = || std::fs::metadata(&mcap).map(|m| m.len()).unwrap_or(0);
    let before = size();
    wait_until(
        "frames recorded after the writes",
        WAIT,
        || size() > before,
        || read(&err),
    );
    // SAFETY: kill with a valid pid of our child and a signal number has no preconditions.
    unsafe { libc::kill(record.0.id() as i32, libc::SIGINT) };
    let status = record.0.wait().unwrap();
    let summary = read(&out);
    assert!(status.success(), "{status}: {}\n{summary}", read(&err));
    assert!(summary.starts_with("recorded "), "{summary}");
    // The last line says how often a broken channel was connected again, if one was.
    assert_eq!(
        summary.contains("connected again"),
        read(&err).contains("connected again"),
        "{summary}\n{}",
        read(&err)
    );
    let frames: u64 = summary
        .split_whitespace()
        .nth(1)
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{summary}"));
    assert!(frames > 0, "{summary}");
    assert!(daemon.is_running(), "{}", daemon.log_text());
}
