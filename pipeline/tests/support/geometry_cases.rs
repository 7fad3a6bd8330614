//! The geometry test vectors shared with the Python training package (`train/`), which checks
//! its PyTorch port of `dear_pipeline::geometry` against them. Test support, outside the library:
//! included by `pipeline/tests/geometry_fixtures.rs` (the committed files still equal what the
//! code computes, so neither side can drift silently) and by the `write_geometry_fixtures`
//! example (which writes them to `fixtures/geometry/*.json`). The format is described in
//! `fixtures/geometry/README.md`.

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, ArrayBase, Data, Dimension};
use serde_json::{json, Map, Value};

use dear_capture::Calibration;
use dear_capture::Flow;
use dear_pipeline::geometry::surface::{DEPTH_EDGE_ABS_M, DEPTH_EDGE_REL};
use dear_pipeline::geometry::{flow_from_depth, splat, synthesize_view, warp_bilinear, warp_depth};
use dear_pipeline::recalibration::lsq::{
    solve_calibration, solve_calibration_robust, CalibrationFit, RobustOptions,
};

/// Height and width of every case.
pub const H: usize = 12;
pub const W: usize = 16;

/// One fixture: the file it lives in and its JSON document.
#[derive(Debug, Clone, PartialEq)]
pub struct FixtureCase {
    /// File name inside `fixtures/geometry/`, e.g. `warp_depth.json`.
    pub file_name: &'static str,
    /// `{"name", "description", "inputs", "outputs"}`.
    pub json: Value,
}

/// `fixtures/geometry/` at the repository root, as seen from this crate's sources.
pub fn fixtures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("fixtures")
        .join("geometry")
}

/// Write every case as pretty JSON into `dir` (created if missing); returns the paths written.
pub fn write_all(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    all_cases()
        .into_iter()
        .map(|case| {
            let path = dir.join(case.file_name);
            let mut text =
                serde_json::to_string_pretty(&case.json).map_err(std::io::Error::other)?;
            text.push('\n');
            std::fs::write(&path, text)?;
            Ok(path)
        })
        .collect()
}

/// Every case, in a fixed order.
pub fn all_cases() -> Vec<FixtureCase> {
    vec![
        warp_depth_case(),
        warp_bilinear_case(),
        lsq_case(),
        lsq_robust_case(),
        flow_from_depth_case(),
        synthesize_view_case(),
    ]
}

/// An f32 as the shortest decimal that reads back to the same f32 (so `0.1` and not
/// `0.10000000149011612`), stored as a JSON number.
fn num(x: f32) -> Value {
    let parsed: f64 = format!("{x}").parse().unwrap_or(f64::NAN);
    serde_json::Number::from_f64(parsed).map_or(Value::Null, Value::Number)
}

fn array_f32<S: Data<Elem = f32>, D: Dimension>(a: &ArrayBase<S, D>) -> Value {
    json!({ "shape": a.shape(), "dtype": "f32", "data": a.iter().map(|&x| num(x)).collect::<Vec<_>>() })
}

fn array_u8<S: Data<Elem = u8>, D: Dimension>(a: &ArrayBase<S, D>) -> Value {
    json!({ "shape": a.shape(), "dtype": "u8", "data": a.iter().copied().collect::<Vec<_>>() })
}

fn array_bool<S: Data<Elem = bool>, D: Dimension>(a: &ArrayBase<S, D>) -> Value {
    json!({ "shape": a.shape(), "dtype": "bool", "data": a.iter().copied().collect::<Vec<_>>() })
}

fn calibration(c: &Calibration) -> Value {
    json!({ "tx": num(c.tx), "ty": num(c.ty), "cx": num(c.cx), "cy": num(c.cy) })
}

fn fit_outputs(fit: &CalibrationFit) -> Value {
    json!({
        "calibration": calibration(&fit.calibration),
        "rms_residual_px": num(fit.rms_residual_px),
        "pixels_used": fit.pixels_used,
    })
}

fn depth_edge_params() -> Value {
    json!({ "depth_edge_rel": num(DEPTH_EDGE_REL), "depth_edge_abs_m": num(DEPTH_EDGE_ABS_M) })
}

fn case(file_name: &'static str, description: &str, inputs: Value, outputs: Value) -> FixtureCase {
    let mut doc = Map::new();
    doc.insert(
        "name".into(),
        Value::String(file_name.trim_end_matches(".json").into()),
    );
    doc.insert("description".into(), Value::String(description.into()));
    doc.insert("inputs".into(), inputs);
    doc.insert("outputs".into(), outputs);
    FixtureCase {
        file_name,
        json: Value::Object(doc),
    }
}

/// Deterministic values in `[0, 1)` (a SplitMix64 finaliser), so the fixtures need no RNG.
fn noise(i: usize) -> f32 {
    let mut x = (i as u64)
        .wrapping_add(1)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    (x >> 40) as f32 / (1u64 << 24) as f32
}

