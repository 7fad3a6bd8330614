//! `dear-impostor`: a publisher on a frame service that is not deard, for the transport tests
//! (issue 34): `dear-impostor SERVICE` publishes empty 16×12 frames every 20 ms after printing
//! `ready`, until killed. A member of the service's group can run as much.

use std::io::Write;
use std::time::{Duration, Instant};

fn main() {
    let service = std::env::args()
        .nth(1)
        .expect("usage: dear-impostor SERVICE");
    let config = dear_proto::node_config().expect("DEAR_IOX2_ROOT");
    let publisher =
        deard::publish::FramePublisher::new(&config, &service, 16, 12).unwrap_or_else(|e| {
            eprintln!("dear-impostor: {e}");
            std::process::exit(2)
        });
    let mut out = std::io::stdout();
    writeln!(out, "ready").and_then(|()| out.flush()).unwrap();
    for id in 0.. {
        let header = dear_proto::FrameHeader::new(id, 16, 12);
        let fill = |_: &mut dear_proto::FrameHeader, _: deard::processing::FrameOutput<'_>| {
            Ok::<(), std::io::Error>(())
        };
        if let Err(e) = publisher.publish(header, Instant::now(), fill) {
            eprintln!("dear-impostor: {e}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
