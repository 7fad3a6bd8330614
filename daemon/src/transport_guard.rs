//! What the daemon does about its transport's files that iceoryx2 0.10 does not (issue 34;
//! the trust model is in docs/security.md).
//!
//! iceoryx2 keeps every resource as a file under the root ([`dear_proto::transport`]) and,
//! built with `dev_permissions`, makes them `0666`/`0777`: the root directory's mode decides
//! who reaches them. It trusts what it reads back from them. This module
//!
//! - removes symbolic links from the root and its `nodes/` and `services/` directories before
//!   the daemon creates anything there ([`remove_symlinks`]): iceoryx2 follows them, and a
//!   daemon running as root then made `0777` directories and `0666` files wherever a link
//!   pointed;
//! - makes the publisher's data segment (`*.data`, the frames) read-only to everyone but the
//!   daemon ([`restrict_data_segments`]): subscribers map it read-only, so they lose nothing,
//!   and no client can rewrite or truncate it (which crashed the daemon);
//! - repairs iceoryx2's node counter (`*node.<version>.global_mgmt`) when its header is
//!   damaged ([`repair_global_mgmt`]): 16 junk bytes in it made every later node creation
//!   fail (`UnableToGenerateUniqueNodeId`), the daemon's start included;
//! - notices when the service's files are deleted ([`ServiceFiles`]) so the daemon can make
//!   them again.

use std::fs::File;
use std::io;
use std::os::unix::fs::{FileExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// Removes the symbolic links directly in `root` and in its `nodes/` and `services/`
/// directories (where iceoryx2 creates directories and files by path), logging each; returns
/// them. A link where iceoryx2 expects a directory (`nodes`) is removed too, and iceoryx2
/// creates the real directory in its place.
pub fn remove_symlinks(root: &Path) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    for dir in [
        root.to_path_buf(),
        root.join("nodes"),
        root.join("services"),
    ] {
        // After the root's own links are gone, `nodes` is a real directory or absent.
        match std::fs::symlink_metadata(&dir) {
            Ok(meta) if meta.is_dir() => {}
            _ => continue,
        }
        let entries = match std::fs::read_dir(&dir) {
            Ok(entries) => entries,
            Err(e) => {
                tracing::warn!(dir = %dir.display(), error = %e, "cannot list the iceoryx2 root to check it for symbolic links");
                continue;
            }
        };
        for entry in entries.flatten() {
            if !entry.file_type().is_ok_and(|t| t.is_symlink()) {
                continue;
            }
            let path = entry.path();
            let target = std::fs::read_link(&path).unwrap_or_default();
            match std::fs::remove_file(&path) {
                Ok(()) => {
                    tracing::warn!(link = %path.display(), target = %target.display(), "removed a symbolic link from the iceoryx2 root (iceoryx2 would have followed it and created the service's files where it points)");
                    removed.push(path);
                }
                Err(e) => {
                    tracing::error!(link = %path.display(), target = %target.display(), error = %e, "cannot remove a symbolic link from the iceoryx2 root")
                }
            }
        }
    }
    removed
}

/// Opens `path` without following a symbolic link and without blocking on a FIFO, and
/// checks it is a regular file.
fn open_regular_nofollow(path: &Path, write: bool) -> io::Result<File> {
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(write)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file",
        ));
    }
    Ok(file)
}

/// The data segment files of the publisher with port id `publisher_id` (iceoryx2 names them
/// `iox2_<hash>_<port id>.data`).
fn data_segments(root: &Path, publisher_id: u128) -> Vec<PathBuf> {
    let tag = format!("_{publisher_id}");
    files_named(root, |n| n.ends_with(".data") && n.contains(&tag))
}

/// The entries of `root` whose file names `keep` accepts (none when it cannot be read).
fn files_named(root: &Path, keep: impl Fn(&str) -> bool) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(root) else {
        return Vec::new();
    };
    entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(&keep))
        .collect()
}

