//! The capture-directory codecs: a round trip keeps every value, and each kind of damage is
//! reported with the name of the damaged file.

use std::fs;
use std::path::Path;

use dear_capture::{
    png, CaptureDir, CaptureError, CaptureManifest, CaptureWriter, GroundTruth, Intrinsics, Sample,
};
use dear_capture::{Calibration, Flow, RgbdFrame};
use ndarray::{Array2, Array3};

const W: usize = 8;
const H: usize = 6;

fn sample(index: u64) -> Sample {
    let rgb = Array3::from_shape_fn((H, W, 3), |(r, c, k)| {
        (r * 40 + c * 7 + k * 3 + index as usize) as u8
    });
    let depth = Array2::from_shape_fn((H, W), |(r, c)| {
        if r == 0 && c == 0 {
            0.0
        } else {
            0.5 + 0.001 * (r * W + c) as f32
        }
    });
    let flow = Flow {
        u: Array2::from_shape_fn((H, W), |(r, c)| r as f32 * 0.25 - c as f32),
        v: Array2::from_shape_fn((H, W), |(r, c)| -(r as f32) + 0.5 * c as f32),
    };
    let amplitude = Array2::from_shape_fn((H, W), |(r, c)| (r * 1000 + c) as f32);
    Sample {
        frame: RgbdFrame::new(index, index * 33_333_333, rgb, amplitude, depth.clone()),
        truth: GroundTruth {
            depth: Some(depth.mapv(|z| z + 0.01)),
            mask: Some(Array2::from_shape_fn((H, W), |(r, c)| (r + c) % 3 != 0)),
            flow: Some(flow),
            perturbation: Some(Calibration {
                tx: 3.0,
                ty: -1.0,
                cx: 2.5,
                cy: 0.5,
            }),
        },
    }
}

fn write_capture(dir: &std::path::Path, frames: u64) {
    let manifest = CaptureManifest::new(
        W as u32,
        H as u32,
        Intrinsics::from_hfov(W as u32, H as u32, 60.0),
    );
    let mut writer = CaptureWriter::create(dir, manifest).unwrap();
    for i in 0..frames {
        let s = sample(i);
        writer.write_sample(&s.frame, &s.truth).unwrap();
    }
    writer.finish().unwrap();
}

#[test]
fn round_trip_keeps_every_value() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cap");
    write_capture(&dir, 3);
    let cap = CaptureDir::open(&dir).unwrap();
    assert_eq!(cap.len(), 3);
    assert!(cap.has_ground_truth());
    let Sample { frame: got, truth } = cap.read_sample(2).unwrap();
    let Sample {
        frame: want,
        truth: want_truth,
    } = sample(2);
    assert_eq!(got.index, 2);
    assert_eq!(got.timestamp_ns, want.timestamp_ns);
    assert_eq!(got.rgb, want.rgb);
    assert_eq!(got.amplitude, want.amplitude);
    assert_eq!(truth.mask, want_truth.mask);
    assert_eq!(truth.flow, want_truth.flow);
    assert_eq!(truth.perturbation, want_truth.perturbation);
    // Depth is quantised to millimetres on disk.
    for (a, b) in got.depth.iter().zip(want.depth.iter()) {
        assert!((a - b).abs() <= 0.0005 + 1e-6, "{a} vs {b}");
    }
    assert_eq!(got.depth[[0, 0]], 0.0, "invalid depth stays invalid");
    let gt = truth.depth.unwrap();
    assert!((gt[[1, 1]] - want_truth.depth.unwrap()[[1, 1]]).abs() <= 0.0005 + 1e-6);
}

fn expect_err_naming<T: std::fmt::Debug>(
    result: Result<T, CaptureError>,
    file: &std::path::Path,
    what: &str,
) {
    let err = result.expect_err("damaged frame must be an error");
    assert_eq!(err.path(), file, "error names the damaged file: {err}");
    let text = err.to_string();
    assert!(
        text.contains(&*file.to_string_lossy()),
        "message names the file: {text}"
    );
    assert!(
        text.contains(what),
        "message says what is wrong ({what}): {text}"
    );
}

/// The replay's read: only the sensor planes. A damaged ground-truth or flow file does not cost
/// it the frame (the full read reports it), a damaged sensor plane still does, by file.
#[test]
fn the_sensor_read_ignores_ground_truth_and_reports_sensor_planes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cap");
    write_capture(&dir, 3);
    let cap = CaptureDir::open(&dir).unwrap();

    let Sample { frame: full, truth } = cap.read_sample(0).unwrap();
    assert!(truth.depth.is_some() && truth.mask.is_some() && truth.flow.is_some());
    let sensor = cap.read_frame(0).unwrap();
    assert_eq!(sensor.rgb, full.rgb);
    assert_eq!(sensor.amplitude, full.amplitude);
    assert_eq!(sensor.depth, full.depth);
    assert_eq!(
        (sensor.index, sensor.timestamp_ns),
        (full.index, full.timestamp_ns)
    );

    fs::write(cap.frame_paths(1).gt_depth, b"not a png").unwrap();
    fs::write(cap.frame_paths(1).flow, b"PIEH").unwrap();
    assert!(cap.read_sample(1).is_err());
    cap.read_frame(1)
        .expect("a damaged ground truth does not cost the sensor frame");

    let depth = cap.frame_paths(2).depth;
    fs::write(&depth, b"not a png").unwrap();
    expect_err_naming(cap.read_frame(2), &depth, "cannot decode");
}