/// A depth map with a foreground step (left, ~1 m, slightly slanted) against a background
/// (right, ~2.5 m) and a few invalid pixels.
fn step_depth() -> Array2<f32> {
    Array2::from_shape_fn((H, W), |(y, x)| {
        if (y * W + x) % 13 == 5 {
            0.0
        } else if x < 7 {
            1.0 + 0.004 * y as f32 + 0.002 * x as f32
        } else {
            2.5 + 0.01 * y as f32 - 0.005 * x as f32
        }
    })
}

/// A flow with fractional parts everywhere and some samples pointing out of the image.
fn fractional_flow() -> Flow {
    Flow {
        u: Array2::from_shape_fn((H, W), |(y, x)| {
            let base = 2.0 * noise(2 * (y * W + x)) - 1.0 + 0.37;
            if x >= W - 2 {
                base + 1.5
            } else {
                base
            }
        }),
        v: Array2::from_shape_fn((H, W), |(y, x)| {
            let base = 1.6 * noise(2 * (y * W + x) + 1) - 0.8;
            if y == 0 {
                base - 1.0
            } else {
                base
            }
        }),
    }
}

fn warp_depth_case() -> FixtureCase {
    let src = step_depth();
    let flow = fractional_flow();
    let mut out = Array2::zeros((H, W));
    warp_depth(src.view(), &flow, out.view_mut());
    case(
        "warp_depth.json",
        "Depth-aware backward warp out(p) = src(p + W(p)). Sample points outside [0, w-1] x [0, h-1] \
         give 0. Among the 4 bilinear taps (order (y0,x0),(y0,x1),(y1,x0),(y1,x1)), taps with zero \
         weight or depth <= 0 are ignored; the remaining tap with the largest weight (first on ties) \
         is the reference z_ref; taps with |z - z_ref| <= max(depth_edge_rel * z_ref, depth_edge_abs_m) \
         are averaged with renormalised bilinear weights; no valid tap gives 0.",
        json!({ "src": array_f32(&src), "flow_u": array_f32(&flow.u), "flow_v": array_f32(&flow.v),
                "params": depth_edge_params() }),
        json!({ "out": array_f32(&out) }),
    )
}

fn warp_bilinear_case() -> FixtureCase {
    let src = Array2::from_shape_fn((H, W), |(y, x)| {
        1000.0 * noise(7 * (y * W + x) + 3) + 20.0 * x as f32
    });
    let flow = fractional_flow();
    let mut out = Array2::zeros((H, W));
    let mut valid = Array2::from_elem((H, W), false);
    warp_bilinear(src.view(), &flow, out.view_mut(), Some(valid.view_mut()));
    case(
        "warp_bilinear.json",
        "Plain bilinear backward warp out(p) = src(p + W(p)) for amplitude images. Sample points \
         outside [0, w-1] x [0, h-1] give out = 0 and valid = false; inside, valid = true.",
        json!({ "src": array_f32(&src), "flow_u": array_f32(&flow.u), "flow_v": array_f32(&flow.v) }),
        json!({ "out": array_f32(&out), "valid": array_bool(&valid) }),
    )
}

/// Depths from 0.6 to 4 m with a few invalid pixels.
fn lsq_depth() -> Array2<f32> {
    Array2::from_shape_fn((H, W), |(y, x)| {
        if (y * W + x) % 17 == 3 {
            0.0
        } else {
            0.6 + 3.4 * noise(5 * (y * W + x) + 11)
        }
    })
}

pub const LSQ_TRUE: Calibration = Calibration {
    tx: 9.0,
    ty: -3.0,
    cx: 2.5,
    cy: -1.5,
};

/// The model flow plus ±0.1 px of noise.
fn lsq_flow(depth: &Array2<f32>) -> Flow {
    let f = |(y, x): (usize, usize), k: usize| {
        let model = LSQ_TRUE
            .flow_at(depth[(y, x)])
            .map_or(0.0, |f| if k == 0 { f.0 } else { f.1 });
        model + 0.2 * (noise(3 * (y * W + x) + 100 + k) - 0.5)
    };
    Flow {
        u: Array2::from_shape_fn((H, W), |p| f(p, 0)),
        v: Array2::from_shape_fn((H, W), |p| f(p, 1)),
    }
}

fn lsq_weights() -> Array2<f32> {
    Array2::from_shape_fn((H, W), |(y, x)| {
        let r = noise(9 * (y * W + x) + 55);
        if r < 0.1 {
            0.0
        } else {
            r
        }
    })
}

const LSQ_DESCRIPTION: &str =
    "Per axis, minimise sum_p w_p (W(p) - (t / D(p) + c))^2 over pixels with \
     depth > 0 (finite), finite flow and weight > 0 (finite); accumulate in float64, centred: \
     a = 1/D, t = sum w (a - mean_a)(W - mean_W) / sum w (a - mean_a)^2, c = mean_W - t mean_a. \
     rms_residual_px = sqrt(sum w |W - W_model|^2 / sum w) (end-point, caller's weights).";

