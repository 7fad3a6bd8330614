//! The MCAP side of `dear record`: channels, the conversion of a frame into Foxglove
//! messages, log times, loss counting and the file's summary. Generic over the output
//! (`Write + Seek`) so that its unit tests run on memory and on a writer that fails.

use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use dear_capture::Intrinsics;
use dear_proto::{CameraIntrinsics, FrameHeader};
use foxglove::bytes::Bytes;
use foxglove::messages::{CameraCalibration, RawImage, Timestamp};
use foxglove::Encode;

/// Depth image encodings `--depth-encoding` offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthEncoding {
    /// `16UC1`: unsigned 16-bit millimetres, 0 = invalid (ROS / OpenCV depth convention).
    #[value(name = "16UC1")]
    Millimetres16,
    /// `32FC1`: the published `f32` metres, bit for bit, 0 = invalid.
    #[value(name = "32FC1")]
    Metres32,
}

impl DepthEncoding {
    /// The `RawImage.encoding` string.
    pub fn name(self) -> &'static str {
        match self {
            DepthEncoding::Millimetres16 => "16UC1",
            DepthEncoding::Metres32 => "32FC1",
        }
    }

    fn unit(self) -> &'static str {
        match self {
            DepthEncoding::Millimetres16 => "mm",
            DepthEncoding::Metres32 => "m",
        }
    }

    fn bytes_per_pixel(self) -> u32 {
        match self {
            DepthEncoding::Millimetres16 => 2,
            DepthEncoding::Metres32 => 4,
        }
    }
}

/// Topic names and the camera frame name, derived from the frame service's name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    pub depth: String,
    pub rgb: String,
    pub confidence: String,
    pub calibration: String,
    /// The header's flow-model calibration and its health (JSON, [`HEALTH_SCHEMA`]).
    pub calibration_health: String,
    /// `frame_id` of every message: the camera's name.
    pub frame_id: String,
}

impl Topics {
    /// `dear/cam0/frames` → `/dear/cam0/{depth,rgb,confidence,calibration}`, frame `cam0`:
    /// the service name without its `/frames` suffix is the topics' prefix, and its last part
    /// the camera's (and so the coordinate frame's) name.
    pub fn for_service(service: &str) -> Topics {
        let base = service.strip_suffix("/frames").unwrap_or(service);
        let base = base.trim_matches('/');
        let frame_id = base.rsplit('/').next().unwrap_or(base).to_string();
        let topic = |leaf: &str| format!("/{base}/{leaf}");
        Topics {
            depth: topic("depth"),
            rgb: topic("rgb"),
            confidence: topic("confidence"),
            calibration: topic("calibration"),
            calibration_health: topic("calibration_health"),
            frame_id,
        }
    }
}

/// The frame's planes, borrowed (from shared memory, or from a test).
pub struct FrameData<'a> {
    pub header: &'a FrameHeader,
    /// Metres, row-major, 0 = invalid.
    pub depth: &'a [f32],
    /// `width·height·3` bytes, R, G, B.
    pub rgb: &'a [u8],
    /// `width·height` bytes, 0 = invalid.
    pub confidence: &'a [u8],
}

/// Turns capture times into MCAP log times that never go back.
///
/// A frame's log time is its `capture_timestamp_ns`, plus an offset that is 0 until the
/// capture clock goes back or stands still, which a looping replay does at every pass and a
/// restarted daemon may do. Readers play messages in log-time order, so two passes with the
/// same times would interleave; instead the offset grows so that the frame follows the previous
/// one by the difference of their publish times (at least 1 ns). The message's own
/// `timestamp` keeps the capture time unchanged.
#[derive(Debug, Default)]
struct LogClock {
    offset: u64,
    last: Option<(u64, u64)>,
    resets: u64,
}

impl LogClock {
    fn log_time(&mut self, capture_ns: u64, publish_ns: u64) -> u64 {
        let mut t = capture_ns.saturating_add(self.offset);
        if let Some((last_log, last_publish)) = self.last {
            if t <= last_log {
                let gap = publish_ns.saturating_sub(last_publish).max(1);
                t = last_log.saturating_add(gap);
                self.offset = t - capture_ns;
                self.resets += 1;
            }
        }
        self.last = Some((t, publish_ns));
        t
    }
}

