//! V4L2 nodes: what each `/dev/video*` offers ([`describe`], [`list`]), and opening one for
//! capture with a requested format ([`open`]) whose error lists what the node offers instead.

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

use v4l::capability::Flags as CapFlags;
use v4l::control::{Control, Type as ControlType, Value};
use v4l::frameinterval::FrameIntervalEnum;
use v4l::framesize::FrameSizeEnum;
use v4l::video::Capture;
use v4l::{Device, FourCC, Fraction};

/// One V4L2 node and what it offers.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeInfo {
    pub path: PathBuf,
    /// Kernel driver (`uvcvideo`, `vivid`, `unicam`, …).
    pub driver: String,
    /// Device name as the driver reports it.
    pub card: String,
    /// Bus location (`usb-0000:00:14.0-1`, `platform:vivid-000`, …).
    pub bus: String,
    /// Whether the node captures video (single-planar). Metadata and output nodes are listed
    /// but cannot be opened for capture.
    pub capture: bool,
    /// Capture formats (empty when `capture` is false).
    pub formats: Vec<FormatInfo>,
    pub controls: Vec<ControlInfo>,
}

/// A pixel format and the sizes a node offers it in.
#[derive(Debug, Clone, PartialEq)]
pub struct FormatInfo {
    /// FourCC as four characters (`"Z16 "`, `"YUYV"`).
    pub fourcc: String,
    pub description: String,
    pub sizes: Vec<SizeInfo>,
}

/// A frame size and its frame rates.
#[derive(Debug, Clone, PartialEq)]
pub enum SizeInfo {
    Discrete {
        width: u32,
        height: u32,
        /// Frames per second, as offered (discrete intervals) — empty when the node does not
        /// enumerate intervals.
        fps: Vec<f64>,
    },
    /// A range of sizes (`min..=max` in `step`s).
    Stepwise {
        min: (u32, u32),
        max: (u32, u32),
        step: (u32, u32),
    },
}

/// A control: its name is what the configuration uses (`[capture.v4l.*.controls]`).
#[derive(Debug, Clone, PartialEq)]
pub struct ControlInfo {
    pub id: u32,
    pub name: String,
    /// `integer`, `boolean`, `menu`, `button`, …
    pub kind: String,
    pub minimum: i64,
    pub maximum: i64,
    pub step: u64,
    pub default: i64,
}

/// What went wrong talking to a node.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    #[error("{}: no such device", path.display())]
    NotFound { path: PathBuf },
    #[error(
        "{}: permission denied (is this user in the device's group? `ls -l {0}`; usually \
         `sudo usermod -aG video $USER`, then log in again)",
        path.display()
    )]
    PermissionDenied { path: PathBuf },
    #[error("{}: device is busy (another program is streaming from it: `fuser -v {0}`)", path.display())]
    Busy { path: PathBuf },
    #[error("{}: the device is gone (unplugged or its driver unbound)", path.display())]
    Gone { path: PathBuf },
    #[error("{}: {what}: {source}", path.display())]
    Io {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: io::Error,
    },
    #[error("{}: {driver} node {card:?} does not capture video", path.display())]
    NotCapture {
        path: PathBuf,
        driver: String,
        card: String,
    },
    #[error("{}: {card:?} does not offer {wanted}; it offers: {offered}", path.display())]
    FormatNotOffered {
        path: PathBuf,
        card: String,
        wanted: String,
        offered: String,
    },
    #[error("{}: asked for {wanted}, the driver set {got}", path.display())]
    FormatRefused {
        path: PathBuf,
        wanted: String,
        got: String,
    },
    #[error("{}: control {name:?} does not exist; the node has: {offered}", path.display())]
    NoSuchControl {
        path: PathBuf,
        name: String,
        offered: String,
    },
    #[error("{}: control {name:?} = {value} is outside {minimum}..={maximum}", path.display())]
    ControlOutOfRange {
        path: PathBuf,
        name: String,
        value: i64,
        minimum: i64,
        maximum: i64,
    },
}

impl DeviceError {
    /// Maps an I/O error of `what` on `path` to the variant that says what happened.
    pub fn from_io(path: &Path, what: &'static str, source: io::Error) -> Self {
        let path = path.to_path_buf();
        match source.raw_os_error() {
            Some(libc::ENOENT) => DeviceError::NotFound { path },
            Some(libc::EACCES) | Some(libc::EPERM) => DeviceError::PermissionDenied { path },
            Some(libc::EBUSY) => DeviceError::Busy { path },
            Some(libc::ENODEV) | Some(libc::ENXIO) => DeviceError::Gone { path },
            _ => DeviceError::Io { path, what, source },
        }
    }

