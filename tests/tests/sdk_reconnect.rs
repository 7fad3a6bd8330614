//! The SDK's `ReconnectingClient` in an application's process, against a real deard: when the
//! daemon makes its service again (here: the transport's files deleted under it, issue 34
//! defect 7), the old channel delivers nothing more; the reconnecting client reports the loss
//! and the new channel, and receives the daemon's frames again.
//!
//! One test in its own binary: the SDK finds the daemon's root through the process's
//! environment (`DEAR_IOX2_ROOT`), which this test sets.

use std::os::unix::fs::PermissionsExt;
use std::time::{Duration, Instant};

use dear_client::{ChannelEvent, ReconnectingClient};
use dear_e2e_tests::processes::deard;
use dear_test_support::daemon::Daemon;
use dear_test_support::process::unique_service;
use dear_test_support::scene;

const WAIT: Duration = Duration::from_secs(30);

/// The next frame within [`WAIT`], with the events the wait produced.
fn next_frame(
    client: &mut ReconnectingClient,
    events: &mut Vec<ChannelEvent>,
) -> dear_client::Frame {
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        let frame = client
            .wait(Duration::from_millis(200))
            .expect("no receive error");
        events.extend(client.take_events());
        if let Some(frame) = frame {
            return frame;
        }
    }
    panic!("no frame within {WAIT:?}; events: {events:?}");
}

#[test]
fn the_reconnecting_client_outlives_a_service_made_again() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("root");
    std::fs::create_dir(&root).unwrap();
    std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o700)).unwrap();
    let capture = scene::write_capture(
        &tmp.path().join("cap"),
        10,
        64,
        48,
        scene::factory_calibration(),
    );
    // The only test of this binary: nothing else reads the environment meanwhile.
    std::env::set_var(dear_proto::IOX2_ROOT_ENV, &root);
    let service = unique_service("sdk-reconnect");
    let capture_dir = capture.root().to_str().unwrap().to_string();
    let mut command = deard(
        &service,
        &["--refine", "none", "--loop", "--replay", &capture_dir],
    );
    command.env(dear_proto::IOX2_ROOT_ENV, &root);
    let mut daemon = Daemon::spawn(command, &tmp.path().join("deard.log"));
    daemon
        .wait_for_log_line("serving", WAIT)
        .unwrap_or_else(|| panic!("deard did not serve:\n{}", daemon.log_text()));

    let mut client = ReconnectingClient::connect(&service).expect("connects");
    client.set_stall_timeout(Duration::from_secs(1));
    let mut events = Vec::new();
    let before = next_frame(&mut client, &mut events).header().run_id;
    assert!(events.is_empty(), "a healthy channel: {events:?}");

    for entry in std::fs::read_dir(&root).unwrap().flatten() {
        let path = entry.path();
        if entry.file_type().unwrap().is_dir() {
            std::fs::remove_dir_all(&path).unwrap();
        } else {
            std::fs::remove_file(&path).unwrap();
        }
    }
    daemon
        .wait_for_log_line("made the transport's files again", WAIT)
        .unwrap_or_else(|| panic!("not made again:\n{}", daemon.log_text()));
    // Frames already queued on the old channel may still come; then the new channel's.
    let deadline = Instant::now() + WAIT;
    while client.reconnects() == 0 || !events.contains(&ChannelEvent::Connected) {
        assert!(
            Instant::now() < deadline,
            "not connected again: {events:?}\n{}",
            daemon.log_text()
        );
        let _ = next_frame_or_none(&mut client, &mut events);
    }
    let after = next_frame(&mut client, &mut events);
    assert_eq!(after.header().run_id, before, "the same daemon's frames");
    assert!(
        matches!(events.first(), Some(ChannelEvent::Lost { reason }) if reason.contains("no frame")),
        "the stalled channel was reported first: {events:?}"
    );
    assert!(client.is_connected());
    assert!(daemon.is_running());
}

/// One wait of 200 ms, its events kept.
fn next_frame_or_none(
    client: &mut ReconnectingClient,
    events: &mut Vec<ChannelEvent>,
) -> Option<dear_client::Frame> {
    let frame = client
        .wait(Duration::from_millis(200))
        .expect("no receive error");
    events.extend(client.take_events());
    frame
}
