//! The DEAR chain against PyTorch (`fixtures/parity`, made by `make_parity.py` with the same
//! untrained bundle): every intermediate and the refined depth agree; the `Cached` modes behave
//! as documented; bad inputs are errors.
#![cfg(feature = "inference")]

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use dear_capture::{Calibration, Flow};
use dear_eval::metrics;
use dear_pipeline::align::StaticAligner;
use dear_pipeline::chain::{
    CachedFusion, ChainError, ChainInput, ChainMode, ChainOptions, ChainOutput, DearChain,
};
use dear_pipeline::geometry::warp_depth;
use dear_pipeline::model::ModelBundle;
use dear_pipeline::recalibration::Evidence;
use ndarray::{s, Array2, Array3, ArrayView2, Axis};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The parity vectors: planes by name, `(C, H, W)`.
struct Parity {
    h: usize,
    w: usize,
    calibration: Calibration,
    planes: HashMap<String, Array3<f32>>,
}

impl Parity {
    fn load() -> Parity {
        let dir = root().join("fixtures/parity");
        let doc: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("parity.json")).unwrap())
                .unwrap();
        let mut planes = HashMap::new();
        for (name, p) in doc["planes"].as_object().unwrap() {
            let shape: Vec<usize> = p["shape"]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| d.as_u64().unwrap() as usize)
                .collect();
            let bytes = std::fs::read(dir.join(p["file"].as_str().unwrap())).unwrap();
            let data: Vec<f32> = bytes
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            let a = Array3::from_shape_vec((shape[0], shape[1], shape[2]), data).unwrap();
            planes.insert(name.clone(), a);
        }
        let c = &doc["calibration"];
        let f = |k: &str| c[k].as_f64().unwrap() as f32;
        Parity {
            h: doc["height"].as_u64().unwrap() as usize,
            w: doc["width"].as_u64().unwrap() as usize,
            calibration: Calibration {
                tx: f("tx"),
                ty: f("ty"),
                cx: f("cx"),
                cy: f("cy"),
            },
            planes,
        }
    }

    fn plane(&self, name: &str, c: usize) -> ArrayView2<'_, f32> {
        self.planes[name].index_axis(Axis(0), c)
    }

    fn flow(&self, name: &str) -> Flow {
        Flow {
            u: self.plane(name, 0).to_owned(),
            v: self.plane(name, 1).to_owned(),
        }
    }

    fn rgb(&self) -> Array3<u8> {
        let p = &self.planes["rgb_u8"];
        Array3::from_shape_fn((self.h, self.w, 3), |(y, x, c)| p[[c, y, x]] as u8)
    }
}

fn bundle() -> ModelBundle {
    ModelBundle::load(root().join("fixtures/bundles/smoke-edge")).unwrap()
}

/// Largest |a − b| over pixels where `mask` holds.
fn max_diff(a: ArrayView2<f32>, b: ArrayView2<f32>, mask: impl Fn(usize, usize) -> bool) -> f32 {
    let mut m = 0.0f32;
    for ((y, x), &va) in a.indexed_iter() {
        if mask(y, x) {
            m = m.max((va - b[[y, x]]).abs());
        }
    }
    m
}

fn max_flow_diff(a: &Flow, b: &Flow) -> f32 {
    max_diff(a.u.view(), b.u.view(), |_, _| true).max(max_diff(a.v.view(), b.v.view(), |_, _| true))
}

/// The chain without the direct fit: the three networks and the least squares only.
fn paper_chain() -> ChainOptions {
    ChainOptions {
        direct_fit: None,
        ..ChainOptions::default()
    }
}

struct Outputs {
    depth: Array2<f32>,
    confidence: Array2<u8>,
}

fn run(
    chain: &mut DearChain,
    p: &Parity,
    mode: ChainMode,
) -> (dear_pipeline::chain::ChainReport, Outputs) {
    let rgb = p.rgb();
    let mut out = Outputs {
        depth: Array2::zeros((p.h, p.w)),
        confidence: Array2::zeros((p.h, p.w)),
    };
    let report = chain
        .process(
            ChainInput {
                rgb: rgb.view(),
                amplitude: p.plane("amplitude_raw", 0),
                depth: p.plane("tof_depth", 0),
            },
            mode,
            ChainOutput {
                depth: out.depth.view_mut(),
                confidence: out.confidence.view_mut(),
            },
        )
        .unwrap();
    (report, out)
}

