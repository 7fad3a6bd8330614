//! deard's configuration file under arbitrary and damaged input (issue 16): whatever the TOML
//! text, [`Config::from_toml`] returns a configuration or an error — never a panic — and a
//! configuration it returns is one the daemon can run with: it passes `validate()`, its
//! statistics interval converts to a `Duration` (audit item 7 panicked there), its service
//! name is a valid iceoryx2 name, and `deard --print-config` can print it and read it back.
//!
//! The inputs are TOML-like documents built from the real sections and keys with values of
//! every type (huge integers, `inf`, `nan`, odd strings, inline tables), and the shipped
//! `daemon/deard.example.toml` edited line by line and byte by byte.

#[path = "../../pipeline/tests/mutate/mod.rs"]
mod mutate;

use std::time::Duration;

use deard::config::{Config, MAX_QUEUE_DEPTH};
use mutate::{apply_bytes, byte_edits};
use proptest::prelude::*;

/// The keys of each section of the real file, so that generated documents reach validation
/// instead of stopping at "unknown key".
const KEYS: [(&str, &[&str]); 4] = [
    ("service", &["camera", "name", "max_subscribers_per_user"]),
    (
        "capture",
        &[
            "source",
            "path",
            "pacing",
            "loop",
            "start",
            "end",
            "queue_depth",
        ],
    ),
    (
        "pipeline",
        &[
            "refine",
            "bundle",
            "calibration",
            "online_interval_frames",
            "online_track_gain",
            "online_network",
            "static_calibration",
        ],
    ),
    ("runtime", &["stats_interval_s", "exit_when_done", "log"]),
];

/// TOML float literals at the edges: what `f64`/`f32` fields and `Duration` conversions break on.
fn float_literal() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("nan".to_string()),
        Just("-0.0".to_string()),
        Just("1e20".to_string()),
        Just("1e300".to_string()),
        Just("1e39".to_string()),
        Just("5e-324".to_string()),
        Just("86400.0".to_string()),
        Just("86400.000001".to_string()),
        Just("0.7".to_string()),
        (-1e6f64..1e6).prop_map(|f| format!("{f:?}")),
        any::<f64>().prop_map(|f| {
            if f.is_finite() {
                format!("{f:e}")
            } else {
                "nan".into()
            }
        }),
    ]
}

fn int_literal() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("0".to_string()),
        Just("1".to_string()),
        Just("-1".to_string()),
        Just("64".to_string()),
        Just("65".to_string()),
        Just("9223372036854775807".to_string()),
        Just("-9223372036854775808".to_string()),
        Just("4294967296".to_string()),
        (0i64..100).prop_map(|i| i.to_string()),
        any::<i64>().prop_map(|i| i.to_string()),
    ]
}

fn string_literal() -> impl Strategy<Value = String> {
    let words = prop_oneof![
        Just(String::new()),
        Just("replay".to_string()),
        Just("timestamps".to_string()),
        Just("fast".to_string()),
        Just("dear".to_string()),
        Just("classical".to_string()),
        Just("none".to_string()),
        Just("online".to_string()),
        Just("every-frame".to_string()),
        Just("background".to_string()),
        Just("inline".to_string()),
        Just("cam0".to_string()),
        Just("dear/cam0/frames".to_string()),
        Just("dear//frames".to_string()),
        Just("/".to_string()),
        Just("samples/demo".to_string()),
        Just("info".to_string()),
        "[a-zA-Z0-9_./-]{0,12}",
        "\\PC{0,8}",
        "[a-z]{201,210}",
    ];
    // Escaped as TOML basic strings.
    words.prop_map(|s| format!("{s:?}"))
}

fn value_literal() -> impl Strategy<Value = String> {
    let scalar = prop_oneof![
        int_literal(),
        float_literal(),
        string_literal(),
        Just("true".to_string()),
        Just("false".to_string()),
        Just("1979-05-27T07:32:00Z".to_string()),
    ];
    let calibration = prop::collection::vec(
        (
            prop::sample::select(vec!["tx", "ty", "cx", "cy", "cz"]),
            float_literal(),
        ),
        0..5,
    )
    .prop_map(|fields| {
        let inner: Vec<String> = fields.iter().map(|(k, v)| format!("{k} = {v}")).collect();
        format!("{{ {} }}", inner.join(", "))
    });
    let array =
        prop::collection::vec(int_literal(), 0..3).prop_map(|v| format!("[{}]", v.join(", ")));
    prop_oneof![6 => scalar, 2 => calibration, 1 => array]
}

/// A TOML-like document: sections (real ones, unknown ones, dotted), each with key = value
/// lines (real keys mostly, unknown ones too), and now and then a line of noise.
fn toml_document() -> impl Strategy<Value = String> {
    let line = prop_oneof![
        8 => (0..KEYS.len(), any::<prop::sample::Index>(), value_literal()).prop_map(
            |(section, key, value)| {
                let keys = KEYS[section].1;
                format!("{} = {value}", keys[key.index(keys.len())])
            }
        ),
        1 => ("[a-z_]{1,10}", value_literal()).prop_map(|(k, v)| format!("{k} = {v}")),
        1 => "\\PC{0,20}",
    ];
    let header = prop_oneof![
        6 => prop::sample::select(KEYS.iter().map(|(s, _)| format!("[{s}]")).collect::<Vec<_>>()),
        1 => "[a-z]{1,8}".prop_map(|s| format!("[{s}]")),
        1 => Just("[capture.extra]".to_string()),
        1 => Just("[[runtime]]".to_string()),
    ];
    prop::collection::vec((header, prop::collection::vec(line, 0..5)), 0..5).prop_map(|sections| {
        let mut text = String::new();
        for (header, lines) in sections {
            text.push_str(&header);
            text.push('\n');
            for line in lines {
                text.push_str(&line);
                text.push('\n');
            }
        }
        text
    })
}

