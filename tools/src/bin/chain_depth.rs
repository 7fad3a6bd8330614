//! `chain_depth`: the DEAR chain's output depth on frames of a capture, written to a file, and
//! the comparison of two such files (a bin of `dear-tools`, built in the same cargo invocation
//! as `deard` and `dear`, so that it has their features and shares their compiled
//! dependencies). `scripts/test-aarch64.sh` runs it natively and as an aarch64 binary under
//! qemu-user on the same frames and bundle, then compares: tract's ARM kernels must give the
//! same depth as the x86 ones (issue 18).
//!
//! ```text
//! cargo run --release -p dear-tools --bin chain_depth -- \
//!     run --bundle models/edge --capture samples/demo --frames 3 --out x86.depth
//! chain_depth compare x86.depth arm.depth --tolerance-mm 1
//! ```
//!
//! `run` processes each frame with the paper's chain on that frame alone (rough flow, the
//! calibration fit, fusion, warp, refinement: `ChainMode::Full`, as `dear eval` does), which
//! depends on nothing but the frame and the bundle, unlike the daemon's online mode, whose
//! background network runs land on frames by timing. The file: `DEARDPT1`, then width, height
//! and frame count (u32 little-endian), then per frame its capture id (u64) and the depth in
//! metres (f32 little-endian, row-major, 0 = invalid).
//!
//! `compare` prints the largest difference in millimetres over all pixels (an invalid pixel
//! counts as depth 0, so a pixel valid on one side only shows up as its whole depth), how many
//! pixels are valid on one side only and how many differ by more than the tolerance, and exits
//! with status 1 when the largest difference exceeds `--tolerance-mm`.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Parser, Subcommand};
use dear_capture::is_valid_depth;
use dear_capture::CaptureDir;
use dear_eval::BundleMethod;
use dear_pipeline::model::ModelBundle;

const MAGIC: &[u8; 8] = b"DEARDPT1";

/// Errors are messages: each names the file or frame and what is wrong.
type Result<T> = std::result::Result<T, String>;

/// Returns the formatted message as the error.
macro_rules! bail {
    ($($message:tt)*) => {
        return Err(format!($($message)*))
    };
}

/// Returns the formatted message as the error unless the condition holds.
macro_rules! ensure {
    ($condition:expr, $($message:tt)*) => {
        if !$condition {
            bail!($($message)*);
        }
    };
}

#[derive(Parser)]
#[command(about = "The DEAR chain's depth on a capture's frames, and comparing two runs")]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the chain on frames of a capture and write their output depth to a file.
    Run {
        /// Model bundle directory (format 2, e.g. models/edge).
        #[arg(long)]
        bundle: PathBuf,
        /// Capture directory (e.g. samples/demo).
        #[arg(long)]
        capture: PathBuf,
        /// How many frames, evenly spaced over the capture, the first included.
        #[arg(long, default_value_t = 3)]
        frames: usize,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
    },
    /// Compare two files written by `run`.
    Compare {
        reference: PathBuf,
        other: PathBuf,
        /// Largest difference allowed, millimetres.
        #[arg(long, default_value_t = 1.0)]
        tolerance_mm: f64,
    },
}

/// The contents of a depth file.
struct DepthFile {
    width: usize,
    height: usize,
    /// Per frame: capture id and depth.
    frames: Vec<(u64, Vec<f32>)>,
}

fn main() {
    let outcome = match Args::parse().command {
        Command::Run {
            bundle,
            capture,
            frames,
            out,
        } => run(&bundle, &capture, frames, &out),
        Command::Compare {
            reference,
            other,
            tolerance_mm,
        } => compare(&reference, &other, tolerance_mm).map(|within| {
            if !within {
                std::process::exit(1)
            }
        }),
    };
    if let Err(message) = outcome {
        eprintln!("chain_depth: {message}");
        std::process::exit(2);
    }
}