/// Makes the data segment of the publisher `publisher_id` (the frames) `0644`: written by the
/// daemon only, read by every client that can reach the root (its directory decides who
/// can). Subscribers map it read-only (iceoryx2 opens it with `AccessMode::Read`), so they
/// receive frames as before; a client can no longer rewrite the segment's bytes or truncate
/// it. Returns the files it restricted.
pub fn restrict_data_segments(root: &Path, publisher_id: u128) -> Vec<PathBuf> {
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    let mut done = Vec::new();
    for path in data_segments(root, publisher_id) {
        let restricted = open_regular_nofollow(&path, false).and_then(|file| {
            if file.metadata()?.uid() != me {
                return Err(io::Error::new(
                    io::ErrorKind::PermissionDenied,
                    "not this user's",
                ));
            }
            file.set_permissions(std::fs::Permissions::from_mode(0o644))
        });
        match restricted {
            Ok(()) => done.push(path),
            Err(e) => {
                tracing::warn!(file = %path.display(), error = %e, "cannot make the data segment read-only to clients")
            }
        }
    }
    if done.is_empty() {
        tracing::warn!(root = %root.display(), publisher_id, "found no data segment of this publisher to make read-only to clients");
    }
    done
}

/// The version iceoryx2 stamps at the start of every dynamic storage file, as it stores it.
fn iceoryx2_version() -> u64 {
    iceoryx2_bb_elementary::package_version::PackageVersion::get().to_u64()
}

/// iceoryx2's node counter files in `root`: `iox2_<hash>_node.<major>_<minor>_<patch>.global_mgmt`.
fn global_mgmt_files(root: &Path) -> Vec<PathBuf> {
    let v = iceoryx2_bb_elementary::package_version::PackageVersion::get();
    let suffix = format!(
        "_node.{}_{}_{}.global_mgmt",
        v.major(),
        v.minor(),
        v.patch()
    );
    files_named(root, |n| n.starts_with("iox2_") && n.ends_with(&suffix))
}

/// Size of iceoryx2 0.10's node counter file: the version (u64) and the counter (u32), padded
/// to the version's alignment.
const GLOBAL_MGMT_BYTES: u64 = 16;

/// Checks iceoryx2's node counter file and repairs a damaged one in place: its size and the
/// version stamp in its first 8 bytes are restored (the counter may hold any value: it only
/// makes node ids unique together with the process id and time). Returns the files repaired;
/// logs each, naming it. A file that is not a regular file is removed (iceoryx2 makes a new
/// one).
pub fn repair_global_mgmt(root: &Path) -> Vec<PathBuf> {
    let version = iceoryx2_version();
    let mut repaired = Vec::new();
    for path in global_mgmt_files(root) {
        let file = match open_regular_nofollow(&path, true) {
            Ok(file) => file,
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => {
                tracing::error!(file = %path.display(), error = %e, "iceoryx2's node counter is not a file iceoryx2 can use: removing it (iceoryx2 makes a new one)");
                if std::fs::remove_file(&path).is_ok() {
                    repaired.push(path);
                }
                continue;
            }
        };
        let len = file.metadata().map(|m| m.len()).unwrap_or(0);
        let mut stamp = [0u8; 8];
        let read = file.read_exact_at(&mut stamp, 0);
        if len == GLOBAL_MGMT_BYTES && read.is_ok() && u64::from_ne_bytes(stamp) == version {
            continue;
        }
        let fixed = file
            .set_len(GLOBAL_MGMT_BYTES)
            .and_then(|()| file.write_all_at(&version.to_ne_bytes(), 0));
        match fixed {
            Ok(()) => {
                tracing::warn!(file = %path.display(), bytes = len, found_version = format_args!("{:#x}", u64::from_ne_bytes(stamp)), "iceoryx2's node counter was damaged (new processes could not join the transport): repaired in place");
                repaired.push(path);
            }
            Err(e) => {
                tracing::error!(file = %path.display(), error = %e, "iceoryx2's node counter is damaged and cannot be repaired")
            }
        }
    }
    repaired
}

