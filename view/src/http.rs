//! The HTTP side: routing, the viewer limit, and the responses. tiny_http parses requests and
//! manages connections; every request gets an answer here, errors included, as plain text
//! with a status that says what was wrong.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use tiny_http::{Header, Method, Request, Response, Server, StatusCode};

use crate::intake::Shared;
use crate::render::Picture;
use crate::POLL;

/// The page: one static HTML file with its script and style.
pub const PAGE: &str = include_str!("page.html");
/// A client address not heard from for this long no longer counts as a viewer.
pub const VIEWER_IDLE: Duration = Duration::from_secs(10);
/// Longest request target answered (the page's own are under 40 bytes).
pub const MAX_URL: usize = 1024;

/// The distinct client addresses served recently, at most `max`.
#[derive(Debug)]
pub struct Viewers {
    max: usize,
    seen: HashMap<Option<IpAddr>, Instant>,
}

impl Viewers {
    pub fn new(max: usize) -> Viewers {
        Viewers {
            max,
            seen: HashMap::new(),
        }
    }

    /// Whether a request from `ip` is served: a known viewer always is, a new one while fewer
    /// than `max` were active within [`VIEWER_IDLE`].
    pub fn admit(&mut self, ip: Option<IpAddr>, now: Instant) -> bool {
        self.seen
            .retain(|_, &mut last| now.duration_since(last) < VIEWER_IDLE);
        if self.seen.contains_key(&ip) || self.seen.len() < self.max {
            self.seen.insert(ip, now);
            true
        } else {
            false
        }
    }
}

/// What a request asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    Page,
    Status,
    Picture(Picture),
    /// 404.
    NotFound,
    /// 405: the viewer is read-only.
    MethodNotAllowed,
    /// 414.
    UrlTooLong,
}

/// Routes a request by its method and target. The query string is ignored (the page adds one
/// to defeat caches); it changes nothing.
pub fn route(method: &Method, url: &str) -> Route {
    if !matches!(method, Method::Get | Method::Head) {
        return Route::MethodNotAllowed;
    }
    if url.len() > MAX_URL {
        return Route::UrlTooLong;
    }
    let path = url.split(['?', '#']).next().unwrap_or("");
    match path {
        "/" | "/index.html" => Route::Page,
        "/status.json" => Route::Status,
        _ => Picture::from_path(path).map_or(Route::NotFound, Route::Picture),
    }
}

/// A worker: answers requests until `stop`.
pub fn serve(server: &Server, shared: &Shared, stop: &AtomicBool) {
    while !stop.load(Ordering::Relaxed) {
        match server.recv_timeout(POLL) {
            Ok(Some(request)) => handle(shared, request),
            Ok(None) => {}
            Err(e) => {
                tracing::warn!(error = %e, "accepting a request failed");
                std::thread::sleep(POLL);
            }
        }
    }
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header without CR/LF")
}

/// Headers every answer carries: nothing is cached (it is live), nothing is sniffed, nothing is
/// framed by another site.
fn common(response: Response<std::io::Cursor<Vec<u8>>>) -> Response<std::io::Cursor<Vec<u8>>> {
    response
        .with_header(header("Cache-Control", "no-store"))
        .with_header(header("X-Content-Type-Options", "nosniff"))
        .with_header(header("X-Frame-Options", "DENY"))
        .with_header(header("Referrer-Policy", "no-referrer"))
}

fn text(status: u16, body: String) -> Response<std::io::Cursor<Vec<u8>>> {
    common(
        Response::from_data(body.into_bytes())
            .with_status_code(StatusCode(status))
            .with_header(header("Content-Type", "text/plain; charset=utf-8")),
    )
}

