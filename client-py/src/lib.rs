//! `dear._dear`: the Python binding of [`dear_client`] (the package `dear` re-exports it).
//!
//! Zero copy: a received sample is owned by a private `_Sample` object; `Frame.depth`, `.rgb`
//! and `.confidence` are read-only numpy arrays over the sample's shared memory whose `base` is
//! that object, so every array keeps the sample alive, whatever happens to its `Frame` or the
//! `Subscriber`. `Frame.release()` drops the frame's own reference only.
//!
//! Threads: iceoryx2's ports and samples are single-threaded (the transport's `Rc`-based
//! policy), so `Subscriber` and `_Sample` are `unsendable`: used from another thread they raise,
//! and one whose last reference goes away on another thread is leaked (with a warning) rather
//! than dropped there. `Frame`, `Header` and the arrays may be used from any thread: a frame
//! keeps plain pointers into the sample and only touches `_Sample`'s reference count.

use std::error::Error;
use std::time::{Duration, Instant};

use dear_client::ReceiveError as ClientReceiveError;
use dear_client::{ChannelEvent, Client, FrameHeader, ReconnectingClient, Stage};
use dear_proto::service::QOS_SUBSCRIBER_BORROWED;
use iceoryx2::port::listener::ListenerWaitError;
use ndarray::{ArrayView2, ArrayView3, Dimension};
use numpy::npyffi::NPY_ARRAY_WRITEABLE;
use numpy::{PyArray, PyArray2, PyArray3, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

create_exception!(
    dear,
    DearError,
    PyException,
    "Base class of the errors of the dear package."
);
create_exception!(
    dear,
    ConnectError,
    DearError,
    "Subscribing to a frame service failed (bad service name, iceoryx2 root, contract, limits)."
);
create_exception!(
    dear,
    ReceiveError,
    DearError,
    "Receiving or waiting for a frame failed."
);
create_exception!(
    dear,
    PointCloudError,
    DearError,
    "A frame's point cloud cannot be made: it carries no (or unusable) intrinsics."
);

/// The default service of camera `cam0`.
const DEFAULT_SERVICE: &str = "dear/cam0/frames";

/// How long the GIL is released at a time while waiting: Ctrl-C is seen within this.
const WAIT_SLICE: Duration = Duration::from_millis(100);

/// `error: source: source…`: the whole Rust error chain as one message.
fn chain(error: &dyn Error) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        message.push_str(": ");
        message.push_str(&e.to_string());
        source = e.source();
    }
    message
}

fn receive_error(error: &ClientReceiveError) -> PyErr {
    let mut message = chain(error);
    if let ClientReceiveError::Receive {
        source: iceoryx2::port::ReceiveError::ExceedsMaxBorrows,
        ..
    } = error
    {
        message.push_str(&format!(
            " (a subscriber holds at most {QOS_SUBSCRIBER_BORROWED} frames at once: release() \
             frames, or drop them and their arrays, before receiving more)"
        ));
    }
    ReceiveError::new_err(message)
}

/// Lets a closure run with the GIL released (`Python::detach`) use the subscriber: sound
/// because `detach` runs it on this very thread, before returning, and `Subscriber` and
/// `_Sample` are `unsendable` (no other thread can use the port meanwhile).
struct OnThisThread<T>(T);
// SAFETY: see the type's documentation: the value never leaves the calling thread.
unsafe impl<T> Send for OnThisThread<T> {}
impl<T> OnThisThread<T> {
    fn into_inner(self) -> T {
        self.0
    }
}

/// Owns one received sample; the `base` of every array over it. Private (`dear._Sample`).
#[pyclass(unsendable, module = "dear", name = "_Sample")]
struct Sample {
    _frame: dear_client::Frame,
}

/// The header of one frame (a copy of the 256-byte `DearFrameHeader`; docs/protocol.md,
/// "Frame layout").
#[pyclass(frozen, module = "dear", name = "Header")]
struct Header(FrameHeader);

