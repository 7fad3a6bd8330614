//! Service names and the quality-of-service settings every party opens the frame service with.
//!
//! Daemon and clients both call [`frame_service`] (`open_or_create`), so either may start
//! first and a restarted daemon is picked up by running clients. The QoS values are constants of
//! the protocol: a client that asked for different ones would fail to open the service.
//!
//! Overflow policy (documented choice): each subscriber has a queue of
//! [`QOS_SUBSCRIBER_BUFFER`] frames; when it is full the *oldest* frame is overwritten
//! ("safe overflow"), so a slow or stuck subscriber only ever loses its own old frames and never
//! blocks the daemon or other subscribers. Live depth is worth more fresh than complete.

use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::header::FrameHeader;

/// Frames queued per subscriber before the oldest is overwritten.
pub const QOS_SUBSCRIBER_BUFFER: usize = 2;
/// Frames a subscriber may hold (borrow) at once.
pub const QOS_SUBSCRIBER_BORROWED: usize = 2;
/// Frames a late-joining subscriber receives at once (the latest one).
pub const QOS_HISTORY: usize = 1;
/// Subscribers one daemon serves. Shared memory grows with it: the publisher's data segment
/// holds [`samples_in_shared_memory`] frames (35 with these values: 21.5 MB at 320×240, 86 MB
/// at 640×480), allocated as written (a frame's pages once it has been sent).
pub const QOS_MAX_SUBSCRIBERS: usize = 8;
/// Publishers: one daemon, plus one slot so a restarted daemon can start before the dead
/// instance's port is cleaned up.
pub const QOS_MAX_PUBLISHERS: usize = 2;
/// Nodes (processes) attached to the service.
pub const QOS_MAX_NODES: usize = QOS_MAX_SUBSCRIBERS + QOS_MAX_PUBLISHERS + 4;

/// Frames the publisher's data segment holds: every subscriber's queue and borrowed samples,
/// the history, and the publisher's own loans (iceoryx2 0.10 sizes it so:
/// `max_subscribers · (buffer + borrowed) + history + max_loaned`, with one loan and one
/// sample in flight). Frame size × this is the shared memory one stream can take.
pub const fn samples_in_shared_memory() -> usize {
    QOS_MAX_SUBSCRIBERS * (QOS_SUBSCRIBER_BUFFER + QOS_SUBSCRIBER_BORROWED) + QOS_HISTORY + 2
}

/// Default camera name.
pub const DEFAULT_CAMERA: &str = "cam0";

/// The default frame service of a camera: `dear/<camera>/frames`.
pub fn default_service_name(camera: &str) -> String {
    format!("dear/{camera}/frames")
}

/// Why a service name was refused ([`validate_service_name`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ServiceNameError {
    #[error("service name {name:?} must be 1 to 200 characters")]
    Length { name: String },
    #[error("service name {name:?} contains {found:?}; use letters, digits and / _ - .")]
    Character { name: String, found: char },
    /// Passed our rules but not iceoryx2's (kept as a source so a future iceoryx2 rule is
    /// reported, not swallowed).
    #[error("service name {name:?} is not accepted by iceoryx2")]
    Iceoryx {
        name: String,
        #[source]
        source: ServiceNameRejected,
    },
}

/// iceoryx2's own service-name error.
pub type ServiceNameRejected = iceoryx2::service::service_name::ServiceNameError;

/// Why the frame service could not be opened or created ([`frame_service`]).
#[derive(Debug, thiserror::Error)]
pub enum FrameServiceError {
    #[error(transparent)]
    Name(#[from] ServiceNameError),
    /// Typically: the service exists with other QoS or another header type (a client or
    /// daemon of another protocol version), or the shared memory is not accessible.
    #[error("cannot open or create the frame service {name:?} (if it exists, another process made it with other QoS or types than this protocol's: README, \"Frame layout\")")]
    OpenOrCreate {
        name: String,
        #[source]
        source: PublishSubscribeOpenOrCreateError,
    },
}

/// Why the event service could not be opened or created ([`frame_event_service`]).
#[derive(Debug, thiserror::Error)]
pub enum EventServiceError {
    #[error(transparent)]
    Name(#[from] ServiceNameError),
    #[error("cannot open or create the event service {name:?}")]
    OpenOrCreate {
        name: String,
        #[source]
        source: EventOpenOrCreateError,
    },
}

/// Checks a service name: non-empty, at most 200 bytes, ASCII letters, digits and `/_-.`.
pub fn validate_service_name(name: &str) -> Result<(), ServiceNameError> {
    if name.is_empty() || name.len() > 200 {
        return Err(ServiceNameError::Length {
            name: name.to_string(),
        });
    }
    if let Some(found) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || "/_-.".contains(*c)))
    {
        return Err(ServiceNameError::Character {
            name: name.to_string(),
            found,
        });
    }
    Ok(())
}

/// The iceoryx2 name of a valid service name.
fn service_name(name: &str) -> Result<ServiceName, ServiceNameError> {
    validate_service_name(name)?;
    name.try_into().map_err(|source| ServiceNameError::Iceoryx {
        name: name.to_string(),
        source,
    })
}

/// The publish-subscribe port factory of the frame service.
pub type FrameService = publish_subscribe::PortFactory<ipc::Service, [u8], FrameHeader>;
/// The event port factory that announces new frames.
pub type FrameEventService = event::PortFactory<ipc::Service>;

