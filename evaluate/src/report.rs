//! Accumulating metrics per method over frames, and rendering them as JSON and Markdown.

use serde::Serialize;

use crate::methods::MethodOutput;
use crate::metrics::{
    aepe, DepthErrorSplit, Reliability, ReliabilityBin, TemporalChange, CLASSES, MAX_EVAL_DEPTH_M,
};
use dear_capture::Flow;
use dear_capture::Sample;
use ndarray::{Array2, ArrayView2};

/// Accumulated results of one method.
#[derive(Debug, Clone, Default)]
pub struct MethodAccumulator {
    split: DepthErrorSplit,
    aepe_sum: f64,
    aepe_frames: usize,
    aepe_rough_sum: f64,
    aepe_rough_frames: usize,
    seconds: Vec<f64>,
    /// Methods that publish expected-error codes: predicted against measured error.
    reliability: Option<Reliability>,
    temporal: TemporalChange,
    /// The last frame added: its index, the method's depth and the masked ground truth.
    previous: Option<(u64, Array2<f32>, Array2<f32>)>,
}

/// The summary of one method, as printed and written.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MethodReport {
    pub method: String,
    pub frames: usize,
    /// MAE in cm within 4 m per input-error class: low, mid, high, outliers.
    pub mae_cm: [Option<f64>; 4],
    /// MAE in cm over all evaluated pixels.
    pub mae_all_cm: Option<f64>,
    /// Fraction of evaluated pixels the method left valid.
    pub coverage: f64,
    /// Mean over frames of the per-frame AEPE (px) of the method's flow, when it has one.
    pub aepe_px: Option<f64>,
    /// The same for the rough (network) flow, for methods that have one.
    pub aepe_rough_px: Option<f64>,
    /// Median seconds per frame ([`dear_stats::median`]: nearest rank, the lower middle frame
    /// for an even count).
    pub median_seconds: f64,
    /// Mean frame-to-frame change (cm) on static surfaces over consecutive evaluated frames
    /// ([`TemporalChange`]); `None` without two consecutive frames.
    pub temporal_change_cm: Option<f64>,
    /// Predicted against measured error per bin, for methods whose confidence is an
    /// expected-error code; empty otherwise.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub reliability: Vec<ReliabilityBin>,
}

/// An evaluation in progress: one accumulator per method name, in insertion order.
#[derive(Debug, Clone, Default)]
pub struct Evaluation {
    methods: Vec<(String, MethodAccumulator)>,
}

impl Evaluation {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `output` of method `name` on `frame`; `valid` is the ground-truth mask and
    /// `truth` the ground-truth flow ([`super::ground_truth_flow`]), when known.
    pub fn add(
        &mut self,
        name: &str,
        sample: &Sample,
        output: &MethodOutput,
        valid: ArrayView2<bool>,
        truth: Option<&Flow>,
    ) {
        let acc = match self.methods.iter().position(|(n, _)| n == name) {
            Some(i) => &mut self.methods[i].1,
            None => {
                self.methods
                    .push((name.to_string(), MethodAccumulator::default()));
                &mut self.methods.last_mut().expect("just pushed").1
            }
        };
        let frame = &sample.frame;
        let gt = sample
            .truth
            .depth
            .as_ref()
            .expect("caller checked ground truth");
        let gt_masked = ndarray::Zip::from(gt)
            .and(valid)
            .map_collect(|&z, &v| if v { z } else { 0.0 });
        acc.split.add_frame(
            frame.depth.view(),
            output.depth.view(),
            gt_masked.view(),
            MAX_EVAL_DEPTH_M,
        );
        if let (Some(flow), Some(truth)) = (&output.flow, truth) {
            if let Some(e) = aepe(flow, truth, valid) {
                acc.aepe_sum += e;
                acc.aepe_frames += 1;
            }
        }
        if let (Some(flow), Some(truth)) = (&output.flow_rough, truth) {
            if let Some(e) = aepe(flow, truth, valid) {
                acc.aepe_rough_sum += e;
                acc.aepe_rough_frames += 1;
            }
        }
        if let Some(codes) = &output.expected_error_code {
            let predicted =
                codes.mapv(|v| dear_proto::confidence::expected_error_m(v).unwrap_or(f32::NAN));
            acc.reliability
                .get_or_insert_with(Reliability::default)
                .add_frame(
                    output.depth.view(),
                    predicted.view(),
                    gt_masked.view(),
                    MAX_EVAL_DEPTH_M,
                );
        }
        if let Some((index, depth, gt)) = &acc.previous {
            if index + 1 == frame.index {
                acc.temporal.add_pair(
                    (depth.view(), gt.view()),
                    (output.depth.view(), gt_masked.view()),
                    MAX_EVAL_DEPTH_M,
                );
            }
        }
        acc.previous = Some((frame.index, output.depth.clone(), gt_masked));
        acc.seconds.push(output.seconds);
    }