#[pymethods]
impl Header {
    /// Frame number from the source (restarts when a replay loops or the daemon restarts).
    #[getter]
    fn frame_id(&self) -> u64 {
        self.0.frame_id
    }
    /// Format version of the header (3).
    #[getter]
    fn version(&self) -> u32 {
        self.0.version
    }
    /// Capture time given by the source, ns (replay: the recorded timestamp).
    #[getter]
    fn capture_timestamp_ns(&self) -> u64 {
        self.0.capture_timestamp_ns
    }
    /// `CLOCK_MONOTONIC` at publication, ns: compare with `time.monotonic_ns()`.
    #[getter]
    fn publish_timestamp_ns(&self) -> u64 {
        self.0.publish_timestamp_ns
    }
    #[getter]
    fn width(&self) -> u32 {
        self.0.width
    }
    #[getter]
    fn height(&self) -> u32 {
        self.0.height
    }
    /// Calibration used (flow model `W = t/z + c`): t_x, px·m.
    #[getter]
    fn calib_tx(&self) -> f32 {
        self.0.calib_tx
    }
    /// t_y, px·m.
    #[getter]
    fn calib_ty(&self) -> f32 {
        self.0.calib_ty
    }
    /// c_x, px.
    #[getter]
    fn calib_cx(&self) -> f32 {
        self.0.calib_cx
    }
    /// c_y, px.
    #[getter]
    fn calib_cy(&self) -> f32 {
        self.0.calib_cy
    }
    /// RMS residual of the last calibration fit, px; NaN when static or fitted to edges.
    #[getter]
    fn calib_residual_px(&self) -> f32 {
        self.0.calib_residual_px
    }
    /// Quality of the calibration estimate in [0, 1]; 0 = static / unknown.
    #[getter]
    fn calib_quality(&self) -> f32 {
        self.0.calib_quality
    }
    /// Frames since the calibration was last estimated.
    #[getter]
    fn calib_age_frames(&self) -> u32 {
        self.0.calib_age_frames
    }
    /// Calibration health: `"unknown"`, `"good"`, `"can improve"` or `"needs recalibration"`
    /// (docs/calibration-health.md).
    #[getter]
    fn calib_health(&self) -> &'static str {
        self.0.calibration_health().name()
    }
    /// The header's calibration health byte: 0 unknown, 1 good, 2 can improve, 3 needs
    /// recalibration.
    #[getter]
    fn calib_health_code(&self) -> u8 {
        self.0.calib_health
    }
    /// Directions of (t_x, t_y, c_x, c_y) the last calibration measurement constrained, 0–4.
    #[getter]
    fn calib_constrained(&self) -> u8 {
        self.0.calib_constrained
    }
    /// Processing flags: `dear.FLAG_*` bits.
    #[getter]
    fn flags(&self) -> u32 {
        self.0.flags
    }
    /// Name of the model bundle that refined the frame; `""` when none.
    #[getter]
    fn bundle(&self) -> &str {
        self.0.bundle_name()
    }
    /// Latency of each pipeline stage in µs (0 = not run), in pipeline order.
    #[getter]
    fn stage_latency_us<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let dict = PyDict::new(py);
        for stage in Stage::ALL {
            dict.set_item(stage.name(), self.0.latency_us(stage))?;
        }
        Ok(dict)
    }
    /// Bad input frames the daemon skipped since it started.
    #[getter]
    fn frames_skipped(&self) -> u64 {
        self.0.frames_skipped
    }
    /// Frames the daemon dropped because processing fell behind, since it started.
    #[getter]
    fn frames_dropped(&self) -> u64 {
        self.0.frames_dropped
    }
    /// Random id of the publisher instance (a new value: the daemon restarted).
    #[getter]
    fn run_id(&self) -> u64 {
        self.0.run_id
    }
    /// Samples this publisher instance sent before this one; a gap is frames this client lost.
    #[getter]
    fn sequence(&self) -> u64 {
        self.0.sequence
    }
    /// Metres per depth unit: 1.0 (the depth is float32 metres).
    #[getter]
    fn depth_unit_m(&self) -> f32 {
        self.0.depth_unit_m
    }
    /// The header's camera model code: 0 unknown, 1 pinhole, 2 Brown–Conrady.
    #[getter]
    fn rgb_camera_model(&self) -> u16 {
        self.0.rgb_camera_model
    }
    /// The RGB camera's intrinsics at the frame's size (the depth's too: it is aligned to the
    /// RGB grid): `{"fx", "fy", "cx", "cy", "model", "distortion"}` with `model` `"pinhole"`
    /// (`distortion` None) or `"brown_conrady"` (`distortion` = (k1, k2, p1, p2, k3)); None when
    /// the publisher knows none. Raises `PointCloudError` for unusable numbers (names the field).
    #[getter]
    fn intrinsics<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(k) = self
            .0
            .intrinsics()
            .map_err(|e| PointCloudError::new_err(e.to_string()))?
        else {
            return Ok(None);
        };
        let dict = PyDict::new(py);
        dict.set_item("fx", k.fx)?;
        dict.set_item("fy", k.fy)?;
        dict.set_item("cx", k.cx)?;
        dict.set_item("cy", k.cy)?;
        match k.distortion {
            None => {
                dict.set_item("model", "pinhole")?;
                dict.set_item("distortion", py.None())?;
            }
            Some(d) => {
                dict.set_item("model", "brown_conrady")?;
                dict.set_item("distortion", PyTuple::new(py, d)?)?;
            }
        }
        Ok(Some(dict))
    }

    fn __repr__(&self) -> String {
        let h = &self.0;
        format!(
            "Header(frame_id={}, {}x{}, run_id={:#x}, sequence={}, flags={:#x}, bundle={:?})",
            h.frame_id,
            h.width,
            h.height,
            h.run_id,
            h.sequence,
            h.flags,
            h.bundle_name()
        )
    }
}