/// Issue 34: a member of the service's group can truncate a shared record the daemon has
/// mapped (`truncate -s0 *.connection`); the daemon's next access to the lost pages raised
/// SIGBUS and killed it. Installs [`dear_proto::transport::survive_truncated_records`]'s
/// SIGBUS handler (the client SDK installs the same one): a fault in such a record is answered
/// with private zero pages, which the patched iceoryx2 refuses as a corrupted record, and the
/// daemon makes the service again ([`truncated_records`] counts the repairs). A fault
/// anywhere else gets the default action (the process dies, as before).
pub fn survive_truncated_records() {
    if let Err(error) = dear_proto::transport::survive_truncated_records() {
        tracing::warn!(%error, "cannot install the SIGBUS handler: a client that truncates a shared record crashes the daemon");
    }
}

/// How many truncated shared records [`survive_truncated_records`] replaced by zeros.
pub fn truncated_records() -> u64 {
    dear_proto::transport::truncated_records()
}

/// How iceoryx2 names a service's records: `services/iox2_<hash>.service` (its static
/// record) and `iox2_<service id>.dynamic` in the root (its dynamic record, where every
/// participant registers its ports).
#[derive(Debug, Clone)]
pub struct ServiceRecordNames {
    pub hashes: [String; 2],
    pub ids: [u128; 2],
}

/// The shared records of the services `names` (removed before the daemon makes the services
/// again after a client damaged them, or its new node would open the old ones).
pub fn service_records(root: &Path, names: &ServiceRecordNames) -> Vec<PathBuf> {
    let ids: Vec<String> = names
        .ids
        .iter()
        .map(|id| format!("_{id}.dynamic"))
        .collect();
    let mut files = files_named(root, |n| ids.iter().any(|id| n.ends_with(id.as_str())));
    files.extend(static_records(root, names));
    files
}

/// The static records of the services `names` in `services/` (named by the service's hash,
/// the same for every service of that name and configuration).
pub fn static_records(root: &Path, names: &ServiceRecordNames) -> Vec<PathBuf> {
    files_named(&root.join("services"), |n| {
        names.hashes.iter().any(|h| n.contains(h.as_str()))
    })
}

/// The first of the services' `*.dynamic` records (see [`service_records`]) whose version
/// stamp (its first 8 bytes, written by iceoryx2 when it made the record) is not iceoryx2's:
/// a client overwrote it, and every new client is refused with `VersionMismatch`.
pub fn record_with_a_bad_stamp(root: &Path, names: &ServiceRecordNames) -> Option<PathBuf> {
    let stamp = iceoryx2_version().to_ne_bytes();
    service_records(root, names)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "dynamic"))
        .find(|p| {
            let mut head = [0u8; 8];
            open_regular_nofollow(p, false)
                .and_then(|f| f.read_exact_at(&mut head, 0))
                .is_ok_and(|()| head != stamp)
        })
}

/// Files without which no new client can find the service: the root, the static service
/// records, the data segment and the node counter. Checked every second by the daemon.
#[derive(Debug, Clone)]
pub struct ServiceFiles {
    files: Vec<PathBuf>,
}

