//! One input tensor in place of a graph's channel concatenation of its inputs.
//!
//! A graph that starts by concatenating its inputs along the channels (the refine graphs:
//! `Concat(amplitude, depth / s, rgb, classical / s)`, and their multi-path gate's
//! `Concat(AveragePool₄(amplitude), AveragePool₄(depth))`, docs/models.md) makes tract copy
//! every plane twice per frame: the runner pads each input into a tensor of its own, and
//! tract's `Concat` copies them all into a fresh tensor (0.8 ms of the 640×480 refine graph on
//! one core, `graph_profile`), after its `Mul` by `1/s` has cloned the scaled inputs (the
//! runner keeps a handle on them to reuse them); its generic average pool took another 0.7 ms
//! for 0.6 M additions. [`stack_concatenated_inputs`] rewires the graph so that each such
//! concatenation is an input itself, which the runner fills from the same planes in one pass:
//! each part copied, multiplied by the scale as tract would have (`x * (1/s)`: tract
//! declutters a division by a constant into a multiplication by its `recip`), or pooled with
//! tract's sums in tract's order ([`average_pool_row`]), so the graph computes the same values
//! bit for bit.

use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::array::TypedConcat;
use tract_onnx::tract_core::ops::binary::TypedBinOp;
use tract_onnx::tract_core::ops::cnn::{PaddingSpec, SumPool};
use tract_onnx::tract_core::ops::nn::DataFormat;
use tract_onnx::tract_core::ops::source::TypedSource;

/// The name of the inputs that replace concatenations, followed by their number.
pub(crate) const STACKED_INPUT: &str = "stacked";

/// One part of a stacked input: `channels` planes of the graph input `input`, at the next
/// channels of the stack, each plane as it is or transformed as [`Transform`] says.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StackPart {
    pub input: String,
    pub channels: usize,
    pub transform: Transform,
}

/// What a part does to its input's (padded) planes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Transform {
    /// The planes as they are.
    None,
    /// Every value multiplied by this factor.
    Scale(f32),
    /// The mean of each `k × k` block (`k` the value, blocks side by side from the top left,
    /// the last partial row and column of blocks dropped), summed as tract's average pool.
    AveragePool(usize),
}

/// A stacked input: its name among the graph's inputs, its shape `1 × C × H × W` and its
/// parts in channel order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Stack {
    pub name: String,
    pub shape: [usize; 4],
    pub parts: Vec<StackPart>,
}

/// Rewires a typed (decluttered) `model` whose inputs meet in channel concatenations (axis 1
/// of `N × C × H × W`) of inputs, inputs times a scalar constant and average pools of inputs:
/// each concatenation's consumers read a new input instead (`stacked0`, `stacked1`, …, appended
/// to the model's inputs), and the inputs nothing else reads are dropped from them. Returns
/// the new inputs; none (and `model` unchanged) when the graph has no such concatenation.
pub(crate) fn stack_concatenated_inputs(model: &mut TypedModel) -> TractResult<Vec<Stack>> {
    let mut stacks = Vec::new();
    while let Some((concat, parts)) = find_stack(model)? {
        let outlet = OutletId::new(concat, 0);
        let fact = model.outlet_fact(outlet)?.clone();
        let shape = fact
            .shape
            .as_concrete()
            .map(|s| s.to_vec())
            .unwrap_or_default();
        let [n, c, h, w] = shape[..] else {
            return Err(TractError::msg(format!(
                "a stacked input needs a concrete 4-D shape, not {:?}",
                fact.shape
            )));
        };
        let name = format!("{STACKED_INPUT}{}", stacks.len());
        let consumers = model.outlet_successors(outlet).to_vec();
        let stacked = model.add_source(&name, fact)?;
        for inlet in consumers {
            model.add_edge(stacked, inlet)?;
        }
        // Inputs still needed: those on a path to an output now that the concatenation is
        // cut off. Compacting drops the concatenation, so the next search cannot find it.
        let needed = model.eval_order()?;
        let inputs: Vec<OutletId> = model
            .input_outlets()?
            .iter()
            .copied()
            .filter(|o| needed.contains(&o.node))
            .collect();
        model.set_input_outlets(&inputs)?;
        model.compact()?;
        stacks.push(Stack {
            name,
            shape: [n, c, h, w],
            parts,
        });
    }
    Ok(stacks)
}

/// The first concatenation node that qualifies, and its parts.
fn find_stack(model: &TypedModel) -> TractResult<Option<(usize, Vec<StackPart>)>> {
    for node in model.nodes() {
        let Some(concat) = node.op_as::<TypedConcat>() else {
            continue;
        };
        if concat.axis != 1 || model.outlet_fact(OutletId::new(node.id, 0))?.rank() != 4 {
            continue;
        }
        let parts: Option<Vec<StackPart>> = node
            .inputs
            .iter()
            .map(|&o| part_of(model, o))
            .collect::<TractResult<_>>()?;
        if let Some(parts) = parts {
            return Ok(Some((node.id, parts)));
        }
    }
    Ok(None)
}

