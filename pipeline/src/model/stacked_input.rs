//! One input tensor in place of a graph's channel concatenation of its inputs.
//!
//! A graph that starts by concatenating its inputs along the channels (the refine graphs:
//! `Concat(amplitude, depth / s, rgb, classical / s)`, docs/models.md) makes tract copy every
//! plane twice per frame: the runner pads each input into a tensor of its own, and tract's
//! `Concat` copies them all into a fresh tensor (0.8 ms of the 640×480 refine graph on one
//! core, `graph_profile`), after its `Mul` by `1/s` has cloned the scaled inputs (the runner
//! keeps a handle on them to reuse them). [`stack_concatenated_inputs`] rewires the graph so
//! that the concatenation is an input itself, which the runner fills from the same planes in
//! one pass: each part copied, or multiplied by the scale as tract would have (`x * (1/s)`:
//! tract declutters a division by a constant into a multiplication by its `recip`), so the
//! graph computes the same values bit for bit.

use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::array::TypedConcat;
use tract_onnx::tract_core::ops::binary::TypedBinOp;
use tract_onnx::tract_core::ops::source::TypedSource;

/// The name of the input that replaces the concatenation.
pub(crate) const STACKED_INPUT: &str = "stacked";

/// One part of the stacked input: `channels` planes of the graph input `input`, each value
/// multiplied by `scale` when there is one, at the next channels of the stack.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StackPart {
    pub input: String,
    pub channels: usize,
    pub scale: Option<f32>,
}

/// Rewires a typed (decluttered) `model` whose inputs meet in one channel concatenation (axis
/// 1 of `N × C × H × W`) of inputs or inputs times a scalar constant: the concatenation's
/// consumers read a new input [`STACKED_INPUT`] instead, appended to the model's inputs, and
/// the inputs nothing else reads are dropped from them. Returns the parts of the new input in
/// channel order, or `None` (and leaves `model` unchanged) when the graph has no such
/// concatenation.
pub(crate) fn stack_concatenated_inputs(
    model: &mut TypedModel,
) -> TractResult<Option<Vec<StackPart>>> {
    let Some((concat, parts)) = find_stack(model)? else {
        return Ok(None);
    };
    let outlet = OutletId::new(concat, 0);
    let fact = model.outlet_fact(outlet)?.clone();
    let consumers = model.outlet_successors(outlet).to_vec();
    let stacked = model.add_source(STACKED_INPUT, fact)?;
    for inlet in consumers {
        model.add_edge(stacked, inlet)?;
    }
    // Inputs still needed: those on a path to an output now that the concatenation is cut off.
    let needed = model.eval_order()?;
    let inputs: Vec<OutletId> = model
        .input_outlets()?
        .iter()
        .copied()
        .filter(|o| needed.contains(&o.node))
        .collect();
    model.set_input_outlets(&inputs)?;
    model.compact()?;
    Ok(Some(parts))
}

/// The concatenation node and its parts, when `model` has one that qualifies.
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

/// What `outlet` is in terms of the model's inputs: an f32 input itself, or an f32 input times
/// a one-element f32 constant.
fn part_of(model: &TypedModel, outlet: OutletId) -> TractResult<Option<StackPart>> {
    let input_part = |o: OutletId, scale: Option<f32>| -> TractResult<Option<StackPart>> {
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
            scale,
        }))
    };
    if let Some(part) = input_part(outlet, None)? {
        return Ok(Some(part));
    }
    let node = model.node(outlet.node);
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
            if let Some(part) = input_part(node.inputs[x], Some(s))? {
                return Ok(Some(part));
            }
        }
    }
    Ok(None)
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
        let parts = stack_concatenated_inputs(&mut stacked).unwrap().unwrap();
        let names: Vec<_> = parts
            .iter()
            .map(|p| (p.input.as_str(), p.channels))
            .collect();
        assert_eq!(
            names,
            [("amplitude", 1), ("depth", 1), ("rgb", 3), ("classical", 1)]
        );
        assert!(parts[0].scale.is_none() && parts[2].scale.is_none());
        assert!(parts[1].scale.is_some() && parts[3].scale.is_some());
        let mut stack = Vec::new();
        for p in &parts {
            let s = p.scale.unwrap_or(1.0);
            let data = planes[&p.input].to_plain_array_view::<f32>().unwrap();
            stack.extend(
                data.iter()
                    .map(|&x| if p.scale.is_some() { x * s } else { x }),
            );
        }
        let stack = Tensor::from_shape(&[1, 6, h, w], &stack).unwrap();
        // The gate still reads amplitude and depth themselves; rgb and classical are gone.
        let kept: Vec<String> = stacked
            .input_outlets()
            .unwrap()
            .iter()
            .map(|o| stacked.node(o.node).name.clone())
            .collect();
        assert_eq!(kept, ["amplitude", "depth", STACKED_INPUT]);
        let got = run(
            stacked,
            tvec![
                planes["amplitude"].clone().into_tvalue(),
                planes["depth"].clone().into_tvalue(),
                stack.into_tvalue(),
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
        assert_eq!(stack_concatenated_inputs(&mut model).unwrap(), None);
        assert_eq!(format!("{model:?}"), before);
        assert_eq!(model.input_outlets().unwrap().len(), inputs.len());
    }
}