/// Opens (or creates) the frame service `name` with the protocol's QoS.
pub fn frame_service(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<FrameService, FrameServiceError> {
    let service_name = service_name(name)?;
    node.service_builder(&service_name)
        .publish_subscribe::<[u8]>()
        .user_header::<FrameHeader>()
        .enable_safe_overflow(true)
        .subscriber_max_buffer_size(QOS_SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(QOS_SUBSCRIBER_BORROWED)
        .history_size(QOS_HISTORY)
        .max_subscribers(QOS_MAX_SUBSCRIBERS)
        .max_publishers(QOS_MAX_PUBLISHERS)
        .max_nodes(QOS_MAX_NODES)
        .open_or_create()
        .map_err(|source| FrameServiceError::OpenOrCreate {
            name: name.to_string(),
            source,
        })
}

/// Opens (or creates) the event service that announces each new frame of `name`.
pub fn frame_event_service(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<FrameEventService, EventServiceError> {
    let service_name = service_name(name)?;
    node.service_builder(&service_name)
        .event()
        .max_listeners(QOS_MAX_SUBSCRIBERS)
        .max_notifiers(QOS_MAX_PUBLISHERS)
        .max_nodes(QOS_MAX_NODES)
        .open_or_create()
        .map_err(|source| EventServiceError::OpenOrCreate {
            name: name.to_string(),
            source,
        })
}

/// Environment variable naming the directory iceoryx2 keeps its bookkeeping in (node and
/// service records, event sockets) for the daemon and every client: see [`node_config`].
pub const IOX2_ROOT_ENV: &str = "DEAR_IOX2_ROOT";

/// The root the systemd unit gives the daemon (`DEAR_IOX2_ROOT`): under `/run/deard`, its
/// `RuntimeDirectory=` (owned by the service's user, in root-owned `/run`, so no other user can
/// create or replace it first). Its clients set the same.
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
/// The root is `$DEAR_IOX2_ROOT` when set and not empty, otherwise iceoryx2's own
/// configuration, unchanged (`/tmp/iceoryx2` unless an iceoryx2 config file says otherwise).
/// The systemd unit sets [`SERVICE_IOX2_ROOT`] for the daemon; its clients set the same.
///
/// Why a variable and not "use `/run/deard/iceoryx2` when it exists": with that rule every
/// DEAR process on a machine where the service has run since boot would join the service's
/// root — the tests and a daemon started by hand too, which then fail unprivileged (they
/// cannot write there) or, as root, mix with the installed service (tried: a concurrent test
/// run's daemons moved into the installed service's root). An explicit setting keeps the
/// default world (`/tmp/iceoryx2`, no root needed: demo, tests) and the service's apart.
///
/// Shared memory itself stays in `/dev/shm` (iceoryx2's POSIX shared memory), which every
/// process shares. Its names start with iceoryx2's `prefix` and are derived from the service
/// name, not the root: a daemon under another root with the default prefix would open the
/// same segments as one under `/tmp/iceoryx2`. So a root other than iceoryx2's default gets a
/// prefix of its own, `dear_<hash of the root>_`, that every party computes the same way.
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
    let mut config = base.clone();
    let Some(value) = from_env else {
        return Ok(config);
    };
    let root = value.to_string_lossy().into_owned();
    if !root.starts_with('/') {
        return Err(NodeConfigError::NotAbsolute { value: root });
    }
    // iceoryx2 joins entries to the root itself; one trailing slash, as in its default.
    let normalised = format!("{}/", root.trim_end_matches('/'));
    let path = Path::new(normalised.as_bytes()).map_err(|source| NodeConfigError::Path {
        value: root.clone(),
        source,
    })?;
    if path != *Config::default().global.root_path() {
        config.global.set_root_path(&path);
        config.global.prefix = root_prefix(&normalised);
    }
    Ok(config)
}

/// `dear_<FNV-1a 32 of the root, 8 hex digits>_`: a shared-memory name prefix per root.
fn root_prefix(root: &str) -> FileName {
    let hash = root.bytes().fold(0x811c_9dc5_u32, |h, b| {
        (h ^ u32::from(b)).wrapping_mul(0x0100_0193)
    });
    FileName::new(format!("dear_{hash:08x}_").as_bytes())
        .expect("letters, digits and _ make a valid file name")
}

#[cfg(test)]
mod node_config_tests {
    use super::*;
    use std::ffi::OsStr;

    fn with_root(root: &str) -> Result<Config, NodeConfigError> {
        node_config_from(&Config::default(), Some(OsStr::new(root)))
    }

    #[test]
    fn no_variable_keeps_iceoryx2s_default() {
        let base = Config::default();
        let config = node_config_from(&base, None).unwrap();
        assert_eq!(config, base);
        assert_eq!(config.global.root_path().to_string(), "/tmp/iceoryx2/");
    }

    #[test]
    fn the_service_root_gets_its_own_prefix() {
        let config = with_root(SERVICE_IOX2_ROOT).unwrap();
        assert_eq!(
            config.global.root_path().to_string(),
            "/run/deard/iceoryx2/"
        );
        // Fixed by the root alone: the README and the install test name it.
        assert_eq!(config.global.prefix.to_string(), "dear_ca47c86f_");
    }

    #[test]
    fn daemon_and_client_agree_however_the_root_is_spelled() {
        let a = with_root("/srv/x//").unwrap();
        let b = with_root("/srv/x").unwrap();
        assert_eq!(a.global.root_path().to_string(), "/srv/x/");
        assert_eq!(a.global.prefix, b.global.prefix);
        assert_eq!(a.global.root_path(), b.global.root_path());
    }

    #[test]
    fn different_roots_never_share_shared_memory_names() {
        let p = |root: &str| with_root(root).unwrap().global.prefix;
        assert_ne!(p("/run/deard/iceoryx2"), p("/run/other/iceoryx2"));
        assert_ne!(p("/run/deard/iceoryx2"), Config::default().global.prefix);
        // Naming the default root explicitly is the default: same prefix as everyone else's.
        assert_eq!(p("/tmp/iceoryx2"), Config::default().global.prefix);
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
}
