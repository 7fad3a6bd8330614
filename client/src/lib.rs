//! `dear-client`: the SDK for applications that consume `deard`'s aligned, refined depth.
//!
//! ```no_run
//! use std::time::Duration;
//! let client = dear_client::Client::connect(&dear_client::default_service_name("cam0"))?;
//! if let Some(frame) = client.wait(Duration::from_secs(1))? {
//!     let h = frame.header();
//!     println!("frame {} {}x{} depth[0] = {} m", h.frame_id, h.width, h.height, frame.depth()[0]);
//! }
//! # Ok::<(), dear_client::ClientError>(())
//! ```
//!
//! Frames are borrowed views into the daemon's shared memory: no copy is made on receive. A
//! [`Frame`] keeps its sample alive; drop it promptly (a subscriber may hold at most
//! [`dear_proto::service::QOS_SUBSCRIBER_BORROWED`] frames at once).

pub mod frame;
pub mod points;
pub mod reconnect;
#[cfg(feature = "images")]
pub mod save;
pub mod sequence;
pub mod subscriber;

pub use dear_proto::{
    camera_model, confidence, default_service_name, flags, CameraIntrinsics, FrameHeader,
    HeaderError, IntrinsicsError, Stage,
};
pub use frame::{Frame, FrameError};
pub use points::{PointCloud, PointCloudError, PointCloudOptions, Rays};
pub use reconnect::{ChannelEvent, ReconnectingClient};
pub use sequence::{SequenceStep, SequenceTracker};
pub use subscriber::{Client, ClientError, ConnectError, ReceiveError};