/// One line-level edit of a TOML file.
#[derive(Debug, Clone)]
enum LineEdit {
    /// Drop the line.
    Remove(prop::sample::Index),
    /// Repeat the line (a duplicate key or section).
    Duplicate(prop::sample::Index),
    /// Uncomment the line (the example's commented-out keys: `end`, `name`,
    /// `static_calibration`).
    Uncomment(prop::sample::Index),
    /// Replace the value of a `key = value` line.
    Revalue(prop::sample::Index, String),
}

fn line_edits() -> impl Strategy<Value = Vec<LineEdit>> {
    let edit = prop_oneof![
        1 => any::<prop::sample::Index>().prop_map(LineEdit::Remove),
        1 => any::<prop::sample::Index>().prop_map(LineEdit::Duplicate),
        1 => any::<prop::sample::Index>().prop_map(LineEdit::Uncomment),
        4 => (any::<prop::sample::Index>(), value_literal())
            .prop_map(|(i, v)| LineEdit::Revalue(i, v)),
    ];
    prop::collection::vec(edit, 1..=4)
}

fn apply_lines(text: &str, edits: &[LineEdit]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    for edit in edits {
        if lines.is_empty() {
            break;
        }
        match edit {
            LineEdit::Remove(i) => {
                lines.remove(i.index(lines.len()));
            }
            LineEdit::Duplicate(i) => {
                let at = i.index(lines.len());
                lines.insert(at, lines[at].clone());
            }
            LineEdit::Uncomment(i) => {
                let at = i.index(lines.len());
                lines[at] = lines[at].trim_start_matches(['#', ' ']).to_string();
            }
            LineEdit::Revalue(i, value) => {
                let at = i.index(lines.len());
                if let Some((key, _)) = lines[at].split_once(" = ") {
                    lines[at] = format!("{key} = {value}");
                }
            }
        }
    }
    lines.join("\n")
}

/// The contract of [`Config::from_toml`] on any text.
fn check(text: &str) -> Result<(), TestCaseError> {
    let config = match Config::from_toml(text) {
        Ok(config) => config,
        Err(e) => {
            prop_assert!(!e.to_string().is_empty(), "an error says what is wrong");
            return Ok(());
        }
    };
    if let Err(e) = config.validate() {
        return Err(TestCaseError::fail(format!(
            "accepted but does not validate: {e}\n{text}"
        )));
    }
    let stats = Duration::try_from_secs_f64(config.runtime.stats_interval_s);
    prop_assert!(stats.is_ok(), "{config:?}");
    prop_assert!((1..=MAX_QUEUE_DEPTH).contains(&config.capture.queue_depth));
    prop_assert!((1..=dear_proto::service::QOS_MAX_SUBSCRIBERS)
        .contains(&config.service.max_subscribers_per_user));
    let service = config.service.service_name();
    prop_assert!(
        dear_proto::validate_service_name(&service).is_ok(),
        "{service:?}"
    );
    // What `deard --print-config` does, then reading its output as a config file.
    let printed = toml::to_string_pretty(&config)
        .map_err(|e| TestCaseError::fail(format!("cannot print {config:?}: {e}")))?;
    let again = Config::from_toml(&printed)
        .map_err(|e| TestCaseError::fail(format!("printed config refused: {e}\n{printed}")))?;
    prop_assert_eq!(again, config);
    Ok(())
}

fn example() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/deard.example.toml")).unwrap()
}

#[test]
fn the_example_config_meets_the_contract() {
    // The starting point of the mutations must itself be accepted, or every mutation would
    // test only the error path.
    let text = example();
    assert!(Config::from_toml(&text).is_ok());
    let mut runner = proptest::test_runner::TestRunner::default();
    runner.run(&Just(text), |t| check(&t)).unwrap();
}

#[test]
fn arbitrary_toml_is_a_config_that_runs_or_an_error() {
    proptest!(mutate::config(1024), |(text in toml_document())| {
        check(&text)?;
    });
}

#[test]
fn arbitrary_text_is_a_config_or_an_error() {
    proptest!(mutate::config(512), |(bytes in prop::collection::vec(any::<u8>(), 0..256))| {
        check(&String::from_utf8_lossy(&bytes))?;
    });
}

#[test]
fn mutated_example_is_a_config_that_runs_or_an_error() {
    let text = example();
    proptest!(mutate::config(1024), |(lines in line_edits(), bytes in byte_edits())| {
        let edited = apply_lines(&text, &lines);
        check(&edited)?;
        check(&String::from_utf8_lossy(&apply_bytes(edited.as_bytes(), &bytes)))?;
    });
}
