//! Live capture from a ToF RGB-D module's two V4L2 nodes (`[capture] source = "v4l"`).
//!
//! Each node streams on its own thread, which decodes its buffers (ToF depth or raw 4-phase
//! frames, RGB in YUYV/NV12/RGB3/MJPG) and hands them over with the driver's timestamp. The
//! source pairs a ToF frame with the RGB frame nearest in time (within half the slower node's
//! period unless configured; unpaired frames are dropped and counted), registers the ToF images
//! onto the RGB grid with the module's calibration file, and yields the frame.
//!
//! A node that goes away while streaming (unplugged, driver unbound: `ENODEV`, `EIO`) is
//! reported, and reopened with backoff until it comes back; the daemon keeps its service, and
//! clients resume receiving when frames flow again. Errors at start (a node missing or busy, no
//! permission, a format the node does not offer) stop the daemon with the node and the reason.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::sync::Arc;
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use dear_capture::{png::quantize_as_stored, Calibration, CaptureManifest, RgbdFrame};
use dear_pipeline::geometry::register::{register_tof, Registration};
use dear_proto::CameraIntrinsics;
use dear_v4l2::device::{DeviceError, FormatRequest};
use dear_v4l2::pair::{Pair, PairCounts, Pairer};
use dear_v4l2::pixel::{self, phase, FrameFormat, PixelFormat};
use dear_v4l2::stream::{Buffer, CaptureStream};
use ndarray::{Array2, Array3};

use super::module::{ModuleCalibration, ModuleCalibrationError};
use super::{sleep_unless, DepthLimit, FrameSource, SourceItem};
use crate::config::{node_format, NodeConfig, QSignConfig, V4lConfig};

/// How long a node's thread waits for a buffer before looking at the stop flag.
const DEQUEUE_TIMEOUT: Duration = Duration::from_millis(200);
/// Reopening a lost node: first wait, and the longest.
const BACKOFF_FIRST: Duration = Duration::from_millis(250);
const BACKOFF_MAX: Duration = Duration::from_secs(5);
/// Decoded frames waiting for the pairing: a couple per node absorbs scheduling jitter.
const CHANNEL_DEPTH: usize = 4;
/// Pairing counts are logged at most this often.
const PAIR_REPORT: Duration = Duration::from_secs(10);
/// Depth is rounded to the capture format's unit (1 mm) before processing, and amplitude to
/// whole units: what `deard --record` writes then replays bit for bit as it was processed.
const STORED_DEPTH_SCALE: f32 = 0.001;

