//! A deard frame's planes as ROS 2 messages (REP 118 depth images, REP 103 optical frame: x
//! right, y down, z forward).

use dear_capture::is_valid_depth;
use dear_client::{CameraIntrinsics, Rays};

use crate::msg::{
    CameraInfo, Header, Image, PointCloud2, PointField, RegionOfInterest, Time, FLOAT32,
};

/// How the depth image is encoded (REP 118 allows both).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthEncoding {
    /// `16UC1`: millimetres, 0 = invalid; what `dear dump` and `dear record` store.
    #[value(name = "16UC1")]
    Mm16,
    /// `32FC1`: metres, NaN = invalid.
    #[value(name = "32FC1")]
    M32,
}

impl DepthEncoding {
    pub fn name(self) -> &'static str {
        match self {
            DepthEncoding::Mm16 => "16UC1",
            DepthEncoding::M32 => "32FC1",
        }
    }
}

/// One frame's planes, borrowed from shared memory (or a test).
pub struct Planes<'a> {
    pub width: u32,
    pub height: u32,
    /// Metres, row-major, 0 or non-finite = invalid.
    pub depth: &'a [f32],
    /// `width·height·3` bytes, R, G, B.
    pub rgb: &'a [u8],
    /// `width·height` bytes.
    pub confidence: &'a [u8],
    /// The RGB camera's intrinsics the frame header carries (format 3), if any.
    pub intrinsics: Option<CameraIntrinsics>,
}

/// The `std_msgs/Header` of every message of a frame.
pub fn header(capture_timestamp_ns: u64, frame_id: &str) -> Header {
    Header {
        stamp: Time::from_ns(capture_timestamp_ns),
        frame_id: frame_id.to_string(),
    }
}

/// Millimetres as `dear dump` writes them (`dear_capture::png::depth_to_u16` with the 1 mm
/// scale): `round(z / 0.001)` saturated to 16 bits; invalid depth → 0.
#[inline]
pub fn depth_mm(z: f32) -> u16 {
    if is_valid_depth(z) {
        (z / 0.001).round().clamp(0.0, 65535.0) as u16
    } else {
        0
    }
}

/// The depth image in the given encoding (little endian).
pub fn depth_image(p: &Planes, encoding: DepthEncoding, header: Header) -> Image {
    let (bytes_per_px, data) = match encoding {
        DepthEncoding::Mm16 => {
            let mut data = Vec::with_capacity(p.depth.len() * 2);
            data.extend(p.depth.iter().flat_map(|&z| depth_mm(z).to_le_bytes()));
            (2, data)
        }
        DepthEncoding::M32 => {
            let mut data = Vec::with_capacity(p.depth.len() * 4);
            data.extend(p.depth.iter().flat_map(|&z| {
                let m = if is_valid_depth(z) { z } else { f32::NAN };
                m.to_le_bytes()
            }));
            (4, data)
        }
    };
    Image {
        header,
        height: p.height,
        width: p.width,
        encoding: encoding.name().to_string(),
        is_bigendian: 0,
        step: p.width * bytes_per_px,
        data,
    }
}

/// The colour image, `rgb8`.
pub fn rgb_image(p: &Planes, header: Header) -> Image {
    Image {
        header,
        height: p.height,
        width: p.width,
        encoding: "rgb8".to_string(),
        is_bigendian: 0,
        step: p.width * 3,
        data: p.rgb.to_vec(),
    }
}

/// The confidence image, `mono8` (0 = invalid, 255 = most confident).
pub fn confidence_image(p: &Planes, header: Header) -> Image {
    Image {
        header,
        height: p.height,
        width: p.width,
        encoding: "mono8".to_string(),
        is_bigendian: 0,
        step: p.width,
        data: p.confidence.to_vec(),
    }
}

