//! The iceoryx2 service type every DEAR process uses, and where its files live.
//!
//! # Why not iceoryx2's `ipc::Service`
//!
//! iceoryx2 0.10 gives every resource fixed permissions: by default owner-only (`0600`), so a
//! daemon running as `deard` and an app running as another user cannot connect at all (the app
//! fails to create its half of the connection, or receives nothing); with its `dev_permissions`
//! feature everything is `0666`/`0777`. Its POSIX shared memory always lives in `/dev/shm`, a
//! directory every local user can list and open, so `dev_permissions` there would let any user
//! write into the frames and the queues' bookkeeping.
//!
//! [`Transport`] is iceoryx2's IPC service with every resource a **file under one root
//! directory** ([`node_config`]): the data segment, the connections, the dynamic service and
//! node records, the event sockets, the liveness locks (iceoryx2-cal's `file` back ends, which
//! map the files shared exactly as `shm_open` does). iceoryx2 is built with `dev_permissions`,
//! so the files themselves are open to all, and **the root directory's own mode decides who
//! may connect**: the systemd unit gives the daemon `/run/deard` (mode `0750`, group `dear`);
//! its `iceoryx2` subdirectory is where the files go. Users in the group receive frames; users
//! outside it cannot even see the service. On tmpfs (`/run`, `/dev/shm`) the files are memory,
//! as POSIX shared memory is.
//!
//! The cost: a client must use this type too. iceoryx2's stock `ipc::Service` (and its C, C++
//! and Python bindings, which offer only that one) looks for the service in `/dev/shm` and does
//! not find it.

use core::fmt::Debug;

use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_lock_free::mpmc::counting_bit_set::RelocatableCountingBitSet;
use iceoryx2_cal::event::trigger::unix_datagram_socket::GenericUnixDatagramSocketTrigger;
use iceoryx2_cal::event::trigger::State;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    arc_sync_policy, bag, dynamic_storage, hash, monitoring, reactor, resizable_shared_memory,
    serialize, shared_memory, static_storage, zero_copy_connection,
};

/// The iceoryx2 service type of DEAR: iceoryx2's IPC service with file-backed shared memory
/// under the root directory (module documentation). Daemon and clients must both use it.
#[derive(Debug, Clone)]
pub struct Transport {}

type FileMemory<Allocator> = shared_memory::file::Memory<Allocator>;

impl iceoryx2::service::Service for Transport {
    type StaticStorage = static_storage::file::Storage;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::file::Storage<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::file::Storage<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = FileMemory<PoolAllocator>;
    type ResizableSharedMemory =
        resizable_shared_memory::dynamic::DynamicMemory<PoolAllocator, FileMemory<PoolAllocator>>;
    type Connection = zero_copy_connection::file::Connection;
    type Event = GenericUnixDatagramSocketTrigger<
        RelocatableCountingBitSet,
        dynamic_storage::file::Storage<State<RelocatableCountingBitSet, ()>>,
    >;
    type Monitoring = monitoring::file_lock::FileLockMonitoring;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::file::Storage<KeyType>;
    type BlackboardPayload = FileMemory<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<Transport> for Transport {}

/// Environment variable naming the root directory of every DEAR process's iceoryx2 files (the
/// daemon's and every client's): see [`node_config`].
pub const IOX2_ROOT_ENV: &str = "DEAR_IOX2_ROOT";

/// The root when [`IOX2_ROOT_ENV`] is not set: on tmpfs on every Linux (the frames are
/// memory, not disk), and needs no privileges (demo, tests, a daemon started by hand).
pub const DEFAULT_IOX2_ROOT: &str = "/dev/shm/dear";

/// The root the systemd unit gives the daemon: inside its `RuntimeDirectory=` `/run/deard`
/// (in root-owned `/run`, so no other user can create or replace it first; mode `0750`, group
/// `dear`, so only the group's members reach the files). Its clients set the same.
pub const SERVICE_IOX2_ROOT: &str = "/run/deard/iceoryx2";

/// Why [`node_config`] refused the configured iceoryx2 root.
#[derive(Debug, thiserror::Error)]
pub enum NodeConfigError {
    #[error("{IOX2_ROOT_ENV}={value:?} must be an absolute path")]
    NotAbsolute { value: String },
    #[error(
        "{IOX2_ROOT_ENV}={value:?} is not a path iceoryx2 accepts (at most 255 bytes, no NUL)"
    )]
    Path {
        value: String,
        #[source]
        source: SemanticStringError,
    },
}

