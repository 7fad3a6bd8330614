//! The served pictures, drawn with `dear_picture` (the colours of `dear dump`'s previews and
//! `dear eval`'s figures) and encoded as JPEG, each at most once per snapshot.

use std::sync::{Arc, Mutex};

use dear_picture::blend::blend_rgb_depth;
use dear_picture::depth::{colorize_depth, display_range};
use image::codecs::jpeg::JpegEncoder;
use image::ExtendedColorType;

use crate::intake::Snapshot;

/// JPEG quality: edges and the colour bar stay readable. 640×480 with a noisy RGB: depth ~50 kB,
/// blend ~190 kB (at 85: 1.3-1.6× that).
pub const JPEG_QUALITY: u8 = 75;
/// Opacity of the depth colours over the RGB in the blend (its edges are drawn opaque).
pub const BLEND_ALPHA: f32 = 0.4;

/// The pictures served.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Picture {
    /// Turbo-coloured depth (near blue, far red, invalid black) with its labelled colour bar
    /// on the right ([`colorize_depth`], the preview `dear dump` writes): wider than the frame
    /// by the bar, and padded below a frame lower than the bar needs.
    Depth,
    /// Depth over RGB with the depth edges in magenta ([`blend_rgb_depth`]).
    Blend,
    /// The confidence plane as grey, 0 black, 255 white.
    Confidence,
}

impl Picture {
    pub const ALL: [Picture; 3] = [Picture::Depth, Picture::Blend, Picture::Confidence];

    /// The URL path it is served at.
    pub fn path(self) -> &'static str {
        match self {
            Picture::Depth => "/depth.jpg",
            Picture::Blend => "/blend.jpg",
            Picture::Confidence => "/confidence.jpg",
        }
    }

    pub fn from_path(path: &str) -> Option<Picture> {
        Picture::ALL.into_iter().find(|p| p.path() == path)
    }
}

/// One encoded picture.
#[derive(Debug, Clone)]
pub struct Encoded {
    /// The snapshot it was drawn from.
    pub snapshot: u64,
    pub frame_id: u64,
    pub jpeg: Arc<Vec<u8>>,
    /// The depth colour scale `(near, far)` in metres ([`Picture::Depth`] and
    /// [`Picture::Blend`]).
    pub depth_range: Option<(f32, f32)>,
}

/// Why a picture could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("the frame is empty ({0}×{1})")]
    Empty(usize, usize),
    #[error(transparent)]
    Shape(#[from] dear_picture::blend::ShapeMismatch),
    #[error("JPEG encoding failed: {0}")]
    Encode(#[from] image::ImageError),
}

/// The newest encoding of each picture. Concurrent requests for the same picture of the same
/// snapshot wait for one rendering instead of each doing it.
#[derive(Debug, Default)]
pub struct Cache {
    slots: [Mutex<Option<Encoded>>; 3],
}

impl Cache {
    /// `picture` of `snapshot`, from the cache or drawn now.
    pub fn get(
        &self,
        picture: Picture,
        snapshot: &Snapshot,
        depth_range: Option<(f32, f32)>,
    ) -> Result<Encoded, RenderError> {
        let mut slot = self.slots[picture as usize]
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        if let Some(encoded) = slot.as_ref().filter(|e| e.snapshot == snapshot.id) {
            return Ok(encoded.clone());
        }
        let encoded = render(picture, snapshot, depth_range)?;
        *slot = Some(encoded.clone());
        Ok(encoded)
    }
}

/// Draws and encodes `picture` of `snapshot`; `depth_range` fixes the colour scale (`None`: the
/// frame's own robust range).
pub fn render(
    picture: Picture,
    snapshot: &Snapshot,
    depth_range: Option<(f32, f32)>,
) -> Result<Encoded, RenderError> {
    let (w, h) = (snapshot.width, snapshot.height);
    if w == 0 || h == 0 {
        return Err(RenderError::Empty(w, h));
    }
    let depth = snapshot.depth_view();
    let (jpeg, range) = match picture {
        Picture::Depth => {
            let range = display_range(depth, depth_range);
            let image = colorize_depth(depth, Some(range));
            let (iw, ih) = (image.width() as usize, image.height() as usize);
            (
                encode(image.as_raw(), iw, ih, ExtendedColorType::Rgb8)?,
                Some(range),
            )
        }
        Picture::Blend => {
            // The blend colours on the frame's own range (dear_picture's choice for judging
            // alignment).
            let image = blend_rgb_depth(snapshot.rgb_view(), depth, BLEND_ALPHA)?;
            let range = display_range(depth, None);
            (
                encode(image.as_raw(), w, h, ExtendedColorType::Rgb8)?,
                Some(range),
            )
        }
        Picture::Confidence => (
            encode(&snapshot.confidence, w, h, ExtendedColorType::L8)?,
            None,
        ),
    };
    Ok(Encoded {
        snapshot: snapshot.id,
        frame_id: snapshot.header.frame_id,
        jpeg: Arc::new(jpeg),
        depth_range: range,
    })
}

fn encode(
    pixels: &[u8],
    w: usize,
    h: usize,
    color: ExtendedColorType,
) -> Result<Vec<u8>, image::ImageError> {
    let mut out = Vec::with_capacity(64 * 1024);
    // The sizes come from a validated header: at most u32 each.
    JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY)
        .encode(pixels, w as u32, h as u32, color)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dear_proto::FrameHeader;

    fn snapshot(w: usize, h: usize) -> Snapshot {
        Snapshot {
            id: 1,
            header: FrameHeader::new(9, w as u32, h as u32),
            width: w,
            height: h,
            depth: (0..w * h).map(|i| 0.5 + (i % w) as f32 * 0.01).collect(),
            rgb: vec![128; w * h * 3],
            confidence: (0..w * h).map(|i| (i % 256) as u8).collect(),
        }
    }

    #[test]
    fn every_picture_decodes_at_the_frame_size() {
        let s = snapshot(64, 48);
        for p in Picture::ALL {
            let e = render(p, &s, None).unwrap();
            let img = image::load_from_memory(&e.jpeg).unwrap();
            if p == Picture::Depth {
                let preview = colorize_depth(s.depth_view(), e.depth_range);
                assert_eq!((img.width(), img.height()), preview.dimensions());
                assert!(img.width() > 64 && img.height() >= 48);
            } else {
                assert_eq!((img.width(), img.height()), (64, 48), "{p:?}");
            }
            assert_eq!(e.depth_range.is_some(), p != Picture::Confidence);
        }
        // A fixed scale is used as given.
        let e = render(Picture::Depth, &s, Some((0.2, 3.0))).unwrap();
        assert_eq!(e.depth_range, Some((0.2, 3.0)));
    }

    #[test]
    fn the_cache_renders_once_per_snapshot_and_an_empty_frame_is_an_error() {
        let cache = Cache::default();
        let mut s = snapshot(8, 6);
        let a = cache.get(Picture::Depth, &s, None).unwrap();
        let b = cache.get(Picture::Depth, &s, None).unwrap();
        assert!(Arc::ptr_eq(&a.jpeg, &b.jpeg));
        s.id = 2;
        let c = cache.get(Picture::Depth, &s, None).unwrap();
        assert!(!Arc::ptr_eq(&a.jpeg, &c.jpeg));
        let empty = snapshot(0, 0);
        assert!(matches!(
            render(Picture::Blend, &empty, None),
            Err(RenderError::Empty(0, 0))
        ));
    }
}
