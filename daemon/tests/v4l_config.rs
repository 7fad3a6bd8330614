//! `[capture] source = "v4l"`: the documented example parses, values that cannot work are
//! refused by key, and a daemon whose module is not there stops at start-up naming the file or
//! the node (the live capture itself is tested against the kernel's vivid driver in a VM:
//! `scripts/test-v4l2-vm.sh --deard`).

use deard::config::Config;

mod support;

const EXAMPLE: &str = include_str!("../deard.example.toml");

/// The example's commented `[capture.v4l]` tables, uncommented (keys that stay commented in
/// the example stay out).
fn v4l_tables() -> String {
    let start = EXAMPLE
        .find("# [capture.v4l]")
        .expect("example documents [capture.v4l]");
    let end = start + EXAMPLE[start..].find("\n\n[").expect("a table follows");
    EXAMPLE[start..end]
        .lines()
        .filter_map(|l| l.strip_prefix("# "))
        .filter(|l| !l.starts_with('#') && !l.starts_with(' '))
        .collect::<Vec<_>>()
        .join("\n")
}

fn live(tables: &str) -> String {
    format!("[capture]\nsource = \"v4l\"\n{tables}\n")
}

fn rejected(toml: &str) -> String {
    match Config::from_toml(toml) {
        Ok(config) => panic!("accepted {toml:?} as {config:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_documented_live_configuration_parses() {
    let config = Config::from_toml(&live(&v4l_tables())).unwrap();
    let v4l = config.capture.v4l.expect("[capture.v4l]");
    assert_eq!(v4l.tof.node.format, "Z16 ");
    assert_eq!(v4l.rgb.format, "YUYV");
    assert_eq!(
        (v4l.rgb.width, v4l.rgb.height, v4l.rgb.fps),
        (640, 480, Some(30))
    );
    assert!(v4l.amplitude.is_none());
    let with_ir = v4l_tables() + "\n[capture.v4l.amplitude]\ndevice = \"/dev/video1\"\nformat = \"Y16 \"\nwidth = 640\nheight = 480\n";
    let config = Config::from_toml(&live(&with_ir)).unwrap();
    assert_eq!(
        config.capture.v4l.unwrap().amplitude.unwrap().format,
        "Y16 "
    );
}

#[test]
fn values_that_cannot_work_are_refused_by_key() {
    let tables = v4l_tables();
    let cases = [
        (
            "[capture]\nsource = \"v4l\"\n".to_string(),
            "needs a [capture.v4l] table",
        ),
        (
            "[capture]\nsource = \"usb\"\n".to_string(),
            "supported sources: \"replay\", \"v4l\"",
        ),
        (
            live(&tables.replace("format = \"Z16 \"", "format = \"Z16\"")),
            "four-character code",
        ),
        (
            live(&tables.replace("format = \"YUYV\"", "format = \"Z16 \"")),
            "not one the daemon decodes for the rgb node",
        ),
        (
            live(&tables.replace("format = \"Z16 \"", "format = \"Y12 \"")),
            "modulation_hz is needed",
        ),
        (
            // A depth format's frequency bounds its depth (c / 2f): it must be one too.
            live(&tables.replace(
                "format = \"Z16 \"",
                "format = \"Z16 \"\nmodulation_hz = -20e6",
            )),
            "modulation_hz = -20000000 must be a positive frequency",
        ),
        (
            live(
                &tables
                    .replace(
                        "format = \"Z16 \"",
                        "format = \"Y12P\"\nmodulation_hz = 75e6",
                    )
                    .replacen("height = 480", "height = 481", 1),
            ),
            "4 × the image height",
        ),
        (live(&tables.replacen("fps = 30", "fps = 0", 1)), "fps = 0"),
        (
            live(&tables.replace("calibration = \"/etc/deard/module.toml\"", "")),
            "calibration",
        ),
        (
            live(&(tables.clone() + "\n[capture.v4l.amplitude]\ndevice = \"/dev/video1\"\nformat = \"GREY\"\nwidth = 320\nheight = 240\n")),
            "must be the ToF node's 640x480",
        ),
        (
            live(&(tables.clone() + "\n[capture.v4l.amplitude]\ndevice = \"/dev/video1\"\nformat = \"YUYV\"\nwidth = 640\nheight = 480\n")),
            "not one the daemon decodes for the amplitude node",
        ),
        (
            live(&(tables.replace("format = \"Z16 \"", "format = \"Y12 \"\nmodulation_hz = 75e6") + "\n[capture.v4l.amplitude]\ndevice = \"/dev/video1\"\nformat = \"GREY\"\nwidth = 640\nheight = 480\n")),
            "is for depth formats",
        ),
    ];
    for (toml, says) in cases {
        let err = rejected(&toml);
        assert!(err.contains(says), "{says:?} not in {err:?} for {toml}");
    }
}

/// Runs deard with `toml`, expecting a start-up failure; returns stderr.
fn start_failure(toml: &str) -> String {
    support::start_failure(toml, &[], "v4l")
}

#[test]
fn a_missing_module_stops_the_daemon_naming_the_file_or_the_node() {
    let tmp = tempfile::tempdir().unwrap();
    let calibration = tmp.path().join("module.toml");
    let tables = v4l_tables().replace("/etc/deard/module.toml", calibration.to_str().unwrap());
    let err = start_failure(&live(&tables));
    assert!(err.contains("module.toml"), "{err}");

    std::fs::write(&calibration, include_str!("../module.example.toml")).unwrap();
    let tables = tables.replace("/dev/video0", "/dev/video-dear-missing");
    let err = start_failure(&live(&tables));
    assert!(
        err.contains("[capture.v4l.tof]")
            && err.contains("/dev/video-dear-missing: no such device"),
        "{err}"
    );
}

/// docs/live-capture.md's module examples (RealSense-like, Arducam-like) are configurations
/// deard accepts.
#[test]
fn the_documented_module_examples_are_valid_configurations() {
    let doc = include_str!("../../docs/live-capture.md");
    let start = doc
        .find("## Live capture from a ToF module")
        .expect("docs/live-capture.md has the configuration section");
    let section = &doc[start..];
    let section = &section[..section[3..].find("\n## ").map_or(section.len(), |e| e + 3)];
    let blocks: Vec<&str> = section
        .split("```toml\n")
        .skip(1)
        .map(|b| &b[..b.find("```").expect("closed block")])
        .collect();
    assert_eq!(blocks.len(), 2, "a Z16 and a 4-phase example");
    let formats: Vec<String> = blocks
        .iter()
        .map(|b| {
            let config = Config::from_toml(b).unwrap_or_else(|e| panic!("{e}\n{b}"));
            config.capture.v4l.expect("[capture.v4l]").tof.node.format
        })
        .collect();
    assert_eq!(formats, ["Z16 ", "Y12 "]);
}