/// Frames lost between the ones recorded: gaps in `sequence` within one publisher instance
/// (`run_id`); a new `run_id` is a restarted daemon, whose sequence starts again.
#[derive(Debug, Default)]
struct Losses {
    last: Option<(u64, u64)>,
    lost: u64,
    restarts: u64,
}

impl Losses {
    fn see(&mut self, run_id: u64, sequence: u64) {
        match self.last {
            Some((run, last)) if run == run_id => {
                self.lost += sequence.saturating_sub(last).saturating_sub(1);
            }
            Some(_) => self.restarts += 1,
            None => {}
        }
        self.last = Some((run_id, sequence));
    }
}

/// What a finished recording holds (printed by `dear record`, and written into the file as
/// the `dear.record` metadata record).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordSummary {
    pub frames: u64,
    /// Frames the recorder did not receive (sequence gaps).
    pub lost: u64,
    /// How often the publisher changed (`run_id`): daemon restarts during the recording.
    pub restarts: u64,
    /// How often the capture clock went back or stood still (replay loops, restarts).
    pub clock_resets: u64,
    /// 16UC1 pixels beyond 65.535 m written as 65535.
    pub saturated_pixels: u64,
}

/// An MCAP file being written.
pub struct Recorder<W: Write + Seek> {
    writer: mcap::Writer<W>,
    path: PathBuf,
    service: String,
    topics: Topics,
    depth_encoding: DepthEncoding,
    /// `--intrinsics`: used instead of the headers' when given.
    intrinsics: Option<Intrinsics>,
    /// The first header intrinsics recorded, for the summary.
    header_intrinsics: Option<CameraIntrinsics>,
    /// Frames whose calibration message had no intrinsics (K, R, P zero).
    frames_without_intrinsics: u64,
    depth_channel: u16,
    rgb_channel: u16,
    confidence_channel: u16,
    calibration_channel: u16,
    health_channel: u16,
    clock: LogClock,
    losses: Losses,
    frames: u64,
    saturated_pixels: u64,
    buf: Vec<u8>,
}

/// JSON schema of the `calibration_health` messages: per frame, the header's flow-model
/// calibration `W = t/z + c` with its fit figures and health state (docs/calibration-health.md).
pub const HEALTH_SCHEMA: &str = r#"{
  "title": "dear.CalibrationHealth",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "description": "capture time",
      "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "frame_id": {"type": "string"},
    "sequence": {"type": "integer"},
    "health": {"type": "string",
      "enum": ["unknown", "good", "can improve", "needs recalibration"]},
    "health_code": {"type": "integer", "description": "0 unknown, 1 good, 2 can improve, 3 needs recalibration"},
    "constrained_directions": {"type": "integer", "description": "directions of (t_x, t_y, c_x, c_y) the last measurement constrained, 0-4"},
    "t_x": {"type": "number", "description": "px·m"},
    "t_y": {"type": "number", "description": "px·m"},
    "c_x": {"type": "number", "description": "px"},
    "c_y": {"type": "number", "description": "px"},
    "residual_px": {"type": ["number", "null"]},
    "quality": {"type": "number"},
    "age_frames": {"type": "integer"},
    "online": {"type": "boolean"}
  }
}"#;

/// What the `CameraCalibration` messages of frames without intrinsics say.
pub const NO_INTRINSICS_NOTE: &str = "uncalibrated: K, R and P all zero (the ROS and Foxglove \
     convention for an unknown calibration; the frame headers said \"unknown\", \
     rgb_camera_model 0), no distortion model";