/// The iceoryx2 configuration every DEAR node is created with: the daemon's, the SDK's and the
/// CLI's. All of them must agree on the root directory, or a client looks for the service where
/// the daemon never wrote it and waits forever.
///
/// The root is `$DEAR_IOX2_ROOT` when set and not empty, otherwise [`DEFAULT_IOX2_ROOT`]. The
/// systemd unit sets [`SERVICE_IOX2_ROOT`] for the daemon; its clients set the same.
///
/// Why a variable and not "use `/run/deard/iceoryx2` when it exists": with that rule every
/// DEAR process on a machine where the service has run since boot would join the service's
/// root — the tests and a daemon started by hand too, which then fail unprivileged (they
/// cannot write there) or, as root, mix with the installed service (tried: a concurrent test
/// run's daemons moved into the installed service's root). An explicit setting keeps the
/// default world and the service's apart.
///
/// iceoryx2's dead-node cleanup on node creation is left as configured; the daemon turns it
/// off itself to report what it cleans.
pub fn node_config() -> Result<Config, NodeConfigError> {
    let from_env = std::env::var_os(IOX2_ROOT_ENV).filter(|v| !v.is_empty());
    node_config_from(Config::global_config(), from_env.as_deref())
}

/// [`node_config`] with its inputs given: the base configuration and the environment
/// variable's value.
pub fn node_config_from(
    base: &Config,
    from_env: Option<&std::ffi::OsStr>,
) -> Result<Config, NodeConfigError> {
    let root = match from_env {
        Some(value) => value.to_string_lossy().into_owned(),
        None => DEFAULT_IOX2_ROOT.to_string(),
    };
    if !root.starts_with('/') {
        return Err(NodeConfigError::NotAbsolute { value: root });
    }
    // iceoryx2 joins entries to the root itself; one trailing slash, as in its default.
    let normalised = format!("{}/", root.trim_end_matches('/'));
    let path = Path::new(normalised.as_bytes()).map_err(|source| NodeConfigError::Path {
        value: root.clone(),
        source,
    })?;
    let mut config = base.clone();
    config.global.set_root_path(&path);
    Ok(config)
}

/// The root directory of a configuration, as a path of this process.
pub fn root_dir(config: &Config) -> std::path::PathBuf {
    // Without iceoryx2's trailing slash: with it, a file there reads as "not a directory" to
    // stat, not as a file.
    let root = config.global.root_path().to_string();
    let trimmed = root.trim_end_matches('/');
    std::path::PathBuf::from(if trimmed.is_empty() { "/" } else { trimmed })
}

