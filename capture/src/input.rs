//! Opening input files safely: only regular files, and never more than a stated size.
//!
//! A FIFO, a socket or a device where a file is expected (`capture.json`, a frame PNG, a
//! configuration, `model.json`, an ONNX graph) would otherwise hang the reader (a FIFO blocks
//! `open` until a writer comes, and then `read` until it writes) or grow its buffer without end
//! (`/dev/zero`). [`open_regular`] refuses anything but a regular file by its metadata before
//! opening it, and opens with `O_NONBLOCK` so a file swapped for a FIFO between the check and
//! the open cannot block either (checked again on the open file). [`read_limited`] also refuses
//! a file larger than the limit its caller states, before reading it.

use std::fs::File;
use std::io::{self, Read};
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::Path;

/// What a non-regular file is, for the error.
fn kind(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else {
        "not a regular file"
    }
}

fn not_regular(meta: &std::fs::Metadata) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("is {}, not a regular file", kind(meta)),
    )
}

/// Opens `path` for reading if it is a regular file (a symbolic link to one is followed);
/// anything else is an [`io::ErrorKind::InvalidInput`] error that says what it is, without
/// opening it. A missing file is [`io::ErrorKind::NotFound`] as from [`File::open`].
pub fn open_regular(path: &Path) -> io::Result<File> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    // Back to blocking reads (O_NONBLOCK means nothing for a regular file on Linux, but it is
    // cleared so the descriptor behaves as File::open's everywhere).
    // SAFETY: fcntl on a descriptor this function owns, with valid commands and flags.
    unsafe {
        use std::os::fd::AsRawFd;
        let fd = file.as_raw_fd();
        let flags = libc::fcntl(fd, libc::F_GETFL);
        if flags >= 0 {
            libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
        }
    }
    Ok(file)
}

/// Human units for a byte count in an error.
fn bytes_text(n: u64) -> String {
    if n >= 1 << 20 {
        format!("{:.1} MiB", n as f64 / (1 << 20) as f64)
    } else {
        format!("{n} bytes")
    }
}

/// Reads all of the regular file `path` ([`open_regular`]) when it holds at most `limit`
/// bytes; a larger one (or one that grows past the limit while read) is an
/// [`io::ErrorKind::InvalidData`] error naming both sizes, and is not read.
pub fn read_limited(path: &Path, limit: u64) -> io::Result<Vec<u8>> {
    let file = open_regular(path)?;
    let len = file.metadata()?.len();
    let too_large = |found: String| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!(
                "is {found}, more than the {} this file may hold",
                bytes_text(limit)
            ),
        )
    };
    if len > limit {
        return Err(too_large(bytes_text(len)));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(format!("more than {}", bytes_text(limit))));
    }
    Ok(bytes)
}

/// [`read_limited`] as UTF-8 text.
pub fn read_text_limited(path: &Path, limit: u64) -> io::Result<String> {
    String::from_utf8(read_limited(path, limit)?)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "is not UTF-8 text"))
}

/// The size limit of a text file of settings (a configuration, a manifest of a few fields).
pub const SETTINGS_LIMIT: u64 = 1 << 20;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fifo_is_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = read_limited(&fifo, 100).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("a FIFO"), "{e}");
        let e = open_regular(dir.path()).unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        let e = read_limited(Path::new("/dev/zero"), 100).unwrap_err();
        assert!(e.to_string().contains("a character device"), "{e}");
    }

    #[test]
    fn a_file_over_the_limit_is_refused_and_one_at_it_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        std::fs::write(&path, [7u8; 100]).unwrap();
        assert_eq!(read_limited(&path, 100).unwrap().len(), 100);
        let e = read_limited(&path, 99).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert!(
            e.to_string().contains("100 bytes, more than the 99 bytes"),
            "{e}"
        );
        assert_eq!(
            read_limited(&dir.path().join("none"), 1)
                .unwrap_err()
                .kind(),
            io::ErrorKind::NotFound
        );
    }
}
