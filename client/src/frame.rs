//! A received frame: typed, zero-copy views of the shared-memory sample.

use dear_proto::Transport;
use dear_proto::{FrameHeader, HeaderError, PayloadLayout};
use iceoryx2::sample::Sample;
use ndarray::{ArrayView2, ArrayView3};

/// One published frame, borrowed from shared memory until dropped.
pub struct Frame {
    sample: Sample<Transport, [u8], FrameHeader>,
    layout: PayloadLayout,
}

impl std::fmt::Debug for Frame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Frame")
            .field("header", self.header())
            .finish()
    }
}

/// Why a received sample is not a usable frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// The header is corrupt, of another protocol version, or does not fit the payload (its
    /// message names the field).
    #[error(transparent)]
    Header(#[from] HeaderError),
    /// The depth plane cannot be read as `f32` in place (the payload does not start at the
    /// protocol's alignment: a service made by a party that changed the user header).
    #[error("the payload at {address:#x} is not aligned for f32 depth")]
    Misaligned { address: usize },
}

impl Frame {
    /// Wraps a sample after checking its header against its payload.
    pub(crate) fn new(sample: Sample<Transport, [u8], FrameHeader>) -> Result<Self, FrameError> {
        let layout = sample.user_header().validate(sample.payload().len())?;
        let address = sample.payload().as_ptr() as usize;
        if !address.is_multiple_of(std::mem::align_of::<f32>()) {
            return Err(FrameError::Misaligned { address });
        }
        Ok(Frame { sample, layout })
    }

    pub fn header(&self) -> &FrameHeader {
        self.sample.user_header()
    }

    /// `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        (self.layout.width, self.layout.height)
    }

    /// The whole payload as bytes (for checksums or forwarding).
    pub fn payload(&self) -> &[u8] {
        &self.sample.payload()[..self.layout.size]
    }

    /// Aligned refined depth, metres, row-major, 0 = invalid.
    pub fn depth(&self) -> &[f32] {
        let bytes = &self.sample.payload()[self.layout.depth_offset..self.layout.rgb_offset];
        // SAFETY: `Frame::new` checked the alignment and `validate` the length; every bit pattern
        // is a valid f32; the sample (and so the memory) lives as long as `self`.
        unsafe { std::slice::from_raw_parts(bytes.as_ptr().cast::<f32>(), self.layout.pixels()) }
    }

    /// RGB image, `width·height·3` bytes, row-major, interleaved.
    pub fn rgb(&self) -> &[u8] {
        &self.sample.payload()[self.layout.rgb_offset..self.layout.confidence_offset]
    }

    /// Per-pixel confidence (0 = invalid, 255 = measured and kept).
    pub fn confidence(&self) -> &[u8] {
        &self.sample.payload()[self.layout.confidence_offset..self.layout.size]
    }

    /// Depth as an `(H, W)` view.
    pub fn depth_view(&self) -> ArrayView2<'_, f32> {
        ArrayView2::from_shape((self.layout.height, self.layout.width), self.depth())
            .expect("layout checked")
    }

    /// RGB as an `(H, W, 3)` view.
    pub fn rgb_view(&self) -> ArrayView3<'_, u8> {
        ArrayView3::from_shape((self.layout.height, self.layout.width, 3), self.rgb())
            .expect("layout checked")
    }

    /// Confidence as an `(H, W)` view.
    pub fn confidence_view(&self) -> ArrayView2<'_, u8> {
        ArrayView2::from_shape((self.layout.height, self.layout.width), self.confidence())
            .expect("layout checked")
    }
}