/// Where the planes of a received sample are; valid while `owner` lives.
struct Planes {
    owner: Py<Sample>,
    height: usize,
    width: usize,
    depth: *const f32,
    rgb: *const u8,
    confidence: *const u8,
}

// SAFETY: the pointers are only read, through arrays that hold a reference to `owner` (so the
// sample, and with it the mapping, outlives them); `Py<Sample>` itself is Send and Sync (only
// its reference count is touched off the sample's thread; see the module documentation).
unsafe impl Send for Planes {}
// SAFETY: as for Send above: shared references only read through the pointers.
unsafe impl Sync for Planes {}

/// One received frame.
#[pyclass(module = "dear", name = "Frame")]
struct Frame {
    header: Py<Header>,
    planes: Option<Planes>,
}

/// A read-only array over `view`'s memory whose `base` is `owner`.
///
/// # Safety
///
/// `view` must point into memory that lives as long as `owner`.
unsafe fn borrowed<'py, T: numpy::Element, D: Dimension>(
    view: ndarray::ArrayView<'_, T, D>,
    owner: &Py<Sample>,
    py: Python<'py>,
) -> Bound<'py, PyArray<T, D>> {
    // SAFETY: the caller's promise; the array holds a reference to `owner` (its base).
    let array = unsafe { PyArray::borrow_from_array(&view, owner.bind(py).clone().into_any()) };
    // Shared memory other subscribers read too: never writeable. numpy refuses to set the
    // flag back (the base does not export a writable buffer).
    // SAFETY: a freshly made array, not yet shared with Python code.
    unsafe { (*array.as_array_ptr()).fields.flags &= !NPY_ARRAY_WRITEABLE };
    array
}

