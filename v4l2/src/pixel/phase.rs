//! Host-side demodulation of 4-phase (4-tap) AMCW ToF raw frames, as delivered by modules that
//! leave depth to the host (Arducam ToF: `Y12 ` on a Raspberry Pi 4, `Y12P` on a Pi 5, four
//! consecutive buffers per depth image; Arducam VGA ToF: `Y12P` with the four phase images
//! stacked vertically in one buffer).
//!
//! With `D₀..D₃` the correlation images at reference phases 0°, 90°, 180°, 270°:
//! `I = D₀ − D₂`, `Q = ±(D₁ − D₃)` ([`QSign`]), phase `φ = atan2(Q, I)` wrapped to `[0, 2π)`,
//! amplitude `½·√(I² + Q²)` (sample units) and radial distance `r = c·φ / (4π·f)`, unambiguous
//! up to `c / 2f`. This is exactly `dear_synth::sensor`'s demodulation, so simulated phase
//! frames decode to the simulator's distances.

use ndarray::{Array2, ArrayView2, ArrayViewMut2, Zip};

use super::depth::for_each_sample;
use super::{check_output, DecodeError, FrameFormat, PixelFormat};

/// Speed of light in vacuum, m/s (as `dear_synth::transport::SPEED_OF_LIGHT`).
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// The sign of the quadrature component, which differs between modules because their
/// 90° and 270° taps are defined against opposite reference directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QSign {
    /// `Q = D₁ − D₃`: tap `k` correlates with `cos(φ − k·π/2)` (the textbook 4-tap model and
    /// `dear_synth::sensor`, whose tap `k` collects `Re(P·e^{−i·k·π/2})`).
    Standard,
    /// `Q = D₃ − D₁`: the Arducam ToF modules, whose SDK documents
    /// `phase = atan2(I3 − I1, I0 − I2)`.
    Inverted,
}

/// How raw phase frames become distances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseParams {
    /// Modulation frequency, Hz (Arducam ToF: 75 MHz for its 2 m range, 37.5 MHz for 4 m).
    pub modulation_hz: f64,
    pub q_sign: QSign,
    /// Pixels whose amplitude (sample units) is below this get distance 0 (invalid): their
    /// phase is mostly noise. 0 keeps every pixel with any signal.
    pub min_amplitude: f32,
}

impl PhaseParams {
    /// The largest distance the phase can express, `c / 2f`, metres.
    pub fn unambiguous_range_m(&self) -> f64 {
        SPEED_OF_LIGHT / (2.0 * self.modulation_hz)
    }

    fn check(&self) -> Result<(), DecodeError> {
        if !(self.modulation_hz.is_finite() && self.modulation_hz > 0.0) {
            return Err(DecodeError::InvalidParameter(format!(
                "modulation frequency must be positive and finite, got {} Hz",
                self.modulation_hz
            )));
        }
        if !(self.min_amplitude.is_finite() && self.min_amplitude >= 0.0) {
            return Err(DecodeError::InvalidParameter(format!(
                "minimum amplitude must be non-negative and finite, got {}",
                self.min_amplitude
            )));
        }
        Ok(())
    }
}

/// One demodulated ToF image.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseImage {
    /// Radial distance along each pixel's ray, metres; 0 = invalid.
    pub radial: Array2<f32>,
    /// Amplitude `½·√(I² + Q²)`, raw sample units.
    pub amplitude: Array2<f32>,
}

/// The formats raw phase frames come in.
const PHASE_FORMATS: [PixelFormat; 2] = [PixelFormat::Y12, PixelFormat::Y12P];

