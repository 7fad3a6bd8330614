//! Publishing frames over iceoryx2: each frame is written by the pipeline directly into a
//! loaned shared-memory sample (no intermediate frame buffer), sent, and announced on the event
//! service so subscribers wake up.

use std::cell::{Cell, RefCell};
use std::time::Instant;

use dear_proto::service::{
    frame_event_service, frame_service, EventServiceError, FrameEventService, FrameService,
    FrameServiceError,
};
use dear_proto::{FrameHeader, LayoutError, PayloadLayout, Stage, Transport};
use iceoryx2::config::Config;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use ndarray::{ArrayViewMut2, ArrayViewMut3};

use crate::processing::{micros, FrameOutput};
use crate::transport_guard::{self, ServiceFiles};

/// Why the publishing end of a frame service cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum PublisherError {
    /// iceoryx2 cannot create the node (e.g. its root directory is not writable).
    #[error("cannot create the iceoryx2 node under {root}: {source:?}")]
    Node {
        root: String,
        #[source]
        source: iceoryx2::node::NodeCreationFailure,
    },
    /// The frame service cannot be opened or created.
    #[error(transparent)]
    Service(#[from] FrameServiceError),
    /// The event service cannot be opened or created.
    #[error(transparent)]
    Events(#[from] EventServiceError),
    /// The frame is larger than the protocol can describe.
    #[error("cannot publish on {service:?}: {source}")]
    Layout {
        service: String,
        #[source]
        source: LayoutError,
    },
    /// The publisher port cannot be created (e.g. the service has no publisher slot left).
    #[error("cannot create a publisher on {service:?}: {source:?}")]
    Publisher {
        service: String,
        #[source]
        source: iceoryx2::port::publisher::PublisherCreateError,
    },
    /// The notifier port cannot be created.
    #[error("cannot create a notifier on {service:?}: {source:?}")]
    Notifier {
        service: String,
        #[source]
        source: iceoryx2::port::notifier::NotifierCreateError,
    },
    /// Another live process publishes on the service.
    #[error("another process already publishes on {service:?} (pid {pids}): one deard per service; stop it, or give this one another [service] camera / --camera")]
    SecondPublisher { service: String, pids: String },
    /// The kernel gave no random run id.
    #[error("cannot draw a run id for {service:?} (getrandom): {source}")]
    RunId {
        service: String,
        #[source]
        source: std::io::Error,
    },
}

/// Why one frame was not published (the daemon skips and counts it). `E` is the error of the
/// function that fills the sample.
#[derive(Debug, thiserror::Error)]
pub enum PublishError<E: std::error::Error + 'static> {
    /// No sample could be loaned (e.g. every sample is held by slow subscribers).
    #[error("cannot loan a sample on {service:?}: {source:?}")]
    Loan {
        service: String,
        #[source]
        source: iceoryx2::port::LoanError,
    },
    /// The loaned payload cannot hold `f32` depth in place.
    #[error("the shared-memory payload on {service:?} is not aligned for f32")]
    Misaligned { service: String },
    /// Filling the sample failed (it is dropped unsent).
    #[error(transparent)]
    Fill(E),
    /// The transport's files were deleted and cannot be made again yet
    /// ([`FramePublisher::check_transport`]).
    #[error(
        "the transport of {service:?} is not available (its files were deleted; being made again)"
    )]
    NoTransport { service: String },
    /// The sample could not be sent.
    #[error("cannot send on {service:?}: {source:?}")]
    Send {
        service: String,
        #[source]
        source: iceoryx2::port::SendError,
    },
}

/// The iceoryx2 ports of a [`FramePublisher`]: made again when the transport's files are
/// deleted under it.
struct Ports {
    node: Node<Transport>,
    publisher: Publisher<Transport, [u8], FrameHeader>,
    notifier: Notifier<Transport>,
    // Keep the port factories alive as long as the ports.
    frames: FrameService,
    _events: FrameEventService,
    /// The files new clients need, checked every second.
    files: ServiceFiles,
    /// The names of the frame and event services' records
    /// ([`transport_guard::ServiceRecordNames`]).
    records: transport_guard::ServiceRecordNames,
}