fn lsq_case() -> FixtureCase {
    let depth = lsq_depth();
    let flow = lsq_flow(&depth);
    let weights = lsq_weights();
    let fit = solve_calibration(&flow, depth.view(), Some(weights.view()))
        .expect("the lsq fixture is well conditioned by construction");
    case(
        "lsq.json",
        LSQ_DESCRIPTION,
        json!({ "flow_u": array_f32(&flow.u), "flow_v": array_f32(&flow.v), "depth": array_f32(&depth),
                "weights": array_f32(&weights), "true_calibration": calibration(&LSQ_TRUE) }),
        fit_outputs(&fit),
    )
}

fn lsq_robust_case() -> FixtureCase {
    let depth = lsq_depth();
    let mut flow = lsq_flow(&depth);
    // 20 % gross, one-sided outliers.
    for (i, (u, v)) in flow.u.iter_mut().zip(flow.v.iter_mut()).enumerate() {
        if noise(13 * i + 7) < 0.2 {
            *u += 6.0 + 20.0 * noise(13 * i + 8);
            *v -= 6.0 + 20.0 * noise(13 * i + 9);
        }
    }
    let options = RobustOptions {
        huber_delta_px: 0.5,
        iterations: 30,
        // Every pixel, as the Python mirror fits.
        max_samples: 0,
    };
    let fit = solve_calibration_robust(&flow, depth.view(), None, options)
        .expect("the lsq_robust fixture is well conditioned by construction");
    case(
        "lsq_robust.json",
        &format!(
            "{LSQ_DESCRIPTION} Robust variant (no caller weights here): start from the plain fit, then \
             up to `iterations` times refit with weights min(1, huber_delta_px / r), r the end-point \
             residual of the current fit; stop early once the predicted flow at the smallest and \
             largest valid inverse depth moves by < 1e-5 px. rms_residual_px uses unit weights."
        ),
        json!({ "flow_u": array_f32(&flow.u), "flow_v": array_f32(&flow.v), "depth": array_f32(&depth),
                "options": { "huber_delta_px": num(options.huber_delta_px), "iterations": options.iterations },
                "true_calibration": calibration(&LSQ_TRUE) }),
        fit_outputs(&fit),
    )
}

fn flow_from_depth_case() -> FixtureCase {
    let depth = step_depth();
    let calib = Calibration {
        tx: 6.5,
        ty: -2.25,
        cx: 1.75,
        cy: 0.5,
    };
    let (flow, valid) = flow_from_depth(depth.view(), &calib);
    case(
        "flow_from_depth.json",
        "W(p) = (tx / D(p) + cx, ty / D(p) + cy) where D(p) > 0 and finite; elsewhere flow 0 and valid = false.",
        json!({ "depth": array_f32(&depth), "calibration": calibration(&calib) }),
        json!({ "flow_u": array_f32(&flow.u), "flow_v": array_f32(&flow.v), "valid": array_bool(&valid) }),
    )
}

fn synthesize_view_case() -> FixtureCase {
    // A slanted background at ~2 m and a foreground block at ~1 m.
    let depth = Array2::from_shape_fn((H, W), |(y, x)| {
        if (3..=7).contains(&y) && (6..=10).contains(&x) {
            1.0 + 0.01 * x as f32
        } else {
            2.0 + 0.02 * x as f32 + 0.01 * y as f32
        }
    });
    let rgb: Array3<u8> = Array3::from_shape_fn((H, W, 3), |(y, x, c)| {
        (40 + 11 * x + 7 * y + 60 * c + (50.0 * noise(3 * (y * W + x) + c)) as usize) as u8
    });
    let perturbation = Calibration {
        tx: 2.6,
        ty: -1.3,
        cx: 0.45,
        cy: 0.3,
    };
    let view = synthesize_view(rgb.view(), depth.view(), &perturbation);
    case(
        "synthesize_view.json",
        &format!(
            "Forward splatting. Each source pixel q with depth z > 0 lands at q - P.flow_at(z) and spreads \
             bilinear weights over the 4 surrounding target pixels (weights <= {} and targets outside the \
             image dropped). Pass 1: per target, z_front = min landing depth. Pass 2: accumulate weight, \
             weight*z and weight*rgb of contributions with |z - z_front| <= max(depth_edge_rel * z_front, \
             depth_edge_abs_m). Pass 3: valid where the weight sum >= {}; depth = sum(w z)/sum(w), rgb = \
             floor(sum(w c)/sum(w) + 0.5), flow = P.flow_at(depth); invalid pixels are 0 everywhere.",
            splat::SPLAT_MIN_WEIGHT,
            splat::SPLAT_MIN_COVERAGE
        ),
        json!({ "rgb": array_u8(&rgb), "depth": array_f32(&depth), "perturbation": calibration(&perturbation),
                "params": { "depth_edge_rel": num(DEPTH_EDGE_REL), "depth_edge_abs_m": num(DEPTH_EDGE_ABS_M),
                            "min_weight": num(splat::SPLAT_MIN_WEIGHT), "min_coverage": num(splat::SPLAT_MIN_COVERAGE) } }),
        json!({ "rgb": array_u8(&view.rgb), "depth": array_f32(&view.depth), "flow_u": array_f32(&view.flow.u),
                "flow_v": array_f32(&view.flow.v), "valid": array_bool(&view.valid) }),
    )
}
