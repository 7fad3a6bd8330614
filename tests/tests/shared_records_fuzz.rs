//! Issue 34: the `shared_records` fuzz target's harness (`fuzz/`, which needs nightly and
//! cargo-fuzz) run on stable in the test tier, on seeded random inputs instead of libFuzzer's
//! guided ones: write sequences into the subscriber's `*.connection`, the services' `*.dynamic`
//! and the listener's `*.event_mgmt` records while a publisher loans, sends, reclaims and
//! updates its connections and a notifier notifies. Neither side may crash nor hang (this
//! process would die or the tier time out), and afterwards a fresh service still delivers.
//!
//! `DEAR_FUZZ_RUNS` (default 1,000) and `DEAR_FUZZ_SEED` (default 1) run it longer or
//! differently; docs/security.md gives the figures of a run.

use std::path::Path;

use dear_e2e_tests::shared_records::Harness;
use iceoryx2::prelude::*;
use rand::{Rng, SeedableRng};

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .map(|v| {
            v.parse()
                .unwrap_or_else(|_| panic!("{name}={v:?} is not a number"))
        })
        .unwrap_or(default)
}

/// One input of up to 24 writes of up to 64 bytes, in the harness's format. Offsets are drawn
/// over the first 4 KiB, where the records' headers and tables lie, and half the bytes are
/// small integers (indices, counts and offsets near the valid ones), half arbitrary.
fn input(rng: &mut rand_pcg::Pcg64) -> Vec<u8> {
    let mut data = Vec::new();
    for _ in 0..rng.random_range(1..=24) {
        let len = rng.random_range(1..=64u8);
        data.push(rng.random::<u8>());
        data.extend_from_slice(&rng.random_range(0..4096u16).to_le_bytes());
        data.push(len);
        for _ in 0..len {
            let byte = if rng.random_bool(0.5) {
                rng.random_range(0..8)
            } else {
                rng.random()
            };
            data.push(byte);
        }
    }
    data
}

#[test]
fn random_writes_into_the_shared_records_cannot_crash_or_stall_the_publisher() {
    let root = tempfile::tempdir().unwrap();
    let mut harness = Harness::new(root.path());
    let (runs, seed) = (env_or("DEAR_FUZZ_RUNS", 1000), env_or("DEAR_FUZZ_SEED", 1));
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let start = std::time::Instant::now();
    for _ in 0..runs {
        harness.run(&input(&mut rng));
    }
    eprintln!(
        "{runs} runs of seed {seed} in {:.1} s: {:?}",
        start.elapsed().as_secs_f64(),
        harness.landed
    );
    // The writes reached every kind of record (a harness that found no files tests nothing).
    let landed = harness.landed;
    assert!(landed.connection > runs && landed.dynamic > runs && landed.event > runs / 2);

    // The transport still works: a fresh service under the same root delivers.
    let config = dear_proto::transport::node_config_from(
        iceoryx2::config::Config::global_config(),
        Some(root.path().as_os_str()),
    )
    .unwrap();
    let node = NodeBuilder::new()
        .config(&config)
        .create::<dear_proto::Transport>()
        .unwrap();
    let service = node
        .service_builder(&"after-fuzz".try_into().unwrap())
        .publish_subscribe::<u64>()
        .create()
        .unwrap();
    let publisher = service.publisher_builder().create().unwrap();
    let subscriber = service.subscriber_builder().create().unwrap();
    publisher.send_copy(42).unwrap();
    assert_eq!(subscriber.receive().unwrap().map(|s| *s), Some(42));
}

/// Inputs the guided fuzzer (`fuzz/`) crashed on, kept in `fuzz/regressions/shared_records`:
/// each must now run through, each in a fresh harness as libFuzzer ran it.
#[test]
fn the_inputs_the_fuzzer_crashed_on_run_through() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions/shared_records");
    let mut inputs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    inputs.sort();
    assert!(!inputs.is_empty(), "{}: no inputs", dir.display());
    for input in inputs {
        let root = tempfile::tempdir().unwrap();
        let mut harness = Harness::new(root.path());
        eprintln!("{}", input.display());
        harness.run(&std::fs::read(&input).unwrap());
    }
}