/// The daemon's publishing end of one frame service.
pub struct FramePublisher {
    name: String,
    /// The transport's configuration, dead-node cleanup on creation off.
    config: Config,
    root: std::path::PathBuf,
    layout: PayloadLayout,
    /// This instance's [`FrameHeader::run_id`], drawn once in `new`.
    run_id: u64,
    /// The [`FrameHeader::sequence`] of the next sample sent. A `Cell`: `publish` takes
    /// `&self`, and the publisher is used from the frame loop's thread only (iceoryx2 ports are
    /// not `Sync` either).
    sequence: Cell<u64>,
    /// `None` while the transport cannot be made again (logged; retried every second).
    ports: RefCell<Option<Ports>>,
    /// Damage to the services' shared records seen at the last check ([`RecordCheck`]).
    records: RefCell<RecordCheck>,
    /// The names of the services' records as last made (kept while `ports` is `None`).
    record_names: transport_guard::ServiceRecordNames,
    /// Loans that failed in a row since the last one that succeeded ([`STARVED_LOANS`]).
    failed_loans: Cell<u32>,
    /// Subscriber slots one user other than the service's own may hold
    /// ([`FramePublisher::set_subscribers_per_user`]).
    subscribers_per_user: Cell<usize>,
}

/// Failed loans in a row after which the service is made again ([`FramePublisher::check_transport`]):
/// about a second of frames. Issue 34: a client whose connection another process overwrote
/// whole keeps the samples lent to it, and the publisher no longer takes anything back through
/// that connection, nor, as iceoryx2 0.10 stands, when it goes: every sample ends up lent and
/// every later frame would be skipped (`OutOfMemory`). A new service has all its samples;
/// clients connect again.
const STARVED_LOANS: u32 = 30;

impl FramePublisher {
    /// Creates the node, cleans up what crashed processes left behind, and opens the services.
    /// `config` is the transport's ([`dear_proto::node_config`]: the root every client uses
    /// too), its root directory prepared ([`dear_proto::transport::prepare_root`]).
    pub fn new(
        config: &Config,
        name: &str,
        width: u32,
        height: u32,
    ) -> Result<Self, PublisherError> {
        let mut config = config.clone();
        // The dead-node cleanup that iceoryx2 runs inside `create` reports nothing; turned off
        // there, the explicit one below can say what it removed (it logged `cleanups: 0` after
        // `create` had already removed everything).
        config.global.node.cleanup_dead_nodes_on_creation = false;
        tracing::info!(root = %config.global.root_path(), "iceoryx2");
        let root = dear_proto::transport::root_dir(&config);
        let layout =
            PayloadLayout::new(width, height).map_err(|source| PublisherError::Layout {
                service: name.to_string(),
                source,
            })?;
        transport_guard::survive_truncated_records();
        let ports = match open_ports(&config, &root, name, layout) {
            Err(PublisherError::Publisher {
                source:
                    iceoryx2::port::publisher::PublisherCreateError::ExceedsMaxSupportedPublishers,
                ..
            }) if take_back_from_other_users(&config, &root, name)? => {
                open_ports(&config, &root, name, layout)?
            }
            opened => opened?,
        };
        let record_names = ports.records.clone();
        refuse_a_second_publisher(&root, &ports.frames, ports.publisher.id(), name)?;
        let run_id = dear_proto::random_run_id().map_err(|source| PublisherError::RunId {
            service: name.to_string(),
            source,
        })?;
        tracing::info!(run_id = format_args!("{run_id:016x}"), "publisher instance");
        Ok(FramePublisher {
            name: name.to_string(),
            config,
            root,
            layout,
            run_id,
            sequence: Cell::new(0),
            ports: RefCell::new(Some(ports)),
            records: RefCell::new(RecordCheck::default()),
            failed_loans: Cell::new(0),
            record_names,
            subscribers_per_user: Cell::new(dear_proto::service::QOS_MAX_SUBSCRIBERS),
        })
    }

