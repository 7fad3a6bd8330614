//! `dear dump`: received frames written as a capture directory, so a live stream can be
//! replayed by `deard`, evaluated or inspected with the same tools as a recording.
//!
//! What deard publishes is not a full capture frame, so three choices make a dump well-defined
//! (all stated in `capture.json`'s `source`):
//! - amplitude: deard publishes none; the frame's confidence × 257 stands in (0–255 spread over
//!   0–65535), so a replay sees low "amplitude" exactly where the daemon had low confidence;
//! - frame ids are 0, 1, 2, … and timestamps are publish times relative to the first dumped
//!   frame, because the daemon's ids and capture times restart when a replay loops and the
//!   format needs them increasing; the daemon's own values are kept per frame in
//!   `source.published_frames`;
//! - the calibration estimate of each frame goes to `source.calibration_estimates`, not to the
//!   frame's `perturbation`, which means ground truth.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Args;
use dear_capture::{layout::MANIFEST_FILE, CaptureManifest, CaptureWriter, Intrinsics, RgbdFrame};
use dear_client::save::{auto_depth_range, save_depth_colorized, save_rgb_depth_blend};
use dear_client::Frame;
use serde_json::{json, Value};

use super::reconnect::ReconnectingClient;
use super::stats::flag_names;
use super::{first_frame, next_frame, parse_intrinsics, Interrupted, StopFlag};

/// What `source.amplitude` says, and the `--help` text repeats.
const AMPLITUDE_NOTE: &str = "confidence×257 (deard publishes no amplitude)";
/// Horizontal field of view assumed when no `--intrinsics` are given (the simulator's default).
const DEFAULT_HFOV_DEG: f32 = 70.0;
/// Opacity of the depth tint in the `.blend.png` previews.
const PREVIEW_ALPHA: f32 = 0.4;

/// Arguments of `dear dump` (the command's help text is on [`super::Command::Dump`]).
#[derive(Debug, Args)]
pub struct DumpArgs {
    /// Number of frames to write.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub count: u64,
    /// Capture directory to create (must not exist, or be empty).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Frame service to read.
    #[arg(long, default_value_t = super::default_service(), value_parser = super::parse_service)]
    pub service: String,
    /// Give up when no frame arrives for this many seconds (first frame included).
    #[arg(long, value_name = "S", default_value_t = 10.0, value_parser = parse_timeout)]
    pub timeout_s: f64,
    /// Also write `previews/NNNNNN.depth.png` (coloured depth with a colour bar in metres; one
    /// colour range, from the first frame, for the whole dump) and `NNNNNN.blend.png` (depth
    /// edges and tint over the RGB, to judge alignment).
    #[arg(long)]
    pub preview: bool,
    /// RGB intrinsics `FX,FY,CX,CY` in px for `capture.json`, instead of the first frame
    /// header's (frames without intrinsics: a centred pinhole with a 70° horizontal field of
    /// view, marked "assumed" in `source.intrinsics`).
    #[arg(long, value_name = "FX,FY,CX,CY", value_parser = parse_intrinsics)]
    pub intrinsics: Option<Intrinsics>,
}

fn parse_timeout(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if v > 0.0 && v <= 86_400.0 {
        Ok(v)
    } else {
        Err(format!("{s} s is not in (0, 86400]"))
    }
}

pub fn run(args: &DumpArgs) -> anyhow::Result<()> {
    check_out_dir(&args.out)?;
    let stop = StopFlag::install()?;
    let mut client = ReconnectingClient::connect(&args.service)?;
    let timeout = Duration::from_secs_f64(args.timeout_s);

    let first = first_frame(&mut client, &args.service, args.timeout_s, &args.out, &stop)?;
    let mut dump = Dump::create(args, &first)?;
    let progress = indicatif::ProgressBar::new(args.count);
    dump.add(first)?;
    progress.inc(1);
    let mut outcome = Ok(());
    while dump.len() < args.count {
        match next_frame(&mut client, timeout, None, &stop) {
            Ok(Some(frame)) => {
                if let Err(e) = dump.add(frame) {
                    outcome = Err(e);
                    break;
                }
                progress.inc(1);
            }
            Ok(None) if stop.is_set() => {
                outcome = Err(Interrupted(format!(
                    "interrupted after {} of {} frames",
                    dump.len(),
                    args.count
                ))
                .into());
                break;
            }
            Ok(None) => {
                outcome = Err(anyhow::anyhow!(
                    "only {} of {} frames arrived from service {:?} (none for {} s)",
                    dump.len(),
                    args.count,
                    args.service,
                    args.timeout_s
                ));
                break;
            }
            Err(e) => {
                outcome = Err(e);
                break;
            }
        }
    }
    progress.finish_and_clear();
    let written = dump.len();
    // Whatever stopped the dump, the frames already written get their manifest, so the
    // directory is a valid (shorter) capture rather than orphaned files.
    let dir = dump.finish()?;
    match outcome {
        Ok(()) => super::write_stdout(&format!(
            "wrote {written} frames from {:?} to {}\n",
            args.service,
            dir.display()
        )),
        Err(e) => Err(e.context(format!(
            "{} holds the {written} frames written before",
            dir.display()
        ))),
    }
}

