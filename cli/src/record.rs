//! `dear record --mcap FILE`: received frames written to an MCAP file that Foxglove, Rerun
//! and the `mcap` tools open (issue 15).
//!
//! Per frame, one message on each of five channels named after the service (`dear/cam0/frames`
//! → `/dear/cam0/…`), the first four with Foxglove's well-known schemas, protobuf-encoded:
//! - `…/depth`: `foxglove.RawImage`, `16UC1` millimetres (default) or `32FC1` metres, 0 = invalid;
//! - `…/rgb`: `foxglove.RawImage`, `rgb8`;
//! - `…/confidence`: `foxglove.RawImage`, `mono8` (0 = invalid … 255 = measured and kept);
//! - `…/calibration`: `foxglove.CameraCalibration` of the RGB camera (the grid the depth is
//!   aligned to): the frame's width and height, and K, R = I, P = [K | 0] and the `plumb_bob`
//!   D from the frame header's intrinsics (format 3), or from `--intrinsics` (a pinhole), which
//!   overrides them. A frame whose header says its intrinsics are unknown gets K, R, P all
//!   zero: the ROS/Foxglove convention for an uncalibrated camera, which viewers ignore
//!   instead of projecting with made-up numbers;
//! - `…/calibration_health`: JSON (schema `dear.CalibrationHealth`, `mcap_file::HEALTH_SCHEMA`)
//!   with the header's flow-model calibration, its fit figures and its health state (good /
//!   can improve / needs recalibration, docs/calibration-health.md).
//!
//! Every message's `frame_id` is the camera's name (`cam0`), its `timestamp` the frame's
//! capture time; the MCAP log time is the capture time too (moved on where the capture clock
//! goes back: a looping replay, a restarted daemon; see [`mcap_file`]), the publish time the
//! frame's `publish_timestamp_ns`, the sequence the header's (mod 2^32). At the end a
//! `dear.record` metadata record holds the counts (frames, lost frames, restarts).
//!
//! Why these crates: the container is the `mcap` crate (Foxglove's own reader/writer,
//! rust-version 1.81; zstd-compressed chunks with the summary and indexes that make the file
//! seekable). The messages are the official `foxglove` SDK crate's generated types (0.30,
//! rust-version 1.88), which carry the schemas' protobuf `FileDescriptorSet`s, so nothing
//! here restates a schema. With its default features off it brings no WebSocket server, tokio
//! or TLS, only prost and a few small crates. Its own MCAP writer is not used: it takes the
//! publish time from the log time, and ours must be the frame's publish time. Protobuf rather
//! than JSON: the images stay binary (no base64, a third larger) and every reader of
//! Foxglove's schemas decodes it.

pub mod mcap_file;

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use clap::Args;
use dear_capture::Intrinsics;
use dear_client::Frame;

use self::mcap_file::{DepthEncoding, FrameData, RecordSummary, Recorder};
use super::reconnect::ReconnectingClient;
use super::{first_frame, next_frame, parse_intrinsics, Interrupted, StopFlag};

/// Arguments of `dear record` (the command's help text is on [`super::Command::Record`]).
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// MCAP file to write (must not exist).
    #[arg(long, value_name = "FILE")]
    pub mcap: PathBuf,
    /// Stop after this many frames.
    #[arg(long, value_name = "N", conflicts_with = "seconds",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub count: Option<u64>,
    /// Stop this many seconds after the first frame arrived.
    #[arg(long, value_name = "S", value_parser = parse_seconds)]
    pub seconds: Option<f64>,
    /// Frame service to read.
    #[arg(long, default_value_t = super::default_service(), value_parser = super::parse_service)]
    pub service: String,
    /// Depth image encoding: 16UC1 (millimetres, u16) or 32FC1 (metres, f32, as published).
    #[arg(long, value_enum, value_name = "ENCODING", default_value = "16UC1")]
    pub depth_encoding: DepthEncoding,
    /// RGB intrinsics `FX,FY,CX,CY` in px for the calibration channel, instead of the ones
    /// each frame header carries (a pinhole, no distortion).
    #[arg(long, value_name = "FX,FY,CX,CY", value_parser = parse_intrinsics)]
    pub intrinsics: Option<Intrinsics>,
    /// Give up when no frame arrives for this many seconds (first frame included).
    #[arg(long, value_name = "S", default_value_t = 10.0, value_parser = parse_seconds)]
    pub timeout_s: f64,
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if v > 0.0 && v <= 31_536_000.0 {
        Ok(v)
    } else {
        Err(format!("{s} s is not in (0, 31536000]"))
    }
}