/// Demodulates one pixel: `(radial metres, amplitude)`.
#[inline]
fn demodulate(
    d: [f32; 4],
    q_sign: QSign,
    metres_per_radian: f32,
    min_amplitude: f32,
) -> (f32, f32) {
    let i = d[0] - d[2];
    let q = match q_sign {
        QSign::Standard => d[1] - d[3],
        QSign::Inverted => d[3] - d[1],
    };
    let amplitude = 0.5 * i.hypot(q);
    if amplitude <= 0.0 || amplitude < min_amplitude {
        return (0.0, amplitude);
    }
    let mut phase = q.atan2(i);
    if phase < 0.0 {
        phase += std::f32::consts::TAU;
    }
    // atan2 of a tiny negative Q rounds to exactly 2π after the shift; that is phase 0.
    if phase >= std::f32::consts::TAU {
        phase = 0.0;
    }
    (phase * metres_per_radian, amplitude)
}

/// Demodulates four phase images (raw sample values, `D₀..D₃`) already in memory.
pub fn demodulate_planes_into(
    phases: [ArrayView2<f32>; 4],
    params: &PhaseParams,
    mut radial: ArrayViewMut2<f32>,
    mut amplitude: ArrayViewMut2<f32>,
) -> Result<(), DecodeError> {
    params.check()?;
    let dim = phases[0].dim();
    for p in &phases[1..] {
        check_output(dim, p.dim())?;
    }
    check_output(dim, radial.dim())?;
    check_output(dim, amplitude.dim())?;
    let mpr = metres_per_radian(params);
    let [d0, d1, d2, d3] = phases;
    Zip::from(&mut radial)
        .and(&mut amplitude)
        .and(&d0)
        .and(&d1)
        .and(&d2)
        .and(&d3)
        .for_each(|r, a, &p0, &p1, &p2, &p3| {
            (*r, *a) = demodulate([p0, p1, p2, p3], params.q_sign, mpr, params.min_amplitude);
        });
    Ok(())
}

fn metres_per_radian(params: &PhaseParams) -> f32 {
    (SPEED_OF_LIGHT / (4.0 * std::f64::consts::PI * params.modulation_hz)) as f32
}

/// Demodulates four consecutive raw buffers (`frames[k]` = the `k·90°` image), each of
/// `frame`'s format (`Y12 ` or `Y12P`) and size: the Arducam ToF layout. The caller tells which
/// buffer is the 0° one (from the driver's sequence numbers or the module's frame tags).
pub fn demodulate_frames_into(
    frame: &FrameFormat,
    frames: [&[u8]; 4],
    params: &PhaseParams,
    radial: ArrayViewMut2<f32>,
    amplitude: ArrayViewMut2<f32>,
) -> Result<(), DecodeError> {
    frame.require(&PHASE_FORMATS, "4-phase ToF frames")?;
    params.check()?;
    for data in frames {
        frame.layout(data)?;
    }
    demodulate_rows(
        frame,
        frame.height,
        |k, y| (frames[k], y),
        params,
        radial,
        amplitude,
    )
}

/// [`demodulate_frames_into`] into new arrays.
pub fn demodulate_frames(
    frame: &FrameFormat,
    frames: [&[u8]; 4],
    params: &PhaseParams,
) -> Result<PhaseImage, DecodeError> {
    let mut image = PhaseImage::zeros(frame.height, frame.width);
    demodulate_frames_into(
        frame,
        frames,
        params,
        image.radial.view_mut(),
        image.amplitude.view_mut(),
    )?;
    Ok(image)
}

/// Demodulates one buffer holding the four phase images stacked vertically (0° on top), as
/// the Arducam VGA ToF delivers them: `frame.height` is the buffer's height, four times the
/// image height, which is what the outputs must have.
pub fn demodulate_stacked_into(
    frame: &FrameFormat,
    data: &[u8],
    params: &PhaseParams,
    radial: ArrayViewMut2<f32>,
    amplitude: ArrayViewMut2<f32>,
) -> Result<(), DecodeError> {
    frame.require(&PHASE_FORMATS, "stacked 4-phase ToF frames")?;
    params.check()?;
    if !frame.height.is_multiple_of(4) {
        return Err(DecodeError::PhaseStack {
            format: frame.format,
            height: frame.height,
        });
    }
    frame.layout(data)?;
    let image_height = frame.height / 4;
    demodulate_rows(
        frame,
        image_height,
        |k, y| (data, k * image_height + y),
        params,
        radial,
        amplitude,
    )
}