impl Frame {
    fn new(py: Python<'_>, frame: dear_client::Frame) -> PyResult<Self> {
        let header = Py::new(py, Header(*frame.header()))?;
        let (width, height) = frame.size();
        let (depth, rgb, confidence) = (
            frame.depth().as_ptr(),
            frame.rgb().as_ptr(),
            frame.confidence().as_ptr(),
        );
        // Moving the frame does not move the shared memory its planes are in.
        let owner = Py::new(py, Sample { _frame: frame })?;
        Ok(Frame {
            header,
            planes: Some(Planes {
                owner,
                height,
                width,
                depth,
                rgb,
                confidence,
            }),
        })
    }

    fn planes(&self) -> PyResult<&Planes> {
        self.planes.as_ref().ok_or_else(|| {
            PyValueError::new_err(
                "the frame was released; arrays taken from it before release() stay valid",
            )
        })
    }
}

#[pymethods]
impl Frame {
    /// The frame's header (a copy; available after `release()` too).
    #[getter]
    fn header(&self, py: Python<'_>) -> Py<Header> {
        self.header.clone_ref(py)
    }

    /// Aligned refined depth, float32 (H, W), metres, 0 = invalid. A read-only view of the
    /// shared-memory sample (no copy); the array keeps the sample alive.
    #[getter]
    fn depth<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let p = self.planes()?;
        // SAFETY: `Frame::new` took the pointer and size from the validated frame that `owner`
        // holds; `borrowed` makes the array keep `owner` alive.
        unsafe {
            let view = ArrayView2::from_shape_ptr((p.height, p.width), p.depth);
            Ok(borrowed(view, &p.owner, py))
        }
    }

    /// RGB, uint8 (H, W, 3). A read-only view of the sample, as `depth`.
    #[getter]
    fn rgb<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let p = self.planes()?;
        // SAFETY: as in `depth`.
        unsafe {
            let view = ArrayView3::from_shape_ptr((p.height, p.width, 3), p.rgb);
            Ok(borrowed(view, &p.owner, py))
        }
    }

    /// Per-pixel confidence, uint8 (H, W): 0 = invalid, 255 = measured and kept. A read-only
    /// view of the sample, as `depth`.
    #[getter]
    fn confidence<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<u8>>> {
        let p = self.planes()?;
        // SAFETY: as in `depth`.
        unsafe {
            let view = ArrayView2::from_shape_ptr((p.height, p.width), p.confidence);
            Ok(borrowed(view, &p.owner, py))
        }
    }

    /// The frame's point cloud from its header's intrinsics, by the Rust SDK's
    /// `dear_client::points` (pinhole, Brown–Conrady distortion undone per pixel). Organised:
    /// one entry per pixel, row-major (`i = v·W + u`; `reshape(H, W, 3)` gives the image
    /// layout). `points` float32 (N, 3) metres in the RGB camera's optical frame (x right, y
    /// down, z forward), NaN where `valid` (bool (N,)) is False — no valid depth, never a point
    /// at the origin; `colors` uint8 (N, 3) and `confidence` uint8 (N,) when asked for, else
    /// None. `points[valid]` is the measured cloud. Copies (not views of shared memory). Raises
    /// `PointCloudError` when the frame carries no intrinsics, ValueError after `release()`.
    #[pyo3(signature = (*, colors = false, confidence = false))]
    fn point_cloud(&self, py: Python<'_>, colors: bool, confidence: bool) -> PyResult<PointCloud> {
        let p = self.planes()?;
        let n = p.height * p.width;
        // SAFETY: `Frame::new` took the pointers and size from the validated frame that
        // `p.owner` holds, alive while `self` (and so `p`) is borrowed here.
        let (depth, rgb, conf) = unsafe {
            (
                std::slice::from_raw_parts(p.depth, n),
                std::slice::from_raw_parts(p.rgb, 3 * n),
                std::slice::from_raw_parts(p.confidence, n),
            )
        };
        let options = dear_client::PointCloudOptions { colors, confidence };
        let cloud =
            dear_client::points::point_cloud(&self.header.get().0, depth, rgb, conf, options)
                .map_err(|e| PointCloudError::new_err(chain(&e)))?;
        let points = ndarray::Array2::from_shape_vec((n, 3), cloud.points.into_flattened())
            .expect("n points of 3");
        Ok(PointCloud {
            points: numpy::PyArray2::from_owned_array(py, points)
                .into_any()
                .unbind(),
            valid: numpy::PyArray1::from_vec(py, cloud.valid)
                .into_any()
                .unbind(),
            colors: cloud.colors.map(|c| {
                let c = ndarray::Array2::from_shape_vec((n, 3), c.into_flattened())
                    .expect("n colours of 3");
                numpy::PyArray2::from_owned_array(py, c).into_any().unbind()
            }),
            confidence: cloud
                .confidence
                .map(|c| numpy::PyArray1::from_vec(py, c).into_any().unbind()),
            width: p.width,
            height: p.height,
        })
    }

    /// `(height, width)`.
    #[getter]
    fn shape(&self) -> (u32, u32) {
        let h = &self.header.get().0;
        (h.height, h.width)
    }

    /// Whether `release()` was called.
    #[getter]
    fn released(&self) -> bool {
        self.planes.is_none()
    }

    /// Drops this frame's reference to its sample. The sample goes back to the subscriber
    /// once no array taken from this frame is left either. Idempotent.
    fn release(&mut self) {
        self.planes = None;
    }

    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&mut self, _args: &Bound<'_, PyTuple>) -> bool {
        self.release();
        false
    }

    fn __repr__(&self) -> String {
        let h = &self.header.get().0;
        format!(
            "Frame(frame_id={}, sequence={}, {}x{}{})",
            h.frame_id,
            h.sequence,
            h.width,
            h.height,
            if self.planes.is_none() {
                ", released"
            } else {
                ""
            }
        )
    }
}

