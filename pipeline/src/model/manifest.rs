//! `model.json`, the manifest of a model bundle (written by `dear-export` in `train/`), and the
//! I/O contract between the three graphs and the DEAR chain that feeds them.
//!
//! The manifest is parsed leniently where the exporter may add information (extra fields are
//! kept or ignored) and strictly where the chain depends on it: the format and its version, the
//! normalisation constants, the size multiple, and each graph's file, checksum and tensor names
//! and channel counts.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::model::error::BundleError;

/// The `format` field every bundle manifest carries.
pub const BUNDLE_FORMAT: &str = "dear-model-bundle";
/// The newest manifest version this crate reads. Version 1: `refine.onnx` outputs the refined
/// depth. Version 2 adds `graphs.refine.apply` ([`RefineApply`]): the graph outputs maps at a
/// lower resolution that the chain applies in Rust (`model::kernel_apply`). Both load.
pub const BUNDLE_FORMAT_VERSION: u64 = 2;

/// The parsed `model.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`BUNDLE_FORMAT`].
    pub format: String,
    /// Always [`BUNDLE_FORMAT_VERSION`].
    pub format_version: u64,
    /// Model tier: `paper` or `edge`.
    pub tier: String,
    /// Refinement variant (`kpn`, `unet`, `norgb`, ...).
    pub variant: String,
    /// Network inputs must have height and width multiples of this; the runner pads.
    pub input_size_multiple: usize,
    /// Constants that turn sensor data into network inputs.
    pub normalisation: Normalisation,
    /// The graphs by role: `flow`, `fuse`, `refine`.
    pub graphs: BTreeMap<String, GraphSpec>,
    /// Training recipe, as recorded by the exporter (informational).
    #[serde(default)]
    pub training: serde_json::Value,
    /// Measured metrics, as recorded by the exporter (informational).
    #[serde(default)]
    pub validation: serde_json::Value,
    /// Versions of the exporting software (informational).
    #[serde(default)]
    pub software: serde_json::Value,
}

/// Normalisation constants (`normalisation` in `model.json`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// Depth scale of the refinement network, metres (applied inside `refine.onnx`).
    pub max_depth_m: f32,
    /// Percentile `p` of `I_raw·D²` over valid-depth pixels that maps to amplitude 1.
    pub amplitude_percentile: f32,
}

/// One graph of the bundle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GraphSpec {
    /// File name inside the bundle directory (no directories).
    pub file: String,
    /// Graph inputs.
    pub inputs: Vec<TensorSpec>,
    /// Graph outputs.
    pub outputs: Vec<TensorSpec>,
    /// Lower-case hex SHA-256 of the file.
    pub sha256: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Format 2, refine graph only: how the chain applies the graph's output.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub apply: Option<RefineApply>,
}

/// `graphs.refine.apply` of a format-2 bundle: the refine graph outputs `channels` maps at
/// 1/`stride` resolution, applied by `model::kernel_apply` (the exporter writes the full
/// definition beside these numbers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefineApply {
    /// `"gated-kernel"` (12 maps applied to the warped depth), `"hybrid-kernel"` (13 maps:
    /// a per-pixel choice between the warped depth and the classical refiner's output, then
    /// the gated kernel) or `"guarded-kernel"` (16 maps: the hybrid's, then the expected error
    /// of each candidate); see [`ApplyKind`].
    pub kind: String,
    /// Upsampling factor of the maps (2, 4 or 8; divides `input_size_multiple`).
    pub stride: usize,
    /// 12 for `gated-kernel`, 13 for `hybrid-kernel`, 16 for `guarded-kernel`.
    pub channels: usize,
    /// Largest depth correction, normalised depth.
    pub max_bias: f32,
    /// Scale of the depth-range attenuation of the kernel weights.
    pub range_scale: f32,
    /// `hybrid-kernel` and `guarded-kernel`: trust-logit added per unit of normalised
    /// |classical − depth|.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jump_scale: Option<f32>,
    /// `hybrid-kernel` and `guarded-kernel`, optional: which pixels the jump term
    /// (`jump_scale · |c − d|`) applies to ([`JumpOn`]; absent: every pixel, as trained).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jump_on: Option<JumpOn>,
    /// `guarded-kernel` only: expected error (normalised depth) of an error-map logit of 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_unit: Option<f32>,
    /// `guarded-kernel` only: the error-map logits are clamped to ±this.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_error_bound: Option<f32>,
    /// `guarded-kernel` only, optional: a floor under the published expected error from the
    /// frame's own disagreement between measurement and classical estimate
    /// ([`crate::model::kernel_apply::floor_expected_error`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_floor: Option<ErrorFloor>,
}