    /// Limits the subscriber slots one user other than the service's own (and root) may hold
    /// (deard's `[service] max_subscribers_per_user`); enforced by
    /// [`check_transport`](Self::check_transport). Without a call: no limit.
    pub fn set_subscribers_per_user(&self, limit: usize) {
        self.subscribers_per_user.set(limit.max(1));
    }

    /// Checks the transport's files (called every second by the daemon): removes symbolic links
    /// from the root, repairs a damaged node counter, and when a file new clients need was deleted (`rm -rf` of the root, a
    /// tmpfs cleaner), makes the service again under the same run id, logging why. Running
    /// clients keep the old files mapped and stop receiving; new clients (and clients that
    /// connect again) find the new service. The same when a client damaged the services'
    /// shared records (`*.dynamic`) at two checks in a row ([`RecordCheck`]): their old files
    /// are removed first, or the new node would open them again. And when no sample could be
    /// loaned for [`STARVED_LOANS`] frames in a row.
    pub fn check_transport(&self) {
        // A check that starts after a write has finished the one before it: tests that damage
        // the records wait for these lines to know the daemon has acted on their last write.
        tracing::debug!("{CHECKING_TRANSPORT}");
        // A link swapped in while serving: iceoryx2 would follow it when it makes or removes
        // a node's directory (a client joining or a dead one cleaned up).
        transport_guard::remove_symlinks(&self.root);
        transport_guard::repair_global_mgmt(&self.root);
        let mut ports = self.ports.borrow_mut();
        let mut damaged = Vec::new();
        if let Some(p) = ports.as_ref() {
            // Issue 34: clients that died (a client whose connection another member scribbled
            // on aborts) leave their nodes registered in the services until someone cleans
            // them up; left alone they fill the services' node slots and keep new clients
            // out (`ExceedsMaxNumberOfNodes`).
            log_cleanup(p.node.try_cleanup_dead_nodes(), "while serving");
            limit_subscribers_per_user(
                &p.frames,
                &p._events,
                &self.root,
                self.subscribers_per_user.get(),
                &self.name,
            );
            if let Some(missing) = p.files.missing() {
                tracing::error!(file = %missing.display(), root = %self.root.display(), service = %self.name, "a file of the transport was deleted: no new client could find the service; making it again");
            } else if let Some(why) = self.records.borrow_mut().check(p, &self.root) {
                damaged = transport_guard::service_records(&self.root, &p.records);
                tracing::error!(reason = %why, files = ?damaged, service = %self.name, "a client damaged the service's shared records: new clients could not use them; making the service again");
            } else if self.failed_loans.get() >= STARVED_LOANS {
                tracing::error!(failed_loans = self.failed_loans.get(), service = %self.name, "no sample could be loaned for the last frames: every sample is held by damaged channels; making the service again");
            } else {
                return;
            }
        }
        // The old ports go first: their node would otherwise count as a second publisher.
        *ports = None;
        // Dropping the ports removed them already where no client holds the old service.
        for file in damaged {
            if let Err(e) = std::fs::remove_file(&file).or_else(|e| match e.kind() {
                std::io::ErrorKind::NotFound => Ok(()),
                _ => Err(e),
            }) {
                tracing::warn!(file = %file.display(), error = %e, "cannot remove a damaged record of the service");
            }
        }
        *self.records.borrow_mut() = RecordCheck::default();
        self.failed_loans.set(0);
        let reopened = dear_proto::transport::prepare_root(&self.config)
            .map_err(|e| e.to_string())
            .and_then(|_| {
                open_ports(&self.config, &self.root, &self.name, self.layout)
                    .map_err(|e| e.to_string())
            });
        match reopened {
            Ok(p) => {
                tracing::warn!(root = %self.root.display(), service = %self.name, files = p.files.len(), "made the transport's files again: new clients can connect (running clients must connect again)");
                *ports = Some(p);
            }
            Err(e) => {
                tracing::error!(error = %e, service = %self.name, "cannot make the transport's files again; frames are not published until it can (retried every second)");
                // Issue 34: a client may have made the service meanwhile (clients open or
                // create it) and damaged its records, or damaged them again while the daemon
                // made them: the static records go (they are named by the service, which
                // does not change), so the next try makes a new service beside the damaged
                // one. Its clients connect again.
                for file in transport_guard::static_records(&self.root, &self.record_names) {
                    match std::fs::remove_file(&file) {
                        Ok(()) => {
                            tracing::warn!(file = %file.display(), service = %self.name, "removed the service's static record: the next try makes a new service")
                        }
                        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                        Err(e) => {
                            tracing::warn!(file = %file.display(), error = %e, "cannot remove the service's static record")
                        }
                    }
                }
            }
        }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The run id stamped on every sample of this instance.
    pub fn run_id(&self) -> u64 {
        self.run_id
    }

    /// Loans a sample, lets `fill` write the frame into it, stamps and sends it, and notifies
    /// listeners. Returns the header as sent. If `fill` fails the sample is dropped unsent and
    /// the error returned. Stamps `run_id` and `sequence` (overwriting whatever `header` had):
    /// every sent sample gets the next number, so a gap a client sees is a frame it lost. The
    /// number is spent even if the send then fails (a gap, counted as a loss), because a
    /// failed send may have reached some subscribers and a number must never repeat.
    pub fn publish<E: std::error::Error + 'static>(
        &self,
        mut header: FrameHeader,
        arrived: Instant,
        fill: impl FnOnce(&mut FrameHeader, FrameOutput<'_>) -> Result<(), E>,
    ) -> Result<FrameHeader, PublishError<E>> {
        let layout = self.layout;
        let ports = self.ports.borrow();
        let Some(ports) = ports.as_ref() else {
            return Err(PublishError::NoTransport {
                service: self.name.clone(),
            });
        };
        let t_loan = Instant::now();
        // `loan_slice` zero-fills (one memset); the frame itself is never copied afterwards.
        let mut sample = ports.publisher.loan_slice(layout.size).map_err(|source| {
            self.failed_loans
                .set(self.failed_loans.get().saturating_add(1));
            PublishError::Loan {
                service: self.name.clone(),
                source,
            }
        })?;
        self.failed_loans.set(0);
        let loan_us = micros(t_loan);
        let payload = sample.payload_mut();
        let (depth_bytes, rest) = payload.split_at_mut(layout.rgb_offset);
        let (rgb_bytes, confidence_bytes) =
            rest.split_at_mut(layout.confidence_offset - layout.rgb_offset);
        let depth_floats = bytes_as_f32(depth_bytes).ok_or_else(|| PublishError::Misaligned {
            service: self.name.clone(),
        })?;
        let shape = (layout.height, layout.width);
        let output = FrameOutput {
            depth: ArrayViewMut2::from_shape(shape, depth_floats).expect("layout"),
            rgb: ArrayViewMut3::from_shape((layout.height, layout.width, 3), rgb_bytes)
                .expect("layout"),
            confidence: ArrayViewMut2::from_shape(shape, &mut confidence_bytes[..layout.pixels()])
                .expect("layout"),
        };
        fill(&mut header, output).map_err(PublishError::Fill)?;
        // The send itself happens after the header is written, so "publish" covers the loan
        // (and its zero fill); the notify cost shows up in the next frame's idle time.
        header.stage_latency_us[Stage::Publish as usize] = loan_us;
        header.stage_latency_us[Stage::Total as usize] = micros(arrived);
        header.publish_timestamp_ns = dear_proto::time::monotonic_ns();
        header.run_id = self.run_id;
        header.sequence = self.sequence.get();
        self.sequence.set(header.sequence + 1);
        *sample.user_header_mut() = header;
        sample.send().map_err(|source| PublishError::Send {
            service: self.name.clone(),
            source,
        })?;
        if let Err(e) = ports.notifier.notify() {
            tracing::warn!(error = ?e, "cannot notify listeners");
        }
        Ok(header)
    }

    /// Removes ports of subscribers that died without cleaning up, so their queues stop taking
    /// samples. Called periodically by the daemon.
    pub fn cleanup_dead_peers(&self) {
        if let Some(ports) = self.ports.borrow().as_ref() {
            log_cleanup(ports.node.try_cleanup_dead_nodes(), "of dead clients");
        }
    }
}

/// What [`FramePublisher::check_transport`] logs (at debug level) as each check starts.
pub const CHECKING_TRANSPORT: &str = "checking the transport's files";

/// Makes the node, the services and the ports under `root`: symbolic links in the root are
/// removed first and a damaged node counter repaired ([`transport_guard`]), and the data
/// segment is made read-only to clients once it exists.
fn open_ports(
    config: &Config,
    root: &std::path::Path,
    name: &str,
    layout: PayloadLayout,
) -> Result<Ports, PublisherError> {
    transport_guard::remove_symlinks(root);
    transport_guard::repair_global_mgmt(root);
    let node = daemon_node(config)?;
    log_cleanup(node.try_cleanup_dead_nodes(), "at start");
    let frames = frame_service(&node, name)?;
    let events = frame_event_service(&node, name)?;
    let service = || name.to_string();
    let publisher = frames
        .publisher_builder()
        .initial_max_slice_len(layout.size)
        .create()
        .map_err(|source| PublisherError::Publisher {
            service: service(),
            source,
        })?;
    let notifier =
        events
            .notifier_builder()
            .create()
            .map_err(|source| PublisherError::Notifier {
                service: service(),
                source,
            })?;
    let publisher_id = publisher.id().value();
    let restricted = transport_guard::restrict_data_segments(root, publisher_id);
    tracing::info!(files = ?restricted, "data segment read-only to clients (mode 0644)");
    let files = ServiceFiles::snapshot(
        root,
        &[
            frames.service_hash().as_str(),
            events.service_hash().as_str(),
        ],
        publisher_id,
    );
    let records = record_names(&frames, &events);
    Ok(Ports {
        node,
        publisher,
        notifier,
        frames,
        _events: events,
        files,
        records,
    })
}

/// The daemon's iceoryx2 node under `config`: its signals are the daemon's own.
fn daemon_node(config: &Config) -> Result<Node<Transport>, PublisherError> {
    NodeBuilder::new()
        .config(config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Transport>()
        .map_err(|source| PublisherError::Node {
            root: config.global.root_path().to_string(),
            source,
        })
}

/// The names of the frame and event services' records.
fn record_names(
    frames: &FrameService,
    events: &FrameEventService,
) -> transport_guard::ServiceRecordNames {
    transport_guard::ServiceRecordNames {
        hashes: [
            frames.service_hash().as_str().to_string(),
            events.service_hash().as_str().to_string(),
        ],
        ids: [
            frames.unique_service_id().value(),
            events.unique_service_id().value(),
        ],
    }
}

/// Issue 34: notices a client's damage to the services' shared records (`*.dynamic`, which
/// every client must write to register its ports). The patched iceoryx2 (third_party/) no
/// longer lets any bytes there crash the daemon: a corrupted container header is refused
/// (and counted, `iceoryx2_bb_lock_free::dear_shared::corruptions`), and the publisher keeps
/// serving the clients it knows. But new clients would find the records unusable, so the
/// daemon checks them every second and makes the service again when, at two checks in a row
/// (a client registering a port is briefly half-written), one of these holds:
///
/// - a header was refused, or a truncated record replaced by zeros
///   ([`transport_guard::survive_truncated_records`]), since the last check;
/// - the daemon's own publisher or notifier is not listed;
/// - a listed port's node has no directory under `nodes/` (a client's node directory is made
///   before its ports and removed after them), or a registered node is undefined (its id
///   names no node);
/// - the count of taken slots differs from the count of listed ports;
/// - a record's version stamp was overwritten (new clients are refused with
///   `VersionMismatch`).
#[derive(Debug, Default)]
struct RecordCheck {
    corruptions: u64,
    suspect: Option<String>,
}

impl RecordCheck {
    /// The damage seen now and at the previous check, if any.
    fn check(&mut self, ports: &Ports, root: &std::path::Path) -> Option<String> {
        let now = damage(ports, root, &mut self.corruptions);
        match (self.suspect.take(), now) {
            (Some(_), Some(why)) => Some(why),
            (None, Some(why)) => {
                tracing::debug!(reason = %why, "the service's shared records look damaged; checking again in a second");
                self.suspect = Some(why);
                None
            }
            (_, None) => None,
        }
    }
}

/// What is wrong with the records now, if anything (see [`RecordCheck`]).
fn damage(ports: &Ports, root: &std::path::Path, corruptions: &mut u64) -> Option<String> {
    let nodes = root.join("nodes");
    let missing_node = |id: &iceoryx2::identifiers::UniqueNodeId| -> bool {
        std::fs::symlink_metadata(nodes.join(id.value().to_string())).is_err()
    };
    let mut why = None;
    let frames = ports.frames.dynamic_config();
    let (mut own, mut listed, mut orphan) = (false, 0usize, false);
    frames.list_publishers(|d| {
        own |= d.publisher_id == ports.publisher.id();
        orphan |= missing_node(&d.node_id);
        CallbackProgression::Continue
    });
    if !own {
        why = Some("the daemon's publisher is not listed".to_string());
    }
    frames.list_subscribers(|d| {
        listed += 1;
        orphan |= missing_node(&d.node_id);
        CallbackProgression::Continue
    });
    if listed != frames.number_of_subscribers() {
        why.get_or_insert(format!(
            "{listed} subscribers listed in {} slots",
            frames.number_of_subscribers()
        ));
    }
    let events = ports._events.dynamic_config();
    let (mut own, mut listed) = (false, 0usize);
    events.list_notifiers(|d| {
        own |= d.notifier_id == ports.notifier.id();
        orphan |= missing_node(&d.node_id);
        CallbackProgression::Continue
    });
    if !own {
        why.get_or_insert("the daemon's notifier is not listed".to_string());
    }
    events.list_listeners(|d| {
        listed += 1;
        orphan |= missing_node(&d.node_id);
        CallbackProgression::Continue
    });
    if listed != events.number_of_listeners() {
        why.get_or_insert(format!(
            "{listed} listeners listed in {} slots",
            events.number_of_listeners()
        ));
    }
    if orphan {
        why.get_or_insert("a listed port's node does not exist".to_string());
    }
    // A registered node that is neither alive nor dead (its id is junk: no node of that id
    // exists) takes a node slot no cleanup frees.
    let mut undefined = 0usize;
    let mut count = |state: NodeState<Transport>| {
        if matches!(state, NodeState::Undefined(_)) {
            undefined += 1;
        }
        CallbackProgression::Continue
    };
    let _ = ports.frames.nodes(&mut count);
    let _ = ports._events.nodes(&mut count);
    if undefined > 0 {
        why.get_or_insert(format!("{undefined} registered nodes that do not exist"));
    }
    if let Some(file) = transport_guard::record_with_a_bad_stamp(root, &ports.records) {
        why.get_or_insert(format!("{} has a wrong version stamp", file.display()));
    }
    let seen =
        iceoryx2_bb_lock_free::dear_shared::corruptions() + transport_guard::truncated_records();
    if seen != *corruptions {
        why.get_or_insert(format!(
            "{} corrupted or truncated shared records",
            seen - *corruptions
        ));
        *corruptions = seen;
    }
    why
}

/// Logs what a dead-node cleanup did, when it did anything.
fn log_cleanup(state: iceoryx2::node::CleanupState, when: &str) {
    if state.cleanups > 0 {
        tracing::info!(
            processes = state.cleanups,
            "removed the shared-memory resources of dead processes ({when})"
        );
    }
    if state.failed_cleanups > 0 {
        tracing::warn!(
            processes = state.failed_cleanups,
            "could not remove the shared-memory resources of dead processes ({when}); \
             they belong to another user or are in use"
        );
    }
}

/// The publishers of `frames` other than `own`: each one's pid (as text) and the user it runs
/// as (the owner of its node's directory under the root), when known.
fn other_publishers(
    root: &std::path::Path,
    frames: &FrameService,
    own: Option<iceoryx2::identifiers::UniquePublisherId>,
) -> Vec<(String, Option<u32>)> {
    use std::os::unix::fs::MetadataExt;
    let mut others = Vec::new();
    frames.dynamic_config().list_publishers(|details| {
        if Some(details.publisher_id) != own {
            let pid = details
                .node_id
                .pid::<Transport>()
                .map(|pid| pid.value().to_string())
                .unwrap_or_else(|_| "unknown".into());
            let node_dir = root.join("nodes").join(details.node_id.value().to_string());
            let uid = std::fs::symlink_metadata(&node_dir).map(|m| m.uid()).ok();
            others.push((pid, uid));
        }
        CallbackProgression::Continue
    });
    others
}

/// Issue 34 (defect 10): one member of the service's group could take every subscriber slot
/// and keep every other client out. Removes the subscribers of each user other than the
/// service's own and root beyond `limit` (the last listed go: list order is slot order, not
/// age), and their nodes' listeners on the event service, logging whose. Their processes stop
/// receiving (a reconnecting client connects again and is held to the limit again).
fn limit_subscribers_per_user(
    frames: &FrameService,
    events: &FrameEventService,
    root: &std::path::Path,
    limit: usize,
    name: &str,
) {
    use std::collections::BTreeMap;
    use std::os::unix::fs::MetadataExt;
    let owner = service_owner(root);
    type Port = (
        iceoryx2::identifiers::UniqueNodeId,
        iceoryx2::identifiers::UniqueSubscriberId,
    );
    let mut by_user: BTreeMap<u32, Vec<Port>> = BTreeMap::new();
    frames.dynamic_config().list_subscribers(|details| {
        let node_dir = root.join("nodes").join(details.node_id.value().to_string());
        if let Ok(uid) = std::fs::symlink_metadata(&node_dir).map(|m| m.uid()) {
            if Some(uid) != owner && uid != 0 {
                by_user
                    .entry(uid)
                    .or_default()
                    .push((details.node_id, details.subscriber_id));
            }
        }
        CallbackProgression::Continue
    });
    for (uid, subscribers) in by_user {
        if subscribers.len() <= limit {
            continue;
        }
        let held = subscribers.len();
        let mut pids = Vec::new();
        for (node, subscriber) in &subscribers[limit..] {
            if frames
                .dynamic_config()
                .dear_evict_subscriber(node, *subscriber)
            {
                // Its node's listener too: the event service has as many slots.
                events.dynamic_config().dear_evict_node_listeners(node);
                pids.push(
                    node.pid::<Transport>()
                        .map(|pid| pid.value().to_string())
                        .unwrap_or_else(|_| "unknown".into()),
                );
            }
        }
        tracing::warn!(service = name, uid, held, limit, removed = pids.len(), pids = ?pids, "a user held more subscriber slots than [service] max_subscribers_per_user allows: removed those beyond the limit");
    }
}

/// The user the service belongs to: the owner of the root (clients trust its publishers and
/// root's).
fn service_owner(root: &std::path::Path) -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(root).map(|m| m.uid()).ok()
}

/// Issue 34 (lock-out): every publisher slot of `name` is taken, and by other users' processes
/// only (members of the service's group who published before the daemon: their frames are
/// refused by clients anyway). The daemon owns the root, so it removes the frame and event
/// services' records and lets the next try make the services again without them: their ports
/// stay mapped to the old, unlinked files, and new clients find the daemon's services.
/// Returns whether it removed anything; `false` when a publisher is the service user's own or
/// root's (a second deard: refused as before) or of unknown owner.
fn take_back_from_other_users(
    config: &Config,
    root: &std::path::Path,
    name: &str,
) -> Result<bool, PublisherError> {
    let node = daemon_node(config)?;
    let frames = frame_service(&node, name)?;
    let events = frame_event_service(&node, name)?;
    let owner = service_owner(root);
    let others = other_publishers(root, &frames, None);
    let foreign =
        |uid: &Option<u32>| matches!((uid, owner), (Some(u), Some(o)) if *u != o && *u != 0);
    if others.is_empty() || !others.iter().all(|(_, uid)| foreign(uid)) {
        return Ok(false);
    }
    let names = record_names(&frames, &events);
    drop((frames, events, node));
    let records = transport_guard::service_records(root, &names);
    let held_by: Vec<String> = others
        .iter()
        .map(|(pid, uid)| format!("pid {pid}, uid {}", uid.unwrap_or_default()))
        .collect();
    tracing::warn!(service = name, publishers = ?held_by, root_owner = owner, files = ?records, "other users' processes hold every publisher slot of this service (clients refuse their frames): making the service again without them");
    for file in &records {
        match std::fs::remove_file(file) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                tracing::warn!(file = %file.display(), error = %e, "cannot remove a record of the service")
            }
        }
    }
    Ok(true)
}