/// Why the daemon cannot use its root directory ([`prepare_root`]).
#[derive(Debug, thiserror::Error)]
pub enum RootError {
    #[error("cannot create the iceoryx2 root {}", path.display())]
    Create {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Typically a user outside the service's group: `/run/deard` is the group's only.
    #[error("cannot reach the iceoryx2 root {} (is this user in the service's group? README, \"Apps as other users\")", path.display())]
    NotReachable {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot inspect the iceoryx2 root {}", path.display())]
    Inspect {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("the iceoryx2 root {} is not a directory", path.display())]
    NotADirectory { path: std::path::PathBuf },
    /// A symbolic link could be pointed anywhere by whoever may replace it.
    #[error("the iceoryx2 root {} is a symbolic link; set {IOX2_ROOT_ENV} to the directory itself", path.display())]
    Symlink { path: std::path::PathBuf },
    /// `/dev/shm`, `/tmp` and the like: every user may create files there.
    #[error("the iceoryx2 root {} is a shared directory (mode {mode:o}: writable by every user, or sticky as /tmp and /dev/shm are): any user could read the frames and rewrite the transport's files; set {IOX2_ROOT_ENV} to a directory of the service's own below it, e.g. /dev/shm/dear", path.display())]
    Shared { path: std::path::PathBuf, mode: u32 },
    /// The owner of a directory above the root can rename the root away and put another in its
    /// place.
    #[error("the iceoryx2 root {} is below {}, which belongs to uid {owner} (not this user, uid {me}, or root): that user could replace the root; choose a root below directories of root or of this user", path.display(), ancestor.display())]
    ForeignAncestor {
        path: std::path::PathBuf,
        ancestor: std::path::PathBuf,
        owner: u32,
        me: u32,
    },
    /// A directory above the root that other users may write (and that is not sticky): they
    /// can rename the root away and put another in its place.
    #[error("the iceoryx2 root {} is below {} (mode {mode:o}), which other users can write and which is not sticky: they could replace the root; choose a root below directories only root or this user can write", path.display(), ancestor.display())]
    WritableAncestor {
        path: std::path::PathBuf,
        ancestor: std::path::PathBuf,
        mode: u32,
    },
    /// Someone else made the directory first: using it would hand them the frames (they could
    /// read and rewrite every file in it) — the pre-emption a world-writable parent such as
    /// `/dev/shm` or `/tmp` allows.
    #[error("the iceoryx2 root {} belongs to uid {owner}, not to this user (uid {me}) or root: another user created it; remove it or set {IOX2_ROOT_ENV} to a directory of this user's", path.display())]
    ForeignOwner {
        path: std::path::PathBuf,
        owner: u32,
        me: u32,
    },
}

/// The root directory when it exists, `None` when it does not (no daemon or client has run
/// under it since boot). One this user cannot reach (outside the service's group) is
/// [`RootError::NotReachable`], not "missing".
pub fn existing_root(config: &Config) -> Result<Option<std::path::PathBuf>, RootError> {
    let path = root_dir(config);
    match std::fs::metadata(&path) {
        Ok(meta) if meta.is_dir() => {
            check_access(&path)?;
            Ok(Some(path))
        }
        Ok(_) => Ok(Some(path)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) if source.kind() == std::io::ErrorKind::PermissionDenied => {
            Err(RootError::NotReachable { path, source })
        }
        Err(source) => Err(RootError::Inspect { path, source }),
    }
}

/// A root this process may stat but not use (`/dev/shm/dear` is `0770`: an outsider sees it
/// but cannot enter it) is [`RootError::NotReachable`] too, before iceoryx2 fails on it with
/// `InsufficientPermissions` or `UnableToGenerateUniqueNodeId`.
fn check_access(path: &std::path::Path) -> Result<(), RootError> {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c_path) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return Ok(()); // iceoryx2 refuses such a path itself (node_config).
    };
    // SAFETY: a NUL-terminated path; faccessat has no other preconditions.
    let rc = unsafe {
        libc::faccessat(
            libc::AT_FDCWD,
            c_path.as_ptr(),
            libc::R_OK | libc::W_OK | libc::X_OK,
            libc::AT_EACCESS,
        )
    };
    if rc == 0 {
        return Ok(());
    }
    let source = std::io::Error::last_os_error();
    match source.kind() {
        std::io::ErrorKind::PermissionDenied => Err(RootError::NotReachable {
            path: path.to_path_buf(),
            source,
        }),
        // Anything else (a read-only file system) is iceoryx2's to report.
        _ => Ok(()),
    }
}

/// Creates the root directory with missing parents when it does not exist, mode `0770` (so
/// the creator's group may connect; iceoryx2 itself would make it `0777`, open to every
/// user). Clients call it too, so one started before the daemon does not open the root up.
pub fn create_root(config: &Config) -> Result<std::path::PathBuf, RootError> {
    use std::os::unix::fs::PermissionsExt;
    if let Some(path) = existing_root(config)? {
        return Ok(path);
    }
    let path = root_dir(config);
    let created = std::fs::create_dir_all(&path)
        // Explicitly: the process's umask (the unit's 0027) would take the group's write.
        .and_then(|()| std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o770)));
    match created {
        Ok(()) => Ok(path),
        // Made by another process meanwhile (a client and the daemon starting together).
        Err(_) if path.is_dir() => Ok(path),
        Err(source) => Err(RootError::Create { path, source }),
    }
}

