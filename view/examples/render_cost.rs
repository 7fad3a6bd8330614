//! Time to draw and JPEG-encode each picture `dear view` serves, from the frames of a capture
//! directory (its ToF depth and RGB; the amplitude, scaled, as the confidence): what one
//! snapshot costs the viewer, however many browsers ask for it.
//!
//! `cargo run --release -p dear-view --example render_cost -- CAPTURE_DIR [ROUNDS]`

use std::time::Instant;

use dear_capture::CaptureDir;
use dear_proto::FrameHeader;
use dear_view::intake::Snapshot;
use dear_view::render::{render, Picture};

fn main() {
    let mut args = std::env::args().skip(1);
    let dir = args
        .next()
        .expect("usage: render_cost CAPTURE_DIR [ROUNDS]");
    let rounds: usize = args.next().map_or(20, |r| r.parse().expect("ROUNDS"));
    let capture = CaptureDir::open(&dir).expect("a capture directory");
    let snapshots: Vec<Snapshot> = (0..capture.len().min(8))
        .map(|i| {
            let f = capture.read_frame(i).expect("a readable frame");
            let (h, w) = f.depth.dim();
            let amp_max = f.amplitude.iter().copied().fold(1e-6f32, f32::max);
            Snapshot {
                id: i as u64 + 1,
                header: FrameHeader::new(i as u64, w as u32, h as u32),
                width: w,
                height: h,
                depth: f.depth.iter().copied().collect(),
                rgb: f.rgb.iter().copied().collect(),
                confidence: f
                    .amplitude
                    .iter()
                    .map(|&a| (a / amp_max * 255.0) as u8)
                    .collect(),
            }
        })
        .collect();
    let (w, h) = (snapshots[0].width, snapshots[0].height);
    println!(
        "{dir}: {w}×{h}, {} frames, {rounds} rounds",
        snapshots.len()
    );
    let mut total_ms = 0.0;
    for picture in Picture::ALL {
        let mut ms = Vec::new();
        let mut bytes = 0;
        for r in 0..rounds {
            let s = &snapshots[r % snapshots.len()];
            let t = Instant::now();
            let e = render(picture, s, None).expect("a picture");
            ms.push(t.elapsed().as_secs_f64() * 1e3);
            bytes = e.jpeg.len();
        }
        ms.sort_by(f64::total_cmp);
        let median = ms[ms.len() / 2];
        total_ms += median;
        println!(
            "{:>12}: median {median:.1} ms, max {:.1} ms, {:.0} kB",
            picture.path(),
            ms[ms.len() - 1],
            bytes as f64 / 1e3
        );
    }
    println!("one snapshot, all three: {total_ms:.1} ms");
}
