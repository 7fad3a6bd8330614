//! `dear eval`: how much better is the depth, and at what cost — measured with the deployed
//! pipeline (`dear-pipeline`, the code the daemon runs), not with the training code.
//!
//! Rows: the ToF input as delivered; with `--baselines`, the classical methods of
//! [`dear_eval::Method`]; per `--bundle`, the DEAR chain's aligned depth (before
//! refinement), its output, and its refinement alone at the true calibration (the protocol of
//! the paper's Tables 2 and 3). Columns: AEPE of the rough and the final flow, depth MAE in
//! the paper's quantile split, coverage and time per frame.
//!
//! With `--online` (for sequences, `dear-synth sequence`), each bundle also runs in the
//! daemon's online-recalibration mode over the frames in order ("NAME online"): the library's
//! per-frame engine that deard runs (`dear_pipeline::engine`), its background measurement
//! replaced by the same measurement delivered exactly `--online-delay-frames` frames after the
//! frame that asked for it (by default the daemon's typical latency at the capture's frame
//! rate), so the rows are reproducible. `tracking.csv` records every frame's flow error for the
//! static calibration, per-frame estimation and the online filter: the tracking comparison of
//! a drifting calibration.

mod figures;

use std::fs;
use std::num::NonZeroU32;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use dear_capture::{CaptureDir, Sample};
use dear_eval::metrics::aepe;
use dear_eval::{
    ground_truth_flow, ground_truth_mask, BundleMethod, Evaluation, Method, MethodOutput,
    MethodReport, MethodRunner, OnlineBundleMethod,
};
use dear_pipeline::engine::{typical_delay_frames, MeasurementSchedule};
use dear_pipeline::model::ModelBundle;
use dear_pipeline::recalibration::{HealthReport, OnlineConfig};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

/// Arguments of `dear eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Capture directory with ground truth (`frames/NNNNNN.gt.png` for every frame).
    #[arg(long)]
    pub capture: PathBuf,
    /// Model bundle to evaluate; repeat for several. Rows are named after the directory.
    #[arg(long = "bundle")]
    pub bundles: Vec<PathBuf>,
    /// Also run the classical baselines: static calibration, edge matching + least squares,
    /// the classical edge-aware filter, and the true calibration (an upper bound).
    #[arg(long)]
    pub baselines: bool,
    /// Where to write eval.json, eval.md and figures/.
    #[arg(long, default_value = "eval-out")]
    pub out: PathBuf,
    /// Evaluate at most this many frames, evenly spaced over the capture.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Frames to draw figures for (evenly spaced over the evaluated ones; 0: none).
    #[arg(long, default_value_t = 2)]
    pub figures: usize,
    /// The capture is a sequence: also run every bundle with the daemon's online
    /// recalibration over the frames in order, and write tracking.csv.
    #[arg(long)]
    pub online: bool,
    /// Online mode: run the rough-flow network at least every this many frames (the daemon's
    /// `online_interval_frames`).
    #[arg(long, default_value_t = OnlineConfig::default().interval_frames)]
    pub online_interval: u32,
    /// Online mode: fraction of the edge check's principal-point correction applied per frame
    /// between network runs (the daemon's `online_track_gain`; 0 turns tracking off).
    #[arg(long, default_value_t = OnlineConfig::default().track_gain)]
    pub online_track_gain: f32,
    /// Online mode: frames from a network frame to the delivery of its measurement, standing
    /// in for deard's background worker (default: its typical latency at the capture's frame
    /// rate and size, `dear_pipeline::engine::typical_delay_frames`); 0 measures on the frame
    /// itself, as deard's `online_network = "inline"`.
    #[arg(long)]
    pub online_delay_frames: Option<u32>,
}

/// What `eval.json` holds.
#[derive(Debug, Serialize)]
struct EvalFile {
    capture: String,
    frames_evaluated: usize,
    frames_skipped: Vec<String>,
    /// The method the figures show.
    figures_method: Option<String>,
    figures: Vec<String>,
    methods: Vec<MethodReport>,
    /// `--online`: per bundle, on how many frames the online mode ran the rough-flow network.
    online_network_frames: Vec<(String, usize)>,
    /// `--online`: frames from a network frame to the delivery of its measurement (0: on the
    /// frame itself).
    #[serde(skip_serializing_if = "Option::is_none")]
    online_delay_frames: Option<u32>,
}