/// Why the frame loop ended.
enum End {
    /// `--count` or `--seconds` reached.
    Limit,
    /// SIGINT / SIGTERM.
    Signal,
}

pub fn run(args: &RecordArgs) -> anyhow::Result<()> {
    let stop = StopFlag::install()?;
    // Create the file first, so that a bad path fails at once rather than after the wait.
    let file = File::create_new(&args.mcap).with_context(|| {
        format!(
            "cannot create the MCAP file {}{}",
            args.mcap.display(),
            if args.mcap.exists() {
                " (dear record does not overwrite: give a new name)"
            } else {
                ""
            }
        )
    })?;
    let mut client = match ReconnectingClient::connect(&args.service) {
        Ok(client) => client,
        Err(e) => {
            remove_unused(&args.mcap);
            return Err(e.into());
        }
    };
    let first = match first_frame(
        &mut client,
        &args.service,
        args.timeout_s,
        &args.mcap,
        &stop,
    ) {
        Ok(frame) => frame,
        Err(e) => {
            remove_unused(&args.mcap);
            return Err(e);
        }
    };
    let mut recorder = Recorder::new(
        BufWriter::with_capacity(1 << 20, file),
        &args.mcap,
        &args.service,
        args.depth_encoding,
        args.intrinsics,
    )?;
    let started = Instant::now();
    let end_at = args.seconds.map(|s| started + Duration::from_secs_f64(s));
    let progress = match args.count {
        Some(n) => indicatif::ProgressBar::new(n),
        None => indicatif::ProgressBar::new_spinner(),
    };
    let outcome = record(
        args,
        &mut client,
        first,
        &mut recorder,
        end_at,
        &stop,
        &progress,
    );
    progress.finish_and_clear();
    // However the loop ended, the frames written get the summary and indexes.
    let written = recorder.frames();
    let (end, summary) = match (outcome, recorder.finish()) {
        (Ok(end), Ok((summary, _))) => (end, summary),
        (Ok(_), Err(finish)) => return Err(finish),
        (Err(e), Ok((summary, _))) => {
            return Err(e.context(format!(
                "{} is finished and holds the {} frames recorded before",
                args.mcap.display(),
                summary.frames
            )))
        }
        (Err(e), Err(finish)) => {
            return Err(e.context(format!(
                "{} holds {written} frames but is not finished (no summary or index): {finish:#}",
                args.mcap.display()
            )))
        }
    };
    let mut line = report(args, &summary, started.elapsed());
    if client.reconnects() > 0 {
        line += &format!(
            "; another process corrupted the channel and it was connected again {} times",
            client.reconnects()
        );
    }
    super::write_stdout(&format!("{line}\n"))?;
    match end {
        End::Limit => Ok(()),
        // Without --count or --seconds a signal is how a recording ends.
        End::Signal if args.count.is_none() && args.seconds.is_none() => Ok(()),
        End::Signal => Err(Interrupted(format!(
            "interrupted after {} frames; {} is finished and holds them",
            summary.frames,
            args.mcap.display()
        ))
        .into()),
    }
}