/// A frame's point cloud (`Frame.point_cloud`): numpy arrays owned by this object.
#[pyclass(frozen, module = "dear", name = "PointCloud")]
struct PointCloud {
    /// float32 (N, 3), metres; NaN where not valid.
    #[pyo3(get)]
    points: Py<PyAny>,
    /// bool (N,): the pixel has valid depth (and a ray).
    #[pyo3(get)]
    valid: Py<PyAny>,
    /// uint8 (N, 3) or None.
    #[pyo3(get)]
    colors: Option<Py<PyAny>>,
    /// uint8 (N,) or None.
    #[pyo3(get)]
    confidence: Option<Py<PyAny>>,
    /// The frame's width: N = width·height.
    #[pyo3(get)]
    width: usize,
    #[pyo3(get)]
    height: usize,
}

#[pymethods]
impl PointCloud {
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let valid = self.valid.bind(py).call_method0("sum")?;
        Ok(format!(
            "PointCloud({}x{}, {} valid points{}{})",
            self.width,
            self.height,
            valid,
            if self.colors.is_some() {
                ", colors"
            } else {
                ""
            },
            if self.confidence.is_some() {
                ", confidence"
            } else {
                ""
            }
        ))
    }
}

/// A subscriber's channel: a plain client, or the SDK's reconnecting one (`reconnect=True`).
enum Channel {
    Plain(Client),
    /// `RefCell`: its waits change its state, and the class's methods take `&self`.
    Reconnecting(std::cell::RefCell<ReconnectingClient>),
}

impl Channel {
    fn wait(&self, timeout: Duration) -> Result<Option<dear_client::Frame>, ClientReceiveError> {
        match self {
            Channel::Plain(client) => client.wait(timeout),
            Channel::Reconnecting(client) => client.borrow_mut().wait(timeout),
        }
    }
}

/// A subscription to one `deard` frame service.
#[pyclass(unsendable, module = "dear", name = "Subscriber")]
struct Subscriber {
    service: String,
    client: Option<Channel>,
}

impl Subscriber {
    fn client(&self) -> PyResult<&Channel> {
        self.client.as_ref().ok_or_else(|| {
            PyValueError::new_err(format!("the subscriber of {:?} is closed", self.service))
        })
    }

