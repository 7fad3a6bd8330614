//! `dear-eval`: the evaluation behind `dear eval`, and nothing the runtime needs. Its one job is
//! to measure methods on captures with ground truth. Each [`Method`] runs the same
//! `dear-pipeline` code the daemon runs; the [`Evaluation`] accumulates the paper's metrics
//! ([`metrics`]) per method, with the time each method took, so accuracy and cost come from one
//! run. `deard` does not depend on this crate (`scripts/test.sh` checks `cargo tree -p deard`).
//!
//! - [`metrics`]: AEPE and the paper's quantile-split depth MAE;
//! - [`methods`]: the alignment and refinement methods, with the classical
//!   [`edge_matching`] baseline;
//! - [`bundle`]: a model bundle's chain, per frame or online through the daemon's engine;
//! - [`report`]: metric accumulation and the per-method report.

#![forbid(unsafe_code)]

pub mod bundle;
pub mod edge_matching;
pub mod methods;
pub mod metrics;
pub mod report;

pub use bundle::{BundleMethod, BundleOutputs, OnlineBundleMethod};
pub use methods::{Method, MethodOutput, MethodRunner};
pub use report::{Evaluation, MethodReport};

use ndarray::{Array2, Zip};

use dear_capture::flo::UNKNOWN_FLOW;
use dear_capture::Flow;
use dear_capture::Sample;

/// Why a frame cannot be evaluated.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EvalError {
    #[error(
        "frame {frame} has no ground-truth depth (frames/{frame:06}.gt.png); evaluation needs it"
    )]
    NoGroundTruth { frame: u64 },
}

/// Pixels where the ground truth is usable: valid gt depth, the mask (when present), and a
/// known ground-truth flow (when present).
pub fn ground_truth_mask(sample: &Sample) -> Result<Array2<bool>, EvalError> {
    let truth = &sample.truth;
    let gt = truth.depth.as_ref().ok_or(EvalError::NoGroundTruth {
        frame: sample.frame.index,
    })?;
    let mut valid = gt.mapv(dear_capture::is_valid_depth);
    if let Some(mask) = &truth.mask {
        Zip::from(&mut valid).and(mask).for_each(|v, &m| *v &= m);
    }
    if let Some(flow) = &truth.flow {
        Zip::from(&mut valid)
            .and(&flow.u)
            .and(&flow.v)
            .for_each(|v, &u, &w| {
                *v &= u.is_finite()
                    && w.is_finite()
                    && u.abs() < UNKNOWN_FLOW / 10.0
                    && w.abs() < UNKNOWN_FLOW / 10.0;
            });
    }
    Ok(valid)
}

/// The ground-truth RGB→ToF flow of a frame: its `.flo` file, else the flow its recorded
/// perturbation predicts at the ground-truth depth (aligned captures record a zero
/// perturbation and no flow file). `None` when neither is known.
pub fn ground_truth_flow(sample: &Sample) -> Option<Flow> {
    let truth = &sample.truth;
    if let Some(flow) = &truth.flow {
        return Some(flow.clone());
    }
    let (p, gt) = (truth.perturbation?, truth.depth.as_ref()?);
    let mut flow = Flow::zeros(gt.nrows(), gt.ncols());
    Zip::from(&mut flow.u)
        .and(&mut flow.v)
        .and(gt)
        .for_each(|u, v, &z| {
            (*u, *v) = p.flow_at(z).unwrap_or((f32::NAN, f32::NAN));
        });
    Some(flow)
}
