//! Helpers of the end-to-end tests: test bundles, the expected pipeline output of a frame, and
//! the `deard` command line and probe client of these tests. What every crate's tests share
//! (the daemon handle, log waits, test captures) is in `dear-test-support`.

pub mod bundles;
pub mod engines;
pub mod processes;
pub mod shared_records;

/// Hex SHA-256 of bytes (what the probe prints for each frame's payload): the bundle
/// format's digest.
pub use dear_pipeline::model::hex_sha256 as sha256_hex;

use std::collections::BTreeMap;

use dear_capture::CaptureDir;
use dear_proto::{FrameHeader, PayloadLayout};
use deard::config::PipelineConfig;
use deard::processing::{FrameOutput, Processor};
use ndarray::{Array2, Array3};

/// What the daemon configured with `pipeline` must publish for each readable frame of
/// `capture` (frame id → SHA-256 of the payload), computed in this process by the same `deard`
/// processing code (frames in order, so the online calibrator sees what the daemon sees).
pub fn expected_payload_hashes(
    capture: &CaptureDir,
    pipeline: &PipelineConfig,
) -> BTreeMap<u64, String> {
    let (w, h) = capture.size();
    let calibration = capture.manifest().initial_calibration;
    let mut processor =
        Processor::from_config(w, h, calibration, pipeline).expect("the pipeline configuration");
    let layout = PayloadLayout::new(w, h).expect("the test capture fits the frame protocol");
    let mut hashes = BTreeMap::new();
    for position in 0..capture.len() {
        let Ok(frame) = capture.read_frame(position) else {
            continue;
        };
        let (hu, wu) = (h as usize, w as usize);
        let mut depth = Array2::<f32>::zeros((hu, wu));
        let mut rgb = Array3::<u8>::zeros((hu, wu, 3));
        let mut confidence = Array2::<u8>::zeros((hu, wu));
        let mut header = FrameHeader::new(frame.index, w, h);
        let out = FrameOutput {
            depth: depth.view_mut(),
            rgb: rgb.view_mut(),
            confidence: confidence.view_mut(),
        };
        if processor.process_into(&frame, &mut header, out).is_err() {
            continue;
        }
        let mut payload = Vec::with_capacity(layout.size);
        payload.extend(depth.iter().flat_map(|z| z.to_le_bytes()));
        payload.extend(rgb.iter());
        payload.extend(confidence.iter());
        assert_eq!(payload.len(), layout.size);
        hashes.insert(frame.index, sha256_hex(&payload));
    }
    hashes
}