    /// The per-method summaries, in the order methods were first added.
    pub fn reports(&self) -> Vec<MethodReport> {
        self.methods
            .iter()
            .map(|(name, acc)| {
                let mut seconds = acc.seconds.clone();
                dear_stats::sort(&mut seconds);
                MethodReport {
                    method: name.clone(),
                    frames: acc.seconds.len(),
                    mae_cm: [0, 1, 2, 3].map(|k| acc.split.mae_cm(k)),
                    mae_all_cm: acc.split.mae_all_cm(),
                    coverage: acc.split.coverage(),
                    aepe_px: (acc.aepe_frames > 0).then(|| acc.aepe_sum / acc.aepe_frames as f64),
                    aepe_rough_px: (acc.aepe_rough_frames > 0)
                        .then(|| acc.aepe_rough_sum / acc.aepe_rough_frames as f64),
                    median_seconds: dear_stats::median(&seconds).unwrap_or(f64::NAN),
                    temporal_change_cm: acc.temporal.mean_cm(),
                    reliability: acc.reliability.map_or_else(Vec::new, |r| r.bins()),
                }
            })
            .collect()
    }

    /// A Markdown table of the reports (paper Tables 1–3 in one: AEPE, split MAE, time).
    pub fn markdown(&self) -> String {
        let mut out = String::from("| Method | AEPE rough (px) | AEPE (px) |");
        for c in CLASSES.iter().take(3) {
            out.push_str(&format!(" MAE {c} (cm) |"));
        }
        out.push_str(
            " MAE all (cm) | Coverage | Flicker (cm) | ms / frame |\n\
             |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        let fmt = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.2}"));
        let reports = self.reports();
        for r in &reports {
            out.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {:.1} % | {} | {:.1} |\n",
                r.method,
                fmt(r.aepe_rough_px),
                fmt(r.aepe_px),
                fmt(r.mae_cm[0]),
                fmt(r.mae_cm[1]),
                fmt(r.mae_cm[2]),
                fmt(r.mae_all_cm),
                100.0 * r.coverage,
                fmt(r.temporal_change_cm),
                1e3 * r.median_seconds
            ));
        }
        for r in reports.iter().filter(|r| !r.reliability.is_empty()) {
            out.push_str(&format!(
                "\nReliability of {}'s expected-error confidence (pixels within 4 m):\n\n\
                 | predicted (cm) | pixels | mean predicted (cm) | mean measured (cm) |\n\
                 |---|---:|---:|---:|\n",
                r.method
            ));
            for b in &r.reliability {
                let range = match b.predicted_hi_cm {
                    Some(hi) => format!("{}–{}", b.predicted_lo_cm, hi),
                    None => format!("≥ {}", b.predicted_lo_cm),
                };
                out.push_str(&format!(
                    "| {range} | {} | {:.2} | {:.2} |\n",
                    b.pixels, b.mean_predicted_cm, b.mean_measured_cm
                ));
            }
        }
        out
    }
}