#[test]
fn damaged_frames_are_reported_by_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cap");
    write_capture(&dir, 5);
    let cap = CaptureDir::open(&dir).unwrap();

    // Missing file.
    fs::remove_file(cap.frame_paths(0).amplitude).unwrap();
    expect_err_naming(cap.read_frame(0), &cap.frame_paths(0).amplitude, "missing");

    // Truncated PNG.
    let rgb = cap.frame_paths(1).rgb;
    let bytes = fs::read(&rgb).unwrap();
    fs::write(&rgb, &bytes[..bytes.len() / 2]).unwrap();
    expect_err_naming(cap.read_frame(1), &rgb, "cannot decode");

    // Wrong bit depth: an 8-bit depth image.
    let depth = cap.frame_paths(2).depth;
    png::write_mask(&depth, Array2::from_elem((H, W), true).view()).unwrap();
    expect_err_naming(cap.read_frame(2), &depth, "16-bit");

    // Wrong resolution.
    let gt = cap.frame_paths(3).gt_depth;
    png::write_depth(&gt, Array2::from_elem((H + 1, W), 1.0).view(), 0.001).unwrap();
    expect_err_naming(cap.read_sample(3), &gt, "is 8x7");

    // Truncated flow file.
    let flo = cap.frame_paths(4).flow;
    let bytes = fs::read(&flo).unwrap();
    fs::write(&flo, &bytes[..bytes.len() - 4]).unwrap();
    expect_err_naming(cap.read_sample(4), &flo, "bytes");
}

#[test]
fn bad_manifest_names_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cap");
    write_capture(&dir, 2);
    let path = dir.join("capture.json");
    let text = fs::read_to_string(&path).unwrap();

    let cases = [
        (text.replace("\"version\": 1", "\"version\": 9"), "version"),
        (
            text.replace("\"depth_scale\": 0.001", "\"depth_scale\": -1.0"),
            "depth_scale",
        ),
        // Issue 34: 1e30 was accepted and every valid pixel published beyond 65 m.
        (
            text.replace("\"depth_scale\": 0.001", "\"depth_scale\": 1e30"),
            "depth_scale",
        ),
        (
            text.replace("\"depth_scale\": 0.001", "\"depth_scale\": 0.011"),
            "depth_scale",
        ),
        (text.replace("\"width\": 8", "\"width\": 0"), "width"),
        (
            text.replace("\"format\": \"dear-capture\"", "\"format\": \"other\""),
            "format",
        ),
        (
            text.replace("\"depth_scale\"", "\"depth_scael\""),
            "depth_scael",
        ),
        (text.replace("\"id\": 1", "\"id\": 0"), "appears twice"),
    ];
    for (bad, what) in cases {
        assert_ne!(bad, text, "test case for {what} must change the file");
        fs::write(&path, bad).unwrap();
        let err = CaptureDir::open(&dir).expect_err("bad manifest must be rejected");
        let msg = err.to_string();
        assert!(
            msg.contains("capture.json") && msg.contains(what),
            "{what}: {msg}"
        );
    }
    fs::remove_file(&path).unwrap();
    assert!(CaptureDir::open(&dir)
        .unwrap_err()
        .to_string()
        .contains("missing"));
}

#[test]
fn writer_refuses_a_non_empty_directory_and_out_of_order_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cap");
    write_capture(&dir, 1);
    let manifest = CaptureManifest::new(
        W as u32,
        H as u32,
        Intrinsics::from_hfov(W as u32, H as u32, 60.0),
    );
    assert!(CaptureWriter::create(&dir, manifest.clone()).is_err());
    let mut writer = CaptureWriter::create(tmp.path().join("b"), manifest).unwrap();
    writer.write_frame(&sample(3).frame).unwrap();
    assert!(writer.write_frame(&sample(2).frame).is_err());
}

/// Issue 34: a FIFO or a device where a capture file is expected is refused by its type, without
/// opening it (a FIFO blocked the reader until a writer came; `/dev/zero` as `capture.json`
/// grew to gigabytes), and the error names the file.
#[test]
fn a_fifo_or_device_in_a_capture_is_refused_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cap");
    write_capture(&dir, 2);
    let mkfifo = |path: &Path| {
        fs::remove_file(path).unwrap();
        let status = std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap();
        assert!(status.success());
    };
    let cap = CaptureDir::open(&dir).unwrap();
    let rgb = cap.frame_paths(1).rgb;
    mkfifo(&rgb);
    expect_err_naming(cap.read_frame(1), &rgb, "a FIFO");
    cap.read_frame(0).unwrap();

    let manifest = dir.join("capture.json");
    mkfifo(&manifest);
    let msg = CaptureDir::open(&dir).unwrap_err().to_string();
    assert!(
        msg.contains("capture.json") && msg.contains("a FIFO"),
        "{msg}"
    );
    fs::remove_file(&manifest).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &manifest).unwrap();
    let msg = CaptureDir::open(&dir).unwrap_err().to_string();
    assert!(
        msg.contains("capture.json") && msg.contains("a character device"),
        "{msg}"
    );
}