/// Fails early, before waiting for frames, if `out` cannot become a new capture directory.
fn check_out_dir(out: &Path) -> anyhow::Result<()> {
    if !out.exists() {
        return Ok(());
    }
    if !out.is_dir() {
        bail!("{} exists and is not a directory", out.display());
    }
    let mut entries = std::fs::read_dir(out)
        .with_context(|| format!("cannot read the output directory {}", out.display()))?;
    if entries.next().is_some() {
        bail!(
            "output directory {} is not empty; give a new one",
            out.display()
        );
    }
    Ok(())
}

/// A dump in progress: the capture writer plus what goes into `source` at the end.
struct Dump {
    writer: CaptureWriter,
    previews: Option<PathBuf>,
    preview_range: Option<(f32, f32)>,
    first_publish_ns: u64,
    last_timestamp_ns: u64,
    estimates: Vec<Value>,
    published: Vec<Value>,
}

impl Dump {
    fn create(args: &DumpArgs, first: &Frame) -> anyhow::Result<Self> {
        let (w, h) = first.size();
        let (w, h) = (w as u32, h as u32);
        let header_intrinsics = first.header().intrinsics().ok().flatten();
        let (intrinsics, intrinsics_note) = match (args.intrinsics, header_intrinsics) {
            (Some(k), _) => (k, "given with --intrinsics".to_string()),
            (None, Some(k)) => (
                Intrinsics {
                    fx: k.fx,
                    fy: k.fy,
                    cx: k.cx,
                    cy: k.cy,
                },
                "from the first frame's header".to_string(),
            ),
            (None, None) => (
                Intrinsics::from_hfov(w, h, DEFAULT_HFOV_DEG),
                format!(
                    "assumed: centred pinhole, {DEFAULT_HFOV_DEG}° horizontal field of view \
                     (the frame headers carry no intrinsics: rgb_camera_model 0)"
                ),
            ),
        };
        let mut manifest = CaptureManifest::new(w, h, intrinsics);
        // The header's distortion goes with its intrinsics (not with --intrinsics, a pinhole).
        if args.intrinsics.is_none() {
            manifest.distortion = header_intrinsics.and_then(|k| k.distortion);
        }
        manifest.source = json!({
            "recorded_by": "dear dump",
            "dear_client_version": env!("CARGO_PKG_VERSION"),
            "service": args.service,
            "amplitude": AMPLITUDE_NOTE,
            "intrinsics": intrinsics_note,
            "timestamps": "publish time (CLOCK_MONOTONIC) relative to the first dumped frame",
        });
        let writer = CaptureWriter::create(&args.out, manifest).with_context(|| {
            format!("cannot create the capture directory {}", args.out.display())
        })?;
        let previews = if args.preview {
            let dir = args.out.join("previews");
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            Some(dir)
        } else {
            None
        };
        Ok(Dump {
            writer,
            previews,
            preview_range: auto_depth_range(first.depth_view()),
            first_publish_ns: first.header().publish_timestamp_ns,
            last_timestamp_ns: 0,
            estimates: Vec::new(),
            published: Vec::new(),
        })
    }

    fn len(&self) -> u64 {
        self.writer.len() as u64
    }