fn run(bundle_dir: &Path, capture_dir: &Path, count: usize, out: &Path) -> Result<()> {
    ensure!(count > 0, "--frames must be at least 1");
    let bundle = ModelBundle::load(bundle_dir)
        .map_err(|e| format!("cannot load the bundle {}: {e}", bundle_dir.display()))?;
    let capture = CaptureDir::open(capture_dir)
        .map_err(|e| format!("cannot open the capture {}: {e}", capture_dir.display()))?;
    ensure!(
        !capture.is_empty(),
        "{}: the capture has no frames",
        capture_dir.display()
    );
    let (w, h) = capture.size();
    let (width, height) = (w as usize, h as usize);
    let mut chain = BundleMethod::new(&bundle, "chain", height, width)
        .map_err(|e| format!("cannot build the chain of {}: {e}", bundle_dir.display()))?;

    let count = count.min(capture.len());
    let mut bytes = Vec::with_capacity(20 + count * (8 + 4 * width * height));
    bytes.extend_from_slice(MAGIC);
    for value in [w, h, count as u32] {
        bytes.extend_from_slice(&value.to_le_bytes());
    }
    let started = Instant::now();
    for position in (0..count).map(|i| i * capture.len() / count) {
        let frame = capture.read_frame(position).map_err(|e| {
            format!(
                "cannot read frame {position} of {}: {e}",
                capture_dir.display()
            )
        })?;
        let frame_start = Instant::now();
        let out = chain
            .run(&frame)
            .map_err(|e| format!("the chain failed on frame {}: {e}", frame.index))?;
        let valid = out
            .refined
            .depth
            .iter()
            .filter(|d| is_valid_depth(**d))
            .count();
        println!(
            "frame {}: {:.2} s, {} of {} pixels valid",
            frame.index,
            frame_start.elapsed().as_secs_f64(),
            valid,
            width * height
        );
        bytes.extend_from_slice(&frame.index.to_le_bytes());
        // Row-major whatever the array's layout.
        for value in out.refined.depth.iter() {
            bytes.extend_from_slice(&value.to_le_bytes());
        }
    }
    println!(
        "{count} frames of {width}x{height} in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    fs::write(out, &bytes).map_err(|e| format!("cannot write {}: {e}", out.display()))?;
    Ok(())
}

fn read(path: &Path) -> Result<DepthFile> {
    let bytes = fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    if bytes.len() < 20 || &bytes[..8] != MAGIC {
        bail!(
            "{}: not a chain_depth file (it does not start with {:?})",
            path.display(),
            std::str::from_utf8(MAGIC).unwrap_or_default()
        );
    }
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let (width, height, count) = (word(8), word(12), word(16));
    let frame_bytes = 8 + 4 * width * height;
    let expected = 20 + count * frame_bytes;
    ensure!(
        bytes.len() == expected,
        "{}: {} bytes, but its header ({count} frames of {width}x{height}) needs {expected}",
        path.display(),
        bytes.len()
    );
    let frames = bytes[20..]
        .chunks_exact(frame_bytes)
        .map(|chunk| {
            let id = u64::from_le_bytes(chunk[..8].try_into().unwrap());
            let depth = chunk[8..]
                .chunks_exact(4)
                .map(|v| f32::from_le_bytes(v.try_into().unwrap()))
                .collect();
            (id, depth)
        })
        .collect();
    Ok(DepthFile {
        width,
        height,
        frames,
    })
}

/// Prints the comparison; whether the largest difference is within the tolerance.
fn compare(reference: &Path, other: &Path, tolerance_mm: f64) -> Result<bool> {
    let (a, b) = (read(reference)?, read(other)?);
    ensure!(
        (a.width, a.height, a.frames.len()) == (b.width, b.height, b.frames.len()),
        "{} holds {} frames of {}x{}, {} holds {} frames of {}x{}: not the same run",
        reference.display(),
        a.frames.len(),
        a.width,
        a.height,
        other.display(),
        b.frames.len(),
        b.width,
        b.height
    );
    let mut largest = (0.0f64, 0u64, 0usize, 0.0f32, 0.0f32);
    let (mut one_sided, mut over, mut pixels) = (0usize, 0usize, 0usize);
    for ((id_a, depth_a), (id_b, depth_b)) in a.frames.iter().zip(&b.frames) {
        ensure!(
            id_a == id_b,
            "frame {id_a} in {} faces frame {id_b} in {}: not the same frames",
            reference.display(),
            other.display()
        );
        for (i, (&da, &db)) in depth_a.iter().zip(depth_b).enumerate() {
            let (va, vb) = (is_valid_depth(da), is_valid_depth(db));
            let diff_mm = 1000.0
                * (f64::from(if va { da } else { 0.0 }) - f64::from(if vb { db } else { 0.0 }))
                    .abs();
            pixels += 1;
            one_sided += usize::from(va != vb);
            over += usize::from(diff_mm > tolerance_mm);
            if diff_mm > largest.0 {
                largest = (diff_mm, *id_a, i, da, db);
            }
        }
    }
    let (diff, id, i, da, db) = largest;
    println!(
        "{} frames, {pixels} pixels: largest difference {diff:.4} mm (frame {id}, row {}, column \
         {}: {da} m vs {db} m); valid on one side only: {one_sided} pixels; over {tolerance_mm} \
         mm: {over} pixels",
        a.frames.len(),
        i / a.width.max(1),
        i % a.width.max(1)
    );
    Ok(diff <= tolerance_mm)
}
