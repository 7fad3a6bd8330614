//! Where a bundle graph spends its time in tract: every node of the optimised plan timed over
//! ten runs at a given input size, summed per op kind and listed for the slowest nodes. Inputs
//! are synthetic (the time does not depend on the values).
//!
//! ```sh
//! cargo run --release -p dear-tools --bin graph_profile -- models/edge/refine.onnx 480 640 1,1,3,1
//! ```
//! Arguments: the ONNX file, height, width, and the channel count of each graph input in the
//! graph's order (the refine graph: amplitude, depth, rgb, classical).
use std::collections::HashMap;
use std::time::Instant;

use tract_onnx::prelude::*;

fn main() -> TractResult<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = &args[1];
    let h: usize = args[2].parse()?;
    let w: usize = args[3].parse()?;
    let mut model = tract_onnx::onnx().model_for_path(path)?;
    let n_inputs = model.inputs.len();
    let mut tensors = tvec![];
    for i in 0..n_inputs {
        let c: usize = args[4].split(',').nth(i).unwrap().parse()?;
        model.set_input_fact(
            i,
            InferenceFact::dt_shape(f32::datum_type(), tvec![1, c, h, w]),
        )?;
        let t = tract_ndarray::Array4::<f32>::from_shape_fn((1, c, h, w), |(_, c, y, x)| {
            ((x * 7 + y * 13 + c * 3) % 17) as f32 / 17.0
        });
        tensors.push(Tensor::from(t).into_tvalue());
    }
    let typed = model.into_optimized()?;
    let plan = typed.into_runnable()?;
    let mut state = TypedSimpleState::new(&plan)?;
    for _ in 0..3 {
        state.run(tensors.clone())?;
    }
    let n = 10;
    let mut times: HashMap<usize, (String, String, f64)> = HashMap::new();
    let t0 = Instant::now();
    for _ in 0..n {
        state.run_plan_with_eval(tensors.clone(), |ctx, st, node, input| {
            let t = Instant::now();
            let r = tract_onnx::tract_core::plan::eval(ctx, st, node, input);
            let e = t.elapsed().as_secs_f64() * 1e3;
            let entry = times
                .entry(node.id)
                .or_insert_with(|| (node.name.clone(), format!("{}", node.op().name()), 0.0));
            entry.2 += e;
            r
        })?;
    }
    let total = t0.elapsed().as_secs_f64() * 1e3 / n as f64;
    let mut v: Vec<_> = times.into_iter().collect();
    v.sort_by(|a, b| b.1 .2.partial_cmp(&a.1 .2).unwrap());
    println!("total {total:.2} ms per run");
    let mut by_op: HashMap<String, f64> = HashMap::new();
    for (_, (_, op, t)) in &v {
        *by_op.entry(op.clone()).or_default() += t / n as f64;
    }
    let mut ops: Vec<_> = by_op.into_iter().collect();
    ops.sort_by(|a, b| b.1.partial_cmp(&a.1).unwrap());
    for (op, t) in ops {
        println!("op {op:30} {t:8.2} ms");
    }
    for (id, (name, op, t)) in v.iter().take(25) {
        let node = plan.model().node(*id);
        println!(
            "{:8.2} ms  {op:20} {name}  {:?}",
            t / n as f64,
            node.outputs[0].fact.shape
        );
    }
    Ok(())
}