    /// Whether the node may come back (unplugged, driver reloaded, I/O error): a live source
    /// retries these with backoff; the others are configuration errors.
    pub fn is_transient(&self) -> bool {
        match self {
            DeviceError::NotFound { .. } | DeviceError::Gone { .. } | DeviceError::Busy { .. } => {
                true
            }
            DeviceError::Io { source, .. } => source.raw_os_error() == Some(libc::EIO),
            _ => false,
        }
    }
}

/// The `/dev/video*` nodes in name order (`video2` before `video10`).
pub fn node_paths() -> Vec<PathBuf> {
    node_paths_in(Path::new("/dev"))
}

fn node_paths_in(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut nodes: Vec<(u32, PathBuf)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let n = name.strip_prefix("video")?.parse::<u32>().ok()?;
            Some((n, e.path()))
        })
        .collect();
    nodes.sort();
    nodes.into_iter().map(|(_, p)| p).collect()
}

/// Every node under `/dev`, each described or with the error that stopped it.
pub fn list() -> Vec<(PathBuf, Result<NodeInfo, DeviceError>)> {
    node_paths()
        .into_iter()
        .map(|p| {
            let info = describe(&p);
            (p, info)
        })
        .collect()
}

/// Opens `path` (non-blocking, as streaming needs) with errors that name the node.
pub(crate) fn open_device(path: &Path) -> Result<Device, DeviceError> {
    Device::with_path(path).map_err(|e| DeviceError::from_io(path, "open", e))
}

/// What one node offers: driver, formats with sizes and rates, controls.
pub fn describe(path: &Path) -> Result<NodeInfo, DeviceError> {
    let dev = open_device(path)?;
    describe_open(path, &dev)
}

fn describe_open(path: &Path, dev: &Device) -> Result<NodeInfo, DeviceError> {
    let io = |what: &'static str| move |e: io::Error| DeviceError::from_io(path, what, e);
    let caps = dev.query_caps().map_err(io("VIDIOC_QUERYCAP"))?;
    let capture = caps.capabilities.contains(CapFlags::VIDEO_CAPTURE);
    let mut formats = Vec::new();
    if capture {
        for f in Capture::enum_formats(dev).map_err(io("VIDIOC_ENUM_FMT"))? {
            let sizes = sizes_of(dev, f.fourcc);
            formats.push(FormatInfo {
                fourcc: fourcc_text(f.fourcc),
                description: f.description,
                sizes,
            });
        }
    }
    // A node without controls answers the query with an error on some drivers: no controls.
    let controls = dev
        .query_controls()
        .unwrap_or_default()
        .into_iter()
        .filter(|c| !matches!(c.typ, ControlType::CtrlClass))
        .map(|c| ControlInfo {
            id: c.id,
            name: control_key(&c.name),
            kind: format!("{:?}", c.typ).to_lowercase(),
            minimum: c.minimum,
            maximum: c.maximum,
            step: c.step,
            default: c.default,
        })
        .collect();
    Ok(NodeInfo {
        path: path.to_path_buf(),
        driver: caps.driver,
        card: caps.card,
        bus: caps.bus,
        capture,
        formats,
        controls,
    })
}

fn sizes_of(dev: &Device, fourcc: FourCC) -> Vec<SizeInfo> {
    let Ok(sizes) = Capture::enum_framesizes(dev, fourcc) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for s in sizes {
        match s.size {
            FrameSizeEnum::Discrete(d) => {
                let fps = Capture::enum_frameintervals(dev, fourcc, d.width, d.height)
                    .unwrap_or_default()
                    .into_iter()
                    .filter_map(|i| match i.interval {
                        FrameIntervalEnum::Discrete(f) => rate(f),
                        FrameIntervalEnum::Stepwise(s) => rate(s.min),
                    })
                    .collect();
                out.push(SizeInfo::Discrete {
                    width: d.width,
                    height: d.height,
                    fps,
                });
            }
            FrameSizeEnum::Stepwise(s) => out.push(SizeInfo::Stepwise {
                min: (s.min_width, s.min_height),
                max: (s.max_width, s.max_height),
                step: (s.step_width, s.step_height),
            }),
        }
    }
    out
}

/// Frames per second of a frame interval (`None` for a zero interval).
fn rate(interval: Fraction) -> Option<f64> {
    (interval.numerator > 0).then(|| interval.denominator as f64 / interval.numerator as f64)
}

/// A FourCC as its four characters (non-printable bytes as `?`).
pub fn fourcc_text(f: FourCC) -> String {
    f.repr
        .iter()
        .map(|&b| {
            if b.is_ascii_graphic() || b == b' ' {
                b as char
            } else {
                '?'
            }
        })
        .collect()
}

/// The configuration key of a control: its driver name lower-cased with runs of other
/// characters as `_` (`"Exposure Time, Absolute"` → `exposure_time_absolute`), the form
/// `v4l2-ctl --list-ctrls` prints.
pub fn control_key(name: &str) -> String {
    let mut key = String::new();
    for c in name.chars() {
        if c.is_ascii_alphanumeric() {
            key.push(c.to_ascii_lowercase());
        } else if !key.ends_with('_') {
            key.push('_');
        }
    }
    key.trim_matches('_').to_string()
}

