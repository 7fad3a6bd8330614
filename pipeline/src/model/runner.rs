//! Running the three graphs of a bundle at one stream resolution.
//!
//! tract optimises a graph best when every dimension is known, so [`BundleRunner::new`] fixes
//! the input shapes to `1 × C × H' × W'` (the stream's size rounded up to the bundle's
//! `input_size_multiple`) and optimises each graph once; a stream that changes resolution needs
//! a new runner. Inputs are replicate-padded at the bottom and right (so pixel coordinates, and
//! hence flows, are unchanged, and the network sees no artificial edge), outputs are cropped
//! back to `H × W`.
//!
//! Each graph keeps one tract state that is reused frame after frame. With `threads > 1` (and
//! this crate's `multithread` feature) matrix products run on a private rayon pool of that
//! size, attached to the plans, so the pipeline's own rayon work is not starved by them.

use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use tract_onnx::prelude::*;

use crate::model::bundle::{LoadedGraph, ModelBundle};
use crate::model::error::BundleError;
use crate::model::kernel_apply::{
    apply_gated, blend_classical, floor_expected_error, select_guarded, ClassicalEstimate,
    GatedKernel,
};
use crate::model::manifest::{output_contract, GraphOutput, GraphRole};
use crate::model::stacked_input::{
    average_pool_row, stack_concatenated_inputs, Stack, StackPart, Transform,
};
use dear_capture::frame::Flow;

/// Largest padded side a runner accepts: beyond it a single plane is gigabytes.
pub const MAX_SIDE: usize = 16384;

/// How the runner executes graphs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunnerOptions {
    /// Threads for tract's matrix products. `1` runs them on the calling thread. Values above
    /// 1 take effect only with the crate feature `multithread` (tract-linalg's
    /// `multithread-mm`); without it they are ignored.
    pub threads: usize,
}

impl Default for RunnerOptions {
    /// Single-threaded: measured faster on the 2-core target (see `benches/dear_chain.rs`).
    fn default() -> Self {
        RunnerOptions { threads: 1 }
    }
}

/// The three graphs of a bundle, optimised for one resolution.
#[derive(Debug)]
pub struct BundleRunner {
    width: usize,
    height: usize,
    padded: (usize, usize),
    refine_uses_rgb: bool,
    flow: GraphRunner,
    fuse: GraphRunner,
    refine: GraphRunner,
    /// Format 2: the refiner's tail, applied in Rust, and the buffers of its maps.
    refine_tail: Option<(GatedKernel, Vec<Array2<f32>>)>,
    /// Hybrid refiners: the blend of depth and classical output the gated kernel runs on.
    blended: Option<Array2<f32>>,
    /// Guarded refiners: `ln` of the published depth's expected error (metres) of the last
    /// [`refine`](BundleRunner::refine).
    log_error: Option<Array2<f32>>,
}

impl BundleRunner {
    /// Optimises every graph of `bundle` for `width × height` frames, single-threaded.
    ///
    /// # Errors
    /// [`BundleError::Resolution`] for a zero or oversized frame, [`BundleError::Onnx`] when
    /// tract cannot type or optimise a graph at that size, [`BundleError::Contract`] when a
    /// graph's output does not have the contract's shape.
    pub fn new(bundle: &ModelBundle, width: usize, height: usize) -> Result<Self, BundleError> {
        Self::with_options(bundle, width, height, RunnerOptions::default())
    }

