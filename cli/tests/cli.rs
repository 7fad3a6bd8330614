//! The real `dear` binary against a tiny in-test publisher speaking the frame protocol (no
//! daemon): `dump` writes what was published, `watch` reports it, `list` finds it.
//!
//! The transport overwrites a slow subscriber's oldest frame by design, so no test here demands
//! every frame: they check what the protocol guarantees (samples of one run arrive in
//! `sequence` order with the content that was published under that number, and gaps are
//! counted as lost).

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use dear_capture::CaptureDir;
use dear_proto::service::{frame_event_service, frame_service, FrameEventService, FrameService};
use dear_proto::Transport;
use dear_proto::{flags, random_run_id, FrameHeader, PayloadLayout, Stage};
use dear_test_support::process::{output_within, unique_service};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;

const W: usize = 16;
const H: usize = 12;
/// Distinct frame contents; frame `k` carries content `k % VARIANTS`.
const VARIANTS: u64 = 3;
/// The test source's first frame id: ids and sequence numbers differ, so a mix-up shows.
const FIRST_FRAME_ID: u64 = 100;

fn expected_depth(k: u64, r: usize, c: usize) -> f32 {
    if (r + c).is_multiple_of(7) {
        0.0 // invalid pixels survive the dump as 0
    } else {
        // Sub-millimetre parts check the rounding to the 16-bit PNG.
        0.5 + 0.25 * k as f32 + 0.0013 * (r * W + c) as f32
    }
}

fn expected_rgb(k: u64, r: usize, c: usize, ch: usize) -> u8 {
    ((r * W + c) * 3 + ch + 50 * k as usize) as u8
}

fn expected_confidence(k: u64, r: usize, c: usize) -> u8 {
    ((r * W + c + 17 * k as usize) % 256) as u8
}

/// One publisher and notifier on a fresh frame service, like deard's.
struct TestPublisher {
    publisher: Publisher<Transport, [u8], FrameHeader>,
    notifier: Notifier<Transport>,
    layout: PayloadLayout,
    /// Drawn per instance, as deard does.
    run_id: u64,
    /// Samples sent so far = the next sample's `sequence`.
    sent: u64,
    _frames: FrameService,
    _events: FrameEventService,
    _node: Node<Transport>,
}

impl TestPublisher {
    fn new(service: &str) -> Self {
        // The root `dear` uses too ($DEAR_IOX2_ROOT, else /dev/shm/dear).
        let config = dear_proto::node_config().unwrap();
        dear_proto::transport::create_root(&config).unwrap();
        let node = NodeBuilder::new()
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Transport>()
            .unwrap();
        let frames = frame_service(&node, service).unwrap();
        let events = frame_event_service(&node, service).unwrap();
        let layout = PayloadLayout::new(W as u32, H as u32).unwrap();
        let publisher = frames
            .publisher_builder()
            .initial_max_slice_len(layout.size)
            .create()
            .unwrap();
        let notifier = events.notifier_builder().create().unwrap();
        TestPublisher {
            publisher,
            notifier,
            layout,
            run_id: random_run_id().unwrap(),
            sent: 0,
            _frames: frames,
            _events: events,
            _node: node,
        }
    }

    /// Publishes the next frame (sequence `sent`, frame id `FIRST_FRAME_ID + sent`) with the
    /// known content of its variant.
    fn publish(&mut self) {
        let sequence = self.sent;
        let id = FIRST_FRAME_ID + sequence;
        let k = id % VARIANTS;
        let l = self.layout;
        let mut sample = self.publisher.loan_slice(l.size).unwrap();
        let payload = sample.payload_mut();
        for r in 0..H {
            for c in 0..W {
                let p = r * W + c;
                let d = expected_depth(k, r, c).to_ne_bytes();
                payload[l.depth_offset + 4 * p..l.depth_offset + 4 * p + 4].copy_from_slice(&d);
                for ch in 0..3 {
                    payload[l.rgb_offset + 3 * p + ch] = expected_rgb(k, r, c, ch);
                }
                payload[l.confidence_offset + p] = expected_confidence(k, r, c);
            }
        }
        let mut header = FrameHeader::new(id, W as u32, H as u32);
        header.capture_timestamp_ns = 1_000 * id;
        header.calib_tx = 10.0 + id as f32;
        header.calib_cy = -2.5;
        header.calib_residual_px = 0.25;
        header.calib_quality = 0.75;
        header.calib_age_frames = 3;
        header.flags = flags::ALIGNED | flags::CALIBRATION_ONLINE;
        header.stage_latency_us[Stage::Flow as usize] = 1_500;
        header.stage_latency_us[Stage::Total as usize] = 4_000;
        header.frames_dropped = id / 10;
        header.set_bundle_name("test");
        header.run_id = self.run_id;
        header.sequence = sequence;
        header.publish_timestamp_ns = dear_proto::time::monotonic_ns();
        *sample.user_header_mut() = header;
        sample.send().unwrap();
        self.sent += 1;
        self.notifier.notify().unwrap();
    }