/// A capture format to ask a node for.
#[derive(Debug, Clone, PartialEq)]
pub struct FormatRequest {
    /// Four characters, space-padded (`"Z16 "`, `"Y12 "`).
    pub fourcc: [u8; 4],
    pub width: u32,
    pub height: u32,
    /// Frames per second; `None` keeps the node's current rate.
    pub fps: Option<u32>,
}

impl fmt::Display for FormatRequest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:?} {}x{}",
            fourcc_text(FourCC::new(&self.fourcc)),
            self.width,
            self.height
        )?;
        if let Some(fps) = self.fps {
            write!(f, " at {fps} fps")?;
        }
        Ok(())
    }
}

/// The format a node was set to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Negotiated {
    pub fourcc: [u8; 4],
    pub width: u32,
    pub height: u32,
    /// Bytes per line (may exceed the width times the bytes per pixel).
    pub stride: u32,
    /// Bytes of one buffer's image.
    pub size: u32,
    /// Frames per second the driver reports after the request (`None`: it did not say).
    pub fps: Option<f64>,
}

/// Opens `path` for capture in the requested format: the node must offer the FourCC and the
/// size (the error lists what it offers instead); the frame rate is asked for and the
/// driver's answer reported.
pub fn open(path: &Path, want: &FormatRequest) -> Result<(Device, Negotiated), DeviceError> {
    let dev = open_device(path)?;
    let info = describe_open(path, &dev)?;
    if !info.capture {
        return Err(DeviceError::NotCapture {
            path: path.to_path_buf(),
            driver: info.driver,
            card: info.card,
        });
    }
    let fourcc = fourcc_text(FourCC::new(&want.fourcc));
    let offered = info.formats.iter().find(|f| f.fourcc == fourcc);
    let size_ok = offered.is_some_and(|f| {
        f.sizes.is_empty()
            || f.sizes.iter().any(|s| match *s {
                SizeInfo::Discrete { width, height, .. } => {
                    (width, height) == (want.width, want.height)
                }
                SizeInfo::Stepwise { min, max, step } => {
                    (min.0..=max.0).contains(&want.width)
                        && (min.1..=max.1).contains(&want.height)
                        && (want.width - min.0).is_multiple_of(step.0.max(1))
                        && (want.height - min.1).is_multiple_of(step.1.max(1))
                }
            })
    });
    if !size_ok {
        return Err(DeviceError::FormatNotOffered {
            path: path.to_path_buf(),
            card: info.card.clone(),
            wanted: want.to_string(),
            offered: offered_text(&info.formats),
        });
    }
    let io = |what: &'static str| move |e: io::Error| DeviceError::from_io(path, what, e);
    let mut fmt = Capture::format(&dev).map_err(io("VIDIOC_G_FMT"))?;
    fmt.width = want.width;
    fmt.height = want.height;
    fmt.fourcc = FourCC::new(&want.fourcc);
    let set = Capture::set_format(&dev, &fmt).map_err(io("VIDIOC_S_FMT"))?;
    if (set.width, set.height, set.fourcc) != (want.width, want.height, fmt.fourcc) {
        return Err(DeviceError::FormatRefused {
            path: path.to_path_buf(),
            wanted: want.to_string(),
            got: format!("{:?} {}x{}", fourcc_text(set.fourcc), set.width, set.height),
        });
    }
    let mut fps = None;
    if let Some(rate_wanted) = want.fps {
        let params = v4l::video::capture::Parameters::with_fps(rate_wanted);
        // Drivers without frame-rate control (vivid's some inputs, many MIPI bridges) refuse
        // the request: the stream still runs at the sensor's rate, which the log reports.
        if let Ok(p) = Capture::set_params(&dev, &params) {
            fps = rate(p.interval);
        }
    } else if let Ok(p) = Capture::params(&dev) {
        fps = rate(p.interval);
    }
    Ok((
        dev,
        Negotiated {
            fourcc: set.fourcc.repr,
            width: set.width,
            height: set.height,
            stride: set.stride,
            size: set.size,
            fps,
        },
    ))
}

/// `"Z16 " 640x480 (30, 15 fps), 320x240; "YUYV" …` — what a node offers, for errors.
pub fn offered_text(formats: &[FormatInfo]) -> String {
    if formats.is_empty() {
        return "no capture formats".into();
    }
    formats
        .iter()
        .map(|f| {
            let sizes: Vec<String> = f.sizes.iter().map(|s| s.to_string()).collect();
            if sizes.is_empty() {
                format!("{:?}", f.fourcc)
            } else {
                format!("{:?} {}", f.fourcc, sizes.join(", "))
            }
        })
        .collect::<Vec<_>>()
        .join("; ")
}

