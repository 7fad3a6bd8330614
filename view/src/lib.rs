//! `dear view`: a small, read-only HTTP server that shows one deard frame service in a browser
//! — the live colourised depth, the RGB/depth blend, the confidence plane, the calibration the
//! frames carry over time, and the frame rate. What a person opens on a laptop to look at a
//! board's camera (docs/view.md).
//!
//! Its own crate so that the SDK (`dear-client`) stays thin; the `dear` CLI's `view` subcommand
//! only parses arguments and calls [`Viewer::start`].
//!
//! Design:
//! - one **intake** thread ([`intake`]) holds the only subscription and reads every frame as it
//!   comes (so the daemon never waits on a viewer): each header updates the statistics and the
//!   history; at most `max_fps` times a second the newest frame's planes are copied into a
//!   [`intake::Snapshot`] and the shared-memory sample is released at once;
//! - a fixed pool of **HTTP workers** ([`http`]) answers requests from that snapshot; each
//!   picture is rendered and JPEG-encoded at most once per snapshot ([`render::Cache`]), however
//!   many viewers ask, so the CPU spent is bounded by `max_fps`, not by the number of browsers.
//!   A slow browser holds one worker, never the intake;
//! - **read-only**: GET and HEAD only (anything else is 405), no query parameter changes
//!   anything, no request reaches the daemon; at most `max_viewers` distinct client addresses
//!   are served at a time (others get 503 until one has been idle for
//!   [`http::VIEWER_IDLE`]).

#![forbid(unsafe_code)]

pub mod http;
pub mod intake;
pub mod render;
pub mod status;

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

/// Pictures per second each viewer is offered (and snapshots taken) unless configured.
pub const DEFAULT_MAX_FPS: f64 = 10.0;
/// The highest `max_fps` accepted: more than a browser needs to judge a stream.
pub const MAX_FPS_LIMIT: f64 = 30.0;
/// Distinct client addresses served at once unless configured.
pub const DEFAULT_MAX_VIEWERS: usize = 4;
/// Threads answering HTTP requests.
pub const WORKERS: usize = 4;

/// What to serve and how much of it.
#[derive(Debug, Clone)]
pub struct ViewConfig {
    /// Address to listen on, `HOST:PORT` (port 0: any free port; [`Viewer::local_addr`] says
    /// which).
    pub bind: String,
    /// The deard frame service, e.g. `dear/cam0/frames`.
    pub service: String,
    /// Snapshots (and pictures offered to each viewer) per second, `(0, MAX_FPS_LIMIT]`.
    pub max_fps: f64,
    /// Distinct client addresses served at once, at least 1.
    pub max_viewers: usize,
    /// A fixed depth colour scale `(near, far)` in metres; `None`: each frame's own robust
    /// range (1st–99th percentile), as `dear dump`'s previews.
    pub depth_range: Option<(f32, f32)>,
}

impl ViewConfig {
    /// A configuration with the defaults for everything but the address and the service.
    pub fn new(bind: impl Into<String>, service: impl Into<String>) -> Self {
        ViewConfig {
            bind: bind.into(),
            service: service.into(),
            max_fps: DEFAULT_MAX_FPS,
            max_viewers: DEFAULT_MAX_VIEWERS,
            depth_range: None,
        }
    }
}

/// Why the viewer did not start.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("max_fps must be in (0, {MAX_FPS_LIMIT}], got {0}")]
    MaxFps(f64),
    #[error("max_viewers must be at least 1")]
    MaxViewers,
    #[error("cannot listen on {bind}: {message}")]
    Bind { bind: String, message: String },
    #[error(transparent)]
    Connect(#[from] dear_client::ConnectError),
    #[error("cannot start the {what} thread: {source}")]
    Thread {
        what: &'static str,
        source: std::io::Error,
    },
}

/// A running viewer: the intake thread and the HTTP workers. Stopped (threads joined) by
/// [`Viewer::stop`] or on drop.
pub struct Viewer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    server: Arc<tiny_http::Server>,
    threads: Vec<JoinHandle<()>>,
}

impl Viewer {
    /// Subscribes to `config.service` and starts serving on `config.bind`. Works whether or
    /// not the daemon runs yet: the page says "no frames" until they come.
    pub fn start(config: ViewConfig) -> Result<Viewer, ViewError> {
        if !(config.max_fps > 0.0 && config.max_fps <= MAX_FPS_LIMIT) {
            return Err(ViewError::MaxFps(config.max_fps));
        }
        if config.max_viewers == 0 {
            return Err(ViewError::MaxViewers);
        }
        let server = tiny_http::Server::http(&config.bind).map_err(|e| ViewError::Bind {
            bind: config.bind.clone(),
            message: e.to_string(),
        })?;
        let addr = server
            .server_addr()
            .to_ip()
            .ok_or_else(|| ViewError::Bind {
                bind: config.bind.clone(),
                message: "not an IP address".into(),
            })?;
        let server = Arc::new(server);
        let stop = Arc::new(AtomicBool::new(false));
        let shared = Arc::new(intake::Shared::new(&config));
        let mut viewer = Viewer {
            addr,
            stop: Arc::clone(&stop),
            server: Arc::clone(&server),
            threads: Vec::new(),
        };

        // The subscription lives on the intake thread (an iceoryx2 node stays on the thread
        // that made it); the connection's outcome comes back over a channel.
        let (connected_tx, connected_rx) = mpsc::channel();
        let intake = {
            let shared = Arc::clone(&shared);
            let stop = Arc::clone(&stop);
            let service = config.service.clone();
            std::thread::Builder::new()
                .name("view-intake".into())
                .spawn(move || match dear_client::Client::connect(&service) {
                    Ok(client) => {
                        let _ = connected_tx.send(Ok(()));
                        intake::run(&client, &shared, &stop);
                    }
                    Err(e) => {
                        let _ = connected_tx.send(Err(e));
                    }
                })
                .map_err(|source| ViewError::Thread {
                    what: "intake",
                    source,
                })?
        };
        viewer.threads.push(intake);
        match connected_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e.into()),
            Err(_) => {
                return Err(ViewError::Thread {
                    what: "intake",
                    source: std::io::Error::other("it ended before connecting"),
                })
            }
        }
        for i in 0..WORKERS {
            let shared = Arc::clone(&shared);
            let stop = Arc::clone(&stop);
            let server = Arc::clone(&server);
            let worker = std::thread::Builder::new()
                .name(format!("view-http-{i}"))
                .spawn(move || http::serve(&server, &shared, &stop))
                .map_err(|source| ViewError::Thread {
                    what: "HTTP worker",
                    source,
                })?;
            viewer.threads.push(worker);
        }
        Ok(viewer)
    }

    /// The address the server listens on (the port chosen when `bind` gave port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops serving and waits for the threads (at most about one poll interval each).
    pub fn stop(self) {
        // Drop does it.
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for _ in 0..WORKERS {
            self.server.unblock();
        }
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// How long one blocking wait (for a frame, for a request) may last: bounds the reaction to
/// [`Viewer::stop`].
pub(crate) const POLL: Duration = Duration::from_millis(100);