#[test]
fn full_chain_matches_pytorch() {
    let p = Parity::load();
    // The paper's chain, as PyTorch runs it: no direct fit after the network's calibration.
    let mut chain = DearChain::with_options(&bundle(), p.w, p.h, paper_chain()).unwrap();
    let (report, out) = run(&mut chain, &p, ChainMode::Full);
    assert!(report.ran_flow_network && report.ran_fusion_network);

    let amp = max_diff(
        chain.amplitude().view(),
        p.plane("amplitude_norm", 0),
        |_, _| true,
    );
    assert!(amp < 1e-5, "normalised amplitude differs by {amp}");
    let rough = max_flow_diff(chain.flow_rough(), &p.flow("flow_rough"));
    assert!(rough < 1e-3, "W_rough differs by {rough} px");

    let m = report.measurement.clone().unwrap().unwrap();
    let c = m.calibration;
    let pc = p.calibration;
    for (a, b, name) in [
        (c.tx, pc.tx, "tx"),
        (c.ty, pc.ty, "ty"),
        (c.cx, pc.cx, "cx"),
        (c.cy, pc.cy, "cy"),
    ] {
        assert!((a - b).abs() < 2e-3, "{name}: rust {a}, pytorch {b}");
    }
    let convt = max_flow_diff(chain.flow_convt(), &p.flow("flow_convt"));
    assert!(convt < 2e-3, "W_convt differs by {convt} px");
    let refined = max_flow_diff(chain.flow_refined(), &p.flow("flow_refined"));
    assert!(refined < 2e-3, "W_refn differs by {refined} px");

    // Depth: 1 mm wherever the warped depth is valid, no depth where it is not.
    let valid = p.plane("depth_valid", 0);
    let want = p.plane("depth_refined", 0);
    let (mut checked, mut off) = (0usize, 0usize);
    for ((y, x), &v) in valid.indexed_iter() {
        if v > 0.5 {
            checked += 1;
            if (out.depth[[y, x]] - want[[y, x]]).abs() > 1e-3 {
                off += 1;
            }
        } else {
            assert_eq!(
                out.depth[[y, x]],
                0.0,
                "no measurement at ({y},{x}) but a depth"
            );
            assert_eq!(out.confidence[[y, x]], 0);
        }
    }
    println!(
        "parity: W_rough {rough:.2e} px, W_convt {convt:.2e} px, W_refn {refined:.2e} px, \
         {off} of {checked} refined depths beyond 1 mm"
    );
    assert!(checked > 5000, "only {checked} valid pixels");
    assert!(
        off * 200 <= checked,
        "{off} of {checked} refined depths differ by > 1 mm"
    );
    let warped = max_diff(
        chain.depth_warped().view(),
        p.plane("depth_warped", 0),
        |y, x| valid[[y, x]] > 0.5,
    );
    assert!(warped < 1e-3, "warped depth differs by {warped}");
    // The chain reports the same coverage as PyTorch's validity mask.
    let fixture_valid = checked as f32 / valid.len() as f32;
    assert!(
        (report.valid_fraction - fixture_valid).abs() < 0.01,
        "valid fraction: rust {}, pytorch {fixture_valid}",
        report.valid_fraction
    );
    assert!(report.timings.flow > std::time::Duration::ZERO);
    assert!(out.confidence.iter().any(|&c| c > 200));
}

#[test]
fn each_network_matches_pytorch_on_pytorch_inputs() {
    let p = Parity::load();
    let mut chain = DearChain::new(&bundle(), p.w, p.h).unwrap();
    let runner = chain.runner_mut();
    let rgb = [
        p.plane("rgb_u8", 0),
        p.plane("rgb_u8", 1),
        p.plane("rgb_u8", 2),
    ]
    .map(|c| c.mapv(|v| v / 255.0));

    let mut flow = Flow::zeros(p.h, p.w);
    runner
        .flow(
            [rgb[0].view(), rgb[1].view(), rgb[2].view()],
            p.plane("amplitude_norm", 0),
            &mut flow,
        )
        .unwrap();
    let d = max_flow_diff(&flow, &p.flow("flow_rough"));
    assert!(d < 1e-3, "flow.onnx: {d} px");

    runner
        .fuse(&p.flow("flow_rough"), &p.flow("flow_convt"), &mut flow)
        .unwrap();
    let d = max_flow_diff(&flow, &p.flow("flow_refined"));
    assert!(d < 1e-3, "fuse.onnx: {d} px");

    let mut depth = Array2::zeros((p.h, p.w));
    runner
        .refine(
            p.plane("amplitude_warped", 0),
            p.plane("depth_warped", 0),
            Some([rgb[0].view(), rgb[1].view(), rgb[2].view()]),
            None,
            depth.view_mut(),
        )
        .unwrap();
    let d = max_diff(depth.view(), p.plane("depth_refined", 0), |_, _| true);
    assert!(d < 1e-3, "refine.onnx: {d} m");
}

