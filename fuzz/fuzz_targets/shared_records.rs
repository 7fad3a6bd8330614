//! Issue 34: writes into the shared records a client may write, against a publisher driven as
//! deard's frame loop drives it. The harness (what an input means, what runs) is
//! `tests/src/shared_records.rs`, included here by path; the test tier runs the same harness on
//! stable with seeded inputs (`tests/tests/shared_records_fuzz.rs`).
#![no_main]

use std::sync::{Mutex, OnceLock};

use libfuzzer_sys::fuzz_target;

#[path = "../../tests/src/shared_records.rs"]
mod shared_records;

fn harness() -> &'static Mutex<shared_records::Harness> {
    static HARNESS: OnceLock<Mutex<shared_records::Harness>> = OnceLock::new();
    HARNESS.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("dear-fuzz-{}", std::process::id()));
        Mutex::new(shared_records::Harness::new(&dir))
    })
}

fuzz_target!(|data: &[u8]| {
    harness().lock().unwrap().run(data);
});