/// One publisher per service (after the cleanup above, every other one is alive): a second
/// daemon on the same service would interleave two streams whose frame ids and calibrations
/// have nothing to do with each other. Two daemons starting in the same instant both see the
/// other and both refuse; one of them is restarted by its supervisor and finds the service
/// free. A publisher of another user than the root's owner (or root) does not count: clients
/// refuse its frames, so the daemon serves beside it (issue 34).
fn refuse_a_second_publisher(
    root: &std::path::Path,
    frames: &FrameService,
    own: iceoryx2::identifiers::UniquePublisherId,
    name: &str,
) -> Result<(), PublisherError> {
    let owner = service_owner(root);
    let mut others = Vec::new();
    for (pid, uid) in other_publishers(root, frames, Some(own)) {
        match (uid, owner) {
            // Issue 34: a member of the service's group who publishes first. Clients refuse
            // its frames (dear_client::ReceiveError::UntrustedPublisher), so the service is
            // served anyway instead of being locked out.
            (Some(uid), Some(owner)) if uid != owner && uid != 0 => {
                tracing::warn!(service = name, pid, uid, root_owner = owner, "another user's process publishes on this service: clients refuse its frames; serving anyway");
            }
            (Some(uid), _) => others.push(format!("{pid}, uid {uid}")),
            (None, _) => others.push(pid),
        }
    }
    if others.is_empty() {
        return Ok(());
    }
    Err(PublisherError::SecondPublisher {
        service: name.to_string(),
        pids: others.join("; "),
    })
}

/// Reinterprets the depth plane as `f32`. The payload starts 8-byte aligned
/// ([`dear_proto::PAYLOAD_ALIGNMENT`]) and the depth plane at offset 0 with a length of
/// `4·pixels`, so this cannot fail unless iceoryx2 changed where it puts the payload.
fn bytes_as_f32(bytes: &mut [u8]) -> Option<&mut [f32]> {
    if !(bytes.as_ptr() as usize).is_multiple_of(std::mem::align_of::<f32>())
        || !bytes.len().is_multiple_of(4)
    {
        return None;
    }
    // SAFETY: alignment and length checked above; every byte pattern is a valid f32; the
    // returned slice borrows `bytes` mutably, so no aliasing.
    Some(unsafe {
        std::slice::from_raw_parts_mut(bytes.as_mut_ptr().cast::<f32>(), bytes.len() / 4)
    })
}