impl fmt::Display for SizeInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SizeInfo::Discrete { width, height, fps } => {
                write!(f, "{width}x{height}")?;
                if !fps.is_empty() {
                    let rates: Vec<String> = fps.iter().map(|r| format!("{r:.4}")).collect();
                    let rates: Vec<&str> = rates
                        .iter()
                        .map(|r| r.trim_end_matches('0').trim_end_matches('.'))
                        .collect();
                    write!(f, " ({} fps)", rates.join(", "))?;
                }
                Ok(())
            }
            SizeInfo::Stepwise { min, max, step } => write!(
                f,
                "{}x{} to {}x{} in steps of {}x{}",
                min.0, min.1, max.0, max.1, step.0, step.1
            ),
        }
    }
}

/// Sets controls by their configuration key ([`control_key`]); each value is checked against
/// the control's range first, so a typo or an out-of-range value is an error naming it.
pub fn set_controls(
    path: &Path,
    dev: &Device,
    controls: &[(String, i64)],
) -> Result<(), DeviceError> {
    if controls.is_empty() {
        return Ok(());
    }
    let available = dev
        .query_controls()
        .map_err(|e| DeviceError::from_io(path, "VIDIOC_QUERYCTRL", e))?;
    for (name, value) in controls {
        let Some(desc) = available.iter().find(|c| control_key(&c.name) == *name) else {
            let offered: Vec<String> = available
                .iter()
                .filter(|c| !matches!(c.typ, ControlType::CtrlClass))
                .map(|c| control_key(&c.name))
                .collect();
            return Err(DeviceError::NoSuchControl {
                path: path.to_path_buf(),
                name: name.clone(),
                offered: offered.join(", "),
            });
        };
        if *value < desc.minimum || *value > desc.maximum {
            return Err(DeviceError::ControlOutOfRange {
                path: path.to_path_buf(),
                name: name.clone(),
                value: *value,
                minimum: desc.minimum,
                maximum: desc.maximum,
            });
        }
        let value = match desc.typ {
            ControlType::Boolean => Value::Boolean(*value != 0),
            _ => Value::Integer(*value),
        };
        dev.set_control(Control { id: desc.id, value })
            .map_err(|e| DeviceError::from_io(path, "VIDIOC_S_CTRL", e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_keys_are_the_lower_case_words_joined_by_underscores() {
        assert_eq!(
            control_key("Exposure Time, Absolute"),
            "exposure_time_absolute"
        );
        assert_eq!(control_key("Loop Video"), "loop_video");
        assert_eq!(control_key("  Gain "), "gain");
    }

    #[test]
    fn nodes_are_listed_in_numeric_order_and_other_files_are_ignored() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["video10", "video2", "video0", "videox", "media0"] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        let names: Vec<String> = node_paths_in(dir.path())
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["video0", "video2", "video10"]);
    }

    #[test]
    fn errors_say_what_happened_to_the_node() {
        let p = Path::new("/dev/video7");
        let e = |n| DeviceError::from_io(p, "open", io::Error::from_raw_os_error(n));
        assert!(matches!(e(2), DeviceError::NotFound { .. }));
        let denied = e(13);
        assert!(denied.to_string().contains("usermod -aG video"), "{denied}");
        assert!(e(16).to_string().contains("busy"));
        assert!(e(19).to_string().contains("gone"));
        assert!(e(19).is_transient() && e(5).is_transient() && !e(13).is_transient());
    }

    #[test]
    fn a_missing_node_is_named() {
        let err = describe(Path::new("/dev/video-does-not-exist")).unwrap_err();
        assert!(matches!(err, DeviceError::NotFound { .. }), "{err}");
        assert!(err.to_string().contains("/dev/video-does-not-exist"));
    }

    #[test]
    fn offered_formats_read_as_a_list() {
        let formats = vec![
            FormatInfo {
                fourcc: "Z16 ".into(),
                description: "16-bit depth".into(),
                sizes: vec![
                    SizeInfo::Discrete {
                        width: 640,
                        height: 480,
                        fps: vec![30.0, 15.0],
                    },
                    SizeInfo::Discrete {
                        width: 320,
                        height: 240,
                        fps: vec![],
                    },
                ],
            },
            FormatInfo {
                fourcc: "YUYV".into(),
                description: String::new(),
                sizes: vec![SizeInfo::Stepwise {
                    min: (16, 16),
                    max: (1920, 1080),
                    step: (2, 2),
                }],
            },
        ];
        assert_eq!(
            offered_text(&formats),
            "\"Z16 \" 640x480 (30, 15 fps), 320x240; \"YUYV\" 16x16 to 1920x1080 in steps of 2x2"
        );
    }
}
