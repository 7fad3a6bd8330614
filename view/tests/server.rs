//! The viewer against a real `deard` replaying `samples/demo` (320×240): what a browser gets
//! over real HTTP — the status shows frames arriving, the pictures decode at the frame's size
//! and follow the stream, and every bad request gets its error while the server keeps serving.
//!
//! Needs `target/<profile>/deard` (built by `cargo test --workspace` or `cargo build`).

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use dear_test_support::daemon::Daemon;
use dear_test_support::paths::{binary, demo_capture};
use dear_test_support::process::unique_service;
use dear_view::{ViewConfig, Viewer};

const WAIT: Duration = Duration::from_secs(60);

/// `deard` replaying the bundled sample in a loop at its recorded pace (classical engine), its
/// log in `log`.
fn start_daemon(service: &str, log: &Path) -> Daemon {
    let mut command = Command::new(binary("deard"));
    command
        .args(["--service", service, "--refine", "classical", "--loop"])
        .arg("--replay")
        .arg(demo_capture());
    Daemon::spawn(command, log)
}

/// One HTTP answer.
struct Answer {
    status: u16,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Answer {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    fn json(&self) -> serde_json::Value {
        assert_eq!(self.status, 200, "{}", String::from_utf8_lossy(&self.body));
        serde_json::from_slice(&self.body).expect("JSON")
    }
}

/// Sends `raw` as it is and reads the answer to the end (HTTP/1.0: the server closes the
/// connection after it, and sends the body unchunked).
fn exchange(addr: SocketAddr, raw: &[u8]) -> Answer {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(WAIT)).unwrap();
    stream.write_all(raw).unwrap();
    let mut bytes = Vec::new();
    stream.read_to_end(&mut bytes).unwrap();
    let split = bytes
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or_else(|| panic!("no header end in {:?}", String::from_utf8_lossy(&bytes)));
    let head = String::from_utf8(bytes[..split].to_vec()).unwrap();
    let mut lines = head.split("\r\n");
    let status = lines
        .next()
        .unwrap()
        .split(' ')
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(n, v)| (n.trim().to_string(), v.trim().to_string()))
        .collect();
    Answer {
        status,
        headers,
        body: bytes[split + 4..].to_vec(),
    }
}

fn request(addr: SocketAddr, method: &str, path: &str) -> Answer {
    exchange(
        addr,
        format!("{method} {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").as_bytes(),
    )
}

fn get(addr: SocketAddr, path: &str) -> Answer {
    request(addr, "GET", path)
}

