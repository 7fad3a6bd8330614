//! What the daemon does to each frame, writing straight into the output planes it is given
//! (the loaned shared-memory sample): align the ToF depth to the RGB grid with the current
//! calibration, then refine it.
//!
//! Until a model bundle is configured this is the *static* pipeline: the static calibration and
//! the classical edge-aware filter (`dear_pipeline::filter`).

use std::time::Instant;

use dear_pipeline::align::StaticAligner;
use dear_pipeline::filter::ClassicalRefiner;
use dear_pipeline::{Calibration, RgbdFrame};
use dear_proto::{flags, FrameHeader, Stage};
use ndarray::{Array2, ArrayViewMut2, ArrayViewMut3};

use crate::config::RefineMode;

/// The output planes of one frame (views over the shared-memory payload).
pub struct FrameOutput<'a> {
    /// `(H, W)` metres, 0 = invalid.
    pub depth: ArrayViewMut2<'a, f32>,
    /// `(H, W, 3)`.
    pub rgb: ArrayViewMut3<'a, u8>,
    /// `(H, W)`, 0 = invalid … 255 = measured and kept.
    pub confidence: ArrayViewMut2<'a, u8>,
}

/// Per-stream processing state (scratch buffers sized for the stream).
pub struct Processor {
    width: usize,
    height: usize,
    calibration: Calibration,
    aligner: StaticAligner,
    aligned: Array2<f32>,
    refiner: Option<ClassicalRefiner>,
}

impl Processor {
    /// A processor for `width`×`height` frames aligned with `calibration`.
    pub fn new(width: u32, height: u32, calibration: Calibration, refine: RefineMode) -> Self {
        let (w, h) = (width as usize, height as usize);
        Processor {
            width: w,
            height: h,
            calibration,
            aligner: StaticAligner::new(h, w),
            aligned: Array2::zeros((h, w)),
            refiner: match refine {
                RefineMode::Classical => Some(ClassicalRefiner::default()),
                RefineMode::None => None,
            },
        }
    }

    /// The calibration frames are aligned with.
    pub fn calibration(&self) -> Calibration {
        self.calibration
    }

    /// Processes `frame` into `out` and fills the header's calibration, flags and the
    /// warp/refine latencies. A frame of the wrong size is an error (the caller skips it).
    pub fn process_into(
        &mut self,
        frame: &RgbdFrame,
        header: &mut FrameHeader,
        mut out: FrameOutput<'_>,
    ) -> Result<(), String> {
        let (h, w) = frame.dim();
        if (h, w) != (self.height, self.width)
            || frame.rgb.dim() != (h, w, 3)
            || frame.amplitude.dim() != (h, w)
        {
            return Err(format!(
                "frame {} is {}x{} (rgb {:?}), the stream is {}x{}",
                frame.index,
                w,
                h,
                frame.rgb.dim(),
                self.width,
                self.height
            ));
        }
        let calib = self.calibration;
        header.calib_tx = calib.tx;
        header.calib_ty = calib.ty;
        header.calib_cx = calib.cx;
        header.calib_cy = calib.cy;
        header.calib_residual_px = f32::NAN;
        header.calib_quality = 0.0;
        header.calib_age_frames = 0;
        header.flags = flags::ALIGNED;

        let t = Instant::now();
        out.rgb.assign(&frame.rgb);
        match &mut self.refiner {
            Some(refiner) => {
                self.aligner
                    .align_into(frame.depth.view(), &calib, self.aligned.view_mut());
                header.stage_latency_us[Stage::Warp as usize] = micros(t);
                let t = Instant::now();
                refiner.refine_into(
                    self.aligned.view(),
                    frame.rgb.view(),
                    out.depth.view_mut(),
                    out.confidence.view_mut(),
                );
                header.stage_latency_us[Stage::Refine as usize] = micros(t);
                header.flags |= flags::REFINED_CLASSICAL;
            }
            None => {
                self.aligner
                    .align_into(frame.depth.view(), &calib, out.depth.view_mut());
                out.confidence
                    .zip_mut_with(&out.depth, |c, &z| *c = if z > 0.0 { 255 } else { 0 });
                header.stage_latency_us[Stage::Warp as usize] = micros(t);
            }
        }
        Ok(())
    }
}

/// Microseconds since `t`, saturating.
pub fn micros(t: Instant) -> u32 {
    t.elapsed().as_micros().min(u32::MAX as u128) as u32
}
