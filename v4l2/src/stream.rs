//! mmap streaming from one capture node: [`CaptureStream::next_buffer`] hands out each buffer with
//! the driver's timestamp and sequence, and maps every failure to a [`DeviceError`] that says
//! whether the node is gone (unplugged: retry) or misconfigured.

use std::path::{Path, PathBuf};
use std::time::Duration;

use v4l::buffer::{Flags as BufFlags, Type};
use v4l::io::mmap::Stream;
use v4l::io::traits::CaptureStream as _;
use v4l::Device;

use crate::device::{self, DeviceError, FormatRequest, Negotiated};

/// Buffers the driver cycles through: enough that a late dequeue does not make it drop.
const BUFFERS: u32 = 4;

/// One captured buffer, borrowed until the next [`CaptureStream::next_buffer`].
#[derive(Debug)]
pub struct Buffer<'a> {
    /// The image bytes the driver filled (`bytesused`; the whole buffer when a driver leaves
    /// it 0).
    pub data: &'a [u8],
    /// The driver's timestamp in microseconds. `CLOCK_MONOTONIC` when `monotonic` (uvcvideo:
    /// start of exposure), which is what pairing two nodes needs.
    pub timestamp_us: i64,
    /// Whether the timestamp is on `CLOCK_MONOTONIC` (`V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC`).
    pub monotonic: bool,
    /// The driver's frame counter; a gap means the driver dropped frames.
    pub sequence: u32,
    /// The driver marked the buffer as corrupt (`V4L2_BUF_FLAG_ERROR`): skip it.
    pub corrupt: bool,
}

/// A node streaming in a negotiated format.
pub struct CaptureStream {
    path: PathBuf,
    format: Negotiated,
    // Declared before `device`: the buffers are unmapped and streaming stopped before the
    // file is closed.
    stream: Stream<'static>,
    // Kept open for the stream's life (the buffers map its file).
    _device: Device,
}

impl std::fmt::Debug for CaptureStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CaptureStream")
            .field("path", &self.path)
            .field("format", &self.format)
            .finish()
    }
}

impl CaptureStream {
    /// Opens `path` in the requested format ([`device::open`]), sets `controls` (by
    /// configuration key), and maps its buffers. `timeout` bounds each wait for a frame, so
    /// the caller can look at its shutdown flag.
    pub fn open(
        path: &Path,
        want: &FormatRequest,
        controls: &[(String, i64)],
        timeout: Duration,
    ) -> Result<Self, DeviceError> {
        let (device, format) = device::open(path, want)?;
        device::set_controls(path, &device, controls)?;
        let mut stream = Stream::with_buffers(&device, Type::VideoCapture, BUFFERS)
            .map_err(|e| DeviceError::from_io(path, "VIDIOC_REQBUFS", e))?;
        stream.set_timeout(timeout);
        Ok(CaptureStream {
            path: path.to_path_buf(),
            format,
            stream,
            _device: device,
        })
    }

    /// The node's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The format the node streams in.
    pub fn format(&self) -> &Negotiated {
        &self.format
    }

    /// The next buffer, or `Ok(None)` when none arrived within the timeout. A node that is
    /// gone answers [`DeviceError::Gone`] (or an `EIO` [`DeviceError::Io`]); both are
    /// [`DeviceError::is_transient`].
    pub fn next_buffer(&mut self) -> Result<Option<Buffer<'_>>, DeviceError> {
        match self.stream.next() {
            Ok((data, meta)) => {
                let used = meta.bytesused as usize;
                let data = if used > 0 && used <= data.len() {
                    &data[..used]
                } else {
                    data
                };
                let ts = meta.timestamp;
                Ok(Some(Buffer {
                    data,
                    timestamp_us: ts.sec * 1_000_000 + ts.usec,
                    monotonic: meta.flags.contains(BufFlags::TIMESTAMP_MONOTONIC),
                    sequence: meta.sequence,
                    corrupt: meta.flags.contains(BufFlags::ERROR),
                }))
            }
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(None),
            Err(e) => Err(DeviceError::from_io(&self.path, "VIDIOC_DQBUF", e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opening_a_missing_node_names_it() {
        let want = FormatRequest {
            fourcc: *b"Z16 ",
            width: 640,
            height: 480,
            fps: Some(30),
        };
        let err = CaptureStream::open(
            Path::new("/dev/video-missing"),
            &want,
            &[],
            Duration::from_millis(100),
        )
        .unwrap_err();
        assert!(
            err.is_transient(),
            "a missing node may be plugged in: {err}"
        );
        assert!(err.to_string().contains("/dev/video-missing"), "{err}");
    }

    #[test]
    fn a_file_that_is_not_a_v4l2_node_is_refused_with_the_ioctl_named() {
        let file = tempfile::NamedTempFile::new().unwrap();
        let want = FormatRequest {
            fourcc: *b"YUYV",
            width: 640,
            height: 480,
            fps: None,
        };
        let err =
            CaptureStream::open(file.path(), &want, &[], Duration::from_millis(100)).unwrap_err();
        assert!(err.to_string().contains("VIDIOC_QUERYCAP"), "{err}");
        assert!(!err.is_transient());
    }
}