#[test]
fn cached_mode_skips_the_flow_network_and_warps_with_the_calibration_flow() {
    let p = Parity::load();
    let calib = p.calibration;
    let mut chain = DearChain::new(&bundle(), p.w, p.h).unwrap();
    assert_eq!(chain.options().cached_fusion, CachedFusion::Skip);
    let (report, out) = run(&mut chain, &p, ChainMode::Cached(calib));
    assert!(!report.ran_flow_network && !report.ran_fusion_network);
    assert!(report.measurement.is_none());
    assert_eq!(report.calibration, Some(calib));
    assert_eq!(report.timings.flow, std::time::Duration::ZERO);

    // The flow is the calibration's flow at the splatted depth (the static aligner's); the
    // refiner's input is the ToF depth warped with it like in `Full` mode (and in training).
    let mut aligner = StaticAligner::new(p.h, p.w);
    let mut splat = Array2::zeros((p.h, p.w));
    aligner.align_into(p.plane("tof_depth", 0), &calib, splat.view_mut());
    assert_eq!(chain.flow_refined(), aligner.flow());
    let mut want = Array2::zeros((p.h, p.w));
    warp_depth(p.plane("tof_depth", 0), aligner.flow(), want.view_mut());
    assert_eq!(chain.depth_warped(), &want);
    for ((y, x), &z) in want.indexed_iter() {
        if z > 0.0 {
            assert!(out.depth[[y, x]] > 0.0);
        } else {
            assert_eq!((out.depth[[y, x]], out.confidence[[y, x]]), (0.0, 0));
        }
    }

    chain.set_cached_fusion(CachedFusion::Run);
    let (report, _) = run(&mut chain, &p, ChainMode::Cached(calib));
    assert!(!report.ran_flow_network && report.ran_fusion_network);
    assert!(report.timings.fuse > std::time::Duration::ZERO);
}

#[test]
fn wrong_shapes_are_errors_and_write_nothing() {
    let p = Parity::load();
    let mut chain = DearChain::new(&bundle(), p.w, p.h).unwrap();
    let rgb = p.rgb();
    let mut depth = Array2::from_elem((p.h, p.w), 7.0f32);
    let mut conf = Array2::zeros((p.h, p.w));
    let short = p.plane("tof_depth", 0).slice_move(s![..p.h - 1, ..]);
    let err = chain
        .process(
            ChainInput {
                rgb: rgb.view(),
                amplitude: p.plane("amplitude_raw", 0),
                depth: short,
            },
            ChainMode::Full,
            ChainOutput {
                depth: depth.view_mut(),
                confidence: conf.view_mut(),
            },
        )
        .unwrap_err();
    assert!(
        matches!(err, ChainError::Shape { what: "depth", .. }),
        "{err}"
    );
    assert!(depth.iter().all(|&z| z == 7.0));
}