    /// [`new`](Self::new) with explicit [`RunnerOptions`].
    ///
    /// # Errors
    /// As [`new`](Self::new); [`BundleError::Resolution`] also when the thread pool cannot be
    /// created.
    pub fn with_options(
        bundle: &ModelBundle,
        width: usize,
        height: usize,
        options: RunnerOptions,
    ) -> Result<Self, BundleError> {
        let resolution = |message: String| BundleError::Resolution {
            width,
            height,
            message,
        };
        if width == 0 || height == 0 {
            return Err(resolution("width and height must be positive".into()));
        }
        let m = bundle.input_size_multiple();
        let padded = (height.div_ceil(m) * m, width.div_ceil(m) * m);
        if padded.0 > MAX_SIDE || padded.1 > MAX_SIDE {
            return Err(resolution(format!(
                "padded size {}x{} exceeds {MAX_SIDE}",
                padded.1, padded.0
            )));
        }
        let executor = executor(options.threads).map_err(resolution)?;
        let run_options = RunOptions {
            executor,
            ..RunOptions::default()
        };
        let apply = bundle.refine_apply();
        let build = |role: GraphRole| {
            let output = output_contract(role, apply);
            GraphRunner::new(bundle.graph(role), padded, &run_options, output)
        };
        let refine_tail = apply.map(|a| {
            let k = GatedKernel::new(a, bundle.normalisation().max_depth_m);
            let maps = (0..a.channels)
                .map(|_| Array2::zeros((padded.0 / a.stride, padded.1 / a.stride)))
                .collect();
            (k, maps)
        });
        let blended = refine_tail
            .as_ref()
            .filter(|(k, _)| k.jump_scale.is_some())
            .map(|_| Array2::zeros((height, width)));
        let log_error = refine_tail
            .as_ref()
            .filter(|(k, _)| k.errors.is_some())
            .map(|_| Array2::from_elem((height, width), f32::INFINITY));
        Ok(BundleRunner {
            width,
            height,
            padded,
            refine_uses_rgb: bundle.refine_uses_rgb(),
            flow: build(GraphRole::Flow)?,
            fuse: build(GraphRole::Fuse)?,
            refine: build(GraphRole::Refine)?,
            refine_tail,
            blended,
            log_error,
        })
    }

    /// `(height, width)` of the stream.
    pub fn dim(&self) -> (usize, usize) {
        (self.height, self.width)
    }

    /// `(height, width)` the graphs run at (the stream's, padded up to the size multiple).
    pub fn padded_dim(&self) -> (usize, usize) {
        self.padded
    }

    /// Whether [`refine`](Self::refine) needs the classical refiner's output (a `hybrid`
    /// refiner).
    pub fn refine_uses_classical(&self) -> bool {
        self.blended.is_some()
    }

    /// A guarded refiner's `ln` expected absolute error (metres) of each pixel the last
    /// [`refine`](Self::refine) published (`+∞` where it published no depth); `None` for
    /// refiners without expected-error maps.
    pub fn expected_log_error(&self) -> Option<ArrayView2<'_, f32>> {
        self.log_error.as_ref().map(|e| e.view())
    }

    /// Whether [`refine`](Self::refine) needs the RGB planes.
    pub fn refine_uses_rgb(&self) -> bool {
        self.refine_uses_rgb
    }

    /// Rough flow `W_rough` from RGB planes in `[0, 1]` and the normalised amplitude.
    ///
    /// # Errors
    /// [`BundleError::InputShape`] when a plane is not `H × W`, [`BundleError::Run`] when tract
    /// fails.
    pub fn flow(
        &mut self,
        rgb: [ArrayView2<f32>; 3],
        amplitude: ArrayView2<f32>,
        out: &mut Flow,
    ) -> Result<(), BundleError> {
        self.flow.run(
            &[("rgb", &rgb), ("amplitude", &[amplitude])],
            &mut [out.u.view_mut(), out.v.view_mut()],
        )
    }

    /// Fused flow `W_refn` from `W_rough` and `W_convt`.
    ///
    /// # Errors
    /// As [`flow`](Self::flow).
    pub fn fuse(&mut self, rough: &Flow, convt: &Flow, out: &mut Flow) -> Result<(), BundleError> {
        self.fuse.run(
            &[
                ("flow_rough", &[rough.u.view(), rough.v.view()]),
                ("flow_convt", &[convt.u.view(), convt.v.view()]),
            ],
            &mut [out.u.view_mut(), out.v.view_mut()],
        )
    }

    /// Refined depth (metres) from the warped normalised amplitude, the warped depth (metres),
    /// for variants that use them the RGB planes, and for `hybrid` and `guarded` refiners the
    /// classical refiner's output on the warped depth (metres) with its confidence. A guarded
    /// refiner publishes, per pixel, the candidate with the smallest expected error and leaves
    /// that error in [`expected_log_error`](Self::expected_log_error).
    ///
    /// # Errors
    /// As [`flow`](Self::flow); [`BundleError::Run`] also when the graph needs RGB or the
    /// classical output and it is `None`.
    pub fn refine(
        &mut self,
        amplitude: ArrayView2<f32>,
        depth: ArrayView2<f32>,
        rgb: Option<[ArrayView2<f32>; 3]>,
        classical: Option<ClassicalEstimate>,
        mut out: ArrayViewMut2<f32>,
    ) -> Result<(), BundleError> {
        let missing = |what: &str| BundleError::Run {
            graph: GraphRole::Refine.name(),
            message: format!("this refinement variant needs {what}"),
        };
        let amp = [amplitude];
        let dep = [depth];
        let mut inputs: Vec<(&str, &[ArrayView2<f32>])> =
            vec![("amplitude", &amp), ("depth", &dep)];
        let rgb_planes;
        if self.refine_uses_rgb {
            rgb_planes = rgb.ok_or_else(|| missing("the RGB image"))?;
            inputs.push(("rgb", &rgb_planes));
        }
        let classical_plane;
        if self.blended.is_some() {
            classical_plane = [classical
                .ok_or_else(|| missing("the classical refiner's output"))?
                .depth];
            inputs.push(("classical", &classical_plane));
        }
        match &mut self.refine_tail {
            None => self.refine.run(&inputs, &mut [out]),
            Some((kernel, maps)) => {
                let mut views: Vec<ArrayViewMut2<f32>> =
                    maps.iter_mut().map(|m| m.view_mut()).collect();
                self.refine.run(&inputs, &mut views)?;
                match (&mut self.blended, classical) {
                    (Some(base), Some(c)) => {
                        blend_classical(maps, depth, c, base.view_mut(), kernel);
                        apply_gated(maps, base.view(), out.view_mut(), kernel);
                        if let Some(log_error) = &mut self.log_error {
                            let cd = c.depth;
                            select_guarded(maps, depth, cd, out, log_error.view_mut(), kernel);
                            if let Some(floor) = kernel.errors.and_then(|e| e.floor) {
                                floor_expected_error(depth, cd, log_error.view_mut(), &floor);
                            }
                        }
                    }
                    _ => apply_gated(maps, depth, out, kernel),
                }
                Ok(())
            }
        }
    }
}

