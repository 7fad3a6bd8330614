//! The online estimator's principal-point tracker on simulated sensor data: RGB and ToF
//! amplitude of `samples/demo` (rendered by `dear-synth`, different textures in the two
//! modalities), aligned with a calibration whose principal point is off by a known amount.
//! The edge check must measure that offset, with the sign the estimator applies.

use std::path::PathBuf;

use dear_capture::Calibration;
use dear_capture::CaptureDir;
use dear_pipeline::align::StaticAligner;
use dear_pipeline::geometry::{warp_bilinear, warp_depth};
use dear_pipeline::recalibration::EdgeCheck;
use ndarray::Array2;

fn demo() -> CaptureDir {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../samples/demo");
    CaptureDir::open(root).expect("samples/demo")
}

#[test]
fn the_edge_check_measures_a_principal_point_offset_on_sensor_data() {
    let capture = demo();
    let mut worst = 0.0f32;
    for position in [0, 14, 28] {
        let frame = capture.read_frame(position).unwrap();
        let truth = capture.manifest().frames[position]
            .perturbation
            .expect("the demo records its true calibration");
        let (h, w) = frame.depth.dim();
        let mut aligner = StaticAligner::new(h, w);
        let mut check = EdgeCheck::new(3);
        let (mut d_rgb, mut depth_w, mut amp_w) = (
            Array2::zeros((h, w)),
            Array2::zeros((h, w)),
            Array2::zeros((h, w)),
        );
        for (du, dv) in [(0.0, 0.0), (2.0, 0.0), (0.0, -2.0), (-1.5, 1.5)] {
            // The estimate's principal point is (du, dv) short of the truth.
            let estimate = Calibration {
                cx: truth.cx - du,
                cy: truth.cy - dv,
                ..truth
            };
            aligner.align_into(frame.depth.view(), &estimate, d_rgb.view_mut());
            warp_depth(frame.depth.view(), aligner.flow(), depth_w.view_mut());
            warp_bilinear(
                frame.amplitude.view(),
                aligner.flow(),
                amp_w.view_mut(),
                None,
            );
            let m = check
                .measure(frame.rgb.view(), amp_w.view(), depth_w.view())
                .expect("enough edges");
            let s = m.shift.expect("a clear correlation peak");
            let error = (s.du - du).hypot(s.dv - dv);
            worst = worst.max(error);
            assert!(
                error < 0.75,
                "frame {position}: offset ({du}, {dv}) measured ({:.2}, {:.2})",
                s.du,
                s.dv
            );
            if (du, dv) != (0.0, 0.0) {
                assert!(s.gain > 0.0, "frame {position}: {s:?}");
            }
        }
    }
    println!("worst principal-point error of the edge check: {worst:.2} px");
}