    /// Copies the frame out of shared memory (releasing the sample at once), writes its files
    /// and records its metadata.
    fn add(&mut self, frame: Frame) -> anyhow::Result<()> {
        let header = *frame.header();
        let id = self.len();
        // Publish times are monotonic per daemon; a restarted daemon could still go back, so
        // clamp to keep the format's non-decreasing timestamps.
        let timestamp_ns = header
            .publish_timestamp_ns
            .saturating_sub(self.first_publish_ns)
            .max(self.last_timestamp_ns);
        let rgbd = RgbdFrame::new(
            id,
            timestamp_ns,
            frame.rgb_view().to_owned(),
            frame.confidence_view().mapv(|c| f32::from(c) * 257.0),
            frame.depth_view().to_owned(),
        );
        drop(frame);
        self.writer
            .write_frame(&rgbd)
            .with_context(|| format!("cannot write frame {id} of the dump"))?;
        self.last_timestamp_ns = timestamp_ns;
        if let Some(dir) = &self.previews {
            let depth_path = dir.join(format!("{id:06}.depth.png"));
            save_depth_colorized(&depth_path, rgbd.depth.view(), self.preview_range)?;
            let blend_path = dir.join(format!("{id:06}.blend.png"));
            save_rgb_depth_blend(
                &blend_path,
                rgbd.rgb.view(),
                rgbd.depth.view(),
                PREVIEW_ALPHA,
            )?;
        }
        let residual = Some(header.calib_residual_px).filter(|r| r.is_finite());
        self.estimates.push(json!({
            "id": id,
            "tx": header.calib_tx,
            "ty": header.calib_ty,
            "cx": header.calib_cx,
            "cy": header.calib_cy,
            "residual_px": residual,
            "quality": header.calib_quality,
            "age_frames": header.calib_age_frames,
            "online": header.flags & dear_proto::flags::CALIBRATION_ONLINE != 0,
        }));
        self.published.push(json!({
            "id": id,
            // Which publisher instance sent the frame and its number within that instance:
            // `frame_id` alone repeats when a replay loops or the daemon restarts.
            "run_id": format!("{:016x}", header.run_id),
            "sequence": header.sequence,
            "frame_id": header.frame_id,
            "capture_timestamp_ns": header.capture_timestamp_ns,
            "publish_timestamp_ns": header.publish_timestamp_ns,
            "flags": flag_names(header.flags),
            "bundle": header.bundle_name(),
            "frames_skipped": header.frames_skipped,
            "frames_dropped": header.frames_dropped,
        }));
        Ok(())
    }

    /// Writes the manifest, then adds the per-frame metadata to its `source`.
    ///
    /// The writer fixes `source` at creation and the estimates are only known frame by frame,
    /// so `capture.json` is rewritten once more (again via a temporary file and a rename): it
    /// is valid at every moment, only briefly without the per-frame entries.
    fn finish(self) -> anyhow::Result<PathBuf> {
        let dir = self
            .writer
            .finish()
            .context("cannot write the capture manifest")?;
        let path = dir.join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read back {}", path.display()))?;
        // Through the typed manifest, so the file keeps the writer's field order.
        let mut manifest: CaptureManifest = serde_json::from_str(&text)
            .with_context(|| format!("cannot parse {} just written", path.display()))?;
        manifest.source["calibration_estimates"] = Value::Array(self.estimates);
        manifest.source["published_frames"] = Value::Array(self.published);
        let tmp = dir.join(format!("{MANIFEST_FILE}.tmp"));
        let text = serde_json::to_string_pretty(&manifest).context("cannot encode the manifest")?;
        std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
        std::fs::rename(&tmp, &path)
            .with_context(|| format!("cannot replace {}", path.display()))?;
        Ok(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intrinsics_are_parsed_and_checked() {
        let k = parse_intrinsics("500, 510,319.5,239.5").unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (500.0, 510.0, 319.5, 239.5));
        assert!(parse_intrinsics("1,2,3")
            .unwrap_err()
            .contains("has 3 values"));
        assert!(parse_intrinsics("a,2,3,4").unwrap_err().contains("four"));
        assert!(parse_intrinsics("0,2,3,4")
            .unwrap_err()
            .contains("positive"));
        assert!(parse_intrinsics("1,2,inf,4")
            .unwrap_err()
            .contains("finite"));
    }

    #[test]
    fn timeouts_must_be_positive() {
        assert_eq!(parse_timeout("2.5"), Ok(2.5));
        assert!(parse_timeout("0").is_err());
        assert!(parse_timeout("-1").is_err());
        assert!(parse_timeout("soon").unwrap_err().contains("soon"));
    }

    #[test]
    fn out_dir_must_be_new_or_empty() {
        let dir = tempfile::tempdir().unwrap();
        assert!(check_out_dir(&dir.path().join("new")).is_ok());
        assert!(check_out_dir(dir.path()).is_ok());
        let file = dir.path().join("f");
        std::fs::write(&file, "x").unwrap();
        let e = check_out_dir(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("not empty") && e.contains(&dir.path().display().to_string()),
            "{e}"
        );
        let e = check_out_dir(&file).unwrap_err().to_string();
        assert!(e.contains("not a directory"), "{e}");
    }
}