/// The executor of the plans: `None` (the calling thread) or a private pool.
#[cfg(feature = "multithread")]
fn executor(threads: usize) -> Result<Option<multithread::Executor>, String> {
    if threads <= 1 {
        return Ok(None);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("dear-tract-{i}"))
        .build()
        .map_err(|e| format!("cannot start {threads} inference threads: {e}"))?;
    Ok(Some(multithread::Executor::MultiThread(
        std::sync::Arc::new(pool),
    )))
}

#[cfg(not(feature = "multithread"))]
fn executor(_threads: usize) -> Result<Option<multithread::Executor>, String> {
    Ok(None)
}

/// One optimised graph with its reusable state and its input order.
struct GraphRunner {
    role: GraphRole,
    state: TypedSimpleState,
    /// Per graph input, in the graph's order, its shape and the provided inputs it is made of:
    /// the one of its name, or for a stacked input (`stacked_input`) the parts of the
    /// concatenation it replaces.
    inputs: Vec<Stack>,
    out_channels: usize,
    /// The output is at 1/`out_stride` of the padded input and returned whole (not cropped).
    out_stride: usize,
    padded: (usize, usize),
    /// The input tensors of the last run, refilled in place when tract has let go of them: a
    /// fresh 640×480 tensor per input and frame cost page faults (the kernel zeroing new
    /// pages) comparable to the small convolutions.
    input_tensors: Vec<Option<Arc<Tensor>>>,
    /// Scratch: the padded input rows of a pooled part (`stacked_input::Transform`).
    pool_rows: Vec<f32>,
}

impl std::fmt::Debug for GraphRunner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GraphRunner")
            .field("role", &self.role)
            .field("inputs", &self.inputs)
            .field("out_channels", &self.out_channels)
            .field("padded", &self.padded)
            .finish_non_exhaustive()
    }
}