/// Makes sure the daemon's root directory is its own before any iceoryx2 file is made there:
/// creates it ([`create_root`]) or checks that an existing one is a directory (not a symbolic
/// link) owned by this user or root, not shared with every user (world-writable or sticky:
/// `/dev/shm`, `/tmp` themselves), below directories that only root or this user can change
/// (issue 34).
pub fn prepare_root(config: &Config) -> Result<std::path::PathBuf, RootError> {
    use std::os::unix::fs::MetadataExt;
    let path = create_root(config)?;
    let meta = std::fs::symlink_metadata(&path).map_err(|source| RootError::Inspect {
        path: path.clone(),
        source,
    })?;
    if meta.file_type().is_symlink() {
        return Err(RootError::Symlink { path });
    }
    if !meta.is_dir() {
        return Err(RootError::NotADirectory { path });
    }
    // SAFETY: geteuid has no preconditions and cannot fail.
    let me = unsafe { libc::geteuid() };
    if meta.uid() != me && meta.uid() != 0 {
        return Err(RootError::ForeignOwner {
            path,
            owner: meta.uid(),
            me,
        });
    }
    let mode = meta.mode() & 0o7777;
    if mode & 0o002 != 0 || mode & 0o1000 != 0 {
        return Err(RootError::Shared { path, mode });
    }
    check_ancestors(&path, me)?;
    Ok(path)
}

/// Every directory above the root must be root's or this user's, and writable by nobody else
/// unless sticky (`/dev/shm`, `/tmp`: there others cannot rename or remove what is not
/// theirs): otherwise another user could move the root away and put one of theirs in its place.
fn check_ancestors(path: &std::path::Path, me: u32) -> Result<(), RootError> {
    use std::os::unix::fs::MetadataExt;
    let inspect = |source| RootError::Inspect {
        path: path.to_path_buf(),
        source,
    };
    // The directories the path really passes through (a symbolic link above the root is
    // followed by the kernel, so its target's directories are the ones that count).
    let real = std::fs::canonicalize(path).map_err(inspect)?;
    for ancestor in real.ancestors().skip(1) {
        let meta = std::fs::metadata(ancestor).map_err(inspect)?;
        let (owner, mode) = (meta.uid(), meta.mode() & 0o7777);
        if owner != me && owner != 0 {
            return Err(RootError::ForeignAncestor {
                path: path.to_path_buf(),
                ancestor: ancestor.to_path_buf(),
                owner,
                me,
            });
        }
        if mode & 0o022 != 0 && mode & 0o1000 == 0 {
            return Err(RootError::WritableAncestor {
                path: path.to_path_buf(),
                ancestor: ancestor.to_path_buf(),
                mode,
            });
        }
    }
    Ok(())
}

static TRUNCATED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// The SIGBUS disposition before [`survive_truncated_records`] installed its handler: a fault
/// outside the shared records goes back to it. Written once, before the handler is installed,
/// and only read afterwards (from the handler).
static mut PREVIOUS_SIGBUS: std::mem::MaybeUninit<libc::sigaction> =
    std::mem::MaybeUninit::uninit();

/// Issue 34: a member of the service's group can truncate a shared record that another
/// process has mapped (`truncate -s0 *.connection`: clients must be able to write those files,
/// and write permission is what `ftruncate` needs); that process's next access to the lost
/// pages raised SIGBUS and killed it, the daemon or a client. This installs (once per process)
/// a SIGBUS handler that, when the faulting address lies in a mapping of such a record (the
/// patched iceoryx2 registers them: `iceoryx2_bb_lock_free::dear_shared`), maps private zero
/// pages over that whole mapping and returns: the access is retried and reads zeros, which the
/// patched iceoryx2 refuses as a corrupted record ([`truncated_records`] counts the repairs).
/// A fault anywhere else goes to the disposition SIGBUS had before (by default the process
/// dies, as before). The same technique Wayland compositors use against clients that shrink a
/// shared memory pool. `deard` calls it before it serves, the client SDK when it connects; an
/// application that installs a SIGBUS handler of its own after connecting replaces it.
pub fn survive_truncated_records() -> std::io::Result<()> {
    static ONCE: std::sync::OnceLock<Result<(), std::io::ErrorKind>> = std::sync::OnceLock::new();
    let installed = ONCE.get_or_init(|| {
        // SAFETY: a zeroed sigaction with a SA_SIGINFO handler and an empty mask is valid;
        // the handler only calls async-signal-safe functions (atomics, mmap, sigaction).
        // PREVIOUS_SIGBUS is written here once, before the handler can run.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_sigbus as *const () as usize;
            action.sa_flags = libc::SA_SIGINFO;
            libc::sigemptyset(&mut action.sa_mask);
            let previous = (&raw mut PREVIOUS_SIGBUS).cast::<libc::sigaction>();
            std::ptr::write_bytes(previous, 0, 1);
            if libc::sigaction(libc::SIGBUS, &action, previous) != 0 {
                return Err(std::io::Error::last_os_error().kind());
            }
        }
        Ok(())
    });
    installed.map_err(std::io::Error::from)
}