/// What `outlet` is in terms of the model's inputs: an f32 `N × C × H × W` input itself, that
/// input times a one-element f32 constant, or its average pool over square blocks.
fn part_of(model: &TypedModel, outlet: OutletId) -> TractResult<Option<StackPart>> {
    let input_part = |o: OutletId, transform: Transform| -> TractResult<Option<StackPart>> {
        let node = model.node(o.node);
        let fact = model.outlet_fact(o)?;
        if node.op_as::<TypedSource>().is_none()
            || fact.datum_type != f32::datum_type()
            || fact.rank() != 4
        {
            return Ok(None);
        }
        let Some(channels) = fact.shape[1].as_i64() else {
            return Ok(None);
        };
        Ok(Some(StackPart {
            input: node.name.clone(),
            channels: channels as usize,
            transform,
        }))
    };
    if let Some(part) = input_part(outlet, Transform::None)? {
        return Ok(Some(part));
    }
    let node = model.node(outlet.node);
    if let Some(pool) = node.op_as::<SumPool>() {
        return match block_pool_side(pool) {
            Some(k) if node.inputs.len() == 1 => {
                input_part(node.inputs[0], Transform::AveragePool(k))
            }
            _ => Ok(None),
        };
    }
    let Some(bin) = node.op_as::<TypedBinOp>() else {
        return Ok(None);
    };
    if bin.0.name() != "Mul" || node.inputs.len() != 2 {
        return Ok(None);
    }
    let scalar = |o: OutletId| -> TractResult<Option<f32>> {
        let fact = model.outlet_fact(o)?;
        Ok(match &fact.konst {
            Some(k) if k.datum_type() == f32::datum_type() && k.len() == 1 => {
                Some(k.cast_to_scalar::<f32>()?)
            }
            _ => None,
        })
    };
    // Multiplication commutes bit for bit, so the constant may be either operand.
    for (x, k) in [(0, 1), (1, 0)] {
        if let Some(s) = scalar(node.inputs[k])? {
            if let Some(part) = input_part(node.inputs[x], Transform::Scale(s))? {
                return Ok(Some(part));
            }
        }
    }
    Ok(None)
}

/// `k` when `pool` is a mean over `k × k` blocks of an NCHW input, side by side (stride `k`,
/// no dilation, no padding), which [`average_pool_row`] computes as tract does.
fn block_pool_side(pool: &SumPool) -> Option<usize> {
    let spec = &pool.pool_spec;
    let k = match spec.kernel_shape.as_slice() {
        &[a, b] if a == b && a > 0 => a,
        _ => return None,
    };
    let strides_ok = spec.strides.as_deref() == Some(&[k, k][..]);
    let dilations_ok = spec
        .dilations
        .as_deref()
        .is_none_or(|d| d.iter().all(|&x| x == 1));
    let unpadded = match &spec.padding {
        PaddingSpec::Valid => true,
        PaddingSpec::Explicit(a, b) => a.iter().chain(b).all(|&p| p == 0),
        PaddingSpec::ExplicitOnnxPool(a, b, ceil) => !ceil && a.iter().chain(b).all(|&p| p == 0),
        _ => false,
    };
    (pool.normalize
        && spec.data_format == DataFormat::NCHW
        && strides_ok
        && dilations_ok
        && unpadded)
        .then_some(k)
}