impl GraphRunner {
    fn new(
        graph: &LoadedGraph,
        padded: (usize, usize),
        options: &RunOptions,
        output: GraphOutput,
    ) -> Result<Self, BundleError> {
        let onnx_err = |e: TractError| BundleError::Onnx {
            path: graph.path.clone(),
            graph: graph.role.name(),
            message: format!("{e:#}"),
        };
        let contract = graph.role.contract();
        let (hp, wp) = padded;
        let mut model = graph.model.clone();
        let mut channels_of = std::collections::HashMap::new();
        for (i, name) in graph.input_names.iter().enumerate() {
            let channels = contract
                .inputs
                .iter()
                .find(|c| c.0 == name)
                .map(|c| c.1)
                .expect("ModelBundle::load checked the input names");
            let fact = InferenceFact::dt_shape(f32::datum_type(), tvec![1, channels, hp, wp]);
            model.set_input_fact(i, fact).map_err(onnx_err)?;
            channels_of.insert(name.clone(), channels);
        }
        let mut typed = model
            .into_typed()
            .and_then(|m| m.into_decluttered())
            .map_err(onnx_err)?;
        let stacks = stack_concatenated_inputs(&mut typed).map_err(onnx_err)?;
        let mut inputs = Vec::new();
        for outlet in typed.input_outlets().map_err(onnx_err)? {
            let name = &typed.node(outlet.node).name;
            let stack = stacks.iter().find(|s| &s.name == name);
            inputs.push(match (stack, channels_of.get(name)) {
                (Some(stack), _) => stack.clone(),
                (None, Some(&channels)) => Stack {
                    name: name.clone(),
                    shape: [1, channels, hp, wp],
                    parts: vec![StackPart {
                        input: name.clone(),
                        channels,
                        transform: Transform::None,
                    }],
                },
                (None, None) => {
                    return Err(BundleError::Onnx {
                        path: graph.path.clone(),
                        graph: graph.role.name(),
                        message: format!("input {name:?} is not an input of the bundle's contract"),
                    })
                }
            });
        }
        let typed = typed.into_optimized().map_err(onnx_err)?;
        let out_channels = output.channels;
        let (ho, wo) = (hp / output.stride, wp / output.stride);
        let want: TVec<TDim> = tvec![1.into(), out_channels.into(), ho.into(), wo.into()];
        let got = &typed.output_fact(0).map_err(onnx_err)?.shape;
        if got.iter().cloned().collect::<TVec<TDim>>() != want {
            return Err(BundleError::Contract {
                path: graph.path.clone(),
                graph: graph.role.name(),
                message: format!(
                    "output {:?} has shape {got:?} for {hp}x{wp} inputs, expected {want:?}",
                    output.name
                ),
            });
        }
        let plan = typed
            .into_runnable_with_options(options)
            .map_err(onnx_err)?;
        let state = TypedSimpleState::new(&plan).map_err(onnx_err)?;
        let input_tensors = vec![None; inputs.len()];
        Ok(GraphRunner {
            role: graph.role,
            state,
            inputs,
            out_channels,
            out_stride: output.stride,
            padded,
            input_tensors,
            pool_rows: Vec::new(),
        })
    }

    /// Pads the named inputs into tensors, runs, crops the single output into `outputs`
    /// (one plane per output channel; with `out_stride > 1`, the whole low-resolution output).
    /// Every input plane has the shape of the first output plane (`out_stride` 1) or of the
    /// first input's (otherwise).
    fn run(
        &mut self,
        provided: &[(&str, &[ArrayView2<f32>])],
        outputs: &mut [ArrayViewMut2<f32>],
    ) -> Result<(), BundleError> {
        let run_err = |message: String| BundleError::Run {
            graph: self.role.name(),
            message,
        };
        let out_dim = outputs
            .first()
            .map(|o| o.dim())
            .ok_or_else(|| run_err("no output planes".into()))?;
        if outputs.len() != self.out_channels || outputs.iter().any(|o| o.dim() != out_dim) {
            return Err(run_err(format!(
                "expected {} output planes of one shape",
                self.out_channels
            )));
        }
        let (hp, wp) = self.padded;
        let (ho, wo) = (hp / self.out_stride, wp / self.out_stride);
        let dim = if self.out_stride == 1 {
            out_dim
        } else {
            if out_dim != (ho, wo) {
                return Err(run_err(format!(
                    "output planes are {out_dim:?}, expected the graph's {ho}x{wo}"
                )));
            }
            provided
                .first()
                .and_then(|(_, p)| p.first())
                .map(|p| p.dim())
                .ok_or_else(|| run_err("no input planes".into()))?
        };
        let mut tensors: TVec<TValue> = TVec::with_capacity(self.inputs.len());
        for (i, spec) in self.inputs.iter().enumerate() {
            let mut stack: TVec<(&[ArrayView2<f32>], Transform)> = TVec::new();
            for StackPart {
                input: name,
                channels,
                transform,
            } in &spec.parts
            {
                let planes = provided
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, p)| *p)
                    .ok_or_else(|| run_err(format!("input {name:?} was not provided")))?;
                if planes.len() != *channels {
                    return Err(run_err(format!(
                        "input {name:?} has {} planes, expected {channels}",
                        planes.len()
                    )));
                }
                for p in planes {
                    if p.dim() != dim {
                        return Err(BundleError::InputShape {
                            graph: self.role.name(),
                            input: static_input(name),
                            expected: dim,
                            found: p.dim(),
                        });
                    }
                }
                stack.push((planes, *transform));
            }
            let slot = &mut self.input_tensors[i];
            // Reuse last run's tensor when nothing else holds it; otherwise a new one.
            let reusable = slot.as_mut().and_then(Arc::get_mut);
            let tensor = match reusable {
                Some(t) => t,
                None => {
                    let fresh =
                        Tensor::zero::<f32>(&spec.shape).map_err(|e| run_err(format!("{e:#}")))?;
                    Arc::get_mut(slot.insert(Arc::new(fresh))).expect("a new Arc is unique")
                }
            };
            fill_padded(self.padded.1, &stack, tensor, &mut self.pool_rows)
                .map_err(|e| run_err(format!("{e:#}")))?;
            tensors.push(slot.clone().expect("filled above").into_tvalue());
        }
        let result = self
            .state
            .run(tensors)
            .map_err(|e| run_err(format!("{e:#}")))?;
        let out = result
            .first()
            .ok_or_else(|| run_err("the graph returned no output".into()))?;
        if out.shape() != [1, self.out_channels, ho, wo] {
            return Err(run_err(format!(
                "output shape {:?}, expected [1, {}, {ho}, {wo}]",
                out.shape(),
                self.out_channels
            )));
        }
        let plain = out
            .try_as_plain_ram()
            .map_err(|e| run_err(format!("{e:#}")))?;
        let data = plain
            .as_slice::<f32>()
            .map_err(|e| run_err(format!("{e:#}")))?;
        let w = out_dim.1;
        for (c, plane) in outputs.iter_mut().enumerate() {
            let base = c * ho * wo;
            for (y, mut row) in plane.rows_mut().into_iter().enumerate() {
                let src = &data[base + y * wo..base + y * wo + w];
                for (o, s) in row.iter_mut().zip(src) {
                    *o = *s;
                }
            }
        }
        Ok(())
    }
}