fn handle(shared: &Shared, request: Request) {
    let route = route(request.method(), request.url());
    let ip = request.remote_addr().map(|a| a.ip());
    let (admitted, max_viewers) = {
        let mut viewers = shared.viewers.lock().unwrap_or_else(|e| e.into_inner());
        let served = matches!(route, Route::Page | Route::Status | Route::Picture(_));
        (!served || viewers.admit(ip, Instant::now()), viewers.max)
    };
    let response = match route {
        Route::MethodNotAllowed => text(
            405,
            format!(
                "405 Method Not Allowed: {} — dear view is read-only; it answers GET and HEAD\n",
                request.method()
            ),
        )
        .with_header(header("Allow", "GET, HEAD")),
        Route::UrlTooLong => text(414, format!("414 URI Too Long: at most {MAX_URL} bytes\n")),
        Route::NotFound => text(
            404,
            "404 Not Found: dear view serves /, /status.json, /depth.jpg, /blend.jpg and \
             /confidence.jpg\n"
                .into(),
        ),
        Route::Page | Route::Status | Route::Picture(_) if !admitted => text(
            503,
            format!(
                "503 Service Unavailable: too many viewers (at most {max_viewers} addresses at a \
                 time; try again when one has been idle for {} s)\n",
                VIEWER_IDLE.as_secs()
            ),
        )
        .with_header(header("Retry-After", &VIEWER_IDLE.as_secs().to_string())),
        Route::Page => common(
            Response::from_data(PAGE.as_bytes().to_vec())
                .with_header(header("Content-Type", "text/html; charset=utf-8"))
                // The page's own script and style are inline; it loads nothing from elsewhere.
                .with_header(header(
                    "Content-Security-Policy",
                    "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; \
                     img-src 'self' blob:; connect-src 'self'; base-uri 'none'; \
                     form-action 'none'; frame-ancestors 'none'",
                )),
        ),
        Route::Status => match serde_json::to_vec(&crate::status::status(shared)) {
            Ok(body) => common(
                Response::from_data(body).with_header(header("Content-Type", "application/json")),
            ),
            Err(e) => text(500, format!("500 Internal Server Error: {e}\n")),
        },
        Route::Picture(picture) => picture_response(shared, picture),
    };
    let status = response.status_code().0;
    if status >= 400 {
        tracing::debug!(status, url = request.url(), "request refused");
    }
    // A browser that went away is no error of ours.
    if let Err(e) = request.respond(response) {
        tracing::debug!(error = %e, "the client went away before the answer was sent");
    }
}

fn picture_response(shared: &Shared, picture: Picture) -> Response<std::io::Cursor<Vec<u8>>> {
    let Some(snapshot) = shared.snapshot() else {
        return text(
            503,
            format!(
                "503 Service Unavailable: no frame from {} yet (is deard running and \
                 publishing there? `dear list` shows the frame services)\n",
                shared.service
            ),
        )
        .with_header(header("Retry-After", "1"));
    };
    match shared.cache.get(picture, &snapshot, shared.depth_range) {
        Ok(encoded) => {
            let mut response = common(
                Response::from_data(encoded.jpeg.as_ref().clone())
                    .with_header(header("Content-Type", "image/jpeg"))
                    .with_header(header("X-Frame-Id", &encoded.frame_id.to_string()))
                    .with_header(header("X-Snapshot", &encoded.snapshot.to_string())),
            );
            if let Some((near, far)) = encoded.depth_range {
                response =
                    response.with_header(header("X-Depth-Range", &format!("{near:.3} {far:.3}")));
            }
            response
        }
        Err(e) => text(
            500,
            format!("500 Internal Server Error: cannot draw {picture:?}: {e}\n"),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn routes() {
        assert_eq!(route(&Method::Get, "/"), Route::Page);
        assert_eq!(route(&Method::Head, "/index.html"), Route::Page);
        assert_eq!(route(&Method::Get, "/status.json?x=1"), Route::Status);
        assert_eq!(
            route(&Method::Get, "/depth.jpg?n=42"),
            Route::Picture(Picture::Depth)
        );
        assert_eq!(
            route(&Method::Get, "/confidence.jpg"),
            Route::Picture(Picture::Confidence)
        );
        for bad in ["/depth.png", "/../etc/passwd", "", "/status.json/", "//"] {
            assert_eq!(route(&Method::Get, bad), Route::NotFound, "{bad}");
        }
        for m in [Method::Post, Method::Put, Method::Delete, Method::Options] {
            assert_eq!(route(&m, "/"), Route::MethodNotAllowed);
        }
        let long = format!("/{}", "a".repeat(MAX_URL));
        assert_eq!(route(&Method::Get, &long), Route::UrlTooLong);
    }

    #[test]
    fn viewers_are_limited_by_address_and_idle_ones_are_forgotten() {
        let mut v = Viewers::new(2);
        let t0 = Instant::now();
        let ip = |n: u8| Some(IpAddr::from([10, 0, 0, n]));
        assert!(v.admit(ip(1), t0));
        assert!(v.admit(ip(2), t0));
        assert!(!v.admit(ip(3), t0 + Duration::from_secs(1)));
        // Known viewers keep being served.
        assert!(v.admit(ip(1), t0 + Duration::from_secs(9)));
        // ip 2 idle for 10 s: its place is free.
        assert!(v.admit(ip(3), t0 + Duration::from_secs(10)));
        assert!(!v.admit(ip(2), t0 + Duration::from_secs(11)));
    }
}
