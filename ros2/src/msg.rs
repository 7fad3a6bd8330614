//! The ROS 2 messages the bridge publishes, as serde structs whose CDR encoding (RustDDS's
//! `CDRSerializerAdapter`, little endian) is the one ROS 2's DDS middlewares use: fields in the
//! `.msg` order, `string` as a length-prefixed NUL-terminated string, `T[]` as a length-prefixed
//! sequence, `T[N]` without a length.

use serde::{Deserialize, Serialize};

/// DDS type names (`<package>::msg::dds_::<Type>_`, what rmw_fastrtps and rmw_cyclonedds
/// register) of the messages below.
pub const IMAGE_TYPE: &str = "sensor_msgs::msg::dds_::Image_";
pub const CAMERA_INFO_TYPE: &str = "sensor_msgs::msg::dds_::CameraInfo_";
pub const POINT_CLOUD2_TYPE: &str = "sensor_msgs::msg::dds_::PointCloud2_";

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// A nanosecond time (seconds saturate at `i32::MAX`, year 2038 for wall-clock stamps).
    pub fn from_ns(ns: u64) -> Time {
        Time {
            sec: (ns / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: u8,
    pub step: u32,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/RegionOfInterest`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    pub x_offset: u32,
    pub y_offset: u32,
    pub height: u32,
    pub width: u32,
    pub do_rectify: bool,
}

/// `sensor_msgs/CameraInfo`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    pub roi: RegionOfInterest,
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

/// `sensor_msgs/PointField.FLOAT32`.
pub const FLOAT32: u8 = 7;

/// `sensor_msgs/PointCloud2`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PointCloud2 {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
    pub is_dense: bool,
}