/// Positions `0..len` thinned to at most `limit`, evenly spaced, first included.
fn select(len: usize, limit: Option<usize>) -> Vec<usize> {
    match limit {
        Some(n) if n < len => (0..n).map(|i| i * len / n.max(1)).collect(),
        _ => (0..len).collect(),
    }
}

/// The capture's frame rate from its timestamps (`None` with fewer than two frames, or when
/// they span no time).
fn capture_fps(capture: &CaptureDir) -> Option<f64> {
    let frames = &capture.manifest().frames;
    let (first, last) = (frames.first()?, frames.last()?);
    let span_s = last.timestamp_ns.checked_sub(first.timestamp_ns)? as f64 * 1e-9;
    (frames.len() > 1 && span_s > 0.0).then(|| (frames.len() - 1) as f64 / span_s)
}

/// A bundle's row names.
fn bundle_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// Runs the evaluation; see the module docs.
pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    let capture = CaptureDir::open(&args.capture)
        .with_context(|| format!("cannot open capture {}", args.capture.display()))?;
    if capture.is_empty() {
        bail!("{}: the capture has no frames", args.capture.display());
    }
    if let Some(missing) = (0..capture.len()).find(|&i| !capture.frame_paths(i).gt_depth.is_file())
    {
        bail!(
            "{}: frame {} has no ground truth ({}); dear eval needs ground-truth depth for every \
             frame (captures from `dear-synth` have it; recordings from a device do not)",
            args.capture.display(),
            capture.manifest().frames[missing].id,
            capture.frame_paths(missing).gt_depth.display()
        );
    }
    let (w, h) = capture.size();
    let (w, h) = (w as usize, h as usize);
    let initial = capture.manifest().initial_calibration;
    let mut classical = vec![Method::RawTof];
    if args.baselines {
        classical.extend(Method::CLASSICAL.iter().filter(|m| **m != Method::RawTof));
    }
    let mut runner = MethodRunner::new(h, w, initial);
    let online_config = OnlineConfig {
        interval_frames: args.online_interval,
        track_gain: args.online_track_gain,
        ..OnlineConfig::default()
    };
    let online_delay = args.online.then(|| {
        args.online_delay_frames.unwrap_or_else(|| {
            let fps = capture_fps(&capture).unwrap_or_else(|| {
                eprintln!(
                    "dear eval: the capture's timestamps give no frame rate; the online \
                     measurement's delay assumes 30 fps (set --online-delay-frames)"
                );
                30.0
            });
            typical_delay_frames(w, h, fps).get()
        })
    });
    let schedule = match online_delay.and_then(NonZeroU32::new) {
        Some(frames) => MeasurementSchedule::Delayed(frames),
        None => MeasurementSchedule::Inline,
    };
    let mut bundles = Vec::new();
    // Per bundle with `--online`: the daemon's engine, and on how many frames it measured.
    let mut online: Vec<Option<(OnlineBundleMethod, usize)>> = Vec::new();
    for path in &args.bundles {
        let bundle = ModelBundle::load(path)
            .with_context(|| format!("cannot load model bundle {}", path.display()))?;
        let name = bundle_name(path);
        let prepare = || format!("cannot prepare bundle {} for {w}×{h}", path.display());
        // The capture's static calibration is the one in use: the chain moves it only when
        // the frame clearly shows it wrong, as deard does with its factory calibration.
        bundles.push(
            BundleMethod::new(&bundle, &name, h, w)
                .with_context(prepare)?
                .with_reference(Some(initial)),
        );
        online.push(if args.online {
            // The capture's static calibration is the prior, as the daemon's (issue 32).
            let method =
                OnlineBundleMethod::new(&bundle, &name, (h, w), initial, online_config, schedule)
                    .with_context(prepare)?;
            Some((method, 0))
        } else {
            None
        });
    }
    let mut tracking = String::from(
        "frame,method,aepe_px,flow_network,health,constrained,correction_px,uncertainty_px,\
         held_back,disagreement,shift_px,shift_ncc,shift_at_limit\n",
    );
    let positions = select(capture.len(), args.frames);
    let figure_positions: Vec<usize> = select(positions.len(), Some(args.figures))
        .into_iter()
        .map(|i| positions[i])
        .collect();
    let figures_dir = args.out.join("figures");
    fs::create_dir_all(&figures_dir)
        .with_context(|| format!("cannot create {}", figures_dir.display()))?;

    let bar = ProgressBar::new(positions.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("eval {bar:30} {pos}/{len} frames  {elapsed} (eta {eta})")
            .expect("static template"),
    );
    let mut eval = Evaluation::new();
    let mut skipped = Vec::new();
    let mut figure_files = Vec::new();
    let mut figures_method = None;
    for &pos in &positions {
        bar.inc(1);
        let id = capture.manifest().frames[pos].id;
        let sample = match capture.read_sample(pos) {
            Ok(s) => s,
            Err(e) => {
                bar.suspend(|| eprintln!("dear eval: skipping frame {id}: {e}"));
                skipped.push(format!("frame {id}: {e}"));
                continue;
            }
        };
        let frame = &sample.frame;
        let valid = ground_truth_mask(&sample)?;
        let truth = ground_truth_flow(&sample);
        let mut add = |name: &str,
                       out: &MethodOutput,
                       network: Option<bool>,
                       health: Option<HealthReport>| {
            eval.add(name, &sample, out, valid.view(), truth.as_ref());
            if let (true, Some(flow), Some(truth)) = (args.online, &out.flow, &truth) {
                let error = aepe(flow, truth, valid.view()).unwrap_or(f64::NAN);
                let network = network.map_or(String::new(), |n| u8::from(n).to_string());
                let health = health.map_or_else(
                    || ",,,,,,,,".to_string(),
                    |h| {
                        let a = h.frame_alignment;
                        let shift = a.and_then(|a| a.shift);
                        format!(
                            "{},{},{:.4},{:.4},{},{},{},{},{}",
                            h.state.name(),
                            h.constrained,
                            h.correction_px,
                            h.uncertainty_px,
                            h.held_back,
                            a.map_or(String::new(), |a| format!("{:.4}", a.disagreement)),
                            shift.map_or(String::new(), |s| format!("{:.3}", s.du.hypot(s.dv))),
                            shift.map_or(String::new(), |s| format!("{:.3}", s.peak_ncc)),
                            shift.map_or(String::new(), |s| u8::from(s.at_limit).to_string()),
                        )
                    },
                );
                tracking.push_str(&format!("{id},{name},{error:.4},{network},{health}\n"));
            }
        };

        // The figures show the first bundle's output, else the classical pipeline's.
        let mut shown: Option<(String, ndarray::Array2<f32>)> = None;
        let mut bundle_shown = false;
        for &method in &classical {
            if let Some(out) = runner.run(method, &sample) {
                add(method.name(), &out, None, None);
                if method == Method::StaticClassical || shown.is_none() {
                    shown = Some((method.name().to_string(), out.depth));
                }
            }
        }
        for (b, online) in bundles.iter_mut().zip(&mut online) {
            let name = b.name().to_string();
            match b.run(frame) {
                Ok(o) => {
                    add(&format!("{name} aligned"), &o.aligned, None, None);
                    add(&name, &o.refined, Some(true), None);
                    if !bundle_shown {
                        shown = Some((name.clone(), o.refined.depth));
                        bundle_shown = true;
                    }
                }
                Err(e) => {
                    bar.suspend(|| eprintln!("dear eval: {name} failed on frame {id}: {e}"));
                    skipped.push(format!("frame {id}: bundle {name}: {e}"));
                    continue;
                }
            }
            if let Some(result) = b.run_refine_only(&sample) {
                match result {
                    Ok(out) => add(
                        &format!("{name} refine @ true calibration"),
                        &out,
                        None,
                        None,
                    ),
                    Err(e) => skipped.push(format!("frame {id}: bundle {name} refine-only: {e}")),
                }
            }
            if let Some((method, network_frames)) = online {
                match method.run(frame) {
                    Ok((out, report)) => {
                        *network_frames += usize::from(report.measured);
                        add(
                            &format!("{name} online"),
                            &out,
                            Some(report.measured),
                            method.engine().online().map(|o| o.health()),
                        );
                    }
                    Err(e) => skipped.push(format!("frame {id}: bundle {name} online: {e}")),
                }
            }
        }
        if figure_positions.contains(&pos) {
            if let Some((method, depth)) = &shown {
                figure_files.extend(write_figures(&figures_dir, &sample, depth.view())?);
                figures_method = Some(method.clone());
            }
        }
    }
    bar.finish_and_clear();

    let reports = eval.reports();
    let frames_evaluated = reports.first().map_or(0, |r| r.frames);
    let file = EvalFile {
        capture: args.capture.display().to_string(),
        frames_evaluated,
        frames_skipped: skipped,
        figures_method,
        figures: figure_files,
        methods: reports,
        online_network_frames: online
            .iter()
            .flatten()
            .map(|(m, n)| (m.name().to_string(), *n))
            .collect(),
        online_delay_frames: online_delay,
    };
    let markdown = markdown(&file, &eval);
    fs::create_dir_all(&args.out)?;
    let json_path = args.out.join("eval.json");
    fs::write(&json_path, serde_json::to_string_pretty(&file)? + "\n")
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    let md_path = args.out.join("eval.md");
    fs::write(&md_path, &markdown)
        .with_context(|| format!("cannot write {}", md_path.display()))?;
    if args.online {
        let csv_path = args.out.join("tracking.csv");
        fs::write(&csv_path, &tracking)
            .with_context(|| format!("cannot write {}", csv_path.display()))?;
    }
    crate::write_stdout(&markdown)?;
    eprintln!(
        "dear eval: wrote {} and {}",
        json_path.display(),
        md_path.display()
    );
    Ok(())
}

