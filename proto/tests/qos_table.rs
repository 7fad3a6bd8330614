//! docs/protocol.md's QoS table (for clients in other languages) states the protocol's
//! constants: a client built from it opens the service instead of breaking it.

use dear_proto::service::{
    QOS_HISTORY, QOS_MAX_NODES, QOS_MAX_PUBLISHERS, QOS_MAX_SUBSCRIBERS, QOS_SUBSCRIBER_BORROWED,
    QOS_SUBSCRIBER_BUFFER,
};

/// The value column of docs/protocol.md's row whose setting column is `setting`.
fn documented_value(doc: &str, setting: &str) -> String {
    doc.lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            (cells.len() == 5 && cells[2] == setting).then(|| cells[3].to_string())
        })
        .next()
        .unwrap_or_else(|| panic!("docs/protocol.md has no QoS row {setting:?}"))
}

#[test]
fn the_protocol_doc_qos_table_states_the_protocols_constants() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/protocol.md"))
        .expect("docs/protocol.md");
    let ports = format!("{QOS_MAX_SUBSCRIBERS} / {QOS_MAX_PUBLISHERS} / {QOS_MAX_NODES}");
    for (setting, want) in [
        (
            "subscriber max buffer size",
            QOS_SUBSCRIBER_BUFFER.to_string(),
        ),
        (
            "subscriber max borrowed samples",
            QOS_SUBSCRIBER_BORROWED.to_string(),
        ),
        ("history size", QOS_HISTORY.to_string()),
        ("safe overflow", "on".to_string()),
        ("max subscribers / publishers / nodes", ports.clone()),
        ("max listeners / notifiers / nodes", ports),
        (
            "user header type",
            format!(
                "`DearFrameHeader`, size {}, alignment {}",
                std::mem::size_of::<dear_proto::FrameHeader>(),
                std::mem::align_of::<dear_proto::FrameHeader>()
            ),
        ),
    ] {
        assert_eq!(documented_value(&doc, setting), want, "{setting}");
    }
}
