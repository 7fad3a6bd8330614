//! Loading a model bundle: `model.json` plus three ONNX graphs, each verified against the
//! SHA-256 the manifest records before tract parses a byte of it.
//!
//! The file is read once and the verified bytes are what gets parsed, so a file swapped
//! between the check and the parse cannot slip through. Loading parses but does not optimise:
//! optimisation needs the stream's resolution and happens in
//! [`BundleRunner::new`](crate::model::BundleRunner::new).

use std::io::Cursor;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};
use tract_onnx::prelude::*;
use tract_onnx::tract_hir::infer::Factoid;
use tract_onnx::tract_hir::internal::DimLike;

use crate::model::error::BundleError;
use crate::model::manifest::{output_contract, GraphRole, Manifest, Normalisation};

/// A verified, parsed bundle, ready to be instantiated for a stream resolution.
#[derive(Debug, Clone)]
pub struct ModelBundle {
    dir: PathBuf,
    manifest: Manifest,
    graphs: Vec<LoadedGraph>,
}

/// One parsed graph and where it came from.
#[derive(Debug, Clone)]
pub(crate) struct LoadedGraph {
    pub role: GraphRole,
    pub path: PathBuf,
    pub model: InferenceModel,
    /// Input names in the graph's own input order.
    pub input_names: Vec<String>,
}

impl ModelBundle {
    /// Reads `dir/model.json`, verifies the size and SHA-256 of every graph file, parses the
    /// graphs and checks that their input and output names and channel counts are the ones the
    /// DEAR chain feeds and reads.
    ///
    /// # Errors
    /// [`BundleError::Missing`] (no such directory or file), [`BundleError::Manifest`],
    /// [`BundleError::Checksum`] / [`BundleError::Size`] (a tampered or truncated graph; the
    /// error names the file and both values), [`BundleError::Contract`],
    /// [`BundleError::Onnx`] (tract cannot parse the file), [`BundleError::Io`].
    pub fn load(dir: impl AsRef<Path>) -> Result<ModelBundle, BundleError> {
        let dir = dir.as_ref().to_path_buf();
        match std::fs::metadata(&dir) {
            Ok(meta) if meta.is_dir() => {}
            Ok(_) => return Err(BundleError::NotADirectory { path: dir }),
            Err(e) => return Err(BundleError::io(&dir, e)),
        }
        let manifest_path = dir.join("model.json");
        let text = dear_capture::input::read_text_limited(
            &manifest_path,
            dear_capture::input::SETTINGS_LIMIT,
        )
        .map_err(|e| BundleError::io(&manifest_path, e))?;
        let manifest = Manifest::parse(&text, &manifest_path)?;
        let mut graphs = Vec::with_capacity(GraphRole::ALL.len());
        for role in GraphRole::ALL {
            let spec = manifest
                .graph(role)
                .expect("Manifest::parse checked every role");
            let path = dir.join(&spec.file);
            // Never more than model.json says the graph holds (a FIFO or a device is refused
            // before it is opened; a larger file before it is read).
            let meta = std::fs::metadata(&path).map_err(|e| BundleError::io(&path, e))?;
            if meta.is_file() && meta.len() > spec.bytes {
                return Err(BundleError::Size {
                    path,
                    expected: spec.bytes,
                    actual: meta.len(),
                });
            }
            let bytes = dear_capture::input::read_limited(&path, spec.bytes)
                .map_err(|e| BundleError::io(&path, e))?;
            let actual = hex_sha256(&bytes);
            if !actual.eq_ignore_ascii_case(&spec.sha256) {
                return Err(BundleError::Checksum {
                    path,
                    expected: spec.sha256.to_ascii_lowercase(),
                    actual,
                });
            }
            if bytes.len() as u64 != spec.bytes {
                return Err(BundleError::Size {
                    path,
                    expected: spec.bytes,
                    actual: bytes.len() as u64,
                });
            }
            graphs.push(parse_graph(role, path, &bytes, spec)?);
        }
        Ok(ModelBundle {
            dir,
            manifest,
            graphs,
        })
    }