/// Writes the planes of `parts`, one after the other, into the `1 × C × H × W` tensor `t`: each
/// plane replicate-padded to the runner's `H' × W'` (its last row and column repeated; `wp` is
/// `W'`), then transformed as its part says (`stacked_input::Transform`: as it is, scaled, or
/// pooled, which makes `H × W` smaller than `H' × W'`). `rows` is scratch for a pool's padded
/// rows.
fn fill_padded(
    wp: usize,
    parts: &[(&[ArrayView2<f32>], Transform)],
    t: &mut Tensor,
    rows: &mut Vec<f32>,
) -> TractResult<()> {
    let (th, tw) = (t.shape()[2], t.shape()[3]);
    let mut view = t.try_as_plain_ram_mut()?;
    let data = view.as_slice_mut::<f32>()?;
    let planes = parts
        .iter()
        .flat_map(|(planes, transform)| planes.iter().map(move |p| (p, *transform)));
    for (c, (plane, transform)) in planes.enumerate() {
        let out = &mut data[c * th * tw..(c + 1) * th * tw];
        let h = plane.nrows();
        let padded_row = |y: usize, dst: &mut [f32], scale: Option<f32>| {
            let src = plane.row(y.min(h - 1));
            match src.as_slice() {
                Some(row) => fill_row(dst, row, scale),
                None => {
                    let w = src.len();
                    for (x, d) in dst.iter_mut().enumerate() {
                        let v = src[x.min(w - 1)];
                        *d = scale.map_or(v, |s| v * s);
                    }
                }
            }
        };
        let mut padded_rows = |scale: Option<f32>| {
            for (y, dst) in out.chunks_exact_mut(wp).enumerate() {
                padded_row(y, dst, scale);
            }
        };
        match transform {
            Transform::None => padded_rows(None),
            Transform::Scale(s) => padded_rows(Some(s)),
            Transform::AveragePool(k) => {
                rows.resize(k * wp, 0.0);
                for (by, dst) in out.chunks_exact_mut(tw).enumerate() {
                    for (dy, row) in rows.chunks_exact_mut(wp).enumerate() {
                        padded_row(by * k + dy, row, None);
                    }
                    let rows: TVec<&[f32]> = rows.chunks_exact(wp).collect();
                    average_pool_row(&rows, k, dst);
                }
            }
        }
    }
    Ok(())
}