impl<W: Write + Seek> Recorder<W> {
    /// Starts the file on `out` (`path` only names it in messages): header, schemas, channels.
    pub fn new(
        out: W,
        path: &Path,
        service: &str,
        depth_encoding: DepthEncoding,
        intrinsics: Option<Intrinsics>,
    ) -> anyhow::Result<Self> {
        let context = || format!("cannot start the MCAP file {}", path.display());
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .library(format!("dear record {}", env!("CARGO_PKG_VERSION")));
        let mut writer = mcap::Writer::with_options(out, options).with_context(context)?;
        let image_schema = RawImage::get_schema().expect("foxglove.RawImage has a schema");
        let calibration_schema =
            CameraCalibration::get_schema().expect("foxglove.CameraCalibration has a schema");
        let image = writer
            .add_schema(
                &image_schema.name,
                &image_schema.encoding,
                &image_schema.data,
            )
            .with_context(context)?;
        let calibration = writer
            .add_schema(
                &calibration_schema.name,
                &calibration_schema.encoding,
                &calibration_schema.data,
            )
            .with_context(context)?;
        let health_schema = writer
            .add_schema(
                "dear.CalibrationHealth",
                "jsonschema",
                HEALTH_SCHEMA.as_bytes(),
            )
            .with_context(context)?;
        let topics = Topics::for_service(service);
        let encoding = RawImage::get_message_encoding();
        let mut channel = |schema: u16, topic: &str, meta: &[(&str, &str)]| {
            let mut metadata: BTreeMap<String, String> = meta
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect();
            metadata.insert("dear.service".into(), service.to_string());
            writer
                .add_channel(schema, topic, &encoding, &metadata)
                .with_context(context)
        };
        let depth_channel = channel(
            image,
            &topics.depth,
            &[
                ("dear.unit", depth_encoding.unit()),
                ("dear.invalid", "0"),
                ("dear.content", "aligned refined depth"),
            ],
        )?;
        let rgb_channel = channel(image, &topics.rgb, &[])?;
        let confidence_channel = channel(
            image,
            &topics.confidence,
            &[(
                "dear.content",
                "0 = invalid, 255 = measured and kept, between = filled or smoothed",
            )],
        )?;
        let calibration_channel = channel(calibration, &topics.calibration, &[])?;
        let health_channel = {
            let metadata: BTreeMap<String, String> = [
                ("dear.service".to_string(), service.to_string()),
                (
                    "dear.content".to_string(),
                    "the header's flow-model calibration W = t/z + c and its health \
                     (docs/calibration-health.md)"
                        .to_string(),
                ),
            ]
            .into_iter()
            .collect();
            writer
                .add_channel(health_schema, &topics.calibration_health, "json", &metadata)
                .with_context(context)?
        };
        Ok(Recorder {
            writer,
            path: path.to_path_buf(),
            service: service.to_string(),
            topics,
            depth_encoding,
            intrinsics,
            header_intrinsics: None,
            frames_without_intrinsics: 0,
            depth_channel,
            rgb_channel,
            confidence_channel,
            calibration_channel,
            health_channel,
            clock: LogClock::default(),
            losses: Losses::default(),
            frames: 0,
            saturated_pixels: 0,
            buf: Vec::new(),
        })
    }

    pub fn topics(&self) -> &Topics {
        &self.topics
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Writes one frame: a message on each of the four channels.
    pub fn add(&mut self, frame: &FrameData<'_>) -> anyhow::Result<()> {
        let h = frame.header;
        let (w, ht) = (h.width, h.height);
        let pixels = w as usize * ht as usize;
        anyhow::ensure!(
            frame.depth.len() == pixels
                && frame.rgb.len() == 3 * pixels
                && frame.confidence.len() == pixels,
            "frame {} of {}x{} has planes of {}, {} and {} values",
            h.sequence,
            w,
            ht,
            frame.depth.len(),
            frame.rgb.len(),
            frame.confidence.len()
        );
        self.losses.see(h.run_id, h.sequence);
        let log_time = self
            .clock
            .log_time(h.capture_timestamp_ns, h.publish_timestamp_ns);
        let message = mcap::records::MessageHeader {
            channel_id: 0,
            // MCAP's sequence is 32 bits: the header's, modulo 2^32.
            sequence: h.sequence as u32,
            log_time,
            publish_time: h.publish_timestamp_ns,
        };
        let stamp = Some(timestamp(h.capture_timestamp_ns));
        let frame_id = self.topics.frame_id.clone();

        let depth = match self.depth_encoding {
            DepthEncoding::Millimetres16 => {
                let mut data = Vec::with_capacity(2 * pixels);
                for &z in frame.depth {
                    let (mm, saturated) = depth_mm(z);
                    self.saturated_pixels += u64::from(saturated);
                    data.extend_from_slice(&mm.to_le_bytes());
                }
                data
            }
            DepthEncoding::Metres32 => frame.depth.iter().flat_map(|z| z.to_le_bytes()).collect(),
        };
        let image = |encoding: &str, bytes_per_pixel: u32, data: Vec<u8>| RawImage {
            timestamp: stamp,
            frame_id: frame_id.clone(),
            width: w,
            height: ht,
            encoding: encoding.to_string(),
            step: w * bytes_per_pixel,
            data: Bytes::from(data),
        };
        let messages = [
            (
                self.depth_channel,
                image(
                    self.depth_encoding.name(),
                    self.depth_encoding.bytes_per_pixel(),
                    depth,
                ),
            ),
            (self.rgb_channel, image("rgb8", 3, frame.rgb.to_vec())),
            (
                self.confidence_channel,
                image("mono8", 1, frame.confidence.to_vec()),
            ),
        ];
        for (channel, msg) in messages {
            self.buf.clear();
            msg.encode(&mut self.buf)
                .context("cannot encode a foxglove.RawImage")?;
            self.write(channel, &message, h.sequence)?;
        }
        // `--intrinsics` overrides; else the header's (format 3); a header without usable ones
        // gives the "uncalibrated" message.
        let intrinsics = match self.intrinsics {
            Some(k) => Some(CameraIntrinsics::pinhole(k.fx, k.fy, k.cx, k.cy)),
            None => h.intrinsics().ok().flatten(),
        };
        match intrinsics {
            None => self.frames_without_intrinsics += 1,
            Some(k) if self.intrinsics.is_none() && self.header_intrinsics.is_none() => {
                self.header_intrinsics = Some(k)
            }
            Some(_) => {}
        }
        let calibration = calibration(h, stamp, frame_id, intrinsics.as_ref());
        self.buf.clear();
        calibration
            .encode(&mut self.buf)
            .context("cannot encode a foxglove.CameraCalibration")?;
        self.write(self.calibration_channel, &message, h.sequence)?;
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, &health_message(h, &self.topics.frame_id))
            .context("cannot encode a calibration health message")?;
        self.write(self.health_channel, &message, h.sequence)?;
        self.frames += 1;
        Ok(())
    }