impl ServiceFiles {
    /// The files as they are now: the root, the records in `services/` named by
    /// `service_hashes`, the data segment of `publisher_id` and the node counter.
    pub fn snapshot(root: &Path, service_hashes: &[&str], publisher_id: u128) -> Self {
        let mut files = vec![root.to_path_buf()];
        let services = root.join("services");
        if let Ok(entries) = std::fs::read_dir(&services) {
            files.extend(entries.flatten().map(|e| e.path()).filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| service_hashes.iter().any(|h| n.contains(h)))
            }));
        }
        files.extend(data_segments(root, publisher_id));
        files.extend(global_mgmt_files(root));
        ServiceFiles { files }
    }

    /// The first file that is gone, if any.
    pub fn missing(&self) -> Option<&Path> {
        self.files
            .iter()
            .find(|p| std::fs::symlink_metadata(p).is_err())
            .map(PathBuf::as_path)
    }

    pub fn len(&self) -> usize {
        self.files.len()
    }

    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_damaged_node_counter_is_repaired_in_place_and_a_good_one_left_alone() {
        let tmp = tempfile::tempdir().unwrap();
        let v = iceoryx2_bb_elementary::package_version::PackageVersion::get();
        let name = format!(
            "iox2_abc_node.{}_{}_{}.global_mgmt",
            v.major(),
            v.minor(),
            v.patch()
        );
        let path = tmp.path().join(&name);
        let mut good = iceoryx2_version().to_ne_bytes().to_vec();
        good.extend_from_slice(&[7, 0, 0, 0, 0, 0, 0, 0]);
        std::fs::write(&path, &good).unwrap();
        assert!(repair_global_mgmt(tmp.path()).is_empty());
        assert_eq!(std::fs::read(&path).unwrap(), good);

        std::fs::write(&path, [0xA5u8; 16]).unwrap();
        assert_eq!(repair_global_mgmt(tmp.path()), vec![path.clone()]);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes.len(), 16);
        assert_eq!(bytes[..8], iceoryx2_version().to_ne_bytes());

        std::fs::write(&path, [1u8; 3]).unwrap();
        assert_eq!(repair_global_mgmt(tmp.path()), vec![path.clone()]);
        assert_eq!(std::fs::read(&path).unwrap().len(), 16);
    }

    #[test]
    fn a_service_record_with_an_overwritten_stamp_is_named() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path();
        std::fs::create_dir(root.join("services")).unwrap();
        let names = ServiceRecordNames {
            hashes: ["aaa".into(), "bbb".into()],
            ids: [17, 42],
        };
        let mut good = iceoryx2_version().to_ne_bytes().to_vec();
        good.extend_from_slice(&[0; 64]);
        std::fs::write(root.join("iox2_p_17.dynamic"), &good).unwrap();
        std::fs::write(root.join("iox2_p_42.dynamic"), &good).unwrap();
        std::fs::write(root.join("iox2_p_7.dynamic"), [0xA5u8; 72]).unwrap();
        std::fs::write(root.join("services/iox2_aaa.service"), "x").unwrap();
        std::fs::write(root.join("services/iox2_ccc.service"), "x").unwrap();
        let mut records = service_records(root, &names);
        records.sort();
        assert_eq!(
            records,
            vec![
                root.join("iox2_p_17.dynamic"),
                root.join("iox2_p_42.dynamic"),
                root.join("services/iox2_aaa.service"),
            ]
        );
        assert_eq!(record_with_a_bad_stamp(root, &names), None);
        let mut bad = good.clone();
        bad[3] ^= 0x10;
        std::fs::write(root.join("iox2_p_42.dynamic"), &bad).unwrap();
        assert_eq!(
            record_with_a_bad_stamp(root, &names),
            Some(root.join("iox2_p_42.dynamic"))
        );
    }

    #[test]
    fn symbolic_links_in_the_root_are_removed_and_files_kept() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("root");
        let elsewhere = tmp.path().join("elsewhere");
        std::fs::create_dir_all(root.join("services")).unwrap();
        std::fs::create_dir(&elsewhere).unwrap();
        std::os::unix::fs::symlink(&elsewhere, root.join("nodes")).unwrap();
        std::os::unix::fs::symlink(&elsewhere, root.join("services/x.service")).unwrap();
        std::fs::write(root.join("services/y.service"), "keep").unwrap();
        let mut removed = remove_symlinks(&root);
        removed.sort();
        assert_eq!(
            removed,
            vec![root.join("nodes"), root.join("services/x.service")]
        );
        assert!(root.join("services/y.service").is_file());
        assert!(elsewhere.is_dir());
    }
}