    /// Publishes every 20 ms until `child` exits (it may subscribe late: history is one frame),
    /// at most for `limit`; then collects its output.
    fn serve(&mut self, child: Child, limit: Duration) -> Output {
        output_within(child, "child", limit, || self.publish())
    }
}

fn dear(args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_dear"));
    cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
    cmd
}

/// `dear watch --json` on `service` for `seconds` reports, stdout and stderr piped.
fn spawn_watch_json(service: &str, seconds: u32) -> Child {
    dear(&[
        "watch",
        "--service",
        service,
        "--json",
        "--count-seconds",
        &seconds.to_string(),
    ])
    .spawn()
    .unwrap()
}

fn check_success(out: &Output) {
    assert!(
        out.status.success(),
        "dear failed with {}: stdout {} stderr {}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn dump_writes_the_published_frames_as_a_capture() {
    let service = unique_service("dump");
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("dump");
    let mut publisher = TestPublisher::new(&service);
    let child = dear(&[
        "dump",
        "--count",
        "3",
        "--out",
        out_dir.to_str().unwrap(),
        "--service",
        &service,
        "--timeout-s",
        "10",
        "--preview",
    ])
    .spawn()
    .unwrap();
    let out = publisher.serve(child, Duration::from_secs(30));
    check_success(&out);
    assert!(String::from_utf8_lossy(&out.stdout).contains("wrote 3 frames"));

    let capture = CaptureDir::open(&out_dir).unwrap();
    assert_eq!(capture.len(), 3);
    assert_eq!(capture.size(), (W as u32, H as u32));
    let source = &capture.manifest().source;
    assert_eq!(source["recorded_by"], "dear dump");
    assert_eq!(source["service"], service.as_str());
    assert!(source["amplitude"].as_str().unwrap().contains("confidence"));
    let published = source["published_frames"].as_array().unwrap();
    let estimates = source["calibration_estimates"].as_array().unwrap();
    assert_eq!((published.len(), estimates.len()), (3, 3));

    let run_id = format!("{:016x}", publisher.run_id);
    let mut last_sequence = None;
    for i in 0..3 {
        let sample = capture.read_sample(i).unwrap();
        let frame = &sample.frame;
        assert_eq!(frame.index, i as u64);
        assert!(
            sample.truth.perturbation.is_none(),
            "estimates are not ground truth"
        );
        // Frames may be lost (the queue overwrites), never reordered or repeated: the sequence
        // of one run strictly increases, and each sample is the one published under it.
        assert_eq!(published[i]["run_id"], run_id.as_str());
        let sequence = published[i]["sequence"].as_u64().unwrap();
        assert!(last_sequence < Some(sequence), "frames in publish order");
        assert!(sequence < publisher.sent);
        last_sequence = Some(sequence);
        let daemon_id = published[i]["frame_id"].as_u64().unwrap();
        assert_eq!(daemon_id, FIRST_FRAME_ID + sequence);
        assert_eq!(published[i]["id"], i);
        assert_eq!(published[i]["bundle"], "test");
        let e = &estimates[i];
        assert_eq!(e["id"], i);
        assert_eq!(e["tx"].as_f64().unwrap(), 10.0 + daemon_id as f64);
        assert_eq!(e["cy"].as_f64().unwrap(), -2.5);
        assert_eq!(e["residual_px"].as_f64().unwrap(), 0.25);
        assert_eq!(e["age_frames"], 3);
        assert_eq!(e["online"], true);

        let k = daemon_id % VARIANTS;
        for r in 0..H {
            for c in 0..W {
                let want = expected_depth(k, r, c);
                let got = frame.depth[(r, c)];
                assert!(
                    (got - want).abs() <= 0.0005 + 1e-6,
                    "frame {i} depth ({r}, {c}): {got} vs {want}"
                );
                assert_eq!(got == 0.0, want == 0.0);
                for ch in 0..3 {
                    assert_eq!(frame.rgb[(r, c, ch)], expected_rgb(k, r, c, ch));
                }
                let amp = f32::from(expected_confidence(k, r, c)) * 257.0;
                assert_eq!(frame.amplitude[(r, c)], amp);
            }
        }
        for kind in ["depth", "blend"] {
            let path = out_dir.join(format!("previews/{i:06}.{kind}.png"));
            let img = image::open(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
                .into_rgb8();
            assert!(img.width() >= W as u32 && img.height() >= H as u32);
        }
    }
    let timestamps: Vec<u64> = capture
        .manifest()
        .frames
        .iter()
        .map(|f| f.timestamp_ns)
        .collect();
    assert_eq!(timestamps[0], 0);
    assert!(
        timestamps.windows(2).all(|t| t[0] <= t[1]),
        "{timestamps:?}"
    );
}

#[test]
fn dump_without_a_publisher_fails_naming_the_service() {
    let service = unique_service("dump-none");
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("never");
    let out = dear(&[
        "dump",
        "--count",
        "2",
        "--out",
        out_dir.to_str().unwrap(),
        "--service",
        &service,
        "--timeout-s",
        "0.5",
    ])
    .output()
    .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&service) && stderr.contains("no frame"),
        "{stderr}"
    );
    assert!(!out_dir.exists(), "nothing is created when no frame came");
}