    fn write(
        &mut self,
        channel_id: u16,
        header: &mcap::records::MessageHeader,
        sequence: u64,
    ) -> anyhow::Result<()> {
        let header = mcap::records::MessageHeader {
            channel_id,
            ..*header
        };
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .with_context(|| {
                format!(
                    "cannot write frame {sequence} to the MCAP file {}",
                    self.path.display()
                )
            })
    }

    /// The counts so far.
    pub fn summary(&self) -> RecordSummary {
        RecordSummary {
            frames: self.frames,
            lost: self.losses.lost,
            restarts: self.losses.restarts,
            clock_resets: self.clock.resets,
            saturated_pixels: self.saturated_pixels,
        }
    }

    /// Writes the `dear.record` metadata record and the summary section (channels, statistics,
    /// chunk and message indexes), so that readers can seek; then flushes. Without this the
    /// file has its messages but no index (readers that scan still read it).
    pub fn finish(mut self) -> anyhow::Result<(RecordSummary, W)> {
        let summary = self.summary();
        let calibration = match (self.intrinsics, self.header_intrinsics) {
            (Some(k), _) => format!(
                "given with --intrinsics: fx={} fy={} cx={} cy={} (pinhole, no distortion)",
                k.fx, k.fy, k.cx, k.cy
            ),
            (None, Some(k)) => format!(
                "from the frame headers (format 3), first: fx={} fy={} cx={} cy={} ({}); {} \
                 frames without intrinsics ({NO_INTRINSICS_NOTE})",
                k.fx,
                k.fy,
                k.cx,
                k.cy,
                match k.distortion {
                    Some(d) => format!("plumb_bob D={d:?}"),
                    None => "pinhole, no distortion".to_string(),
                },
                self.frames_without_intrinsics
            ),
            (None, None) => NO_INTRINSICS_NOTE.to_string(),
        };
        let metadata: BTreeMap<String, String> = [
            ("service", self.service.clone()),
            (
                "recorded_by",
                format!("dear record {}", env!("CARGO_PKG_VERSION")),
            ),
            ("frames", summary.frames.to_string()),
            ("lost_frames", summary.lost.to_string()),
            ("publisher_restarts", summary.restarts.to_string()),
            ("capture_clock_resets", summary.clock_resets.to_string()),
            ("depth_encoding", self.depth_encoding.name().to_string()),
            (
                "depth_saturated_pixels",
                summary.saturated_pixels.to_string(),
            ),
            ("calibration", calibration),
            (
                "log_time",
                "capture_timestamp_ns, offset to stay increasing where the capture clock went \
                 back (replay loops, restarts); the messages' timestamp is the capture time as \
                 published"
                    .to_string(),
            ),
            (
                "publish_time",
                "publish_timestamp_ns (CLOCK_MONOTONIC of the publishing machine)".to_string(),
            ),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        let context = || format!("cannot finish the MCAP file {}", self.path.display());
        self.writer
            .write_metadata(&mcap::records::Metadata {
                name: "dear.record".into(),
                metadata,
            })
            .with_context(context)?;
        self.writer.finish().with_context(context)?;
        let mut out = self.writer.into_inner();
        out.flush().with_context(context)?;
        Ok((summary, out))
    }
}

/// Depth in metres as 16-bit millimetres: 0 stays invalid (so do negative and non-finite
/// values, which deard does not publish), valid depth is at least 1 mm (a positive depth under
/// 0.5 mm must not become "invalid") and at most 65535 mm (`true`: saturated).
fn depth_mm(z: f32) -> (u16, bool) {
    if !dear_capture::is_valid_depth(z) {
        return (0, false);
    }
    let mm = (f64::from(z) * 1000.0).round();
    if mm > f64::from(u16::MAX) {
        (u16::MAX, true)
    } else {
        (mm.max(1.0) as u16, false)
    }
}

/// A nanosecond time as a Foxglove timestamp (seconds saturate at `u32::MAX`, year 2106).
fn timestamp(ns: u64) -> Timestamp {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (ns % 1_000_000_000) as u32)
}