/// [`demodulate_stacked_into`] into new arrays of a quarter of the buffer's height.
pub fn demodulate_stacked(
    frame: &FrameFormat,
    data: &[u8],
    params: &PhaseParams,
) -> Result<PhaseImage, DecodeError> {
    let mut image = PhaseImage::zeros(frame.height / 4, frame.width);
    demodulate_stacked_into(
        frame,
        data,
        params,
        image.radial.view_mut(),
        image.amplitude.view_mut(),
    )?;
    Ok(image)
}

impl PhaseImage {
    fn zeros(height: usize, width: usize) -> Self {
        PhaseImage {
            radial: Array2::zeros((height, width)),
            amplitude: Array2::zeros((height, width)),
        }
    }
}

/// The shared row loop: `source(k, y)` names the buffer and buffer row of phase `k`'s image
/// row `y`; every buffer has been checked against `frame` already. One row of each phase is
/// unpacked into a small reusable buffer, then demodulated.
fn demodulate_rows<'a>(
    frame: &FrameFormat,
    image_height: usize,
    source: impl Fn(usize, usize) -> (&'a [u8], usize),
    params: &PhaseParams,
    mut radial: ArrayViewMut2<f32>,
    mut amplitude: ArrayViewMut2<f32>,
) -> Result<(), DecodeError> {
    let (width, stride) = (frame.width, frame.bytes_per_line);
    check_output((image_height, width), radial.dim())?;
    check_output((image_height, width), amplitude.dim())?;
    let row_bytes = frame.format.min_bytes_per_line(width).unwrap_or_default();
    let mpr = metres_per_radian(params);
    // Per-row scratch: one row of each phase image, not whole images.
    let mut rows: [Vec<f32>; 4] = std::array::from_fn(|_| vec![0.0; width]);
    for y in 0..image_height {
        for (k, row_k) in rows.iter_mut().enumerate() {
            let (data, row) = source(k, y);
            let start = row * stride;
            for_each_sample(
                frame.format,
                &data[start..start + row_bytes],
                width,
                |x, v| row_k[x] = f32::from(v),
            );
        }
        for x in 0..width {
            let d = [rows[0][x], rows[1][x], rows[2][x], rows[3][x]];
            (radial[[y, x]], amplitude[[y, x]]) =
                demodulate(d, params.q_sign, mpr, params.min_amplitude);
        }
    }
    Ok(())
}

/// Pinhole intrinsics of the ToF camera, pixels, with pixel centres at integer coordinates
/// (the principal point of a centred `W×H` image is `((W−1)/2, (H−1)/2)`), the convention of
/// `dear_pipeline`'s `Intrinsics` and `dear_synth::scene::Camera`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Pinhole {
    /// The factor turning the radial distance along the ray through pixel `(u, v)` into
    /// z-depth: `1 / √(1 + ((u−cx)/fx)² + ((v−cy)/fy)²)`, the cosine of the ray's angle to the
    /// optical axis (`dear_synth::scene::Camera::radial_to_z`).
    pub fn radial_to_z(&self, u: f32, v: f32) -> f32 {
        let x = (u - self.cx) / self.fx;
        let y = (v - self.cy) / self.fy;
        1.0 / (1.0 + x * x + y * y).sqrt()
    }
}

