//! Issue 34: the harness of the `shared_records` fuzz target (`fuzz/`, nightly and cargo-fuzz)
//! and of its stable run in the test tier (`tests/tests/shared_records_fuzz.rs`); the fuzz
//! target includes this file by path, so both run the same code.
//!
//! A publisher serves a subscriber in this process, and a notifier a listener, as deard serves
//! a client; an input's bytes are written into the shared records every client may write —
//! the subscriber's `*.connection`, the services' `*.dynamic` and the listener's `*.event_mgmt`
//! (its event state, which the notifier writes into) — and the publisher then loans, sends,
//! reclaims and updates its connections and the notifier notifies, as deard's frame loop does,
//! and the listener drains its events. Nothing read there may crash or hang either side, nor
//! the client's ports when they are dropped (the patched iceoryx2 in third_party/ checks every
//! offset, size and index).
//!
//! Input: a sequence of writes, each `[file: u8][offset: u16 le][len: u8][bytes...]`; `file`
//! from 0xC0 on picks a `*.event_mgmt`, below it even a `*.connection` and odd a `*.dynamic`
//! (the file's index among them modulo their count).

use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use iceoryx2::config::Config;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;

/// Writes that landed in each kind of record, over every run of a [`Harness`].
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Landed {
    pub connection: u64,
    pub dynamic: u64,
    pub event: u64,
}

/// One iceoryx2 root and a counter of runs (each run makes its own service).
pub struct Harness {
    dir: PathBuf,
    config: Config,
    runs: u64,
    pub landed: Landed,
}

impl Harness {
    /// A harness whose services live under `dir` (made if missing).
    pub fn new(dir: &Path) -> Self {
        std::fs::create_dir_all(dir).expect("the harness's iceoryx2 root");
        let config =
            dear_proto::transport::node_config_from(Config::global_config(), Some(dir.as_os_str()))
                .expect("a node configuration under the harness's root");
        set_log_level(LogLevel::Fatal);
        Harness {
            dir: dir.to_path_buf(),
            config,
            runs: 0,
            landed: Landed::default(),
        }
    }

    /// One input (see the module docs) against a fresh service.
    pub fn run(&mut self, data: &[u8]) {
        let name = format!("fuzz{}", self.runs);
        self.runs += 1;
        let node = NodeBuilder::new()
            .config(&self.config)
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
        let events = node
            .service_builder(&name.as_str().try_into().unwrap())
            .event()
            .max_notifiers(1)
            .max_listeners(2)
            .create()
            .unwrap();
        let notifier = events.notifier_builder().create().unwrap();
        let listener = events.listener_builder().create().unwrap();
        for n in 0..3 {
            publisher.send_copy(n).unwrap();
        }
        // One sample returned, one kept: the connection has chunks lent and returned.
        drop(subscriber.receive().unwrap());
        let kept = subscriber.receive().unwrap();

        let connections = records(&self.dir, ".connection");
        let dynamic = records(&self.dir, ".dynamic");
        let event_states = records(&self.dir, ".event_mgmt");
        let mut rest = data;
        while rest.len() >= 4 {
            let (file, at, len) = (
                rest[0],
                u16::from_le_bytes([rest[1], rest[2]]),
                rest[3] as usize,
            );
            let bytes = &rest[4..(4 + len).min(rest.len())];
            rest = &rest[(4 + len).min(rest.len())..];
            let (pool, landed) = if file >= 0xC0 {
                (&event_states, &mut self.landed.event)
            } else if file % 2 == 0 {
                (&connections, &mut self.landed.connection)
            } else {
                (&dynamic, &mut self.landed.dynamic)
            };
            if pool.is_empty() {
                continue;
            }
            let path = &pool[(file as usize / 2) % pool.len()];
            if let Ok(f) = std::fs::OpenOptions::new().write(true).open(path) {
                let size = f.metadata().map(|m| m.len()).unwrap_or(0);
                if size > 0 && f.write_all_at(bytes, u64::from(at) % size).is_ok() {
                    *landed += 1;
                }
            }
            // The publisher's side, as the frame loop drives it.
            for n in 0..2 {
                if let Ok(sample) = publisher.loan_uninit() {
                    let _ = sample.write_payload(n).send();
                }
                let _ = publisher.update_connections();
                let _ = notifier.notify();
            }
            // The client's side of the event: it drains its state.
            let _ = listener.try_wait(|_| {});
        }
        // The client's side goes too: it checks what it reads back (issue 34), and a port
        // leaked here would keep its mapping in the shared-range table, which holds 256.
        drop(kept);
        drop(listener);
        drop(notifier);
        drop(events);
        drop(subscriber);
        drop(publisher);
        drop(service);
        drop(node);
    }
}

/// The files under `dir` whose names end with `suffix`, sorted.
fn records(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    files.retain(|p| p.to_str().is_some_and(|n| n.ends_with(suffix)));
    files.sort();
    files
}
