//! `dear list`: the DEAR frame services on this machine.
//!
//! A frame service is recognised by its contract, not its name: a publish-subscribe service
//! whose user header type is `DearFrameHeader` (the `#[type_name]` of
//! [`dear_proto::FrameHeader`]), so services started with any `--service` name are found.

use anyhow::Context;
use dear_proto::FrameHeader;
use dear_proto::Transport;
use iceoryx2::prelude::*;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as Pattern;

/// The type name every DEAR frame service carries as its user header.
pub const FRAME_HEADER_TYPE_NAME: &str = "DearFrameHeader";

/// What `dear list` shows of one service.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameServiceInfo {
    pub name: String,
    /// Processes attached to the service (daemon, clients, and `dear list` itself while it
    /// looks).
    pub nodes: usize,
    /// Publisher and subscriber ports; `None` when the service could not be opened to count.
    pub publishers: Option<usize>,
    pub subscribers: Option<usize>,
}

/// Finds the frame services. Counting ports needs the service opened, which attaches this
/// process as one more node (not as a publisher or subscriber) for the moment it looks.
pub fn frame_services() -> anyhow::Result<Vec<FrameServiceInfo>> {
    let mut found = Vec::new();
    // The daemon's iceoryx2 root: $DEAR_IOX2_ROOT, else /dev/shm/dear (node_config).
    let config = dear_proto::node_config()?;
    // No root directory: nothing to list. One this user cannot enter (outside the service's
    // group) is an error that says so, not "none found".
    if dear_proto::transport::existing_root(&config)?.is_none() {
        return Ok(found);
    }
    Transport::list(&config, |details| {
        if let Pattern::PublishSubscribe(pubsub) = details.static_details.messaging_pattern() {
            let header = pubsub.message_type_details().user_header.type_name();
            if *header == FRAME_HEADER_TYPE_NAME {
                let nodes = details.dynamic_details.as_ref().map_or(0, |d| {
                    d.nodes
                        .iter()
                        .filter(|n| matches!(n, NodeState::Alive(_)))
                        .count()
                });
                found.push(FrameServiceInfo {
                    name: details.static_details.name().as_str().to_string(),
                    nodes,
                    publishers: None,
                    subscribers: None,
                });
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| {
        anyhow::anyhow!(
            "cannot list the iceoryx2 services under {}: {e:?}",
            config.global.root_path()
        )
    })?;
    if found.is_empty() {
        return Ok(found);
    }
    let node = NodeBuilder::new()
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Transport>()
        .map_err(|e| anyhow::anyhow!("cannot create an iceoryx2 node: {e:?}"))?;
    for info in &mut found {
        if let Some((publishers, subscribers)) = count_ports(&node, &info.name) {
            info.publishers = Some(publishers);
            info.subscribers = Some(subscribers);
        }
    }
    found.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(found)
}

/// Opens (never creates) the service with the frame types only, so any QoS it was created
/// with is accepted, and reads its port counts. `None` if it vanished or cannot be opened.
fn count_ports(node: &Node<Transport>, name: &str) -> Option<(usize, usize)> {
    let service_name: ServiceName = name.try_into().ok()?;
    let service = node
        .service_builder(&service_name)
        .publish_subscribe::<[u8]>()
        .user_header::<FrameHeader>()
        .open()
        .inspect_err(|e| tracing::debug!(service = name, error = ?e, "cannot open to count ports"))
        .ok()?;
    let dynamic = service.dynamic_config();
    Some((
        dynamic.number_of_publishers(),
        dynamic.number_of_subscribers(),
    ))
}

pub fn run() -> anyhow::Result<()> {
    let services = frame_services().context("dear list")?;
    if services.is_empty() {
        return super::write_stdout(&format!(
            "no DEAR frame services found (is deard running? it publishes {:?} by default)\n",
            super::default_service()
        ));
    }
    let width = services
        .iter()
        .map(|s| s.name.len())
        .max()
        .unwrap_or(0)
        .max(7);
    let mut text = format!(
        "{:<width$}  publishers  subscribers  processes\n",
        "service"
    );
    let count = |n: Option<usize>| n.map_or_else(|| "?".to_string(), |n| n.to_string());
    for s in &services {
        text.push_str(&format!(
            "{:<width$}  {:>10}  {:>11}  {:>9}\n",
            s.name,
            count(s.publishers),
            count(s.subscribers),
            s.nodes
        ));
    }
    super::write_stdout(&text)
}