/// Why the live source cannot start.
#[derive(Debug, thiserror::Error)]
pub enum V4lOpenError {
    #[error(transparent)]
    Calibration(#[from] ModuleCalibrationError),
    #[error("[capture.v4l.{role}] {message}")]
    Config { role: &'static str, message: String },
    #[error("[capture.v4l.{role}] {source}")]
    Device {
        role: &'static str,
        #[source]
        source: DeviceError,
    },
}

/// The ToF images of one frame, on the ToF camera's grid.
struct TofImages {
    depth: Array2<f32>,
    /// `None` for a depth format: the amplitude node's image is filled in by the pairing, or
    /// without one [`V4lSource::frame`] uses 1 wherever depth is valid.
    amplitude: Option<Array2<f32>>,
}

/// What a node's thread hands over.
enum NodeMsg {
    Tof {
        ts_us: u64,
        images: TofImages,
    },
    Rgb {
        ts_us: u64,
        rgb: Array3<u8>,
    },
    Amplitude {
        ts_us: u64,
        amplitude: Array2<f32>,
    },
    /// A buffer that could not be decoded (or the driver flagged as corrupt).
    Bad {
        reason: String,
    },
    Lost {
        role: &'static str,
        error: String,
    },
    Back {
        role: &'static str,
    },
}

/// A live module.
pub struct V4lSource {
    rx: Receiver<NodeMsg>,
    pairer: Pairer<TofImages, Array3<u8>>,
    /// With an amplitude node: depth and amplitude of one sensor, paired first (their
    /// timestamps are one exposure's).
    amplitude_pairer: Option<Pairer<TofImages, Array2<f32>>>,
    /// Complete frames waiting to be handed out (one message can complete several).
    ready: VecDeque<Pair<TofImages, Array3<u8>>>,
    registration: Registration,
    size: (u32, u32),
    calibration: Calibration,
    description: String,
    /// What a recording of this module's stream says about it.
    manifest: CaptureManifest,
    /// The calibration file's `[rgb]` intrinsics, distortion included, for the frame header.
    rgb_intrinsics: CameraIntrinsics,
    /// The calibration file's `max_range_m` or the modulation's unambiguous range, the nearer.
    depth_limit: Option<DepthLimit>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    next_index: u64,
    reported: (PairCounts, Instant),
}

/// How a ToF node's buffers become depth and amplitude.
#[derive(Clone, Copy)]
enum TofDecoding {
    /// `Z16 `/`Y16 ` depth times the scale; the amplitude comes from the amplitude node, if any.
    Depth { scale: f32 },
    /// Four phase images in one buffer (`Y12P` stacked), or in four consecutive buffers.
    Phase {
        params: phase::PhaseParams,
        stacked: bool,
    },
}

impl V4lSource {
    /// Loads the calibration file, opens both nodes in their formats (errors name the node and
    /// what it offers), and starts streaming.
    pub fn open(config: &V4lConfig) -> Result<Self, V4lOpenError> {
        let module = ModuleCalibration::load(&config.calibration)?;
        let cfg_err = |role, message: String| V4lOpenError::Config { role, message };
        let tof_format = node_format(&config.tof.node).map_err(|m| cfg_err("tof", m))?;
        let rgb_format = node_format(&config.rgb).map_err(|m| cfg_err("rgb", m))?;
        let stacked = tof_format == PixelFormat::Y12P;
        let tof_rows = if stacked {
            config.tof.node.height / 4
        } else {
            config.tof.node.height
        };
        let cal_path = config.calibration.display();
        if (config.tof.node.width, tof_rows) != (module.tof.width, module.tof.height) {
            return Err(cfg_err(
                "tof",
                format!(
                    "streams {}x{tof_rows} images but {cal_path} [tof] is {}x{}",
                    config.tof.node.width, module.tof.width, module.tof.height
                ),
            ));
        }
        if (config.rgb.width, config.rgb.height) != (module.rgb.width, module.rgb.height) {
            return Err(cfg_err(
                "rgb",
                format!(
                    "streams {}x{} but {cal_path} [rgb] is {}x{}",
                    config.rgb.width, config.rgb.height, module.rgb.width, module.rgb.height
                ),
            ));
        }
        let tof_decoding = match tof_format {
            PixelFormat::Z16 | PixelFormat::Y16 => TofDecoding::Depth {
                scale: module.depth_scale_m,
            },
            _ => TofDecoding::Phase {
                params: phase::PhaseParams {
                    modulation_hz: config.tof.modulation_hz.unwrap_or(0.0),
                    q_sign: match config.tof.q_sign {
                        QSignConfig::Standard => phase::QSign::Standard,
                        QSignConfig::Inverted => phase::QSign::Inverted,
                    },
                    min_amplitude: config.tof.min_amplitude,
                },
                stacked,
            },
        };

        let tof_stream = open_node("tof", &config.tof.node)?;
        let rgb_stream = open_node("rgb", &config.rgb)?;
        let amplitude_stream = match &config.amplitude {
            Some(node) => Some((node, open_node("amplitude", node)?)),
            None => None,
        };
        let periods: Vec<u64> = [tof_stream.format().fps, rgb_stream.format().fps]
            .iter()
            .map(|fps| fps.map_or(33_333, |f| (1e6 / f) as u64))
            .collect();
        let mut tolerance_us = config
            .pair_tolerance_ms
            .map_or(periods[0].max(periods[1]) / 2, |ms| (ms * 1000.0) as u64);
        if matches!(tof_decoding, TofDecoding::Phase { stacked: false, .. }) {
            // Four buffers make one ToF frame, stamped with the first: the RGB frame may be up
            // to four ToF periods later.
            tolerance_us = tolerance_us.max(periods[0] * 4);
        }
        let description = format!(
            "v4l ToF {} {} {}x{}{}, RGB {} {} {}x{}{}",
            config.tof.node.device.display(),
            tof_format,
            config.tof.node.width,
            config.tof.node.height,
            fps_text(tof_stream.format().fps),
            config.rgb.device.display(),
            rgb_format,
            config.rgb.width,
            config.rgb.height,
            fps_text(rgb_stream.format().fps),
        );
        let description = match &amplitude_stream {
            Some((node, stream)) => format!(
                "{description}, amplitude {} {:?} {}x{}{}",
                node.device.display(),
                node.format,
                node.width,
                node.height,
                fps_text(stream.format().fps)
            ),
            None => description,
        };

        let mut manifest =
            CaptureManifest::new(module.rgb.width, module.rgb.height, module.rgb.intrinsics());
        manifest.initial_calibration = module.initial_calibration();
        manifest.distortion = module.rgb.distortion;
        manifest.depth_scale = STORED_DEPTH_SCALE;
        if let Some(f) = config.tof.modulation_hz {
            manifest.modulation_frequencies_hz = vec![f];
        }
        manifest.source = serde_json::json!({
            "kind": "deard --record of a live V4L2 module",
            "description": description,
            "calibration_file": config.calibration.display().to_string(),
            "module": serde_json::to_value(&module).expect("plain data serialises"),
            "depth": "z-depth in the RGB camera, registered onto the RGB grid (rotation and intrinsics undone; the translation left to the calibration), mm on disk",
            "amplitude": match (tof_decoding, &config.amplitude) {
                (TofDecoding::Phase { .. }, _) => "0.5·|(D0−D2, D1−D3)| of the 4 phases, raw units".to_string(),
                (TofDecoding::Depth { .. }, Some(node)) => format!("the amplitude node {}'s raw values", node.device.display()),
                (TofDecoding::Depth { .. }, None) => "1 where depth is valid: no amplitude node is configured".to_string(),
            },
            "timestamps": "CLOCK_MONOTONIC of the RGB buffer, ns",
        });
        let (tx, rx) = mpsc::sync_channel(CHANNEL_DEPTH);
        let stop = Arc::new(AtomicBool::new(false));
        let tof_frame = frame_format(tof_format, &tof_stream);
        let rgb_frame = frame_format(rgb_format, &rgb_stream);
        let mut amplitude_pairer = None;
        let mut threads = Vec::new();
        if let Some((node, stream)) = amplitude_stream {
            let format = node_format(node).map_err(|m| cfg_err("amplitude", m))?;
            let frame = frame_format(format, &stream);
            // One sensor's two images of one exposure: their timestamps agree to well within a
            // quarter period.
            amplitude_pairer = Some(Pairer::new(periods[0] / 4));
            threads.push(spawn_node(
                "amplitude",
                node.clone(),
                stream,
                AmplitudeDecoder { frame },
                tx.clone(),
                stop.clone(),
            ));
        }
        threads.extend([
            spawn_node(
                "tof",
                config.tof.node.clone(),
                tof_stream,
                TofDecoder::new(
                    tof_frame,
                    tof_decoding,
                    phase::Pinhole {
                        fx: module.tof.fx,
                        fy: module.tof.fy,
                        cx: module.tof.cx,
                        cy: module.tof.cy,
                    },
                ),
                tx.clone(),
                stop.clone(),
            ),
            spawn_node(
                "rgb",
                config.rgb.clone(),
                rgb_stream,
                RgbDecoder { frame: rgb_frame },
                tx,
                stop.clone(),
            ),
        ]);
        Ok(V4lSource {
            rx,
            pairer: Pairer::new(tolerance_us),
            amplitude_pairer,
            ready: VecDeque::new(),
            registration: module.registration(),
            size: (module.rgb.width, module.rgb.height),
            calibration: module.initial_calibration(),
            description,
            manifest,
            rgb_intrinsics: module.rgb_intrinsics(),
            depth_limit: DepthLimit::nearer(
                module.max_range_m.map(|max_m| DepthLimit {
                    max_m,
                    origin: format!("max_range_m in {cal_path}"),
                }),
                config.tof.modulation_hz.and_then(DepthLimit::unambiguous),
            ),
            stop,
            threads,
            next_index: 0,
            reported: (PairCounts::default(), Instant::now()),
        })
    }

    /// The RgbdFrame of a pair: ToF images registered onto the RGB grid.
    fn frame(&mut self, tof: TofImages, rgb: Array3<u8>, ts_us: u64) -> RgbdFrame {
        let (w, h) = (self.size.0 as usize, self.size.1 as usize);
        // No amplitude node: 1 wherever depth is valid (the chain normalises amplitude by a
        // percentile, so a constant carries no signal but no bias either).
        let tof_amplitude = tof
            .amplitude
            .unwrap_or_else(|| tof.depth.mapv(|d| if d > 0.0 { 1.0 } else { 0.0 }));
        let (mut depth, mut amplitude) =
            if self.registration.is_identity() && tof.depth.dim() == (h, w) {
                (tof.depth, tof_amplitude)
            } else {
                let mut depth = Array2::zeros((h, w));
                let mut amplitude = Array2::zeros((h, w));
                register_tof(
                    &self.registration,
                    tof.depth.view(),
                    tof_amplitude.view(),
                    depth.view_mut(),
                    amplitude.view_mut(),
                );
                (depth, amplitude)
            };
        quantize_as_stored(depth.view_mut(), amplitude.view_mut(), STORED_DEPTH_SCALE);
        let index = self.next_index;
        self.next_index += 1;
        RgbdFrame::new(index, ts_us * 1000, rgb, amplitude, depth)
    }

    /// A pair as a frame, registered; `decode_us` is the registration's time (the decoding
    /// ran on the node threads, overlapped with processing).
    fn item(&mut self, pair: Pair<TofImages, Array3<u8>>) -> SourceItem {
        let arrived = Instant::now();
        let frame = self.frame(pair.a, pair.b, pair.ts_b_us);
        SourceItem::Frame {
            frame: Box::new(frame),
            arrived,
            decode_us: arrived.elapsed().as_micros() as u32,
        }
    }

    /// Depth frames that found their amplitude, on to the pairing with RGB; returns the first
    /// complete frame and keeps the others in `ready`.
    fn depth_with_amplitude(
        &mut self,
        first: Option<Pair<TofImages, Array2<f32>>>,
    ) -> Option<Pair<TofImages, Array3<u8>>> {
        let mut next = first;
        while let Some(p) = next {
            let mut images = p.a;
            images.amplitude = Some(p.b);
            if let Some(done) = self.pairer.push_a(p.ts_a_us, images) {
                self.ready.push_back(done);
            }
            next = self.amplitude_pairer.as_mut().and_then(|a| a.pop_ready());
        }
        self.ready.pop_front()
    }

    fn report_pairing(&mut self) {
        let counts = self.pairer.counts();
        let (last, at) = self.reported;
        let unpaired = counts.unpaired_a + counts.unpaired_b;
        if unpaired > last.unpaired_a + last.unpaired_b && at.elapsed() >= PAIR_REPORT {
            tracing::warn!(
                paired = counts.paired,
                unpaired_tof = counts.unpaired_a,
                unpaired_rgb = counts.unpaired_b,
                "frames without a partner within the pairing tolerance were dropped"
            );
            self.reported = (counts, Instant::now());
        }
    }
}

fn fps_text(fps: Option<f64>) -> String {
    fps.map_or(String::new(), |f| format!(" at {f:.3} fps"))
}

fn open_node(role: &'static str, node: &NodeConfig) -> Result<CaptureStream, V4lOpenError> {
    let format = node_format(node).map_err(|message| V4lOpenError::Config { role, message })?;
    let want = FormatRequest {
        fourcc: format.fourcc(),
        width: node.width,
        height: node.height,
        fps: node.fps,
    };
    let controls: Vec<(String, i64)> = node.controls.iter().map(|(k, v)| (k.clone(), *v)).collect();
    CaptureStream::open(&node.device, &want, &controls, DEQUEUE_TIMEOUT)
        .map_err(|source| V4lOpenError::Device { role, source })
}

fn frame_format(format: PixelFormat, stream: &CaptureStream) -> FrameFormat {
    let n = stream.format();
    FrameFormat::new(
        format,
        n.width as usize,
        n.height as usize,
        n.stride as usize,
    )
}

/// Turns one node's buffers into messages.
trait Decoder: Send + 'static {
    /// `Ok(None)`: the buffer was taken but completes nothing yet (a phase frame of four).
    fn decode(&mut self, buffer: &Buffer) -> Result<Option<NodeMsg>, String>;
    /// The stream was interrupted: partial state is dropped.
    fn reset(&mut self) {}
}

struct RgbDecoder {
    frame: FrameFormat,
}

impl Decoder for RgbDecoder {
    fn decode(&mut self, buffer: &Buffer) -> Result<Option<NodeMsg>, String> {
        let mut rgb = Array3::zeros((self.frame.height, self.frame.width, 3));
        pixel::colour::rgb_into(&self.frame, buffer.data, rgb.view_mut())
            .map_err(|e| e.to_string())?;
        Ok(Some(NodeMsg::Rgb {
            ts_us: buffer.timestamp_us.max(0) as u64,
            rgb,
        }))
    }
}

/// The amplitude / IR node of a depth module.
struct AmplitudeDecoder {
    frame: FrameFormat,
}

impl Decoder for AmplitudeDecoder {
    fn decode(&mut self, buffer: &Buffer) -> Result<Option<NodeMsg>, String> {
        let mut amplitude = Array2::zeros((self.frame.height, self.frame.width));
        pixel::depth::intensity_into(&self.frame, buffer.data, amplitude.view_mut())
            .map_err(|e| e.to_string())?;
        Ok(Some(NodeMsg::Amplitude {
            ts_us: buffer.timestamp_us.max(0) as u64,
            amplitude,
        }))
    }
}

struct TofDecoder {
    frame: FrameFormat,
    decoding: TofDecoding,
    /// The ToF camera's intrinsics: a 4-phase distance is along the pixel's ray, the chain
    /// wants z.
    pinhole: phase::Pinhole,
    /// Consecutive phase buffers of the frame being collected, with the first's timestamp.
    phases: Vec<Vec<u8>>,
    first_ts_us: u64,
    last_sequence: Option<u32>,
}

impl TofDecoder {
    fn new(frame: FrameFormat, decoding: TofDecoding, pinhole: phase::Pinhole) -> Self {
        TofDecoder {
            frame,
            decoding,
            pinhole,
            phases: Vec::with_capacity(4),
            first_ts_us: 0,
            last_sequence: None,
        }
    }
}

impl TofDecoder {
    /// A demodulated phase frame as z-depth (radial distance times the ray's cosine) and its
    /// amplitude.
    fn z_images(&self, image: phase::PhaseImage) -> TofImages {
        let mut depth = image.radial;
        phase::radial_to_z_in_place(depth.view_mut(), &self.pinhole);
        TofImages {
            depth,
            amplitude: Some(image.amplitude),
        }
    }
}

impl Decoder for TofDecoder {
    fn decode(&mut self, buffer: &Buffer) -> Result<Option<NodeMsg>, String> {
        let ts_us = buffer.timestamp_us.max(0) as u64;
        let (w, h) = (self.frame.width, self.frame.height);
        let images = match self.decoding {
            TofDecoding::Depth { scale } => {
                let mut depth = Array2::zeros((h, w));
                pixel::depth::depth_into(&self.frame, buffer.data, scale, depth.view_mut())
                    .map_err(|e| e.to_string())?;
                TofImages {
                    depth,
                    amplitude: None,
                }
            }
            TofDecoding::Phase {
                params,
                stacked: true,
            } => {
                let image = phase::demodulate_stacked(&self.frame, buffer.data, &params)
                    .map_err(|e| e.to_string())?;
                self.z_images(image)
            }
            TofDecoding::Phase {
                params,
                stacked: false,
            } => {
                // A frame is four buffers in a row, the 0° one at a sequence number divisible
                // by four (how the Arducam ToF driver counts); a gap starts over.
                let contiguous = self
                    .last_sequence
                    .is_some_and(|s| buffer.sequence == s.wrapping_add(1));
                self.last_sequence = Some(buffer.sequence);
                if !contiguous || buffer.sequence.is_multiple_of(4) {
                    self.phases.clear();
                }
                if self.phases.is_empty() {
                    if !buffer.sequence.is_multiple_of(4) {
                        return Ok(None);
                    }
                    self.first_ts_us = ts_us;
                }
                self.phases.push(buffer.data.to_vec());
                if self.phases.len() < 4 {
                    return Ok(None);
                }
                let frames = [
                    &self.phases[0][..],
                    &self.phases[1][..],
                    &self.phases[2][..],
                    &self.phases[3][..],
                ];
                let image = phase::demodulate_frames(&self.frame, frames, &params);
                self.phases.clear();
                let image = image.map_err(|e| e.to_string())?;
                return Ok(Some(NodeMsg::Tof {
                    ts_us: self.first_ts_us,
                    images: self.z_images(image),
                }));
            }
        };
        Ok(Some(NodeMsg::Tof { ts_us, images }))
    }

