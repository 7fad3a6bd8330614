//! Format 3 and format 2 cannot share a service (docs/protocol.md, "Format 3"): the header grew
//! from 192 to 256 bytes, so iceoryx2 refuses to open a service made with the other header
//! type. Checked over real iceoryx2 services under a private root, both ways: a format-3 party
//! meeting a format-2 service gets `FrameServiceError::OtherFormat`, naming both formats; a
//! format-2 party cannot open a format-3 service.

use dear_proto::service::{
    QOS_HISTORY, QOS_MAX_NODES, QOS_MAX_PUBLISHERS, QOS_MAX_SUBSCRIBERS, QOS_SUBSCRIBER_BORROWED,
    QOS_SUBSCRIBER_BUFFER,
};
use dear_proto::transport::{node_config_from, prepare_root};
use dear_proto::{frame_service, FrameServiceError, Transport};
use iceoryx2::prelude::*;

/// Format 2's user header as a format-2 party declared it: the same type name, 192 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("DearFrameHeader")]
struct Format2Header {
    magic: u32,
    version: u32,
    rest: [u64; 23],
}

const _: () = assert!(std::mem::size_of::<Format2Header>() == 192);

fn node(root: &std::path::Path) -> Node<Transport> {
    let config =
        node_config_from(&iceoryx2::config::Config::default(), Some(root.as_os_str())).unwrap();
    prepare_root(&config).unwrap();
    NodeBuilder::new()
        .config(&config)
        .create::<Transport>()
        .unwrap()
}

/// The frame service as a format-2 deard or client opened it: same QoS, the 192-byte header.
fn format_2_service(
    node: &Node<Transport>,
    name: &str,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, [u8], Format2Header>,
    iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError,
> {
    let service_name: ServiceName = name.try_into().unwrap();
    node.service_builder(&service_name)
        .publish_subscribe::<[u8]>()
        .user_header::<Format2Header>()
        .enable_safe_overflow(true)
        .subscriber_max_buffer_size(QOS_SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(QOS_SUBSCRIBER_BORROWED)
        .history_size(QOS_HISTORY)
        .max_subscribers(QOS_MAX_SUBSCRIBERS)
        .max_publishers(QOS_MAX_PUBLISHERS)
        .max_nodes(QOS_MAX_NODES)
        .open_or_create()
}

#[test]
fn a_format_2_service_is_refused_naming_both_formats() {
    let tmp = tempfile::tempdir().unwrap();
    let node = node(&tmp.path().join("root"));
    let name = dear_test_support::process::unique_service("format-2");
    let _old = format_2_service(&node, &name).expect("a format-2 party makes the service");
    let Err(err) = frame_service(&node, &name) else {
        panic!("format 3 opened a format-2 service");
    };
    assert!(
        matches!(err, FrameServiceError::OtherFormat { .. }),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains(&format!("{name:?}"))
            && msg.contains("format 3")
            && msg.contains("256 bytes")
            && msg.contains("format 2 had 192")
            && msg.contains("update the older"),
        "{msg}"
    );
}

#[test]
fn a_format_2_party_cannot_open_a_format_3_service() {
    let tmp = tempfile::tempdir().unwrap();
    let node = node(&tmp.path().join("root"));
    let name = dear_test_support::process::unique_service("format-3");
    let _new = frame_service(&node, &name).expect("format 3 makes the service");
    let Err(err) = format_2_service(&node, &name) else {
        panic!("a format-2 header type opened a format-3 service");
    };
    assert_eq!(
        err,
        iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError::IncompatibleTypes
        )
    );
    // The same service opened by another format-3 party is fine.
    assert!(frame_service(&node, &name).is_ok());
}