/// The RGB camera's calibration (the depth is aligned to it, so depth and colour share it):
/// `plumb_bob` with the Brown–Conrady D the header carries (zero for a pinhole), R the
/// identity, P = [K | 0] (the images are published as captured, not rectified).
pub fn camera_info(width: u32, height: u32, k: &CameraIntrinsics, header: Header) -> CameraInfo {
    let (fx, fy, cx, cy) = (k.fx as f64, k.fy as f64, k.cx as f64, k.cy as f64);
    CameraInfo {
        header,
        height,
        width,
        distortion_model: "plumb_bob".to_string(),
        d: k.distortion.unwrap_or_default().map(f64::from).to_vec(),
        k: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

/// The organised point cloud (height × width points, row-major like the image): `x, y, z`
/// float32 in metres in the optical frame, back-projected by the client SDK's `Rays` (the one
/// definition every SDK uses: pinhole, distortion undone), and with `with_rgb` the ROS `rgb`
/// field (a float32 whose bytes are B, G, R, 0, as PCL packs it). Invalid depth gives NaN x,
/// y, z (`is_dense` false). `rays` must be of the frame's size.
pub fn point_cloud(p: &Planes, rays: &Rays, with_rgb: bool, header: Header) -> PointCloud2 {
    let (w, h) = (p.width as usize, p.height as usize);
    let point_step: usize = if with_rgb { 16 } else { 12 };
    let field = |name: &str, offset: u32| PointField {
        name: name.to_string(),
        offset,
        datatype: FLOAT32,
        count: 1,
    };
    let mut fields = vec![field("x", 0), field("y", 4), field("z", 8)];
    if with_rgb {
        fields.push(field("rgb", 12));
    }
    assert_eq!(rays.size(), (w, h), "rays of another size than the frame");
    let mut data = vec![0u8; w * h * point_step];
    for (v, row) in data.chunks_exact_mut(w * point_step).enumerate() {
        for (u, point) in row.chunks_exact_mut(point_step).enumerate() {
            let i = v * w + u;
            let xyz = rays.point(i, p.depth[i]).unwrap_or([f32::NAN; 3]);
            point[0..4].copy_from_slice(&xyz[0].to_le_bytes());
            point[4..8].copy_from_slice(&xyz[1].to_le_bytes());
            point[8..12].copy_from_slice(&xyz[2].to_le_bytes());
            if with_rgb {
                let i = (v * w + u) * 3;
                point[12..16].copy_from_slice(&[p.rgb[i + 2], p.rgb[i + 1], p.rgb[i], 0]);
            }
        }
    }
    PointCloud2 {
        header,
        height: p.height,
        width: p.width,
        fields,
        is_bigendian: false,
        point_step: point_step as u32,
        row_step: (w * point_step) as u32,
        data,
        is_dense: false,
    }
}

/// A ROS 2 name token from any text: characters other than ASCII letters, digits and `_`
/// become `_`, and a token that would start with a digit gets a leading `_` (ROS 2 names allow
/// neither).
pub fn ros_token(s: &str) -> String {
    let mut t: String = s
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if t.is_empty() || t.starts_with(|c: char| c.is_ascii_digit()) {
        t.insert(0, '_');
    }
    t
}

/// The topics' namespace and the camera's name from a deard service name, as `dear record
/// --mcap` names its topics: `dear/cam0/frames` → (`/dear/cam0`, `cam0`). Each part is made a
/// valid ROS 2 name token ([`ros_token`]).
pub fn namespace_for_service(service: &str) -> (String, String) {
    let base = service.strip_suffix("/frames").unwrap_or(service);
    let tokens: Vec<String> = base
        .split('/')
        .filter(|t| !t.is_empty())
        .map(ros_token)
        .collect();
    let camera = tokens
        .last()
        .cloned()
        .unwrap_or_else(|| "camera".to_string());
    (format!("/{}", tokens.join("/")), camera)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::ArrayView2;

    fn planes<'a>(depth: &'a [f32], rgb: &'a [u8], confidence: &'a [u8]) -> Planes<'a> {
        Planes {
            width: 3,
            height: 2,
            depth,
            rgb,
            confidence,
            intrinsics: None,
        }
    }

    #[test]
    fn depth_mm_is_what_dump_writes() {
        let depth = [
            0.0,
            1.0,
            0.0015,
            0.0025,
            65.535,
            70.0,
            -1.0,
            f32::NAN,
            f32::INFINITY,
            1.234_567,
            0.000_49,
            3.999_5,
        ];
        let dump =
            dear_capture::png::depth_to_u16(ArrayView2::from_shape((3, 4), &depth).unwrap(), 0.001);
        let ours: Vec<u16> = depth.iter().map(|&z| depth_mm(z)).collect();
        assert_eq!(ours, dump.iter().copied().collect::<Vec<_>>());
        assert_eq!(ours[1], 1000);
        assert_eq!(ours[5], 65535);
        assert_eq!(ours[7], 0);
    }

    #[test]
    fn depth_images_in_both_encodings() {
        let depth = [1.0, 0.0, 2.5, f32::NAN, 0.5, 4.0];
        let p = planes(&depth, &[0; 18], &[0; 6]);
        let mm = depth_image(&p, DepthEncoding::Mm16, header(5_000_000_001, "f"));
        assert_eq!(
            (mm.encoding.as_str(), mm.step, mm.data.len()),
            ("16UC1", 6, 12)
        );
        assert_eq!(&mm.data[0..6], &[0xe8, 0x03, 0, 0, 0xc4, 0x09]);
        assert_eq!(mm.header.stamp, Time { sec: 5, nanosec: 1 });
        let m = depth_image(&p, DepthEncoding::M32, header(0, "f"));
        assert_eq!(
            (m.encoding.as_str(), m.step, m.data.len()),
            ("32FC1", 12, 24)
        );
        assert_eq!(f32::from_le_bytes(m.data[8..12].try_into().unwrap()), 2.5);
        assert!(f32::from_le_bytes(m.data[4..8].try_into().unwrap()).is_nan());
    }

    #[test]
    fn point_cloud_back_projects() {
        let depth = [2.0, 0.0, 2.0, 2.0, 2.0, 1.0];
        let rgb: Vec<u8> = (0..18).collect();
        let p = planes(&depth, &rgb, &[0; 6]);
        let k = CameraIntrinsics::pinhole(2.0, 4.0, 1.0, 0.0);
        let rays = Rays::new(&k, 3, 2).unwrap();
        let cloud = point_cloud(&p, &rays, true, header(0, "f"));
        assert_eq!(
            (cloud.width, cloud.height, cloud.point_step, cloud.row_step),
            (3, 2, 16, 48)
        );
        let xyz = |i: usize| -> [f32; 3] {
            let b = &cloud.data[i * 16..];
            [0, 4, 8].map(|o| f32::from_le_bytes(b[o..o + 4].try_into().unwrap()))
        };
        assert_eq!(xyz(0), [-1.0, 0.0, 2.0]);
        assert!(xyz(1).iter().all(|v| v.is_nan()));
        assert_eq!(xyz(5), [0.5, 0.25, 1.0]);
        assert_eq!(&cloud.data[5 * 16 + 12..5 * 16 + 16], &[17, 16, 15, 0]);
        let names: Vec<&str> = cloud.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["x", "y", "z", "rgb"]);
        let plain = point_cloud(&p, &rays, false, header(0, "f"));
        assert_eq!(
            (plain.point_step, plain.data.len(), plain.fields.len()),
            (12, 72, 3)
        );
    }

    #[test]
    fn camera_info_carries_k() {
        let k = CameraIntrinsics::pinhole(500.0, 510.0, 319.5, 239.5);
        let info = camera_info(640, 480, &k, header(0, "f"));
        assert_eq!(
            info.k,
            [500.0, 0.0, 319.5, 0.0, 510.0, 239.5, 0.0, 0.0, 1.0]
        );
        assert_eq!(info.p[..4], [500.0, 0.0, 319.5, 0.0]);
        assert_eq!(info.distortion_model, "plumb_bob");
        assert_eq!(info.d, [0.0; 5]);
        // The header's Brown–Conrady coefficients are D.
        let distorted = CameraIntrinsics {
            distortion: Some([0.5, -0.25, 0.125, 0.0, 1.0]),
            ..k
        };
        let info = camera_info(640, 480, &distorted, header(0, "f"));
        assert_eq!(info.d, [0.5, -0.25, 0.125, 0.0, 1.0]);
    }

    #[test]
    fn names_follow_ros_rules() {
        assert_eq!(
            namespace_for_service("dear/cam0/frames"),
            ("/dear/cam0".to_string(), "cam0".to_string())
        );
        assert_eq!(
            namespace_for_service("dear-test/123/ros2/frames"),
            ("/dear_test/_123/ros2".to_string(), "ros2".to_string())
        );
        assert_eq!(ros_token(""), "_");
    }
}
