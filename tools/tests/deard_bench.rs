//! `deard-bench` runs the daemon's processing over a real capture and reports what it claims:
//! every measured frame counted once, split by whether the flow network ran, stage medians and
//! resident memory, in its JSON as in its text.

use std::path::PathBuf;
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Runs `deard-bench` on `samples/demo` with the smoke bundle and `args`; returns its
/// standard output and its `--json` report (it must succeed).
fn bench(args: &[&str]) -> (String, serde_json::Value) {
    let tmp = tempfile::tempdir().unwrap();
    let json = tmp.path().join("bench.json");
    let out = Command::new(env!("CARGO_BIN_EXE_deard-bench"))
        .current_dir(root())
        .args([
            "--capture",
            "samples/demo",
            "--bundle",
            "fixtures/bundles/smoke-edge",
        ])
        .args(args)
        .arg("--json")
        .arg(&json)
        .output()
        .expect("run deard-bench");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    (stdout, report)
}

#[test]
fn deard_bench_reports_every_measured_frame() {
    let (stdout, report) = bench(&[
        "--frames",
        "5",
        "--warmup",
        "1",
        "--mode",
        "online",
        "--mode",
        "every-frame",
    ]);
    assert!(
        stdout.contains("online:") && stdout.contains("every-frame:"),
        "{stdout}"
    );
    assert_eq!(
        (report["width"].as_u64(), report["height"].as_u64()),
        (Some(320), Some(240))
    );
    let modes = report["modes"].as_array().unwrap();
    assert_eq!(modes.len(), 2);
    for m in modes {
        let count = |k: &str| m[k]["count"].as_u64().unwrap_or(0);
        assert_eq!(m["all"]["count"].as_u64(), Some(5), "{m}");
        assert_eq!(count("with_network") + count("without_network"), 5, "{m}");
        assert!(m["all"]["median_ms"].as_f64().unwrap() > 0.0);
        assert!(m["rss_end_mib"].as_f64().unwrap() > 1.0);
        // Processing a frame takes CPU time, counted over every thread.
        assert!(m["cpu_ms_per_frame"].as_f64().unwrap() > 0.0, "{m}");
        let stages = m["stage_median_ms"].as_array().unwrap();
        assert!(
            stages
                .iter()
                .any(|s| s[0] == "refine" && s[1].as_f64().unwrap() > 0.0),
            "{m}"
        );
    }
    // The paper's mode runs the network on every frame; the online mode warms up on it (its
    // first frames) and then uses it at most on a few.
    assert_eq!(modes[1]["with_network"]["count"].as_u64(), Some(5));
    assert_eq!(modes[0]["mode"], "online");
    // Back to back, online mode (network in the background) prepares every frame but the
    // last beside the previous one's refinement; the paper's mode runs a network in every
    // frame's first half and never overlaps. A frame's latency spans its two halves.
    assert_eq!(
        modes[0]["overlapped_frames"].as_u64(),
        Some(5),
        "{}",
        modes[0]
    );
    assert_eq!(
        modes[1]["overlapped_frames"].as_u64(),
        Some(0),
        "{}",
        modes[1]
    );
    for m in modes {
        assert_eq!(m["latency"]["count"].as_u64(), Some(5), "{m}");
        assert!(m["latency"]["median_ms"].as_f64().unwrap() > 0.0, "{m}");
    }
}

#[test]
fn deard_bench_sequential_never_overlaps_frames() {
    let (_, report) = bench(&[
        "--frames",
        "3",
        "--warmup",
        "1",
        "--mode",
        "online",
        "--sequential",
    ]);
    let online = &report["modes"][0];
    assert_eq!(online["overlapped_frames"].as_u64(), Some(0), "{online}");
    assert_eq!(online["all"]["count"].as_u64(), Some(3), "{online}");
}

#[test]
fn deard_bench_names_a_missing_capture() {
    let out = Command::new(env!("CARGO_BIN_EXE_deard-bench"))
        .args(["--capture", "/nonexistent/capture"])
        .output()
        .expect("run deard-bench");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/capture"), "{err}");
}

/// The CPUs this test process may run on (its affinity), from `/proc/self/status`.
fn allowed_cpus() -> Vec<usize> {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let list = status
        .lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
        .unwrap()
        .trim();
    list.split(',')
        .flat_map(|part| match part.split_once('-') {
            Some((a, b)) => (a.parse().unwrap()..=b.parse().unwrap()).collect::<Vec<usize>>(),
            None => vec![part.parse().unwrap()],
        })
        .collect()
}

#[test]
fn deard_bench_pinned_to_one_core_runs_every_thread_there_and_ends_its_hog() {
    let cpus = allowed_cpus();
    let pin = cpus[0].to_string();
    let mut args = vec!["--frames", "3", "--warmup", "1", "--mode", "online"];
    args.extend(["--pin-cpu", &pin]);
    // A busy board where there is a second CPU to keep busy.
    let hog = cpus.get(1).map(|c| c.to_string());
    if let Some(hog) = &hog {
        args.extend(["--hog-cpu", hog]);
    }
    let (stdout, report) = bench(&args);
    assert_eq!(
        report["pinned_cpu"].as_u64(),
        Some(cpus[0] as u64),
        "{report}"
    );
    // The parallelism the bench saw is its affinity: the one core.
    assert_eq!(report["threads_available"].as_u64(), Some(1), "{report}");
    assert!(stdout.contains("1 rayon thread"), "{stdout}");
    assert_eq!(report["modes"][0]["all"]["count"].as_u64(), Some(3));
    if let Some(hog) = &hog {
        assert_eq!(report["hog_cpus"][0].as_u64(), hog.parse().ok(), "{report}");
        // The hog was started, and is gone (killed and reaped) once the bench has exited.
        let line = stdout
            .lines()
            .find(|l| l.starts_with("busy board:"))
            .unwrap_or_else(|| panic!("{stdout}"));
        let pid = line.rsplit("pid ").next().unwrap().trim_end_matches(')');
        let pid: u32 = pid.parse().unwrap_or_else(|e| panic!("{line}: {e}"));
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        assert!(
            !String::from_utf8_lossy(&cmdline).contains("--spin-cpu"),
            "the hog {pid} outlived the bench"
        );
    }
}

#[test]
fn deard_bench_refuses_a_cpu_it_cannot_use_by_number() {
    for (args, expected) in [
        (vec!["--pin-cpu", "100000"], "CPU 100000"),
        (
            vec!["--pin-cpu", "0", "--hog-cpu", "0"],
            "--hog-cpu names the CPU",
        ),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_deard-bench"))
            .current_dir(root())
            .args(["--capture", "samples/demo", "--frames", "1"])
            .args(&args)
            .output()
            .expect("run deard-bench");
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expected), "{args:?}: {err}");
    }
}