    /// Waits until `deadline` (`None`: forever) with the GIL released, in slices, so that
    /// Ctrl-C (any Python signal handler) interrupts the wait.
    fn receive(&self, py: Python<'_>, deadline: Option<Instant>) -> PyResult<Option<Frame>> {
        let client = self.client()?;
        loop {
            let slice = match deadline {
                Some(deadline) => deadline
                    .saturating_duration_since(Instant::now())
                    .min(WAIT_SLICE),
                None => WAIT_SLICE,
            };
            let port = OnThisThread(client);
            let result = py
                .detach(move || OnThisThread(port.into_inner().wait(slice)))
                .into_inner();
            match result {
                Ok(Some(frame)) => return Frame::new(py, frame).map(Some),
                Ok(None) => {}
                // A signal interrupted the wait: its Python handler runs below.
                Err(ClientReceiveError::Wait {
                    source: ListenerWaitError::InterruptSignal,
                    ..
                }) => {}
                Err(e) => {
                    py.check_signals()?;
                    return Err(receive_error(&e));
                }
            }
            py.check_signals()?;
            if deadline.is_some_and(|d| Instant::now() >= d) {
                return Ok(None);
            }
        }
    }
}

#[pymethods]
impl Subscriber {
    /// Subscribes to `service` under the iceoryx2 root of `$DEAR_IOX2_ROOT` (else
    /// `/dev/shm/dear`). Works whether or not the daemon runs yet. Raises `ConnectError`.
    /// With `reconnect=True` the subscription outlives a damaged channel and a service the
    /// daemon made again (the SDK's `ReconnectingClient`): a channel that was corrupted, or
    /// delivered nothing for `stall_s` seconds, is dropped and connected again; meanwhile
    /// waits time out as on an idle stream. `reconnects` and `take_events()` say what happened.
    #[new]
    #[pyo3(signature = (service = DEFAULT_SERVICE, *, reconnect = false, stall_s = 3.0))]
    fn new(service: &str, reconnect: bool, stall_s: f64) -> PyResult<Self> {
        let client = if reconnect {
            let stall = Duration::try_from_secs_f64(stall_s)
                .ok()
                .filter(|d| !d.is_zero())
                .ok_or_else(|| {
                    PyValueError::new_err(format!(
                        "stall_s must be a finite number > 0, not {stall_s}"
                    ))
                })?;
            let mut client = ReconnectingClient::connect(service)
                .map_err(|e| ConnectError::new_err(chain(&e)))?;
            client.set_stall_timeout(stall);
            Channel::Reconnecting(std::cell::RefCell::new(client))
        } else {
            Channel::Plain(Client::connect(service).map_err(|e| ConnectError::new_err(chain(&e)))?)
        };
        Ok(Subscriber {
            service: service.to_string(),
            client: Some(client),
        })
    }

    /// How many times the channel was connected again (0 without `reconnect=True`).
    #[getter]
    fn reconnects(&self) -> u64 {
        match &self.client {
            Some(Channel::Reconnecting(client)) => client.borrow().reconnects(),
            _ => 0,
        }
    }

    /// What happened to the channel since the last call, oldest first: `("lost", reason)`
    /// or `("connected", "")` (always empty without `reconnect=True`).
    fn take_events(&self) -> Vec<(&'static str, String)> {
        let Some(Channel::Reconnecting(client)) = &self.client else {
            return Vec::new();
        };
        client
            .borrow_mut()
            .take_events()
            .into_iter()
            .map(|event| match event {
                ChannelEvent::Lost { reason } => ("lost", reason),
                ChannelEvent::Connected => ("connected", String::new()),
            })
            .collect()
    }

    /// The service name.
    #[getter]
    fn service(&self) -> &str {
        &self.service
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.client.is_none()
    }

