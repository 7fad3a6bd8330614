//! How much shared memory a stream needs, checked before any is taken: the daemon's own limit
//! (`[service] max_shared_memory_mb`) and what the transport's root directory (a tmpfs:
//! `/dev/shm/dear`, `/run/deard/iceoryx2`) has free. iceoryx2 creates the data segment
//! sparse, so without this check an oversized stream starts, then dies (SIGBUS) or fills the
//! machine's tmpfs the first time the frames are written.

use std::path::Path;

use dear_proto::{samples_in_shared_memory, LayoutError, PayloadLayout};

const MB: f64 = 1e6;

/// Why a stream's shared memory cannot be had.
#[derive(Debug, thiserror::Error)]
pub enum SharedMemoryError {
    /// The frame is larger than the protocol can describe.
    #[error(transparent)]
    Layout(#[from] LayoutError),
    /// The stream needs more than `[service] max_shared_memory_mb`.
    #[error("{need}, more than [service] max_shared_memory_mb = {limit_mb}")]
    OverLimit { need: StreamNeed, limit_mb: u64 },
    /// The stream needs more than the shared-memory file system has free.
    #[error("{need}, more than the {:.1} MB free in {}", *free as f64 / MB, dir.display())]
    OverFree {
        need: StreamNeed,
        free: u64,
        dir: std::path::PathBuf,
    },
    /// The free space cannot be read.
    #[error("cannot read the free space of {}: {source}", dir.display())]
    Statvfs {
        dir: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// What a stream needs: its size and bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamNeed {
    pub width: u32,
    pub height: u32,
    pub bytes: u64,
}

impl std::fmt::Display for StreamNeed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = samples_in_shared_memory();
        write!(
            f,
            "a {}x{} stream needs {:.1} MB of shared memory ({n} frames of {:.2} MB)",
            self.width,
            self.height,
            self.bytes as f64 / MB,
            self.bytes as f64 / n as f64 / MB
        )
    }
}

/// Bytes the frame service of a `width`×`height` stream takes: the publisher's data segment.
pub fn stream_bytes(width: u32, height: u32) -> Result<u64, LayoutError> {
    let layout = PayloadLayout::new(width, height)?;
    Ok(samples_in_shared_memory() as u64 * layout.size as u64)
}

/// `Ok` when a `width`×`height` stream fits both `limit_mb` and the free space of `shm_dir`;
/// otherwise the error says how much it needs and which bound it exceeds.
pub fn check_fits(
    width: u32,
    height: u32,
    limit_mb: u64,
    shm_dir: &Path,
) -> Result<(), SharedMemoryError> {
    let need = StreamNeed {
        width,
        height,
        bytes: stream_bytes(width, height)?,
    };
    if need.bytes > limit_mb.saturating_mul(1_000_000) {
        return Err(SharedMemoryError::OverLimit { need, limit_mb });
    }
    let free = free_bytes(shm_dir)?;
    if need.bytes > free {
        return Err(SharedMemoryError::OverFree {
            need,
            free,
            dir: shm_dir.to_path_buf(),
        });
    }
    Ok(())
}

/// Bytes an unprivileged process may still write to the file system of `dir`.
fn free_bytes(dir: &Path) -> Result<u64, SharedMemoryError> {
    use std::os::unix::ffi::OsStrExt;
    let statvfs_error = |source| SharedMemoryError::Statvfs {
        dir: dir.to_path_buf(),
        source,
    };
    let path = std::ffi::CString::new(dir.as_os_str().as_bytes()).map_err(|_| {
        statvfs_error(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "a path with a NUL byte",
        ))
    })?;
    let mut stat = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `path` is a NUL-terminated string and `stat` a buffer statvfs fills on success.
    let rc = unsafe { libc::statvfs(path.as_ptr(), stat.as_mut_ptr()) };
    if rc != 0 {
        return Err(statvfs_error(std::io::Error::last_os_error()));
    }
    // SAFETY: statvfs returned 0, so it filled the buffer.
    let stat = unsafe { stat.assume_init() };
    // `fsblkcnt_t` and `c_ulong` are 32 bits on some targets (armv7) and 64 on others.
    #[allow(clippy::unnecessary_cast)]
    Ok((stat.f_bavail as u64).saturating_mul(stat.f_frsize as u64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vga_stream_takes_the_protocols_samples_of_eight_bytes_per_pixel() {
        let need = stream_bytes(640, 480).unwrap();
        assert_eq!(need, samples_in_shared_memory() as u64 * 640 * 480 * 8);
        assert_eq!(need, 86_016_000);
    }

    #[test]
    fn the_limit_and_the_free_space_bound_the_stream() {
        let shm = Path::new("/dev/shm");
        check_fits(320, 240, 1024, shm).unwrap();
        let e = check_fits(320, 240, 10, shm).unwrap_err().to_string();
        assert!(
            e.contains("320x240 stream needs 21.5 MB") && e.contains("max_shared_memory_mb = 10"),
            "{e}"
        );
        // More than any machine's /dev/shm: 35 frames of 4 GB.
        let e = check_fits(23_170, 23_170, 65_536 * 1024, shm)
            .unwrap_err()
            .to_string();
        assert!(e.contains("free in /dev/shm"), "{e}");
    }

    #[test]
    fn a_missing_directory_is_named() {
        let e = check_fits(8, 8, 1, Path::new("/nonexistent-shm"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent-shm"), "{e}");
    }
}