/// The Cached-mode decision (see `chain::dear_chain::CachedFusion`): on the parity frame, with the
/// true calibration, compare the final flow and depth of Skip and Run against ground truth.
/// Prints the figures (`cargo test -p dear-pipeline --test model_chain -- --nocapture`).
#[test]
fn cached_fusion_choice_on_ground_truth() {
    let p = Parity::load();
    let truth = Calibration {
        tx: 4.0,
        ty: -2.5,
        cx: 2.0,
        cy: -1.5,
    };
    let gt_depth = p.plane("gt_depth", 0);
    let gt_flow = p.flow("gt_flow");
    let mut chain = DearChain::with_options(&bundle(), p.w, p.h, paper_chain()).unwrap();
    let mut results = Vec::new();
    for (name, mode, fusion) in [
        ("full", ChainMode::Full, CachedFusion::Skip),
        ("cached-skip", ChainMode::Cached(truth), CachedFusion::Skip),
        ("cached-run", ChainMode::Cached(truth), CachedFusion::Run),
    ] {
        chain.set_cached_fusion(fusion);
        let (report, out) = run(&mut chain, &p, mode);
        let f = chain.flow_refined();
        let (mut epe, mut mae, mut n, mut nd) = (0.0f64, 0.0f64, 0usize, 0usize);
        for ((y, x), &z) in gt_depth.indexed_iter() {
            if z > 0.0 {
                epe += f64::from(
                    (f.u[[y, x]] - gt_flow.u[[y, x]]).hypot(f.v[[y, x]] - gt_flow.v[[y, x]]),
                );
                n += 1;
                if out.depth[[y, x]] > 0.0 && z < 4.0 {
                    mae += f64::from((out.depth[[y, x]] - z).abs());
                    nd += 1;
                }
            }
        }
        let (epe, mae_cm) = (epe / n as f64, 100.0 * mae / nd as f64);
        println!(
            "{name:12} AEPE {epe:.3} px, depth MAE {mae_cm:.2} cm, warped-input MAE {:.2} cm, {:?}",
            {
                let w = chain.depth_warped();
                let (mut s, mut k) = (0.0f64, 0usize);
                for ((y, x), &z) in gt_depth.indexed_iter() {
                    if z > 0.0 && z < 4.0 && w[[y, x]] > 0.0 {
                        s += f64::from((w[[y, x]] - z).abs());
                        k += 1;
                    }
                }
                100.0 * s / k as f64
            },
            report.timings.total()
        );
        results.push((name, epe));
    }
    // With the true calibration, the calibration flow alone is (near) exact: skipping fusion
    // must align at least as well as a full run of the (untrained) networks.
    assert!(results[1].1 < 0.5, "cached-skip AEPE {}", results[1].1);
    assert!(results[1].1 <= results[0].1, "{results:?}");
}

/// `Full` mode by default refines the network's calibration by the direct fit to the frame's
/// edges; when that fit is confident, the frame is aligned by its calibration exactly as a
/// `Cached` frame is (no fusion, the splat's flow), and closer to the truth than the untrained
/// networks' flow.
#[test]
fn full_mode_refines_the_network_calibration_by_the_direct_fit() {
    let p = Parity::load();
    let gt_flow = p.flow("gt_flow");
    let valid = p.plane("gt_depth", 0).mapv(|z| z > 0.0);
    let aepe = |f: &Flow| metrics::aepe(f, &gt_flow, valid.view()).unwrap();
    let mut paper = DearChain::with_options(&bundle(), p.w, p.h, paper_chain()).unwrap();
    run(&mut paper, &p, ChainMode::Full);
    let paper_aepe = aepe(paper.flow_refined());

    let mut chain = DearChain::new(&bundle(), p.w, p.h).unwrap();
    assert!(chain.options().direct_fit.is_some());
    let (report, _) = run(&mut chain, &p, ChainMode::Full);
    assert!(report.ran_flow_network && report.ran_direct_fit);
    let m = report.measurement.unwrap().unwrap();
    assert!(
        matches!(m.evidence, Evidence::Edges { correlation, .. } if correlation > 0.2),
        "the direct fit should be confident on the parity frame: {m:?}"
    );
    assert!(!report.ran_fusion_network);
    assert_eq!(report.calibration, Some(m.calibration));
    let mut aligner = StaticAligner::new(p.h, p.w);
    let mut splat = Array2::zeros((p.h, p.w));
    aligner.align_into(p.plane("tof_depth", 0), &m.calibration, splat.view_mut());
    assert_eq!(chain.flow_refined(), aligner.flow());
    let direct_aepe = aepe(chain.flow_refined());
    println!("parity frame AEPE: paper chain {paper_aepe:.3} px, with the direct fit {direct_aepe:.3} px");
    assert!(direct_aepe < paper_aepe, "{direct_aepe} vs {paper_aepe}");
}