/// How many truncated shared records [`survive_truncated_records`] replaced by zeros in this
/// process.
pub fn truncated_records() -> u64 {
    TRUNCATED.load(std::sync::atomic::Ordering::Relaxed)
}

extern "C" fn on_sigbus(_: libc::c_int, info: *mut libc::siginfo_t, _: *mut libc::c_void) {
    // SAFETY: the kernel passes a valid siginfo for a SA_SIGINFO handler.
    let address = unsafe { (*info).si_addr() } as usize;
    if let Some((start, end)) = iceoryx2_bb_lock_free::dear_shared::mapping_of(address) {
        // SAFETY: replaces pages of a mapping this process made (registered by iceoryx2)
        // with private zero pages of the same extent; nothing else lives there.
        let mapped = unsafe {
            libc::mmap(
                start as *mut libc::c_void,
                end - start,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS | libc::MAP_FIXED,
                -1,
                0,
            )
        };
        if mapped != libc::MAP_FAILED {
            TRUNCATED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            return;
        }
    }
    // Not a shared record: the previous disposition handles the access when it is retried.
    // SAFETY: sigaction is async-signal-safe; PREVIOUS_SIGBUS was written before this handler
    // was installed and is not written again.
    unsafe {
        libc::sigaction(
            libc::SIGBUS,
            (&raw const PREVIOUS_SIGBUS).cast::<libc::sigaction>(),
            std::ptr::null_mut(),
        )
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::OsStr;

    fn with_root(root: &str) -> Result<Config, NodeConfigError> {
        node_config_from(&Config::default(), Some(OsStr::new(root)))
    }

    #[test]
    fn no_variable_means_the_tmpfs_default() {
        let config = node_config_from(&Config::default(), None).unwrap();
        assert_eq!(config.global.root_path().to_string(), "/dev/shm/dear/");
    }

    #[test]
    fn daemon_and_client_agree_however_the_root_is_spelled() {
        let a = with_root("/srv/x//").unwrap();
        let b = with_root("/srv/x").unwrap();
        assert_eq!(a.global.root_path().to_string(), "/srv/x/");
        assert_eq!(a.global.root_path(), b.global.root_path());
        assert_eq!(root_dir(&a), std::path::PathBuf::from("/srv/x"));
    }

    #[test]
    fn a_relative_or_overlong_root_is_refused_by_name() {
        let e = with_root("run/x").unwrap_err();
        assert!(matches!(e, NodeConfigError::NotAbsolute { .. }), "{e}");
        assert!(e.to_string().contains("DEAR_IOX2_ROOT=\"run/x\""), "{e}");
        let e = with_root(&format!("/{}", "a".repeat(300))).unwrap_err();
        assert!(matches!(e, NodeConfigError::Path { .. }), "{e}");
    }

    #[test]
    fn the_base_configuration_is_kept() {
        let mut base = Config::default();
        base.global.node.cleanup_dead_nodes_on_creation = false;
        let config = node_config_from(&base, Some(OsStr::new("/run/x"))).unwrap();
        assert!(!config.global.node.cleanup_dead_nodes_on_creation);
    }

    #[test]
    fn prepare_root_creates_a_group_directory_and_refuses_a_file() {
        use std::os::unix::fs::PermissionsExt;
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("a/b");
        let config = with_root(root.to_str().unwrap()).unwrap();
        let made = prepare_root(&config).unwrap();
        let mode = std::fs::metadata(&made).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o770, "the group may connect, others not: {mode:o}");
        // Idempotent: a restarted daemon finds its own directory.
        prepare_root(&config).unwrap();

        let file = tmp.path().join("file");
        std::fs::write(&file, b"x").unwrap();
        let e = prepare_root(&with_root(file.to_str().unwrap()).unwrap()).unwrap_err();
        assert!(matches!(e, RootError::NotADirectory { .. }), "{e}");
        assert!(e.to_string().contains("file"), "{e}");
    }

    /// Issue 34: `/dev/shm` or `/tmp` themselves (world-writable, sticky), a symbolic link,
    /// and a root below a directory others may write are refused by name.
    #[test]
    fn prepare_root_refuses_shared_linked_and_exposed_roots() {
        use std::os::unix::fs::PermissionsExt;
        let tmp = tempfile::tempdir().unwrap();
        let chmod = |p: &std::path::Path, mode| {
            std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode)).unwrap()
        };
        let prepare = |p: &std::path::Path| prepare_root(&with_root(p.to_str().unwrap()).unwrap());

        let shared = tmp.path().join("shared");
        std::fs::create_dir(&shared).unwrap();
        for mode in [0o1777, 0o777, 0o1770] {
            chmod(&shared, mode);
            let e = prepare(&shared).unwrap_err();
            assert!(matches!(e, RootError::Shared { .. }), "{mode:o}: {e}");
            assert!(e.to_string().contains("shared directory"), "{e}");
        }
        for real in ["/dev/shm", "/tmp"] {
            let e = prepare(std::path::Path::new(real)).unwrap_err();
            assert!(matches!(e, RootError::Shared { .. }), "{real}: {e}");
        }
        // Below a sticky shared directory is fine (as /dev/shm/dear): others cannot move it.
        let below = shared.join("dear");
        prepare(&below).unwrap();
        // Below a directory others may write and rename in, it is not.
        chmod(&shared, 0o777);
        let e = prepare(&below).unwrap_err();
        assert!(matches!(e, RootError::WritableAncestor { .. }), "{e}");
        assert!(e.to_string().contains("shared"), "{e}");
        chmod(&shared, 0o755);
        prepare(&below).unwrap();

        let link = tmp.path().join("link");
        std::os::unix::fs::symlink(&below, &link).unwrap();
        let e = prepare(&link).unwrap_err();
        assert!(matches!(e, RootError::Symlink { .. }), "{e}");
    }

    /// A root below a directory another (non-root) user owns is refused, naming both. Needs
    /// root to make a directory of another user; CI runs as root.
    #[test]
    fn prepare_root_refuses_a_root_below_another_users_directory() {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            eprintln!("not root: cannot give a directory to another user; not checked");
            return;
        }
        let tmp = tempfile::tempdir().unwrap();
        let theirs = tmp.path().join("theirs");
        std::fs::create_dir(&theirs).unwrap();
        std::os::unix::fs::chown(&theirs, Some(65534), None).unwrap();
        let root = theirs.join("dear");
        let e = prepare_root(&with_root(root.to_str().unwrap()).unwrap()).unwrap_err();
        assert!(
            matches!(e, RootError::ForeignAncestor { owner: 65534, .. }),
            "{e}"
        );
        assert!(
            e.to_string().contains("theirs") && e.to_string().contains("uid 65534"),
            "{e}"
        );
    }

    /// A root another user made first (in `/dev/shm` or `/tmp` anyone can) is refused, naming
    /// its owner. Needs root to make a directory of another user; CI runs as root.
    #[test]
    fn prepare_root_refuses_a_directory_of_another_user() {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            eprintln!("not root: cannot give a directory to another user; not checked");
            return;
        }
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("pre-empted");
        std::fs::create_dir(&root).unwrap();
        std::os::unix::fs::chown(&root, Some(65534), None).unwrap();
        let e = prepare_root(&with_root(root.to_str().unwrap()).unwrap()).unwrap_err();
        assert!(
            matches!(e, RootError::ForeignOwner { owner: 65534, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("uid 65534"), "{e}");
    }
}
