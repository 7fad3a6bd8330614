//! Frame sources. A [`FrameSource`] yields frames one by one; a bad frame is reported as
//! [`SourceItem::Skipped`] (with the error naming the file) and the stream goes on.
//!
//! Back ends: [`replay`] (a capture directory). Live V4L2 capture will sit beside it behind the
//! same trait.

pub mod replay;

use std::time::Instant;

use dear_pipeline::{Calibration, RgbdFrame};

/// What a source produced next.
#[derive(Debug)]
pub enum SourceItem {
    /// A good frame, and when it became available (for latency accounting).
    Frame {
        frame: Box<RgbdFrame>,
        arrived: Instant,
        decode_us: u32,
    },
    /// A frame that could not be read; `reason` names the file and the problem.
    Skipped { frame_id: u64, reason: String },
    /// The source has no more frames.
    End,
}

/// A stream of RGB-D frames.
pub trait FrameSource: Send {
    /// The next item. Blocks for pacing when the source is paced.
    fn next_item(&mut self) -> SourceItem;
    /// `(width, height)` of every frame.
    fn size(&self) -> (u32, u32);
    /// The factory calibration that came with the stream.
    fn initial_calibration(&self) -> Calibration;
    /// Human-readable description for logs.
    fn describe(&self) -> String;
}