#[test]
fn dump_refuses_a_non_empty_directory_before_waiting() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("keep.txt"), "x").unwrap();
    let started = Instant::now();
    let out = dear(&[
        "dump",
        "--count",
        "1",
        "--out",
        tmp.path().to_str().unwrap(),
        "--service",
        &unique_service("dump-busy"),
    ])
    .output()
    .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("not empty") && stderr.contains(&tmp.path().display().to_string()),
        "{stderr}"
    );
    assert!(started.elapsed() < Duration::from_secs(5), "fails at once");
    assert!(Path::new(&tmp.path().join("keep.txt")).exists());
}

#[test]
fn watch_reports_each_second_as_json() {
    let service = unique_service("watch");
    let mut publisher = TestPublisher::new(&service);
    let started = Instant::now();
    let child = spawn_watch_json(&service, 2);
    let out = publisher.serve(child, Duration::from_secs(30));
    let test_ms = started.elapsed().as_secs_f64() * 1e3;
    check_success(&out);
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    // Every frame is numbered by this publisher's run; what was received plus what was lost
    // (sequence gaps) spans consecutive samples, so it cannot exceed what was sent.
    let run_id = format!("{:016x}", publisher.run_id);
    let mut spanned = 0;
    for line in &lines {
        assert_eq!(line["publisher_restarts"], 0, "{line}");
        if line["frames"].as_u64().unwrap() > 0 {
            assert_eq!(line["run_id"], run_id.as_str(), "{line}");
        }
        spanned += line["frames"].as_u64().unwrap() + line["lost"].as_u64().unwrap();
    }
    assert!(
        (1..=publisher.sent).contains(&spanned),
        "received + lost = {spanned}, sent {}",
        publisher.sent
    );
    // The second line covers a full second of 20 ms frames (loaded CI: allow a wide margin).
    let last = &lines[1];
    let fps = last["fps"].as_f64().unwrap();
    assert!((5.0..=60.0).contains(&fps), "fps {fps}");
    assert_eq!(last["daemon_total"]["median_ms"], 4.0);
    let flow = last["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == "flow")
        .unwrap();
    assert_eq!(flow["median_ms"], 1.5);
    // Publication precedes receipt on the one clock both use (CLOCK_MONOTONIC), so the
    // latency is positive: 0 is what `dear watch` shows when a publish time lies in the
    // client's future (another clock), and must fail here. Every frame it received was
    // published during this test, which bounds the latency from above.
    let median = last["end_to_end"]["median_ms"].as_f64().unwrap();
    let max = last["end_to_end"]["max_ms"].as_f64().unwrap();
    assert!(
        0.0 < median && median <= max,
        "end-to-end median {median} max {max} ms"
    );
    assert!(
        max < test_ms,
        "end-to-end max {max} ms, the test took {test_ms} ms"
    );
    assert_eq!(last["calibration"]["quality"], 0.75);
    assert_eq!(last["flags"], serde_json::json!(["aligned", "online"]));
    assert_eq!(last["bundle"], "test");
}

/// A publisher restart (a new instance: new run id, sequence and frame ids from the start)
/// is reported by `dear watch` as one, without counting the restart as lost frames.
#[test]
fn watch_says_when_the_publisher_restarted() {
    let service = unique_service("watch-restart");
    let mut first = Some(TestPublisher::new(&service));
    let first_run = format!("{:016x}", first.as_ref().unwrap().run_id);
    let mut child = spawn_watch_json(&service, 6);
    // Lines as they come, so the restart happens after watch has seen the first instance.
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<serde_json::Value>();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let _ = tx.send(serde_json::from_str(&line.unwrap()).unwrap());
        }
    });
    let mut lines = Vec::new();
    let mut second: Option<TestPublisher> = None;
    let deadline = Instant::now() + Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "dear watch still running");
        while let Ok(line) = rx.try_recv() {
            if first.is_some() && line["run_id"] == first_run.as_str() {
                // Seen: stop the first instance (its node and ports go), start another.
                first = None;
                second = Some(TestPublisher::new(&service));
            }
            lines.push(line);
        }
        match (&mut first, &mut second) {
            (Some(p), _) | (None, Some(p)) => p.publish(),
            (None, None) => unreachable!(),
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = child.wait().unwrap();
    reader.join().unwrap();
    lines.extend(rx.try_iter());
    assert!(status.success(), "dear watch: {status:?}");
    let second = second.expect("watch reported the first instance");
    let second_run = format!("{:016x}", second.run_id);
    let restarts: u64 = lines
        .iter()
        .map(|l| l["publisher_restarts"].as_u64().unwrap())
        .sum();
    assert_eq!(restarts, 1, "{lines:#?}");
    let at = lines
        .iter()
        .position(|l| l["publisher_restarts"] == 1)
        .unwrap();
    assert_eq!(lines[at]["run_id"], second_run.as_str());
    for l in &lines[at + 1..] {
        assert!(
            l["frames"] == 0 || l["run_id"] == second_run.as_str(),
            "{l}"
        );
    }
}

