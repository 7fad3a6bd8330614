//! Issue 34: a publisher serves a subscriber in this process, the fuzzer's bytes are written
//! into the service's shared records — the subscriber's `*.connection` and the service's
//! `*.dynamic` files, the ones every client may write — and the publisher then loans, sends,
//! reclaims and updates its connections as deard's frame loop does. Nothing it reads there
//! may crash or hang it (the patched iceoryx2 in third_party/ checks every offset, size and
//! index). The subscriber is leaked, not dropped: it is the client side, which trusts its own
//! records (documented in docs/security.md).
//!
//! Input: a sequence of writes, each `[file: u8][offset: u16 le][len: u8][bytes...]`; `file`
//! even picks a `*.connection`, odd a `*.dynamic` (its index among them modulo their count).
#![no_main]

use std::os::unix::fs::FileExt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

use iceoryx2::config::Config;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use libfuzzer_sys::fuzz_target;

fn root() -> &'static (PathBuf, Config) {
    static ROOT: OnceLock<(PathBuf, Config)> = OnceLock::new();
    ROOT.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("dear-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // SAFETY: set once, before any thread of this process reads the environment.
        unsafe { std::env::set_var(dear_proto::IOX2_ROOT_ENV, &dir) };
        let config = dear_proto::node_config().unwrap();
        set_log_level(LogLevel::Fatal);
        (dir, config)
    })
}

fn records(dir: &std::path::Path, suffix: &str) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    files.retain(|p| p.to_str().is_some_and(|n| n.ends_with(suffix)));
    files.sort();
    files
}

fuzz_target!(|data: &[u8]| {
    static RUN: AtomicU64 = AtomicU64::new(0);
    let (dir, config) = root();
    let name = format!("fuzz{}", RUN.fetch_add(1, Ordering::Relaxed));
    let node = NodeBuilder::new()
        .config(config)
        .create::<dear_proto::Transport>()
        .unwrap();
    let service = node
        .service_builder(&name.as_str().try_into().unwrap())
        .publish_subscribe::<u64>()
        .max_publishers(1)
        .max_subscribers(2)
        .subscriber_max_buffer_size(4)
        .history_size(0)
        .create()
        .unwrap();
    let publisher = service.publisher_builder().create().unwrap();
    let subscriber = service.subscriber_builder().create().unwrap();
    for n in 0..3 {
        publisher.send_copy(n).unwrap();
    }
    // One sample returned, one kept: the connection has chunks lent and returned.
    drop(subscriber.receive().unwrap());
    let kept = subscriber.receive().unwrap();

    let connections = records(dir, ".connection");
    let dynamic = records(dir, ".dynamic");
    let mut rest = data;
    while rest.len() >= 4 {
        let (file, at, len) = (
            rest[0],
            u16::from_le_bytes([rest[1], rest[2]]),
            rest[3] as usize,
        );
        let bytes = &rest[4..(4 + len).min(rest.len())];
        rest = &rest[(4 + len).min(rest.len())..];
        let pool = if file % 2 == 0 {
            &connections
        } else {
            &dynamic
        };
        if pool.is_empty() {
            continue;
        }
        let path = &pool[(file as usize / 2) % pool.len()];
        if let Ok(f) = std::fs::OpenOptions::new().write(true).open(path) {
            let size = f.metadata().map(|m| m.len()).unwrap_or(0);
            if size > 0 {
                let _ = f.write_all_at(bytes, u64::from(at) % size);
            }
        }
        // The publisher's side, as the frame loop drives it.
        for n in 0..2 {
            if let Ok(sample) = publisher.loan_uninit() {
                let _ = sample.write_payload(n).send();
            }
            let _ = publisher.update_connections();
        }
    }
    std::mem::forget(kept);
    std::mem::forget(subscriber);
    drop(publisher);
    drop(service);
    drop(node);
});
