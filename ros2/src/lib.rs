//! `dear-ros2`: a ROS 2 bridge for deard. It subscribes to a deard frame service (zero-copy,
//! through `dear-client`) and publishes each frame as ROS 2 topics over DDS with RustDDS, a
//! pure-Rust DDS: no ROS install is needed to build or run it, and ROS 2 nodes (any RMW that
//! speaks DDS: Fast DDS, Cyclone DDS, Connext) receive the messages as their own.
//!
//! - [`msg`]: the ROS 2 message types (`sensor_msgs/Image`, `CameraInfo`, `PointCloud2`) as
//!   serde structs in their DDS (CDR) layout;
//! - [`convert`]: a frame's planes as those messages;
//! - [`bridge`]: the DDS participant, topics and writers (sensor-data QoS).
//!
//! docs/ros2.md has the topics, options and figures.

pub mod bridge;
pub mod convert;
pub mod msg;
