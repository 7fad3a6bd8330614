//! `dear devices`: every V4L2 node on this machine with its driver, capture formats, sizes,
//! frame rates and controls — what `[capture.v4l.tof]` / `[capture.v4l.rgb]` can ask for (the
//! role of `v4l2-ctl --list-formats-ext` and `rs-enumerate-devices`).

use std::fmt::Write as _;

use dear_v4l2::device::{self, NodeInfo};
use dear_v4l2::pixel::PixelFormat;

/// Prints every node (or says there is none); a node that cannot be opened is listed with the
/// reason (no permission, busy) instead of being left out.
pub fn run() -> anyhow::Result<()> {
    let nodes = device::list();
    if nodes.is_empty() {
        return super::write_stdout("no V4L2 devices (/dev/video*)\n");
    }
    for (path, info) in nodes {
        match info {
            Ok(info) => super::write_stdout(&describe(&info))?,
            Err(e) => {
                super::write_stdout(&format!("{}: cannot be opened: {e}\n\n", path.display()))?
            }
        }
    }
    Ok(())
}

/// One node as text: a header line, its formats (marked with the role deard decodes them
/// for), then its controls by the names the configuration uses.
pub fn describe(node: &NodeInfo) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{}: {} ({}, {})",
        node.path.display(),
        node.card,
        node.driver,
        node.bus
    );
    if !node.capture {
        let _ = writeln!(out, "  not a video capture node\n");
        return out;
    }
    for f in &node.formats {
        let role = PixelFormat::ALL
            .into_iter()
            .find(|p| p.to_string() == f.fourcc)
            .map_or("not decoded by deard", role_of);
        let _ = writeln!(out, "  format {:?} {} [{role}]", f.fourcc, f.description);
        for s in &f.sizes {
            let _ = writeln!(out, "    {s}");
        }
    }
    if !node.controls.is_empty() {
        let _ = writeln!(out, "  controls:");
        for c in &node.controls {
            let _ = writeln!(
                out,
                "    {} ({}) {}..={} step {} default {}",
                c.name, c.kind, c.minimum, c.maximum, c.step, c.default
            );
        }
    }
    out.push('\n');
    out
}

/// Which `[capture.v4l]` node a format can feed.
fn role_of(format: PixelFormat) -> &'static str {
    match format {
        PixelFormat::Z16 => "tof depth",
        PixelFormat::Y16 => "tof depth or amplitude",
        PixelFormat::Y12 | PixelFormat::Y12P => "tof 4-phase",
        PixelFormat::Grey => "amplitude",
        PixelFormat::Yuyv | PixelFormat::Nv12 | PixelFormat::Rgb3 | PixelFormat::Mjpg => "rgb",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dear_v4l2::device::{ControlInfo, FormatInfo, SizeInfo};

    #[test]
    fn a_node_reads_with_formats_roles_sizes_and_controls() {
        let node = NodeInfo {
            path: "/dev/video0".into(),
            driver: "vivid".into(),
            card: "vivid".into(),
            bus: "platform:vivid-000".into(),
            capture: true,
            formats: vec![
                FormatInfo {
                    fourcc: "Y16 ".into(),
                    description: "16-bit Greyscale".into(),
                    sizes: vec![SizeInfo::Discrete {
                        width: 640,
                        height: 480,
                        fps: vec![25.0],
                    }],
                },
                FormatInfo {
                    fourcc: "HSV3".into(),
                    description: "24-bit HSV".into(),
                    sizes: vec![],
                },
            ],
            controls: vec![ControlInfo {
                id: 0x00980900,
                name: "brightness".into(),
                kind: "integer".into(),
                minimum: 0,
                maximum: 255,
                step: 1,
                default: 128,
            }],
        };
        let text = describe(&node);
        assert_eq!(
            text,
            "/dev/video0: vivid (vivid, platform:vivid-000)\n  format \"Y16 \" 16-bit Greyscale [tof depth or amplitude]\n    640x480 (25 fps)\n  format \"HSV3\" 24-bit HSV [not decoded by deard]\n  controls:\n    brightness (integer) 0..=255 step 1 default 128\n\n"
        );
    }
}