/// `graphs.refine.apply.jump_on`: the pixels on which the classical estimate's trust rises with
/// its distance from the measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum JumpOn {
    /// Every pixel where both depths are valid (the definition the refiners were trained with).
    EveryPixel,
    /// Only the pixels the classical filter did not measure itself (its confidence below
    /// [`crate::filter::MEASURED_CONFIDENCE`]: a flying pixel snapped onto a surface, an outlier
    /// replaced by its neighbours' median). A large move by its smoothing (across a depth step
    /// whose colours match) is then the network's call like a small one, so a measurement that
    /// was right is not handed to a smoothed estimate that is not.
    Replaced,
}

/// `graphs.refine.apply.error_floor`: the expected error a guarded refiner publishes is raised
/// to at least `min(scale · mean |depth − classical|, cap_m)` metres, the mean taken over the
/// `(2·radius + 1)²` window around the pixel where both are valid. The head learnt its errors
/// on the training family's noise; on a noisier module (the held-out family) it predicted a
/// third of the measured error, and the measurement's disagreement with its smoothed self is
/// the frame's own evidence of that noise. The published depth is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorFloor {
    /// Multiplies the window's mean |depth − classical| (metres).
    pub scale: f32,
    /// Half-width of the window, pixels (1 to [`ErrorFloor::MAX_RADIUS`]).
    pub radius: usize,
    /// The floor never exceeds this many metres: a large disagreement is structure (an edge,
    /// multi-path), not noise, and the head's own prediction speaks for it.
    pub cap_m: f32,
}

impl ErrorFloor {
    /// The widest window a manifest may ask for.
    pub const MAX_RADIUS: usize = 8;
}

/// The kinds of [`RefineApply`] this build implements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ApplyKind {
    /// The gated kernel on the warped depth.
    Gated,
    /// The gated kernel on a per-pixel blend of the warped depth and the classical refiner's
    /// output (the graph also takes that output as its `classical` input).
    Hybrid,
    /// The hybrid refinement, the measurement and the classical estimate, each with an
    /// expected error: each pixel publishes the one expected to be closest to the truth.
    Guarded,
}

impl ApplyKind {
    /// The kind named `kind` in a manifest, if this build implements it.
    pub fn parse(kind: &str) -> Option<Self> {
        match kind {
            "gated-kernel" => Some(ApplyKind::Gated),
            "hybrid-kernel" => Some(ApplyKind::Hybrid),
            "guarded-kernel" => Some(ApplyKind::Guarded),
            _ => None,
        }
    }

    /// Head maps of this kind.
    pub fn channels(self) -> usize {
        match self {
            ApplyKind::Gated => crate::model::kernel_apply::GATED_CHANNELS,
            ApplyKind::Hybrid => crate::model::kernel_apply::HYBRID_CHANNELS,
            ApplyKind::Guarded => crate::model::kernel_apply::GUARDED_CHANNELS,
        }
    }

    /// Whether the refine graph of this kind takes the classical refiner's output.
    pub fn takes_classical(self) -> bool {
        matches!(self, ApplyKind::Hybrid | ApplyKind::Guarded)
    }
}

impl RefineApply {
    /// The validated kind ([`Manifest::parse`] refuses any other).
    pub fn apply_kind(&self) -> ApplyKind {
        ApplyKind::parse(&self.kind).unwrap_or(ApplyKind::Gated)
    }
}

/// What a graph outputs: its name, channels, and its resolution as a divisor of the input's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct GraphOutput {
    pub name: &'static str,
    pub channels: usize,
    pub stride: usize,
}

/// The output the chain reads from graph `role` (`apply`: the bundle's refine `apply`, which
/// only the refine graph's output depends on).
pub(crate) fn output_contract(role: GraphRole, apply: Option<&RefineApply>) -> GraphOutput {
    match (role, apply) {
        (GraphRole::Refine, Some(a)) => GraphOutput {
            name: "refine_maps",
            channels: a.channels,
            stride: a.stride,
        },
        _ => {
            let (name, channels) = role.contract().output;
            GraphOutput {
                name,
                channels,
                stride: 1,
            }
        }
    }
}

