//! The engine configurations the end-to-end tests run `deard` with, stated once for both the
//! daemon's flags and the in-process processing its payloads are compared with
//! ([`crate::expected_payload_hashes`]), so the two cannot drift apart.

use std::path::Path;

use deard::config::{NetworkPlacement, PipelineConfig, RefineMode};

/// One engine: its pipeline configuration and the `deard` flags that select it.
pub struct Engine {
    pub pipeline: PipelineConfig,
    pub args: Vec<String>,
}

impl Engine {
    /// The classical engine (static calibration, edge-aware filter).
    pub fn classical() -> Engine {
        Engine {
            pipeline: PipelineConfig {
                refine: RefineMode::Classical,
                ..PipelineConfig::default()
            },
            args: vec!["--refine".into(), "classical".into()],
        }
    }

    /// The DEAR engine with `bundle`, online calibration with the network every 3rd frame,
    /// run inline on the frame that asks for it: deterministic, so every payload can be
    /// compared with the in-process chain (background delivery depends on timing).
    pub fn dear_inline(bundle: &Path) -> Engine {
        let bundle_arg = bundle.to_str().expect("a UTF-8 bundle path").to_string();
        Engine {
            pipeline: PipelineConfig {
                refine: RefineMode::Dear,
                bundle: bundle.to_path_buf(),
                online_interval_frames: 3,
                online_network: NetworkPlacement::Inline,
                ..PipelineConfig::default()
            },
            args: [
                "--refine",
                "dear",
                "--bundle",
                &bundle_arg,
                "--online-interval",
                "3",
                "--online-network",
                "inline",
            ]
            .map(String::from)
            .to_vec(),
        }
    }

    /// `deard` flags replaying `capture` with this engine as fast as it goes (the capture
    /// queue blocks instead of dropping: every readable frame is published).
    pub fn replay_fast(&self, capture: &Path) -> Vec<String> {
        let mut args = self.args.clone();
        args.extend(["--pacing".into(), "fast".into(), "--replay".into()]);
        args.push(capture.to_str().expect("a UTF-8 capture path").into());
        args
    }
}