/// The frame loop: writes `first` and every frame after it until a limit, a signal or an error.
fn record(
    args: &RecordArgs,
    client: &mut ReconnectingClient,
    first: Frame,
    recorder: &mut Recorder<BufWriter<File>>,
    end_at: Option<Instant>,
    stop: &StopFlag,
    progress: &indicatif::ProgressBar,
) -> anyhow::Result<End> {
    let mut frame = first;
    loop {
        recorder.add(&FrameData {
            header: frame.header(),
            depth: frame.depth(),
            rgb: frame.rgb(),
            confidence: frame.confidence(),
        })?;
        // Release the shared-memory sample before waiting for the next.
        drop(frame);
        progress.inc(1);
        if args.count.is_some_and(|n| recorder.frames() >= n) {
            return Ok(End::Limit);
        }
        let timeout = Duration::from_secs_f64(args.timeout_s);
        match next_frame(client, timeout, end_at, stop)? {
            Some(next) => frame = next,
            None if stop.is_set() => return Ok(End::Signal),
            None if end_at.is_some_and(|t| Instant::now() >= t) => return Ok(End::Limit),
            None => bail!(
                "no frame arrived from service {:?} for {} s after {} frames",
                args.service,
                args.timeout_s,
                recorder.frames()
            ),
        }
    }
}

/// The last line: what was written, and what was lost.
fn report(args: &RecordArgs, s: &RecordSummary, elapsed: Duration) -> String {
    let topics = mcap_file::Topics::for_service(&args.service);
    let mut text = format!(
        "recorded {} frames from {:?} in {:.1} s to {} ({}, {}, {}, {}; depth {}); \
         lost {} frames (sequence gaps)",
        s.frames,
        args.service,
        elapsed.as_secs_f64(),
        args.mcap.display(),
        topics.depth,
        topics.rgb,
        topics.confidence,
        topics.calibration,
        args.depth_encoding.name(),
        s.lost
    );
    if s.restarts > 0 {
        text += &format!("; the daemon restarted {} times", s.restarts);
    }
    if s.clock_resets > 0 {
        text += &format!(
            "; the capture clock went back {} times (replay loop or restart): log times \
             continue from the previous frame",
            s.clock_resets
        );
    }
    if s.saturated_pixels > 0 {
        text += &format!(
            "; {} depth pixels beyond 65.535 m written as 65535 mm (use --depth-encoding 32FC1)",
            s.saturated_pixels
        );
    }
    text
}

/// Removes the file created at start when nothing was written to it.
fn remove_unused(path: &Path) {
    let _ = std::fs::remove_file(path);
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn arguments_are_parsed_and_checked() {
        let cli = crate::Cli::try_parse_from(["dear", "record", "--mcap", "x.mcap"]).unwrap();
        let crate::Command::Record(args) = cli.command else {
            panic!("not record");
        };
        assert_eq!(args.depth_encoding, DepthEncoding::Millimetres16);
        assert_eq!((args.count, args.seconds), (None, None));
        let cli = crate::Cli::try_parse_from([
            "dear",
            "record",
            "--mcap",
            "x.mcap",
            "--seconds",
            "2.5",
            "--depth-encoding",
            "32FC1",
        ])
        .unwrap();
        let crate::Command::Record(args) = cli.command else {
            panic!("not record");
        };
        assert_eq!(args.depth_encoding, DepthEncoding::Metres32);
        assert_eq!(args.seconds, Some(2.5));
        for bad in [
            &["--count", "3", "--seconds", "1"][..],
            &["--count", "0"],
            &["--depth-encoding", "16UC3"],
            &["--seconds", "0"],
            &["--intrinsics", "1,2,3"],
        ] {
            let argv = ["dear", "record", "--mcap", "x.mcap"]
                .iter()
                .chain(bad)
                .copied();
            assert!(crate::Cli::try_parse_from(argv).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn an_existing_file_is_not_overwritten() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.mcap");
        std::fs::write(&path, "keep").unwrap();
        let args = RecordArgs {
            mcap: path.clone(),
            count: Some(1),
            seconds: None,
            service: crate::default_service(),
            depth_encoding: DepthEncoding::Millimetres16,
            intrinsics: None,
            timeout_s: 0.1,
        };
        let e = format!("{:#}", run(&args).unwrap_err());
        assert!(
            e.contains(&path.display().to_string()) && e.contains("does not overwrite"),
            "{e}"
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "keep");
    }
}