/// Panel, blends and scan line of one frame; returns the files' paths relative to the output
/// directory.
fn write_figures(
    dir: &Path,
    sample: &Sample,
    result: ndarray::ArrayView2<f32>,
) -> anyhow::Result<Vec<String>> {
    let frame = &sample.frame;
    let stem = format!("{:06}", frame.index);
    let gt = sample.truth.depth.as_ref().expect("checked above").view();
    let row = figures::scanline_row(gt);
    let files = [
        (
            format!("{stem}.panel.png"),
            figures::panel(frame, gt, result),
        ),
        (format!("{stem}.blend.png"), figures::blends(frame, result)?),
        (
            format!("{stem}.scanline-row{row}.png"),
            figures::scanline_plot(frame, gt, result, row),
        ),
    ];
    let mut names = Vec::new();
    for (name, img) in files {
        figures::save(&img, &dir.join(&name))?;
        names.push(format!("figures/{name}"));
    }
    Ok(names)
}

fn markdown(file: &EvalFile, eval: &Evaluation) -> String {
    let mut md = format!(
        "# dear eval: {}\n\n{} frames evaluated{}.\n\n",
        file.capture,
        file.frames_evaluated,
        if file.frames_skipped.is_empty() {
            String::new()
        } else {
            format!(", {} skipped (see eval.json)", file.frames_skipped.len())
        }
    );
    md.push_str(
        "AEPE: average end-point error of the flow against the ground truth over valid pixels. \
         MAE: depth error within 4 m, pixels split by the *input's* error (low 0–25 %, mid \
         25–50 %, high 50–75 %; \"all\" includes the worst quarter). ms / frame: median wall \
         time of the method on this machine.\n\n",
    );
    md.push_str(&eval.markdown());
    for (name, n) in &file.online_network_frames {
        let frames = file.frames_evaluated;
        let how = match file.online_delay_frames {
            Some(0) | None => format!(
                "ran on {n} of {frames} frames; the others were aligned with the filtered estimate"
            ),
            Some(d) => format!(
                "measured {n} of {frames} frames off the frame path, each measurement delivered \
                 {d} frames later (as deard's background worker); every frame was aligned with \
                 the filtered estimate"
            ),
        };
        md.push_str(&format!(
            "\n{name} online: the rough-flow network {how} (tracking.csv has every frame's \
             flow error).\n"
        ));
    }
    if let Some(method) = &file.figures_method {
        md.push_str(&format!(
            "\nFigures ({method}): panels are RGB | amplitude | ToF depth | result | ground truth \
             | |error| (0–{:.0} cm); blends show depth over RGB before | after; scan lines show \
             ToF (grey), result (red) and ground truth (green) along one row.\n\n",
            100.0 * figures::ERROR_MAP_MAX_M
        ));
        for f in &file.figures {
            md.push_str(&format!("![{f}]({f})\n"));
        }
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selection_is_even_and_bounded() {
        assert_eq!(select(10, None), (0..10).collect::<Vec<_>>());
        assert_eq!(select(10, Some(20)), (0..10).collect::<Vec<_>>());
        assert_eq!(select(10, Some(5)), vec![0, 2, 4, 6, 8]);
        assert_eq!(select(10, Some(0)), Vec::<usize>::new());
    }
}