/// One input or output tensor: its name and `[N, C, H, W]` shape (symbols or numbers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TensorSpec {
    /// Tensor name in the ONNX graph.
    pub name: String,
    /// Shape as written by the exporter, e.g. `["N", 3, "H", "W"]`.
    pub shape: Vec<serde_json::Value>,
}

impl TensorSpec {
    /// The channel count (`shape[1]`) when it is a number.
    pub fn channels(&self) -> Option<usize> {
        self.shape
            .get(1)
            .and_then(serde_json::Value::as_u64)
            .map(|c| c as usize)
    }
}

/// The role of one of a bundle's three graphs; `model.json` names them `flow`, `fuse` and
/// `refine` under `graphs`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GraphRole {
    /// Rough flow from RGB and amplitude.
    Flow,
    /// Fusion of the rough flow with the calibration's flow.
    Fuse,
    /// Depth refinement.
    Refine,
}

impl GraphRole {
    /// Every role, in the order the chain runs them.
    pub const ALL: [GraphRole; 3] = [GraphRole::Flow, GraphRole::Fuse, GraphRole::Refine];

    /// The role's key in `model.json`.
    pub const fn name(self) -> &'static str {
        match self {
            GraphRole::Flow => "flow",
            GraphRole::Fuse => "fuse",
            GraphRole::Refine => "refine",
        }
    }

    /// The I/O contract of the role (train/README.md, "Graph I/O contract").
    pub(crate) const fn contract(self) -> Contract {
        match self {
            GraphRole::Flow => Contract {
                inputs: &[("rgb", 3, true), ("amplitude", 1, true)],
                output: ("flow", 2),
            },
            GraphRole::Fuse => Contract {
                inputs: &[("flow_rough", 2, true), ("flow_convt", 2, true)],
                output: ("flow_refined", 2),
            },
            GraphRole::Refine => Contract {
                inputs: &[
                    ("amplitude", 1, true),
                    ("depth", 1, true),
                    ("rgb", 3, false),
                    ("classical", 1, false),
                ],
                output: ("depth_refined", 1),
            },
        }
    }
}

impl std::fmt::Display for GraphRole {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What the chain feeds a graph and reads from it: `(name, channels, required)` per input and
/// `(name, channels)` of the single output.
pub(crate) struct Contract {
    pub inputs: &'static [(&'static str, usize, bool)],
    pub output: (&'static str, usize),
}