    /// Waits up to `timeout_s` seconds for the next frame; `None` on timeout. The GIL is
    /// released while waiting. Raises `ReceiveError`.
    fn wait(&self, py: Python<'_>, timeout_s: f64) -> PyResult<Option<Frame>> {
        let timeout = Duration::try_from_secs_f64(timeout_s).map_err(|_| {
            PyValueError::new_err(format!(
                "timeout_s must be a finite number >= 0, not {timeout_s}"
            ))
        })?;
        // Past what an Instant can hold: wait forever.
        self.receive(py, Instant::now().checked_add(timeout))
    }

    /// The next queued frame, if any, without waiting. Raises `ReceiveError`.
    fn try_receive(&self, py: Python<'_>) -> PyResult<Option<Frame>> {
        self.receive(py, Some(Instant::now()))
    }

    /// Unsubscribes. Frames and arrays already received stay valid. Idempotent.
    fn close(&mut self) {
        self.client = None;
    }

    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&mut self, _args: &Bound<'_, PyTuple>) -> bool {
        self.close();
        false
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    /// Waits without a time limit for the next frame; iteration ends when the subscriber is
    /// closed.
    fn __next__(&self, py: Python<'_>) -> PyResult<Option<Frame>> {
        if self.client.is_none() {
            return Ok(None);
        }
        self.receive(py, None)
    }

    fn __repr__(&self) -> String {
        format!(
            "Subscriber({:?}{})",
            self.service,
            if self.client.is_none() {
                ", closed"
            } else {
                ""
            }
        )
    }
}

#[pymodule]
fn _dear(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    // As the dear CLI: iceoryx2's own log only for errors unless IOX2_LOG_LEVEL says otherwise
    // (every failure it reports also reaches Python as an exception naming the service).
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    m.add_class::<Subscriber>()?;
    m.add_class::<Frame>()?;
    m.add_class::<Header>()?;
    m.add_class::<PointCloud>()?;
    m.add("PointCloudError", py.get_type::<PointCloudError>())?;
    m.add("DearError", py.get_type::<DearError>())?;
    m.add("ConnectError", py.get_type::<ConnectError>())?;
    m.add("ReceiveError", py.get_type::<ReceiveError>())?;
    m.add("DEFAULT_SERVICE", DEFAULT_SERVICE)?;
    m.add("MAX_BORROWED_FRAMES", QOS_SUBSCRIBER_BORROWED)?;
    m.add("FORMAT_VERSION", dear_proto::FORMAT_VERSION)?;
    m.add("CAMERA_MODEL_UNKNOWN", dear_proto::camera_model::UNKNOWN)?;
    m.add("CAMERA_MODEL_PINHOLE", dear_proto::camera_model::PINHOLE)?;
    m.add(
        "CAMERA_MODEL_BROWN_CONRADY",
        dear_proto::camera_model::BROWN_CONRADY,
    )?;
    use dear_client::flags;
    for (name, bit) in [
        ("FLAG_ALIGNED", flags::ALIGNED),
        ("FLAG_REFINED_NETWORK", flags::REFINED_NETWORK),
        ("FLAG_REFINED_CLASSICAL", flags::REFINED_CLASSICAL),
        ("FLAG_CALIBRATION_ESTIMATED", flags::CALIBRATION_ESTIMATED),
        ("FLAG_CALIBRATION_ONLINE", flags::CALIBRATION_ONLINE),
        (
            "FLAG_NETWORK_OUTPUT_REJECTED",
            flags::NETWORK_OUTPUT_REJECTED,
        ),
        (
            "FLAG_CONFIDENCE_EXPECTED_ERROR",
            flags::CONFIDENCE_EXPECTED_ERROR,
        ),
    ] {
        m.add(name, bit)?;
    }
    // The expected-error code's constants; `dear.expected_error_m` decodes with them.
    m.add(
        "ERROR_CODE_UNIT_M",
        dear_client::confidence::ERROR_CODE_UNIT_M,
    )?;
    m.add(
        "ERROR_CODE_STEPS_PER_DOUBLING",
        dear_client::confidence::ERROR_CODE_STEPS_PER_DOUBLING,
    )?;
    Ok(())
}