#[test]
fn list_finds_the_service_with_its_publisher() {
    let service = unique_service("list");
    let mut publisher = TestPublisher::new(&service);
    publisher.publish();
    let out = dear(&["list"]).output().unwrap();
    check_success(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find(|l| l.split_whitespace().next() == Some(service.as_str()))
        .unwrap_or_else(|| panic!("{service} not listed in:\n{stdout}"));
    let columns: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(columns[1], "1", "one publisher: {line}");
    assert_eq!(columns[2], "0", "no subscriber: {line}");
}

/// Issue 34: a write error on stdout is an error naming stdout, not a panic (exit 101).
#[test]
fn list_to_a_full_device_fails_cleanly() {
    let service = unique_service("list-full");
    let mut publisher = TestPublisher::new(&service);
    publisher.publish();
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let out = dear(&["list"]).stdout(full).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("cannot write to stdout"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// Issue 34: a stop and continue (Ctrl-Z then `fg`, a debugger) interrupts the SDK's wait
/// with EINTR even with no handler for those signals; `dear watch` went on to exit 1 with
/// `InterruptSignal`. Now it keeps watching to the end.
#[test]
fn watch_survives_stop_and_continue() {
    let service = unique_service("watch-stop");
    let mut publisher = TestPublisher::new(&service);
    let mut child = spawn_watch_json(&service, 3);
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let _ = tx.send(line.unwrap());
        }
    });
    let pid = child.id().to_string();
    let kill = |signal: &str| {
        let status = Command::new("kill").args([signal, &pid]).status().unwrap();
        assert!(status.success());
    };
    let mut lines = Vec::new();
    let mut stopped = false;
    let deadline = Instant::now() + Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "dear watch still running");
        lines.extend(rx.try_iter());
        if !stopped && !lines.is_empty() {
            // Watching (a line is out): it waits for frames now. Several stops, so at least
            // one lands in the wait.
            for _ in 0..5 {
                kill("-STOP");
                std::thread::sleep(Duration::from_millis(30));
                kill("-CONT");
                std::thread::sleep(Duration::from_millis(30));
            }
            stopped = true;
        }
        publisher.publish();
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    reader.join().unwrap();
    lines.extend(rx.try_iter());
    assert!(
        out.status.success(),
        "dear watch: {}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stopped);
    assert_eq!(lines.len(), 3, "{lines:?}");
}

/// Issue 34: when every subscriber slot is taken the error states the limit.
#[test]
fn the_subscriber_limit_is_stated_in_the_error() {
    let service = unique_service("limit");
    let mut publisher = TestPublisher::new(&service);
    publisher.publish();
    let clients: Vec<_> = (0..dear_proto::service::QOS_MAX_SUBSCRIBERS)
        .map(|_| dear_client::Client::connect(&service).unwrap())
        .collect();
    let out = dear(&["watch", "--service", &service, "--count-seconds", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains(&service) && err.contains("maximum of 8 subscribers"),
        "{err}"
    );
    drop(clients);
}