/// `dst` is `row` (times `scale`), its last value repeated to the end.
fn fill_row(dst: &mut [f32], row: &[f32], scale: Option<f32>) {
    let w = row.len();
    match scale {
        None => dst[..w].copy_from_slice(row),
        Some(s) => {
            for (d, &x) in dst[..w].iter_mut().zip(row) {
                *d = x * s;
            }
        }
    }
    let last = dst[w - 1];
    dst[w..].fill(last);
}

/// Input names as `'static` strings for [`BundleError::InputShape`].
fn static_input(name: &str) -> &'static str {
    ["rgb", "amplitude", "flow_rough", "flow_convt", "depth"]
        .into_iter()
        .find(|n| *n == name)
        .unwrap_or("input")
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;
    use std::path::PathBuf;

    /// The runner feeds the stacked input (`stacked_input`) from the planes, scaled and
    /// padded, so that its graph computes what the ONNX graph computes on the padded planes
    /// given one by one, bit for bit: here against tract running the graph as written.
    #[test]
    fn a_runner_with_a_stacked_input_gives_the_graph_as_written_bit_for_bit() {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/edge");
        let bundle = ModelBundle::load(&dir).unwrap();
        // Not a multiple of the bundle's size multiple: the padding is exercised too.
        let (h, w): (usize, usize) = (37, 45);
        let m = bundle.input_size_multiple();
        let padded = (h.div_ceil(m) * m, w.div_ceil(m) * m);
        for role in [GraphRole::Fuse, GraphRole::Refine] {
            let graph = bundle.graph(role);
            let output = output_contract(role, bundle.refine_apply());
            let mut runner =
                GraphRunner::new(graph, padded, &RunOptions::default(), output).unwrap();
            assert!(
                runner.inputs.iter().any(|s| s.parts.len() > 1),
                "{role:?}: no stacked input"
            );
            let contract = role.contract();
            let planes: Vec<(String, Vec<Array2<f32>>)> = graph
                .input_names
                .iter()
                .enumerate()
                .map(|(i, name)| {
                    let c = contract.inputs.iter().find(|c| c.0 == name).unwrap().1;
                    let planes = (0..c)
                        .map(|k| {
                            Array2::from_shape_fn((h, w), |(y, x)| {
                                let v = (y * 131 + x * 71 + (i * 3 + k) * 977) % 1009;
                                0.3 + v as f32 / 211.0
                            })
                        })
                        .collect();
                    (name.clone(), planes)
                })
                .collect();
            let views: Vec<(String, Vec<ArrayView2<f32>>)> = planes
                .iter()
                .map(|(n, p)| (n.clone(), p.iter().map(|a| a.view()).collect()))
                .collect();
            let provided: Vec<(&str, &[ArrayView2<f32>])> = views
                .iter()
                .map(|(n, v)| (n.as_str(), v.as_slice()))
                .collect();
            let (ho, wo) = (padded.0 / output.stride, padded.1 / output.stride);
            let out_dim = if output.stride == 1 { (h, w) } else { (ho, wo) };
            let mut got: Vec<Array2<f32>> = (0..output.channels)
                .map(|_| Array2::zeros(out_dim))
                .collect();
            let mut views: Vec<ArrayViewMut2<f32>> = got.iter_mut().map(|g| g.view_mut()).collect();
            runner.run(&provided, &mut views).unwrap();

            // The graph as written, each input padded into a tensor of its own.
            let mut model = graph.model.clone();
            let mut inputs = TVec::new();
            for (i, (_, p)) in planes.iter().enumerate() {
                let shape = [1, p.len(), padded.0, padded.1];
                // Replicate-padded at the bottom and right, written out here on its own.
                let t = tract_ndarray::Array4::from_shape_fn(shape, |(_, c, y, x)| {
                    p[c][[y.min(h - 1), x.min(w - 1)]]
                });
                let t = Tensor::from(t);
                model.set_input_fact(i, f32::fact(shape).into()).unwrap();
                inputs.push(t.into_tvalue());
            }
            let plan = model.into_optimized().unwrap().into_runnable().unwrap();
            let want = plan.run(inputs).unwrap().remove(0).into_tensor();
            let want = want.to_plain_array_view::<f32>().unwrap();
            let mut differ = 0;
            for (c, g) in got.iter().enumerate() {
                for ((y, x), v) in g.indexed_iter() {
                    differ += usize::from(v.to_bits() != want[[0, c, y, x]].to_bits());
                }
            }
            assert_eq!(differ, 0, "{role:?}: {differ} values differ");
        }
    }
}
