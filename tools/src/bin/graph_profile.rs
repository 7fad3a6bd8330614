//! Where a bundle graph spends its time in tract: every node of the optimised plan timed over
//! ten runs at a given input size, summed per op kind and listed for the slowest nodes. Inputs
//! are synthetic (the time does not depend on the values).
//!
//! ```sh
//! cargo run --release -p dear-tools --bin graph_profile -- models/edge/refine.onnx 480 640 1,1,3,1
//! ```
//! Arguments: the ONNX file, height, width, and the channel count of each graph input in the
//! graph's order, comma-separated, one per input (the refine graph: amplitude, depth, rgb,
//! classical).
use std::collections::HashMap;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Instant;

use anyhow::{ensure, Context};
use clap::Parser;
use tract_onnx::prelude::*;

/// Per-node times of an ONNX graph in tract (one thread), at a given input size.
#[derive(Debug, Parser)]
#[command(version)]
struct Cli {
    /// The ONNX graph to profile (e.g. models/edge/refine.onnx).
    onnx: PathBuf,
    /// Input height, pixels.
    height: usize,
    /// Input width, pixels.
    width: usize,
    /// Channel count of each graph input, comma-separated, in the graph's order (refine: 1,1,3,1).
    channels: Channels,
}

/// The `CHANNELS` argument: one channel count per graph input.
#[derive(Debug, Clone)]
struct Channels(Vec<usize>);

impl FromStr for Channels {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        s.split(',')
            .map(|c| {
                c.parse()
                    .map_err(|e| format!("`{c}` is not a channel count: {e}"))
            })
            .collect::<Result<_, _>>()
            .map(Channels)
    }
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (path, h, w) = (&cli.onnx, cli.height, cli.width);
    let mut model = tract_onnx::onnx()
        .model_for_path(path)
        .with_context(|| format!("cannot load the ONNX graph {}", path.display()))?;
    let n_inputs = model.inputs.len();
    let channels = &cli.channels.0;
    ensure!(
        channels.len() == n_inputs,
        "CHANNELS has {} entries but {} has {n_inputs} inputs ({}): give one channel count per \
         graph input, in that order",
        channels.len(),
        path.display(),
        model
            .inputs
            .iter()
            .map(|o| model.node(o.node).name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut tensors = tvec![];
    for (i, &c) in channels.iter().enumerate() {
        model.set_input_fact(
            i,
            InferenceFact::dt_shape(f32::datum_type(), tvec![1, c, h, w]),
        )?;
        let t = tract_ndarray::Array4::<f32>::from_shape_fn((1, c, h, w), |(_, c, y, x)| {
            ((x * 7 + y * 13 + c * 3) % 17) as f32 / 17.0
        });
        tensors.push(Tensor::from(t).into_tvalue());
    }
    let typed = model.into_optimized().with_context(|| {
        format!(
            "cannot optimise {} for inputs of {} channels at {h}x{w}",
            path.display(),
            channels
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(",")
        )
    })?;
    let plan = typed.into_runnable()?;
    let mut state = TypedSimpleState::new(&plan)?;
    for _ in 0..3 {
        state
            .run(tensors.clone())
            .with_context(|| format!("cannot run {}", path.display()))?;
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