    fn reset(&mut self) {
        self.phases.clear();
        self.last_sequence = None;
    }
}

/// Streams one node until `stop`: decodes, sends, and on a lost node reopens it with backoff.
fn spawn_node(
    role: &'static str,
    node: NodeConfig,
    stream: CaptureStream,
    mut decoder: impl Decoder,
    tx: SyncSender<NodeMsg>,
    stop: Arc<AtomicBool>,
) -> JoinHandle<()> {
    thread::Builder::new()
        .name(format!("v4l-{role}"))
        .spawn(move || {
            let mut stream = Some(stream);
            let mut backoff = BACKOFF_FIRST;
            while !stop.load(Ordering::Relaxed) {
                let Some(s) = stream.as_mut() else {
                    if !sleep_unless(&stop, backoff) {
                        break;
                    }
                    match open_node(role, &node) {
                        Ok(s) => {
                            stream = Some(s);
                            backoff = BACKOFF_FIRST;
                            decoder.reset();
                            if tx.send(NodeMsg::Back { role }).is_err() {
                                break;
                            }
                        }
                        Err(e) => {
                            tracing::debug!(role, error = %e, "node not back yet");
                            backoff = (backoff * 2).min(BACKOFF_MAX);
                        }
                    }
                    continue;
                };
                let msg = match s.next_buffer() {
                    Ok(None) => continue,
                    Ok(Some(buffer)) if buffer.corrupt => Some(NodeMsg::Bad {
                        reason: format!(
                            "{} ({role}) sequence {}: the driver flagged the buffer as corrupt",
                            node.device.display(),
                            buffer.sequence
                        ),
                    }),
                    Ok(Some(buffer)) => match decoder.decode(&buffer) {
                        Ok(msg) => msg,
                        Err(reason) => Some(NodeMsg::Bad {
                            reason: format!(
                                "{} ({role}) sequence {}: {reason}",
                                node.device.display(),
                                buffer.sequence
                            ),
                        }),
                    },
                    Err(e) => {
                        stream = None;
                        Some(NodeMsg::Lost {
                            role,
                            error: e.to_string(),
                        })
                    }
                };
                if let Some(msg) = msg {
                    if tx.send(msg).is_err() {
                        break;
                    }
                }
            }
        })
        .expect("spawn a V4L2 node thread")
}

impl FrameSource for V4lSource {
    fn next_item(&mut self, shutdown: &AtomicBool) -> SourceItem {
        loop {
            if shutdown.load(Ordering::Relaxed) {
                return SourceItem::End;
            }
            // One message can complete more than one pair: hand those out first.
            if let Some(pair) = self.ready.pop_front().or_else(|| self.pairer.pop_ready()) {
                return self.item(pair);
            }
            let msg = match self.rx.recv_timeout(Duration::from_millis(100)) {
                Ok(msg) => msg,
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => {
                    return SourceItem::Failed {
                        reason: "both V4L2 node threads ended".into(),
                    }
                }
            };
            let pair = match msg {
                NodeMsg::Tof { ts_us, images } => match &mut self.amplitude_pairer {
                    None => self.pairer.push_a(ts_us, images),
                    Some(amp) => {
                        let first = amp.push_a(ts_us, images);
                        self.depth_with_amplitude(first)
                    }
                },
                NodeMsg::Amplitude { ts_us, amplitude } => {
                    let first = self
                        .amplitude_pairer
                        .as_mut()
                        .and_then(|amp| amp.push_b(ts_us, amplitude));
                    self.depth_with_amplitude(first)
                }
                NodeMsg::Rgb { ts_us, rgb } => self.pairer.push_b(ts_us, rgb),
                NodeMsg::Bad { reason } => {
                    let frame_id = self.next_index;
                    return SourceItem::Skipped { frame_id, reason };
                }
                NodeMsg::Lost { role, error } => {
                    tracing::error!(role, %error, "capture node lost; reopening it with backoff (clients keep the service)");
                    continue;
                }
                NodeMsg::Back { role } => {
                    tracing::info!(role, "capture node is back");
                    continue;
                }
            };
            self.report_pairing();
            if let Some(pair) = pair {
                return self.item(pair);
            }
        }
    }

    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn initial_calibration(&self) -> Calibration {
        self.calibration
    }