/// The background worker measures a frame exactly as a `Full` frame does inline, never makes
/// its caller wait, takes one frame at a time, and refuses a frame of the wrong shape.
#[test]
fn the_background_worker_measures_what_a_full_frame_measures() {
    use dear_pipeline::chain::{BackgroundCalibrator, Submit};
    let p = Parity::load();
    let mut inline = DearChain::new(&bundle(), p.w, p.h).unwrap();
    let (report, _) = run(&mut inline, &p, ChainMode::Full);
    let full = report.measurement.unwrap();
    // `measure` alone gives the same measurement as the full frame.
    let rgb = p.rgb();
    let input = ChainInput {
        rgb: rgb.view(),
        amplitude: p.plane("amplitude_raw", 0),
        depth: p.plane("tof_depth", 0),
    };
    let measured = inline.measure(input).unwrap();
    assert_eq!(measured.measurement, full);
    assert!(measured.ran_direct_fit);

    let worker_chain = DearChain::new(&bundle(), p.w, p.h).unwrap();
    let mut worker = BackgroundCalibrator::spawn(worker_chain, "test-calibrate").unwrap();
    assert!(worker.poll().is_none(), "nothing submitted yet");
    assert_eq!(worker.try_submit(input, 7u32).unwrap(), Submit::Started);
    assert!(worker.is_busy());
    // One frame at a time: a second submission while the first runs is refused, not queued.
    assert_eq!(worker.try_submit(input, 8u32).unwrap(), Submit::Busy);
    let delivered = worker.wait().expect("the submitted frame's measurement");
    assert_eq!(delivered.ticket, 7);
    assert_eq!(delivered.report.unwrap().measurement, full);
    assert!(!worker.is_busy() && !worker.is_stopped());

    // A wrong shape is an error naming the plane, and the worker stays usable.
    let small = Array2::<f32>::zeros((p.h - 1, p.w));
    let bad = ChainInput {
        depth: small.view(),
        ..input
    };
    match worker.try_submit(bad, 9) {
        Err(ChainError::Shape { what, .. }) => assert_eq!(what, "depth"),
        other => panic!("expected a shape error, got {other:?}"),
    }
    assert_eq!(worker.try_submit(input, 10).unwrap(), Submit::Started);
    assert_eq!(worker.wait().unwrap().ticket, 10);
}

/// The worker runs at the lowest scheduling priority (the `SCHED_IDLE` policy, and nice 19 for a
/// caller at nice 0), so under load it takes what the frame path leaves (`background.rs` says
/// what nice +10 and nice +19 alone cost); so do the threads of its own rayon pool, where its
/// parallel loops run instead of the frame path's.
#[cfg(target_os = "linux")]
#[test]
fn the_background_worker_runs_at_the_lowest_priority() {
    use dear_pipeline::chain::BackgroundCalibrator;
    let p = Parity::load();
    let chain = DearChain::new(&bundle(), p.w, p.h).unwrap();
    let name = "nice-worker"; // within the 15 bytes a thread name keeps
    let worker = BackgroundCalibrator::<u32>::spawn(chain, name).unwrap();
    // A thread's nice value and scheduling policy: fields 19 and 41 of its `stat` (counted
    // after the `(comm)` field, which may hold spaces).
    let priority_in = |stat: &str| -> Option<(i64, u32)> {
        let fields: Vec<&str> = stat[stat.rfind(')')? + 2..].split_whitespace().collect();
        Some((fields.get(16)?.parse().ok()?, fields.get(38)?.parse().ok()?))
    };
    let priority_of = |comm: &str| -> Option<(i64, u32)> {
        std::fs::read_dir("/proc/self/task").ok()?.find_map(|task| {
            let dir = task.ok()?.path();
            let this = std::fs::read_to_string(dir.join("comm")).ok()?;
            if this.trim() != comm {
                return None;
            }
            priority_in(&std::fs::read_to_string(dir.join("stat")).ok()?)
        })
    };
    let (own, _) = priority_in(&std::fs::read_to_string("/proc/thread-self/stat").unwrap())
        .expect("the test thread's own nice value");
    // Entering SCHED_IDLE needs no privilege (leaving it does), so it is expected everywhere.
    let expected = Some(((own + 19).min(19), libc::SCHED_IDLE as u32));
    // Each thread lowers its priority as it starts: wait for it to show.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    let settled_priority_of = |comm: &str| loop {
        let priority = priority_of(comm);
        if priority == expected || std::time::Instant::now() > deadline {
            break priority;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    };
    assert_eq!(
        settled_priority_of(name),
        expected,
        "the worker's (nice, policy) (caller at nice {own})"
    );
    // So do the threads of its pool, where the measurement's parallel loops run: one per
    // thread of the caller's pool.
    let pool_threads = rayon::current_num_threads();
    for index in 0..pool_threads {
        let comm = format!("{name}-{index}");
        assert_eq!(
            settled_priority_of(&comm),
            expected,
            "{comm}'s (nice, policy) (caller at nice {own})"
        );
    }
    assert_eq!(
        priority_of(&format!("{name}-{pool_threads}")),
        None,
        "the pool has as many threads as the caller's"
    );
    drop(worker);
}