/// One row of a `k × k` block mean: `out[x]` is the sum of block `x` of `rows` (the `k` input
/// rows, each at least `k × out.len()` long) in row-major order, times `1 / k²`. tract's
/// average pool sums a window's values with `Iterator::sum` (a fold from −0.0) in the same
/// order and multiplies by the `recip` of the window's size, so the values are the same bit
/// for bit; here the sums run across the row, one addition per value and block at a time.
pub(crate) fn average_pool_row(rows: &[&[f32]], k: usize, out: &mut [f32]) {
    let recip = ((k * k) as f32).recip();
    out.fill(-0.0);
    for row in rows {
        for dx in 0..k {
            for (x, o) in out.iter_mut().enumerate() {
                *o += row[x * k + dx];
            }
        }
    }
    for o in out.iter_mut() {
        *o *= recip;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::manifest::GraphRole;
    use std::path::PathBuf;

    fn graph(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../models/edge")
            .join(name)
    }

    /// The graph's inputs as `(name, channels)`, fixed to `1 × C × h × w`, decluttered.
    fn typed(name: &str, (h, w): (usize, usize)) -> (TypedModel, Vec<(String, usize)>) {
        let mut model = tract_onnx::onnx().model_for_path(graph(name)).unwrap();
        let mut inputs = Vec::new();
        for i in 0..model.inputs.len() {
            let name = model.node(model.inputs[i].node).name.clone();
            let channels = [GraphRole::Flow, GraphRole::Refine]
                .iter()
                .flat_map(|r| r.contract().inputs.iter())
                .find(|c| c.0 == name)
                .map(|c| c.1)
                .unwrap();
            model
                .set_input_fact(i, f32::fact([1, channels, h, w]).into())
                .unwrap();
            inputs.push((name, channels));
        }
        (
            model.into_typed().unwrap().into_decluttered().unwrap(),
            inputs,
        )
    }

    /// Deterministic values of several magnitudes and both signs, different per input.
    fn values(seed: usize, len: usize) -> Vec<f32> {
        (0..len)
            .map(|i| (((i * 7919 + seed * 104_729) % 1013) as f32 - 400.0) / 97.0)
            .collect()
    }

    fn run(model: TypedModel, inputs: TVec<TValue>) -> Tensor {
        let plan = model.into_optimized().unwrap().into_runnable().unwrap();
        plan.run(inputs).unwrap().remove(0).into_tensor()
    }

    #[test]
    fn the_stacked_refine_graph_computes_the_concatenated_graph_bit_for_bit() {
        let (h, w) = (32, 48);
        let (plain, inputs) = typed("refine.onnx", (h, w));
        let planes: std::collections::HashMap<String, Tensor> = inputs
            .iter()
            .enumerate()
            .map(|(i, (name, c))| {
                let t = Tensor::from_shape(&[1, *c, h, w], &values(i, c * h * w)).unwrap();
                (name.clone(), t)
            })
            .collect();
        let want = run(
            plain.clone(),
            inputs
                .iter()
                .map(|(n, _)| planes[n].clone().into_tvalue())
                .collect(),
        );

        let mut stacked = plain;
        let stacks = stack_concatenated_inputs(&mut stacked).unwrap();
        let parts: Vec<Vec<(&str, usize, Transform)>> = stacks
            .iter()
            .map(|s| {
                s.parts
                    .iter()
                    .map(|p| (p.input.as_str(), p.channels, p.transform))
                    .collect()
            })
            .collect();
        let scale = match parts[0][1].2 {
            Transform::Scale(s) => s,
            other => panic!("depth is scaled, not {other:?}"),
        };
        assert_eq!(
            parts,
            [
                vec![
                    ("amplitude", 1, Transform::None),
                    ("depth", 1, Transform::Scale(scale)),
                    ("rgb", 3, Transform::None),
                    ("classical", 1, Transform::Scale(scale)),
                ],
                vec![
                    ("amplitude", 1, Transform::AveragePool(4)),
                    ("depth", 1, Transform::AveragePool(4)),
                ],
            ]
        );
        assert_eq!(stacks[0].shape, [1, 6, h, w]);
        assert_eq!(stacks[1].shape, [1, 2, h / 4, w / 4]);
        // The stacks, written out here on their own.
        let plane = |name: &str, c: usize, y: usize, x: usize| {
            planes[name].to_plain_array_view::<f32>().unwrap()[[0, c, y, x]]
        };
        let first = tract_ndarray::Array4::from_shape_fn((1, 6, h, w), |(_, c, y, x)| match c {
            0 => plane("amplitude", 0, y, x),
            1 => plane("depth", 0, y, x) * scale,
            2..=4 => plane("rgb", c - 2, y, x),
            _ => plane("classical", 0, y, x) * scale,
        });
        let second = tract_ndarray::Array4::from_shape_fn((1, 2, h / 4, w / 4), |(_, c, y, x)| {
            let name = ["amplitude", "depth"][c];
            let block = (0..16).map(|i| plane(name, 0, 4 * y + i / 4, 4 * x + i % 4));
            block.sum::<f32>() * 16f32.recip()
        });
        // The gate read amplitude and depth only through its pools: no input is left but the
        // stacks.
        let kept: Vec<String> = stacked
            .input_outlets()
            .unwrap()
            .iter()
            .map(|o| stacked.node(o.node).name.clone())
            .collect();
        assert_eq!(kept, ["stacked0", "stacked1"]);
        let got = run(
            stacked,
            tvec![
                Tensor::from(first).into_tvalue(),
                Tensor::from(second).into_tvalue()
            ],
        );
        assert_eq!(got.shape(), want.shape());
        let g = got.to_plain_array_view::<f32>().unwrap();
        let e = want.to_plain_array_view::<f32>().unwrap();
        let differ = g
            .iter()
            .zip(e)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(differ, 0, "{differ} of {} values differ", g.len());
    }

    #[test]
    fn a_graph_without_a_concatenation_of_its_inputs_is_left_alone() {
        let (mut model, inputs) = typed("flow.onnx", (32, 48));
        let before = format!("{model:?}");
        assert_eq!(stack_concatenated_inputs(&mut model).unwrap(), vec![]);
        assert_eq!(format!("{model:?}"), before);
        assert_eq!(model.input_outlets().unwrap().len(), inputs.len());
    }
}
