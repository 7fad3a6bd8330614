//! iceoryx2's own log reaches the daemon's: its warnings (the only report of a client that
//! cannot connect) as `tracing` events of target `iceoryx2` at WARN, with a short origin instead
//! of iceoryx2's `Debug` dump of the port; below WARN nothing, and not the start-up warning that
//! no iceoryx2 config file exists.

use std::io::Write;
use std::sync::{Arc, Mutex};

#[derive(Clone, Default)]
struct Buffer(Arc<Mutex<Vec<u8>>>);

impl Write for Buffer {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(bytes);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn iceoryx2_warnings_reach_the_daemons_log_and_debug_does_not() {
    std::env::remove_var("IOX2_LOG_LEVEL");
    let buffer = Buffer::default();
    let writer = buffer.clone();
    tracing_subscriber::fmt()
        .with_writer(move || writer.clone())
        .with_ansi(false)
        .with_max_level(tracing::Level::TRACE)
        .init();
    deard::iceoryx_log::install();

    // As iceoryx2 logs `from self`: the port's Debug form, here 10 KB.
    #[derive(Debug)]
    #[allow(dead_code)] // read through Debug only
    struct Receiver {
        connections: Vec<u32>,
    }
    let port = Receiver {
        connections: vec![0; 2000],
    };
    iceoryx2_log::warn!(from port, "Unable to establish connection to new receiver 42.");
    iceoryx2_log::debug!(from "Receiver", "a debug detail");

    let log = String::from_utf8(buffer.0.lock().unwrap().clone()).unwrap();
    let line = log
        .lines()
        .find(|l| l.contains("Unable to establish connection to new receiver 42."))
        .unwrap_or_else(|| panic!("the warning is not in the log:\n{log}"));
    assert!(line.contains("WARN") && line.contains("iceoryx2"), "{line}");
    assert!(line.contains("origin=\"Receiver\""), "{line}");
    assert!(
        line.len() < 300,
        "the port's dump is cut: {} bytes",
        line.len()
    );
    assert!(!log.contains("a debug detail"), "{log}");
    assert!(!log.contains("No config file was loaded"), "{log}");
}