    fn describe(&self) -> String {
        self.description.clone()
    }

    fn recording_manifest(&self) -> CaptureManifest {
        self.manifest.clone()
    }

    fn depth_limit(&self) -> Option<DepthLimit> {
        self.depth_limit.clone()
    }

    fn rgb_intrinsics(&self) -> Option<CameraIntrinsics> {
        Some(self.rgb_intrinsics)
    }
}

impl Drop for V4lSource {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Unblock a thread waiting to send: its receiver goes away with the channel.
        let (_, rx) = mpsc::sync_channel(0);
        drop(std::mem::replace(&mut self.rx, rx));
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phase_frame_becomes_z_depth_along_each_pixels_ray() {
        let pinhole = phase::Pinhole {
            fx: 100.0,
            fy: 100.0,
            cx: 2.0,
            cy: 1.0,
        };
        let decoder = TofDecoder::new(
            FrameFormat::unpadded(PixelFormat::Y12, 5, 3),
            TofDecoding::Phase {
                params: phase::PhaseParams {
                    modulation_hz: 75e6,
                    q_sign: phase::QSign::Standard,
                    min_amplitude: 0.0,
                },
                stacked: true,
            },
            pinhole,
        );
        let mut radial = Array2::from_elem((3, 5), 2.0f32);
        radial[(0, 0)] = 0.0;
        let images = decoder.z_images(phase::PhaseImage {
            radial,
            amplitude: Array2::from_elem((3, 5), 7.0),
        });
        // On the principal point the ray is the axis: z = distance.
        assert_eq!(images.depth[(1, 2)], 2.0);
        // Off axis z is shorter: (4, 2) is (0.02, 0.01) from the axis in normalised units.
        let want = 2.0 / (1.0f32 + 0.02 * 0.02 + 0.01 * 0.01).sqrt();
        assert!((images.depth[(2, 4)] - want).abs() < 1e-6);
        assert!(images.depth[(2, 4)] < 2.0);
        assert_eq!(images.depth[(0, 0)], 0.0, "invalid stays invalid");
        assert_eq!(images.amplitude.unwrap()[(2, 4)], 7.0);
    }
}