    /// The bundle directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The parsed manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Normalisation constants.
    pub fn normalisation(&self) -> Normalisation {
        self.manifest.normalisation
    }

    /// Network inputs must be multiples of this in height and width.
    pub fn input_size_multiple(&self) -> usize {
        self.manifest.input_size_multiple
    }

    /// Whether `refine.onnx` takes the RGB image (every variant but `norgb` / `deeptof`).
    pub fn refine_uses_rgb(&self) -> bool {
        self.graph(GraphRole::Refine)
            .input_names
            .iter()
            .any(|n| n == "rgb")
    }

    /// How the chain applies the refine graph's output (format 2), or `None` when the graph
    /// outputs the refined depth itself (format 1).
    pub fn refine_apply(&self) -> Option<&crate::model::manifest::RefineApply> {
        self.manifest
            .graph(GraphRole::Refine)
            .and_then(|g| g.apply.as_ref())
    }

    pub(crate) fn graph(&self, role: GraphRole) -> &LoadedGraph {
        self.graphs
            .iter()
            .find(|g| g.role == role)
            .expect("load() keeps one graph per role")
    }
}

/// Lower-case hex SHA-256 of `bytes`: how `model.json` writes a graph's digest (and how the
/// end-to-end tests fingerprint payloads).
pub fn hex_sha256(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Parses one verified graph and checks its actual inputs and outputs against the manifest and
/// the chain's contract (the manifest could be right and the file from another export).
fn parse_graph(
    role: GraphRole,
    path: PathBuf,
    bytes: &[u8],
    spec: &crate::model::manifest::GraphSpec,
) -> Result<LoadedGraph, BundleError> {
    let graph = role.name();
    let onnx_err = |e: TractError| BundleError::Onnx {
        path: path.clone(),
        graph,
        message: format!("{e:#}"),
    };
    let broken = |message: String| BundleError::Contract {
        path: path.clone(),
        graph,
        message,
    };
    let model = tract_onnx::onnx()
        .model_for_read(&mut Cursor::new(bytes))
        .map_err(onnx_err)?;
    let contract = role.contract();
    let mut input_names = Vec::new();
    for (i, outlet) in model.input_outlets().map_err(onnx_err)?.iter().enumerate() {
        let name = model.node(outlet.node).name.clone();
        let Some(&(_, channels, _)) = contract.inputs.iter().find(|c| c.0 == name) else {
            return Err(broken(format!(
                "the ONNX graph has an input {name:?} that the chain does not provide"
            )));
        };
        if let Some(found) = model
            .input_fact(i)
            .ok()
            .and_then(|f| f.shape.dim(1))
            .and_then(|d| d.concretize())
            .and_then(|d| d.to_usize().ok())
        {
            if found != channels {
                return Err(broken(format!(
                    "the ONNX input {name:?} has {found} channels, expected {channels}"
                )));
            }
        }
        input_names.push(name);
    }
    for declared in &spec.inputs {
        if !input_names.contains(&declared.name) {
            return Err(broken(format!(
                "model.json declares input {:?} but the ONNX graph's inputs are {input_names:?}",
                declared.name
            )));
        }
    }
    if input_names.len() != spec.inputs.len() {
        return Err(broken(format!(
            "the ONNX graph has inputs {input_names:?}, model.json declares {:?}",
            spec.inputs.iter().map(|t| &t.name).collect::<Vec<_>>()
        )));
    }
    let outputs = model.output_outlets().map_err(onnx_err)?;
    let labels: Vec<&str> = outputs
        .iter()
        .map(|o| model.outlet_label(*o).unwrap_or("<unnamed>"))
        .collect();
    let output = output_contract(role, spec.apply.as_ref());
    if labels != [output.name] {
        return Err(broken(format!(
            "the ONNX graph's outputs are {labels:?}, expected [{:?}]",
            output.name
        )));
    }
    Ok(LoadedGraph {
        role,
        path,
        model,
        input_names,
    })
}