/// Polls `/status.json` until `done` holds (panics with the last status after [`WAIT`]).
fn wait_status(addr: SocketAddr, done: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let deadline = Instant::now() + WAIT;
    loop {
        let status = get(addr, "/status.json").json();
        if done(&status) {
            return status;
        }
        assert!(
            Instant::now() < deadline,
            "status never got there: {status:#}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn decoded_size(answer: &Answer) -> (u32, u32) {
    assert_eq!(
        answer.status,
        200,
        "{}",
        String::from_utf8_lossy(&answer.body)
    );
    assert_eq!(answer.header("Content-Type"), Some("image/jpeg"));
    let image = image::load_from_memory(&answer.body).expect("a JPEG that decodes");
    (image.width(), image.height())
}

#[test]
fn serves_a_live_deard_stream_and_refuses_what_it_does_not_serve() {
    let tmp = tempfile::tempdir().unwrap();
    let service = unique_service("live");
    let _daemon = start_daemon(&service, &tmp.path().join("deard.log"));
    let viewer = Viewer::start(ViewConfig::new("127.0.0.1:0", &service)).unwrap();
    let addr = viewer.local_addr();

    // Frames arrive, the rate is measured, a history builds up.
    let status = wait_status(addr, |s| {
        s["frames_received"].as_u64() >= Some(5)
            && s["snapshot"].as_u64() > Some(0)
            && !s["history"].as_array().unwrap().is_empty()
    });
    let log = || std::fs::read_to_string(tmp.path().join("deard.log")).unwrap_or_default();
    assert_eq!(status["service"], service.as_str());
    assert!(
        status["fps"].as_f64().unwrap() > 0.0,
        "{status:#}\n{}",
        log()
    );
    assert_eq!(status["frame"]["width"], 320);
    assert_eq!(status["frame"]["height"], 240);
    assert_eq!(status["frame"]["refinement"], "classical");
    assert_eq!(status["calibration"]["source"], "static");
    assert!(status["calibration"]["tx"].is_number());
    let health = status["calibration"]["health"].as_str().unwrap();
    assert!(
        ["unknown", "good", "can improve", "needs recalibration"].contains(&health),
        "{health}"
    );
    assert!(status["history"][0]["fps"].is_number());

    // The pictures decode at the frame's size (the depth preview adds its colour bar).
    let (w, h) = decoded_size(&get(addr, "/blend.jpg"));
    assert_eq!((w, h), (320, 240));
    assert_eq!(decoded_size(&get(addr, "/confidence.jpg?n=3")), (320, 240));
    let depth = get(addr, "/depth.jpg");
    let (w, h) = decoded_size(&depth);
    assert!(w > 320 && h >= 240, "depth preview {w}×{h}");
    let range = depth.header("X-Depth-Range").expect("the colour scale");
    let [near, far]: [f32; 2] = range
        .split(' ')
        .map(|v| v.parse().unwrap())
        .collect::<Vec<_>>()
        .try_into()
        .unwrap();
    assert!(0.0 < near && near < far, "{range}");
    assert_eq!(depth.header("Cache-Control"), Some("no-store"));

    // The page.
    let page = get(addr, "/");
    assert_eq!(page.status, 200);
    assert_eq!(
        page.header("Content-Type"),
        Some("text/html; charset=utf-8")
    );
    assert!(String::from_utf8_lossy(&page.body).contains("<title>dear view</title>"));
    let head = request(addr, "HEAD", "/depth.jpg");
    assert_eq!((head.status, head.body.len()), (200, 0));

    // Read-only: every other method is refused, with what is allowed.
    for method in ["POST", "PUT", "DELETE", "PATCH", "OPTIONS"] {
        let answer = exchange(
            addr,
            format!("{method} /status.json HTTP/1.0\r\nContent-Length: 5\r\n\r\nhello").as_bytes(),
        );
        assert_eq!(answer.status, 405, "{method}");
        assert_eq!(answer.header("Allow"), Some("GET, HEAD"));
        assert!(String::from_utf8_lossy(&answer.body).contains("read-only"));
    }
    for path in ["/nope", "/depth.png", "/../../etc/passwd", "/status.json/x"] {
        let answer = get(addr, path);
        assert_eq!(answer.status, 404, "{path}");
        assert!(String::from_utf8_lossy(&answer.body).contains("/status.json"));
    }
    assert_eq!(get(addr, &format!("/{}", "x".repeat(2000))).status, 414);
    // Not HTTP at all: tiny_http's 400, or the connection closed; either way it keeps serving.
    if let Ok(mut s) = TcpStream::connect(addr) {
        let _ = s.write_all(b"\x16\x03\x01 not http\r\n\r\n");
        let _ = s.read_to_end(&mut Vec::new());
    }

    // Still serving, and the stream moves: more frames, a newer picture.
    let first_frame = depth.header("X-Frame-Id").unwrap().to_string();
    let received = status["frames_received"].as_u64().unwrap();
    wait_status(addr, |s| s["frames_received"].as_u64() > Some(received + 5));
    let deadline = Instant::now() + WAIT;
    loop {
        let again = get(addr, "/depth.jpg");
        decoded_size(&again);
        if again.header("X-Frame-Id") != Some(first_frame.as_str()) {
            break;
        }
        assert!(Instant::now() < deadline, "the depth picture never changed");
        std::thread::sleep(Duration::from_millis(50));
    }
    viewer.stop();
}

#[test]
fn without_a_daemon_it_says_so() {
    let service = unique_service("nobody");
    let viewer = Viewer::start(ViewConfig::new("127.0.0.1:0", &service)).unwrap();
    let addr = viewer.local_addr();
    let status = get(addr, "/status.json").json();
    assert_eq!(status["frames_received"], 0);
    assert!(status["frame"].is_null());
    for path in ["/depth.jpg", "/blend.jpg", "/confidence.jpg"] {
        let answer = get(addr, path);
        assert_eq!(answer.status, 503, "{path}");
        assert!(String::from_utf8_lossy(&answer.body).contains("no frame from"));
        assert_eq!(answer.header("Retry-After"), Some("1"));
    }
    assert_eq!(get(addr, "/").status, 200);
}

#[test]
fn a_bad_configuration_is_refused() {
    let mut config = ViewConfig::new("127.0.0.1:0", "dear/nobody/frames");
    config.max_fps = 0.0;
    assert!(Viewer::start(config.clone()).is_err());
    config.max_fps = 10.0;
    config.max_viewers = 0;
    assert!(Viewer::start(config.clone()).is_err());
    config.max_viewers = 1;
    config.bind = "not an address".into();
    let e = Viewer::start(config).err().unwrap().to_string();
    assert!(e.contains("cannot listen on not an address"), "{e}");
}