impl Manifest {
    /// Parses and validates `model.json` text; `path` is only used in error messages.
    ///
    /// # Errors
    /// [`BundleError::Manifest`] for invalid JSON, a wrong format or version, a missing field,
    /// a missing graph or a non-positive constant; [`BundleError::Contract`] when a graph's
    /// declared inputs or outputs are not what the chain feeds and reads.
    pub fn parse(text: &str, path: &Path) -> Result<Manifest, BundleError> {
        let bad = |message: String| BundleError::Manifest {
            path: path.to_path_buf(),
            message,
        };
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| bad(format!("not valid JSON: {e}")))?;
        match value.get("format").and_then(|f| f.as_str()) {
            Some(BUNDLE_FORMAT) => {}
            Some(other) => {
                return Err(bad(format!(
                    "format is {other:?}, expected {BUNDLE_FORMAT:?}"
                )))
            }
            None => return Err(bad(format!("no \"format\": {BUNDLE_FORMAT:?} field"))),
        }
        match value.get("format_version").and_then(|v| v.as_u64()) {
            Some(1..=BUNDLE_FORMAT_VERSION) => {}
            Some(v) => {
                return Err(bad(format!(
                    "format_version {v} is not supported (this build reads 1 to {BUNDLE_FORMAT_VERSION})"
                )))
            }
            None => return Err(bad("no integer \"format_version\" field".into())),
        }
        // The path says which field a type error is in (`graphs.flow.bytes: invalid type ...`);
        // from a parsed value serde_json reports neither a field nor a line.
        let m: Manifest = serde_path_to_error::deserialize(value).map_err(|e| {
            let field = e.path().to_string();
            if field == "." {
                bad(e.inner().to_string())
            } else {
                bad(format!("field `{field}`: {}", e.inner()))
            }
        })?;
        if m.input_size_multiple == 0 || m.input_size_multiple > 1024 {
            return Err(bad(format!(
                "input_size_multiple {} is not in 1..=1024",
                m.input_size_multiple
            )));
        }
        let n = m.normalisation;
        if !(n.max_depth_m > 0.0 && n.max_depth_m.is_finite()) {
            return Err(bad(format!(
                "normalisation.max_depth_m {} is not a positive number",
                n.max_depth_m
            )));
        }
        if !(n.amplitude_percentile > 0.0 && n.amplitude_percentile <= 100.0) {
            return Err(bad(format!(
                "normalisation.amplitude_percentile {} is not in (0, 100]",
                n.amplitude_percentile
            )));
        }
        for role in GraphRole::ALL {
            let Some(g) = m.graphs.get(role.name()) else {
                return Err(bad(format!(
                    "graph \"{role}\" is missing from \"graphs\" (the chain needs flow, fuse and refine)"
                )));
            };
            m.check_graph(role, g, path)?;
        }
        Ok(m)
    }

    fn check_graph(&self, role: GraphRole, g: &GraphSpec, path: &Path) -> Result<(), BundleError> {
        let graph = role.name();
        let broken = |message: String| BundleError::Contract {
            path: path.to_path_buf(),
            graph,
            message,
        };
        let plain_name =
            !g.file.is_empty() && !g.file.contains(['/', '\\']) && g.file != "." && g.file != "..";
        if !plain_name {
            return Err(broken(format!(
                "file {:?} is not a plain file name inside the bundle",
                g.file
            )));
        }
        if g.sha256.len() != 64 || !g.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(broken(format!(
                "sha256 {:?} is not a 64-digit hex digest",
                g.sha256
            )));
        }
        match (&g.apply, role, self.format_version) {
            (None, GraphRole::Refine, 2) => {
                return Err(broken(
                    "format_version 2 needs \"apply\" on the refine graph".into(),
                ))
            }
            (Some(_), GraphRole::Refine, 1) => {
                return Err(broken(
                    "\"apply\" needs format_version 2 (this manifest says 1)".into(),
                ))
            }
            (Some(_), GraphRole::Flow | GraphRole::Fuse, _) => {
                return Err(broken("only the refine graph may have \"apply\"".into()))
            }
            (Some(a), _, _) => check_apply(a, self.input_size_multiple).map_err(&broken)?,
            (None, _, _) => {}
        }
        let contract = role.contract();
        check_tensors(&g.inputs, contract.inputs, "input").map_err(&broken)?;
        let output = output_contract(role, g.apply.as_ref());
        let out = [(output.name, output.channels, true)];
        check_tensors(&g.outputs, &out, "output").map_err(&broken)?;
        if role == GraphRole::Refine {
            let has_rgb = g.inputs.iter().any(|t| t.name == "rgb");
            let wants_rgb = !matches!(self.variant.as_str(), "norgb" | "deeptof");
            if has_rgb != wants_rgb {
                return Err(broken(format!(
                    "variant {:?} {} an rgb input, but the graph {} one",
                    self.variant,
                    if wants_rgb { "takes" } else { "takes no" },
                    if has_rgb {
                        "declares"
                    } else {
                        "does not declare"
                    }
                )));
            }
            let has_classical = g.inputs.iter().any(|t| t.name == "classical");
            let hybrid = g
                .apply
                .as_ref()
                .is_some_and(|a| a.apply_kind().takes_classical());
            if has_classical != hybrid {
                return Err(broken(format!(
                    "the refine graph {} a classical input but its apply kind is {:?} (only \
                     \"hybrid-kernel\" and \"guarded-kernel\" take the classical refiner's \
                     output)",
                    if has_classical {
                        "declares"
                    } else {
                        "does not declare"
                    },
                    g.apply.as_ref().map_or("none", |a| a.kind.as_str())
                )));
            }
        }
        Ok(())
    }

    /// The spec of graph `role`; present after [`parse`](Self::parse).
    pub fn graph(&self, role: GraphRole) -> Option<&GraphSpec> {
        self.graphs.get(role.name())
    }
}

