//! `dear view`: serves one frame service to browsers (the `dear-view` crate does the work).

use std::io::Write;
use std::time::Duration;

use clap::Args;
use dear_view::{ViewConfig, Viewer, DEFAULT_MAX_FPS, DEFAULT_MAX_VIEWERS};

use super::StopFlag;

#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Address to listen on, HOST:PORT: 127.0.0.1:8080 for this machine only, 0.0.0.0:8080 (or
    /// one interface's address) to let a laptop on the network look. Required: nothing is
    /// served anywhere unless asked. Port 0 picks a free port (printed).
    #[arg(long, value_name = "HOST:PORT")]
    pub bind: String,
    /// Frame service to show.
    #[arg(long, default_value_t = super::default_service(), value_parser = super::parse_service)]
    pub service: String,
    /// Pictures per second offered to each viewer (at most 30): what the server's encoding
    /// costs, however many browsers look.
    #[arg(long, default_value_t = DEFAULT_MAX_FPS, value_name = "FPS")]
    pub max_fps: f64,
    /// Distinct client addresses served at a time; others get 503 until one has been idle for
    /// 10 s.
    #[arg(long, default_value_t = DEFAULT_MAX_VIEWERS, value_name = "N")]
    pub max_viewers: usize,
    /// A fixed depth colour scale in metres, NEAR,FAR (default: each frame's 1st–99th
    /// percentile).
    #[arg(long, value_name = "NEAR,FAR", value_parser = parse_range)]
    pub depth_range: Option<(f32, f32)>,
}

/// `NEAR,FAR` in metres, `0 <= NEAR < FAR`, finite.
fn parse_range(s: &str) -> Result<(f32, f32), String> {
    let values: Vec<f32> = s
        .split(',')
        .map(|v| v.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{s:?} is not two comma-separated numbers NEAR,FAR"))?;
    match values[..] {
        [near, far] if near.is_finite() && far.is_finite() && 0.0 <= near && near < far => {
            Ok((near, far))
        }
        _ => Err(format!(
            "{s:?}: expected NEAR,FAR in metres with 0 <= NEAR < FAR"
        )),
    }
}

pub fn run(args: &ViewArgs) -> anyhow::Result<()> {
    let stop = StopFlag::install()?;
    let viewer = Viewer::start(ViewConfig {
        bind: args.bind.clone(),
        service: args.service.clone(),
        max_fps: args.max_fps,
        max_viewers: args.max_viewers,
        depth_range: args.depth_range,
    })?;
    {
        // One line, flushed: scripts read the address from it (port 0).
        let mut out = std::io::stdout().lock();
        let _ = writeln!(
            out,
            "dear view: showing {} at http://{}/ (read-only; Ctrl-C stops)",
            args.service,
            viewer.local_addr()
        );
        let _ = out.flush();
    }
    while !stop.is_set() {
        std::thread::sleep(Duration::from_millis(100));
    }
    viewer.stop();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_ranges() {
        assert_eq!(parse_range("0.3,4.5"), Ok((0.3, 4.5)));
        assert_eq!(parse_range(" 0 , 2 "), Ok((0.0, 2.0)));
        for bad in ["", "1", "2,1", "1,1", "-1,2", "a,b", "1,2,3", "1,inf"] {
            assert!(parse_range(bad).is_err(), "{bad}");
        }
    }
}