/// Converts radial distances to z-depth in place (0 stays 0). The pipeline works with z-depth;
/// a ToF camera measures along each ray.
pub fn radial_to_z_in_place(mut distance: ArrayViewMut2<f32>, intrinsics: &Pinhole) {
    for ((v, u), d) in distance.indexed_iter_mut() {
        *d *= intrinsics.radial_to_z(u as f32, v as f32);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pixel::depth::pack_y12p;

    const F_75MHZ: f64 = 75e6;

    fn params(q_sign: QSign, min_amplitude: f32) -> PhaseParams {
        PhaseParams {
            modulation_hz: F_75MHZ,
            q_sign,
            min_amplitude,
        }
    }

    /// 12-bit samples as `Y12 ` rows of `bytes_per_line` (padding 0xEE).
    fn y12_bytes(samples: &[u16], width: usize, bytes_per_line: usize) -> Vec<u8> {
        let mut out = Vec::new();
        for row in samples.chunks_exact(width) {
            let start = out.len();
            for v in row {
                out.extend_from_slice(&v.to_le_bytes());
            }
            out.resize(start + bytes_per_line, 0xEE);
        }
        out
    }

    #[test]
    fn quarter_phases_map_to_quarter_ranges() {
        let p = params(QSign::Standard, 0.0);
        let range = p.unambiguous_range_m() as f32;
        // (D0, D1, D2, D3) for φ = 0, π/2, π, 3π/2 with offset 1000 and amplitude 500.
        let cases = [
            ([1500.0, 1000.0, 500.0, 1000.0], 0.0),
            ([1000.0, 1500.0, 1000.0, 500.0], 0.25),
            ([500.0, 1000.0, 1500.0, 1000.0], 0.5),
            ([1000.0, 500.0, 1000.0, 1500.0], 0.75),
        ];
        let mpr = metres_per_radian(&p);
        for (d, fraction) in cases {
            let (r, a) = demodulate(d, QSign::Standard, mpr, 0.0);
            assert!((r - fraction * range).abs() < 1e-5, "{d:?} → {r}");
            assert!((a - 500.0).abs() < 1e-3);
            // The Arducam sign mirrors the phase: φ → 2π − φ.
            let (r, _) = demodulate(d, QSign::Inverted, mpr, 0.0);
            let mirrored = if fraction == 0.0 { 0.0 } else { 1.0 - fraction };
            assert!((r - mirrored * range).abs() < 1e-5, "{d:?} → {r}");
        }
        assert!((range - 1.998_616_4).abs() < 1e-6);
    }

    #[test]
    fn weak_and_flat_pixels_are_invalid() {
        let mpr = metres_per_radian(&params(QSign::Standard, 0.0));
        // Amplitude 10 below a threshold of 20.
        let (r, a) = demodulate([1010.0, 1000.0, 990.0, 1000.0], QSign::Standard, mpr, 20.0);
        assert_eq!((r, a), (0.0, 10.0));
        // No modulation at all: no phase, even with the threshold off.
        let (r, a) = demodulate([700.0; 4], QSign::Standard, mpr, 0.0);
        assert_eq!((r, a), (0.0, 0.0));
    }

    #[test]
    fn frames_and_stack_reject_bad_input() {
        let frame = FrameFormat::unpadded(PixelFormat::Y12, 2, 1);
        let good = [0u8; 4];
        let p = params(QSign::Standard, 0.0);
        assert!(matches!(
            demodulate_frames(&frame, [&good, &good, &good[..3], &good], &p),
            Err(DecodeError::ShortBuffer {
                expected: 4,
                actual: 3,
                ..
            })
        ));
        let zero_f = PhaseParams {
            modulation_hz: 0.0,
            ..p
        };
        assert!(matches!(
            demodulate_frames(&frame, [&good; 4], &zero_f),
            Err(DecodeError::InvalidParameter(_))
        ));
        let z16 = FrameFormat::unpadded(PixelFormat::Z16, 2, 1);
        assert!(matches!(
            demodulate_frames(&z16, [&good; 4], &p),
            Err(DecodeError::UnsupportedFormat { .. })
        ));
        let stacked = FrameFormat::unpadded(PixelFormat::Y12P, 2, 6);
        assert_eq!(
            demodulate_stacked(&stacked, &[0; 18], &p).unwrap_err(),
            DecodeError::PhaseStack {
                format: PixelFormat::Y12P,
                height: 6
            }
        );
        let stacked = FrameFormat::unpadded(PixelFormat::Y12P, 2, 8);
        assert!(matches!(
            demodulate_stacked(&stacked, &[0; 23], &p),
            Err(DecodeError::ShortBuffer { expected: 24, .. })
        ));
        let mut small = Array2::zeros((1, 2));
        let mut amp = Array2::zeros((2, 2));
        assert!(matches!(
            demodulate_stacked_into(&stacked, &[0; 24], &p, small.view_mut(), amp.view_mut()),
            Err(DecodeError::OutputShape { .. })
        ));
    }

    #[test]
    fn y12_frames_and_y12p_stack_decode_the_same_pixels() {
        // 3×2 image; pixel i has phase i·π/3 + 0.2, offset 2000, amplitude 1000.
        let (w, h) = (3, 2);
        let mut phases = vec![vec![0u16; w * h]; 4];
        for i in 0..w * h {
            let phi = i as f64 * std::f64::consts::FRAC_PI_3 + 0.2;
            for (k, plane) in phases.iter_mut().enumerate() {
                let psi = k as f64 * std::f64::consts::FRAC_PI_2;
                plane[i] = (2000.0 + 1000.0 * (phi - psi).cos()).round() as u16;
            }
        }
        let p = params(QSign::Standard, 0.0);
        let y12: Vec<Vec<u8>> = phases.iter().map(|s| y12_bytes(s, w, 8)).collect();
        let frame = FrameFormat::new(PixelFormat::Y12, w, h, 8);
        let a = demodulate_frames(&frame, [&y12[0], &y12[1], &y12[2], &y12[3]], &p).unwrap();
        let stacked: Vec<u16> = phases.concat();
        let packed = pack_y12p(&stacked, w, 4 * h, 7).unwrap();
        let frame = FrameFormat::new(PixelFormat::Y12P, w, 4 * h, 7);
        let b = demodulate_stacked(&frame, &packed, &p).unwrap();
        assert_eq!(a, b);
        let planes: Vec<Array2<f32>> = phases
            .iter()
            .map(|s| Array2::from_shape_fn((h, w), |(y, x)| f32::from(s[y * w + x])))
            .collect();
        let mut c = PhaseImage::zeros(h, w);
        demodulate_planes_into(
            [
                planes[0].view(),
                planes[1].view(),
                planes[2].view(),
                planes[3].view(),
            ],
            &p,
            c.radial.view_mut(),
            c.amplitude.view_mut(),
        )
        .unwrap();
        assert_eq!(a, c);
        let range = p.unambiguous_range_m();
        for i in 0..w * h {
            let truth =
                (i as f64 * std::f64::consts::FRAC_PI_3 + 0.2) / std::f64::consts::TAU * range;
            let got = f64::from(a.radial[[i / w, i % w]]);
            // Rounding each tap to an integer moves φ by at most asin(√2 / 2000).
            assert!(
                (got - truth).abs() < 2e-3 * range,
                "pixel {i}: {got} vs {truth}"
            );
        }
    }

    #[test]
    fn radial_to_z_is_one_on_the_axis_and_the_cosine_off_it() {
        let k = Pinhole {
            fx: 100.0,
            fy: 50.0,
            cx: 1.0,
            cy: 1.0,
        };
        assert_eq!(k.radial_to_z(1.0, 1.0), 1.0);
        // (u, v) = (101, 51): x̂ = 1, ŷ = 1 → 1/√3.
        assert!((k.radial_to_z(101.0, 51.0) - 1.0 / 3f32.sqrt()).abs() < 1e-6);
        let mut d = Array2::from_elem((3, 3), 2.0f32);
        d[[0, 0]] = 0.0;
        radial_to_z_in_place(d.view_mut(), &k);
        assert_eq!(d[[0, 0]], 0.0);
        assert_eq!(d[[1, 1]], 2.0);
        let expected = 2.0 / (1.0f32 + 0.01 * 0.01 + 0.02 * 0.02).sqrt();
        assert!((d[[2, 2]] - expected).abs() < 1e-6);
    }
}