/// Checks a refine graph's `apply` against what [`crate::model::kernel_apply`] implements.
fn check_apply(a: &RefineApply, multiple: usize) -> Result<(), String> {
    let Some(kind) = ApplyKind::parse(&a.kind) else {
        return Err(format!(
            "apply.kind {:?} is unknown (this build applies \"gated-kernel\", \
             \"hybrid-kernel\" and \"guarded-kernel\")",
            a.kind
        ));
    };
    if a.channels != kind.channels() {
        return Err(format!(
            "apply.channels is {}, a {} head has {}",
            a.channels,
            a.kind,
            kind.channels()
        ));
    }
    match (kind.takes_classical(), a.jump_scale) {
        (true, None) => return Err(format!("apply.jump_scale is required for {:?}", a.kind)),
        (true, Some(v)) if !(v.is_finite() && v >= 0.0) => {
            return Err(format!("apply.jump_scale {v} is not a non-negative number"))
        }
        (false, Some(_)) => {
            return Err(format!(
                "apply.jump_scale belongs to \"hybrid-kernel\" and \"guarded-kernel\", not \
                 {:?}",
                a.kind
            ))
        }
        _ => {}
    }
    if a.jump_on.is_some() && !kind.takes_classical() {
        return Err(format!(
            "apply.jump_on belongs to \"hybrid-kernel\" and \"guarded-kernel\", not {:?}",
            a.kind
        ));
    }
    let guarded = kind == ApplyKind::Guarded;
    for (name, v) in [
        ("error_unit", a.error_unit),
        ("log_error_bound", a.log_error_bound),
    ] {
        match (guarded, v) {
            (true, None) => return Err(format!("apply.{name} is required for \"guarded-kernel\"")),
            (true, Some(v)) if !(v.is_finite() && v > 0.0) => {
                return Err(format!("apply.{name} {v} is not a positive number"))
            }
            (false, Some(_)) => {
                return Err(format!(
                    "apply.{name} belongs to \"guarded-kernel\", not {:?}",
                    a.kind
                ))
            }
            _ => {}
        }
    }
    match (guarded, a.error_floor) {
        (false, Some(_)) => {
            return Err(format!(
                "apply.error_floor belongs to \"guarded-kernel\", not {:?}",
                a.kind
            ))
        }
        (true, Some(f)) => {
            for (name, v) in [("scale", f.scale), ("cap_m", f.cap_m)] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(format!(
                        "apply.error_floor.{name} {v} is not a positive number"
                    ));
                }
            }
            if !(1..=ErrorFloor::MAX_RADIUS).contains(&f.radius) {
                return Err(format!(
                    "apply.error_floor.radius {} must be 1 to {}",
                    f.radius,
                    ErrorFloor::MAX_RADIUS
                ));
            }
        }
        _ => {}
    }
    if !matches!(a.stride, 2 | 4 | 8) || !multiple.is_multiple_of(a.stride) {
        return Err(format!(
            "apply.stride {} must be 2, 4 or 8 and divide input_size_multiple {multiple}",
            a.stride
        ));
    }
    for (name, v) in [("max_bias", a.max_bias), ("range_scale", a.range_scale)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(format!("apply.{name} {v} is not a positive number"));
        }
    }
    Ok(())
}

/// Checks declared tensors against a contract: every declared name is known, every required one
/// is present, none twice, channel counts match.
fn check_tensors(
    declared: &[TensorSpec],
    contract: &[(&str, usize, bool)],
    kind: &str,
) -> Result<(), String> {
    for (i, t) in declared.iter().enumerate() {
        let Some(&(_, channels, _)) = contract.iter().find(|c| c.0 == t.name) else {
            let known: Vec<&str> = contract.iter().map(|c| c.0).collect();
            return Err(format!(
                "unknown {kind} {:?} (the chain provides {known:?})",
                t.name
            ));
        };
        if declared[..i].iter().any(|o| o.name == t.name) {
            return Err(format!("{kind} {:?} is declared twice", t.name));
        }
        if t.shape.len() != 4 {
            return Err(format!(
                "{kind} {:?} has shape {:?}; expected [N, C, H, W]",
                t.name, t.shape
            ));
        }
        // A dimension is a symbol the runner binds ("N", "H", "W/4") or a fixed positive
        // size; anything else (a negative or fractional number, null, a list) is a broken
        // export, named here rather than met by tract.
        let dimension = |d: &serde_json::Value| match d {
            serde_json::Value::String(s) => !s.is_empty(),
            other => other.as_u64().is_some_and(|n| n > 0),
        };
        if !t.shape.iter().all(dimension) {
            return Err(format!(
                "{kind} {:?} has shape {:?}; each dimension must be a symbol such as \"N\" or \
                 a positive integer",
                t.name, t.shape
            ));
        }
        if t.channels() != Some(channels) {
            return Err(format!(
                "{kind} {:?} has {} channels, expected {channels}",
                t.name, t.shape[1]
            ));
        }
    }
    for &(name, _, required) in contract {
        if required && !declared.iter().any(|t| t.name == name) {
            return Err(format!("required {kind} {name:?} is not declared"));
        }
    }
    Ok(())
}