/// The `calibration_health` message of a frame ([`HEALTH_SCHEMA`]).
fn health_message(h: &FrameHeader, frame_id: &str) -> serde_json::Value {
    let health = h.calibration_health();
    serde_json::json!({
        "timestamp": {
            "sec": h.capture_timestamp_ns / 1_000_000_000,
            "nsec": h.capture_timestamp_ns % 1_000_000_000,
        },
        "frame_id": frame_id,
        "sequence": h.sequence,
        "health": health.name(),
        "health_code": health.code(),
        "constrained_directions": h.calib_constrained,
        "t_x": h.calib_tx,
        "t_y": h.calib_ty,
        "c_x": h.calib_cx,
        "c_y": h.calib_cy,
        "residual_px": Some(h.calib_residual_px).filter(|r| r.is_finite()),
        "quality": h.calib_quality,
        "age_frames": h.calib_age_frames,
        "online": h.flags & dear_proto::flags::CALIBRATION_ONLINE != 0,
    })
}

/// The RGB camera's calibration message: K, R and P from the frame header's intrinsics (format
/// 3) or `--intrinsics`, `plumb_bob` with the Brown–Conrady D the header carries (zeros for a
/// pinhole), R the identity and P = [K | 0] (the image is published as captured, not
/// rectified); without intrinsics all zero, which ROS and Foxglove read as "uncalibrated".
/// (The header's `calib_*` fields are the depth-to-RGB flow model `W = t/z + c`, not a camera
/// matrix.)
fn calibration(
    header: &FrameHeader,
    timestamp: Option<Timestamp>,
    frame_id: String,
    intrinsics: Option<&CameraIntrinsics>,
) -> CameraCalibration {
    let (distortion_model, d, k, r, p) = match intrinsics {
        Some(&CameraIntrinsics {
            fx,
            fy,
            cx,
            cy,
            distortion,
        }) => {
            let (fx, fy, cx, cy) = (f64::from(fx), f64::from(fy), f64::from(cx), f64::from(cy));
            (
                "plumb_bob".to_string(),
                distortion.unwrap_or_default().map(f64::from).to_vec(),
                vec![fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                vec![fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
            )
        }
        None => (
            String::new(),
            Vec::new(),
            vec![0.0; 9],
            vec![0.0; 9],
            vec![0.0; 12],
        ),
    };
    CameraCalibration {
        timestamp,
        frame_id,
        width: header.width,
        height: header.height,
        distortion_model,
        d,
        k,
        r,
        p,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    #[test]
    fn topics_come_from_the_service_name() {
        let t = Topics::for_service("dear/cam0/frames");
        assert_eq!(t.depth, "/dear/cam0/depth");
        assert_eq!(t.rgb, "/dear/cam0/rgb");
        assert_eq!(t.confidence, "/dear/cam0/confidence");
        assert_eq!(t.calibration, "/dear/cam0/calibration");
        assert_eq!(t.frame_id, "cam0");
        let t = Topics::for_service("lab/tof");
        assert_eq!(
            (t.depth.as_str(), t.frame_id.as_str()),
            ("/lab/tof/depth", "tof")
        );
    }

    #[test]
    fn millimetres_keep_invalid_and_valid_apart() {
        assert_eq!(depth_mm(0.0), (0, false));
        assert_eq!(depth_mm(f32::NAN), (0, false));
        assert_eq!(depth_mm(-1.0), (0, false));
        assert_eq!(depth_mm(0.0001), (1, false));
        assert_eq!(depth_mm(1.2345), (1235, false)); // f32 1.2345 is 1.23450005
        assert_eq!(depth_mm(65.535), (65535, false));
        assert_eq!(depth_mm(70.0), (65535, true));
    }

    #[test]
    fn log_times_increase_across_a_replay_loop() {
        let mut clock = LogClock::default();
        assert_eq!(clock.log_time(100, 1_000), 100);
        assert_eq!(clock.log_time(200, 1_100), 200);
        // The replay loops: capture time 0 again, 30 ns of publish time later.
        assert_eq!(clock.log_time(0, 1_130), 230);
        assert_eq!(clock.log_time(100, 1_230), 330);
        assert_eq!(clock.resets, 1);
        // Same capture time and publish time: still strictly later.
        assert_eq!(clock.log_time(100, 1_230), 331);
    }

    #[test]
    fn losses_are_sequence_gaps_within_a_run() {
        let mut l = Losses::default();
        for (run, seq) in [(7, 10), (7, 11), (7, 14), (9, 0), (9, 2)] {
            l.see(run, seq);
        }
        assert_eq!((l.lost, l.restarts), (3, 1));
    }

    fn header(sequence: u64, capture_ns: u64) -> FrameHeader {
        let mut h = FrameHeader::new(sequence, 4, 2);
        h.sequence = sequence;
        h.run_id = 1;
        h.capture_timestamp_ns = capture_ns;
        h.publish_timestamp_ns = 1_000 + capture_ns;
        h
    }

    #[test]
    fn the_calibration_comes_from_the_header_unless_overridden() {
        let k = CameraIntrinsics {
            distortion: Some([0.1, -0.2, 0.001, 0.002, 0.05]),
            ..CameraIntrinsics::pinhole(300.0, 310.0, 160.5, 119.5)
        };
        let mut h = header(0, 10);
        h.set_intrinsics(Some(&k));
        let mut rec = Recorder::new(
            Cursor::new(Vec::new()),
            Path::new("mem.mcap"),
            "dear/cam0/frames",
            DepthEncoding::Millimetres16,
            None,
        )
        .unwrap();
        let (depth, rgb, confidence) = (vec![1.0f32; 8], vec![1u8; 24], vec![255u8; 8]);
        let frame = |h| FrameData {
            header: h,
            depth: &depth,
            rgb: &rgb,
            confidence: &confidence,
        };
        rec.add(&frame(&h)).unwrap();
        let unknown = header(1, 20);
        rec.add(&frame(&unknown)).unwrap();
        let (_, out) = rec.finish().unwrap();
        let bytes = out.into_inner();
        let messages: Vec<CameraCalibration> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .filter(|m| m.channel.topic == "/dear/cam0/calibration")
            .map(|m| <CameraCalibration as foxglove::Decode>::decode(&m.data[..]).unwrap())
            .collect();
        assert_eq!(messages.len(), 2);
        let c = &messages[0];
        assert_eq!(c.distortion_model, "plumb_bob");
        assert_eq!(c.k, [300.0, 0.0, 160.5, 0.0, 310.0, 119.5, 0.0, 0.0, 1.0]);
        assert_eq!(
            c.p,
            [300.0, 0.0, 160.5, 0.0, 0.0, 310.0, 119.5, 0.0, 0.0, 0.0, 1.0, 0.0]
        );
        let d: Vec<f32> = c.d.iter().map(|&v| v as f32).collect();
        assert_eq!(d, [0.1, -0.2, 0.001, 0.002, 0.05]);
        // A frame that says "unknown": uncalibrated, never made-up numbers.
        assert_eq!(messages[1].k, [0.0; 9]);
        assert_eq!(messages[1].distortion_model, "");

        // --intrinsics wins over the header.
        let given = Intrinsics {
            fx: 500.0,
            fy: 500.0,
            cx: 1.5,
            cy: 0.5,
        };
        let pinhole = CameraIntrinsics::pinhole(given.fx, given.fy, given.cx, given.cy);
        let c = calibration(&h, None, "cam0".into(), Some(&pinhole));
        assert_eq!(c.k[0], 500.0);
        assert_eq!(c.d, [0.0; 5]);
    }

    #[test]
    fn a_recording_has_five_channels_and_a_summary() {
        let depth = [0.0, 1.0, 2.5, 0.0, 0.25, 3.0, 0.0, 4.0];
        let rgb = [7u8; 24];
        let confidence = [0, 255, 200, 0, 255, 255, 0, 100];
        let mut rec = Recorder::new(
            Cursor::new(Vec::new()),
            Path::new("mem.mcap"),
            "dear/cam0/frames",
            DepthEncoding::Millimetres16,
            None,
        )
        .unwrap();
        for (seq, t) in [(0, 10), (1, 20), (3, 30)] {
            let mut h = header(seq, t);
            h.calib_health = dear_proto::CalibrationHealth::CanImprove.code();
            h.calib_constrained = 2;
            h.calib_cx = 1.5;
            rec.add(&FrameData {
                header: &h,
                depth: &depth,
                rgb: &rgb,
                confidence: &confidence,
            })
            .unwrap();
        }
        let (summary, out) = rec.finish().unwrap();
        assert_eq!((summary.frames, summary.lost), (3, 1));
        let bytes = out.into_inner();
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let topics: Vec<_> = summary.channels.values().map(|c| c.topic.clone()).collect();
        assert_eq!(topics.len(), 5, "{topics:?}");
        let stats = summary.stats.expect("statistics");
        assert_eq!(stats.message_count, 15);
        // The calibration health channel: JSON per frame with the header's state.
        let health = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .find(|m| m.channel.topic == "/dear/cam0/calibration_health")
            .unwrap();
        assert_eq!(health.channel.message_encoding, "json");
        let schema = health.channel.schema.as_ref().unwrap();
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            ("dear.CalibrationHealth", "jsonschema")
        );
        let v: serde_json::Value = serde_json::from_slice(&health.data).unwrap();
        assert_eq!(v["health"], "can improve");
        assert_eq!(v["health_code"], 2);
        assert_eq!(v["constrained_directions"], 2);
        assert_eq!(v["c_x"], 1.5);
        let depth_image = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .find(|m| m.channel.topic == "/dear/cam0/depth")
            .unwrap();
        assert_eq!(depth_image.log_time, 10);
        assert_eq!(depth_image.publish_time, 1_010);
        let image = <RawImage as foxglove::Decode>::decode(&depth_image.data[..]).unwrap();
        assert_eq!((image.width, image.height, image.step), (4, 2, 8));
        assert_eq!(image.encoding, "16UC1");
        let mm: Vec<u16> = image
            .data
            .chunks(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        assert_eq!(mm, [0, 1000, 2500, 0, 250, 3000, 0, 4000]);
    }

    /// A writer that accepts `room` bytes and then fails as a full disk does.
    struct FullDisk {
        inner: Cursor<Vec<u8>>,
        room: usize,
    }

    impl Write for FullDisk {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if self.inner.get_ref().len() + buf.len() > self.room {
                return Err(std::io::Error::from_raw_os_error(28)); // ENOSPC
            }
            self.inner.write(buf)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Seek for FullDisk {
        fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
            self.inner.seek(pos)
        }
    }

    #[test]
    fn a_full_disk_is_reported_with_the_file_name() {
        let out = FullDisk {
            inner: Cursor::new(Vec::new()),
            room: 4096,
        };
        let mut rec = Recorder::new(
            out,
            Path::new("/media/card/x.mcap"),
            "dear/cam0/frames",
            DepthEncoding::Metres32,
            None,
        )
        .unwrap();
        let (depth, rgb, confidence) = (vec![1.0f32; 8], vec![1u8; 24], vec![255u8; 8]);
        let mut error = None;
        for seq in 0..10_000 {
            let h = header(seq, seq * 10);
            let frame = FrameData {
                header: &h,
                depth: &depth,
                rgb: &rgb,
                confidence: &confidence,
            };
            if let Err(e) = rec.add(&frame) {
                error = Some(e);
                break;
            }
        }
        let error = match error {
            Some(e) => e,
            None => rec.finish().err().expect("the disk is full"),
        };
        let text = format!("{error:#}");
        assert!(text.contains("/media/card/x.mcap"), "{text}");
        assert!(text.contains("No space left on device"), "{text}");
    }
}
