//! The frame service's shared memory is what the protocol says: a data segment of
//! [`samples_in_shared_memory`] frames, and each received payload starts at
//! [`PAYLOAD_ALIGNMENT`]. (With the payload aligned to 64 through iceoryx2, every payload byte
//! took 64: a 1.4 GB data file for a 320×240 stream, 1.2 TB sparse for 8192×8192.) The
//! segment is a file in the transport's root directory, not in `/dev/shm`.

use std::collections::BTreeSet;
use std::path::PathBuf;

use dear_proto::transport::{node_config_from, prepare_root};
use dear_proto::{
    frame_service, samples_in_shared_memory, FrameHeader, PayloadLayout, Transport,
    PAYLOAD_ALIGNMENT,
};
use iceoryx2::prelude::*;

/// The iceoryx2 data segments in `dir`.
fn data_segments(dir: &std::path::Path) -> BTreeSet<PathBuf> {
    std::fs::read_dir(dir)
        .expect("the root directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "data"))
        .collect()
}

#[test]
fn the_data_segment_holds_the_protocols_samples_and_payloads_are_aligned() {
    // An odd size, so no other stream's segment can be mistaken for this one.
    let (w, h) = (104u32, 37u32);
    let layout = PayloadLayout::new(w, h).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let config = node_config_from(
        &iceoryx2::config::Config::default(),
        Some(tmp.path().join("root").as_os_str()),
    )
    .unwrap();
    let root = prepare_root(&config).unwrap();
    let node = NodeBuilder::new()
        .config(&config)
        .create::<Transport>()
        .unwrap();
    let name = dear_test_support::process::unique_service("shm-size");
    let service = frame_service(&node, &name).unwrap();
    let publisher = service
        .publisher_builder()
        .initial_max_slice_len(layout.size)
        .create()
        .unwrap();
    let subscriber = service.subscriber_builder().create().unwrap();

    let want = (samples_in_shared_memory() * layout.size) as u64;
    let sizes: Vec<u64> = data_segments(&root)
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok().map(|m| m.len()))
        .collect();
    // Per sample iceoryx2 adds its own header and our 256-byte one: allow 1 KiB a sample.
    let slack = (samples_in_shared_memory() * 1024) as u64;
    assert!(
        sizes.iter().any(|&s| s >= want && s <= want + slack),
        "data segments {sizes:?} bytes; want {want}..={} ({} samples of {} bytes)",
        want + slack,
        samples_in_shared_memory(),
        layout.size
    );

    let mut sample = publisher.loan_slice(layout.size).unwrap();
    *sample.user_header_mut() = FrameHeader::new(1, w, h);
    sample.send().unwrap();
    let received = subscriber.receive().unwrap().expect("the sample arrives");
    let address = received.payload().as_ptr() as usize;
    assert_eq!(address % PAYLOAD_ALIGNMENT, 0, "payload at {address:#x}");
    received
        .user_header()
        .validate(received.payload().len())
        .unwrap();
}
