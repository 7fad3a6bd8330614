//! The 4-phase decoder against the simulator's AMCW sensor (`dear_synth::sensor`).
//!
//! `dear_synth::sensor::sense` (noise off) gives the simulator's radial distance and z-depth of
//! each pixel. Its tap values are private (`measure`), so the raw phase frames are built here
//! from the same model, quoted from `synth/src/sensor.rs`: tap `k` (reference phase `k·π/2`)
//! collects `μ_k = κ·(B + S + Re(P·e^{−i·k·π/2}))` electrons, read out as `μ_k / g` DN. They are
//! rounded to 12 bits, packed as `Y12 ` (four buffers) and `Y12P` (stacked), decoded, and
//! compared with `sense`.
//!
//! Error bound. Rounding moves each tap by at most ½ DN, so `I = D₀ − D₂` and `Q = D₁ − D₃`
//! each by at most 1 DN: the phasor `(I, Q)`, of length `2A` (`A` the amplitude in DN), moves
//! by at most `√2` DN, which turns it by at most `asin(√2 / 2A)`. The distance error is
//! therefore at most `c / (4πf) · asin(√2 / 2A)`, plus `f32` rounding of the decoder
//! (≲ 1e-6 m at these distances); the amplitude error is at most `√2 / 2` DN. With the
//! amplitudes below (A ≥ 600 DN) and f = 75 MHz that is ≤ 0.38 mm.

use dear_synth::math::Complex;
use dear_synth::scene::Camera;
use dear_synth::sensor::{sense, unambiguous_range, SensorConfig};
use dear_synth::transport::{PixelSignal, SignalImage};
use dear_v4l2::pixel::depth::pack_y12p;
use dear_v4l2::pixel::phase::{
    demodulate_frames, demodulate_stacked, radial_to_z_in_place, PhaseParams, Pinhole, QSign,
    SPEED_OF_LIGHT,
};
use dear_v4l2::pixel::{FrameFormat, PixelFormat};

const WIDTH: usize = 8;
const HEIGHT: usize = 6;
const F_HZ: f64 = 75e6;
/// Electrons per unit signal and electrons per DN: taps reach ≈ κ·(B + S + |P|) / g =
/// 2000 · 2 = 4000 DN, near the top of the 12-bit range.
const KAPPA: f64 = 8_000.0;
const GAIN: f64 = 4.0;
const AMBIENT: f64 = 0.2;
const DC: f64 = 1.0;

/// The scene: pixel `i` at true radial distance `d_i` spread over 0.05 m .. 1.95 m (inside
/// the 2 m unambiguous range) and beyond it (wrapped), with phasor magnitudes 0.3 .. 0.8.
fn signal() -> (SignalImage, Vec<f64>) {
    let n = WIDTH * HEIGHT;
    let mut pixels = Vec::with_capacity(n);
    let mut magnitudes = Vec::with_capacity(n);
    for i in 0..n {
        let distance = 0.05 + 3.5 * i as f64 / (n - 1) as f64;
        let magnitude = 0.3 + 0.5 * ((i * 7) % n) as f64 / n as f64;
        // The phasor of a path of length 2d: exp(i·2π f·2d / c).
        let phase = std::f64::consts::TAU * F_HZ * 2.0 * distance / SPEED_OF_LIGHT;
        let mut px = PixelSignal {
            dc: DC,
            ambient: AMBIENT,
            ..PixelSignal::default()
        };
        px.phasor[0] = Complex::from_polar(magnitude, phase);
        pixels.push(px);
        magnitudes.push(magnitude);
    }
    let image = SignalImage {
        width: WIDTH,
        height: HEIGHT,
        pixels,
    };
    (image, magnitudes)
}

/// The four tap images in DN, rounded to 12 bits, row-major (`taps[k][pixel]`), with tap
/// `k`'s correlation `Re(P·e^{−i·k·π/2})` as in `dear_synth::sensor::measure`.
fn taps(image: &SignalImage) -> [Vec<u16>; 4] {
    let mut out: [Vec<u16>; 4] = Default::default();
    for px in &image.pixels {
        let p = px.phasor[0];
        for (k, corr) in [p.re, p.im, -p.re, -p.im].into_iter().enumerate() {
            let mu = (KAPPA * (px.ambient + px.dc + corr)).max(0.0);
            let dn = (mu / GAIN).round();
            assert!((0.0..=4095.0).contains(&dn), "tap {dn} DN outside 12 bits");
            out[k].push(dn as u16);
        }
    }
    out
}

fn y12_buffer(samples: &[u16], bytes_per_line: usize) -> Vec<u8> {
    let mut out = vec![0u8; bytes_per_line * HEIGHT];
    for (row, dst) in samples
        .chunks_exact(WIDTH)
        .zip(out.chunks_exact_mut(bytes_per_line))
    {
        for (v, d) in row.iter().zip(dst.chunks_exact_mut(2)) {
            d.copy_from_slice(&v.to_le_bytes());
        }
    }
    out
}

fn camera() -> Camera {
    Camera::from_hfov(WIDTH, HEIGHT, 70.0)
}

fn simulated() -> (dear_synth::sensor::TofImage, Vec<f64>, [Vec<u16>; 4]) {
    let (image, magnitudes) = signal();
    let cfg = SensorConfig {
        electrons_per_unit: KAPPA,
        gain_e_per_dn: GAIN,
        noise: false,
        min_amplitude_dn: 0.0,
        ..SensorConfig::default()
    };
    let tof = sense(&image, &camera(), &[F_HZ], &cfg, 0, 0);
    let taps = taps(&image);
    (tof, magnitudes, taps)
}

/// The bound derived in the module documentation for amplitude `a` DN.
fn distance_bound(a: f64) -> f64 {
    SPEED_OF_LIGHT / (4.0 * std::f64::consts::PI * F_HZ) * (2f64.sqrt() / (2.0 * a)).asin() + 2e-6
}

fn params() -> PhaseParams {
    PhaseParams {
        modulation_hz: F_HZ,
        q_sign: QSign::Standard,
        min_amplitude: 0.0,
    }
}

#[test]
fn y12_and_y12p_frames_decode_to_the_simulators_distances() {
    let (tof, magnitudes, taps) = simulated();
    let range = unambiguous_range(F_HZ);
    assert!((params().unambiguous_range_m() - range).abs() < 1e-12);

    let stride = 2 * WIDTH + 6;
    let y12: Vec<Vec<u8>> = taps.iter().map(|t| y12_buffer(t, stride)).collect();
    let frame = FrameFormat::new(PixelFormat::Y12, WIDTH, HEIGHT, stride);
    let from_y12 =
        demodulate_frames(&frame, [&y12[0], &y12[1], &y12[2], &y12[3]], &params()).unwrap();

    let stacked = pack_y12p(&taps.concat(), WIDTH, 4 * HEIGHT, 3 * WIDTH / 2 + 4).unwrap();
    let frame = FrameFormat::new(PixelFormat::Y12P, WIDTH, 4 * HEIGHT, 3 * WIDTH / 2 + 4);
    let from_y12p = demodulate_stacked(&frame, &stacked, &params()).unwrap();
    assert_eq!(from_y12, from_y12p);

    let mut worst = 0.0f64;
    for (i, &magnitude) in magnitudes.iter().enumerate() {
        let (v, u) = (i / WIDTH, i % WIDTH);
        let amplitude_dn = KAPPA * magnitude / GAIN;
        let bound = distance_bound(amplitude_dn);
        let got = f64::from(from_y12.radial[[v, u]]);
        let simulated = f64::from(tof.radial[[v, u]]);
        // Distances near a wrap may land on either side of it: compare on the circle.
        let diff = (got - simulated).rem_euclid(range);
        let err = diff.min(range - diff);
        assert!(
            err <= bound,
            "pixel {i}: decoded {got} m, simulator {simulated} m, bound {bound} m"
        );
        worst = worst.max(err / bound);
        let amp = f64::from(from_y12.amplitude[[v, u]]);
        assert!(
            (amp - f64::from(tof.amplitude[[v, u]])).abs() <= 0.5f64.sqrt() + 1e-3,
            "pixel {i}: amplitude {amp}, simulator {}",
            tof.amplitude[[v, u]]
        );
    }
    // The bound is not loose: some pixel uses a good part of it (0.75 when written).
    assert!(worst > 0.25, "largest error only {worst} of the bound");
}

#[test]
fn radial_to_z_matches_the_simulators_depth() {
    let (tof, magnitudes, taps) = simulated();
    let cam = camera();
    let y12: Vec<Vec<u8>> = taps.iter().map(|t| y12_buffer(t, 2 * WIDTH)).collect();
    let frame = FrameFormat::unpadded(PixelFormat::Y12, WIDTH, HEIGHT);
    let mut decoded =
        demodulate_frames(&frame, [&y12[0], &y12[1], &y12[2], &y12[3]], &params()).unwrap();
    let intrinsics = Pinhole {
        fx: cam.fx as f32,
        fy: cam.fy as f32,
        cx: cam.cx as f32,
        cy: cam.cy as f32,
    };
    radial_to_z_in_place(decoded.radial.view_mut(), &intrinsics);
    for (i, &magnitude) in magnitudes.iter().enumerate() {
        let (v, u) = (i / WIDTH, i % WIDTH);
        let got = f64::from(decoded.radial[[v, u]]);
        let simulated = f64::from(tof.depth[[v, u]]);
        let factor = cam.radial_to_z(u as f64, v as f64);
        // Away from the wrap, the radial bound scaled by the same cosine.
        if f64::from(tof.radial[[v, u]]) > 0.01
            && f64::from(tof.radial[[v, u]]) < unambiguous_range(F_HZ) - 0.01
        {
            let bound = distance_bound(KAPPA * magnitude / GAIN) * factor + 2e-6;
            assert!(
                (got - simulated).abs() <= bound,
                "pixel {i}: z {got} vs {simulated}"
            );
        }
    }
}

#[test]
fn arducam_sign_decodes_mirrored_quadrature_taps() {
    // A module with the opposite Q sign delivers D1 and D3 swapped relative to the simulator's
    // model; QSign::Inverted must recover the same distances.
    let (_, _, taps) = simulated();
    let frame = FrameFormat::unpadded(PixelFormat::Y12, WIDTH, HEIGHT);
    let y12: Vec<Vec<u8>> = taps.iter().map(|t| y12_buffer(t, 2 * WIDTH)).collect();
    let standard =
        demodulate_frames(&frame, [&y12[0], &y12[1], &y12[2], &y12[3]], &params()).unwrap();
    let inverted = PhaseParams {
        q_sign: QSign::Inverted,
        ..params()
    };
    let mirrored =
        demodulate_frames(&frame, [&y12[0], &y12[3], &y12[2], &y12[1]], &inverted).unwrap();
    assert_eq!(standard, mirrored);
    // With the wrong sign the phase is mirrored, so most distances differ.
    let wrong = demodulate_frames(&frame, [&y12[0], &y12[3], &y12[2], &y12[1]], &params()).unwrap();
    let differing = standard
        .radial
        .iter()
        .zip(wrong.radial.iter())
        .filter(|(a, b)| (*a - *b).abs() > 0.01)
        .count();
    assert!(
        differing > WIDTH * HEIGHT / 2,
        "only {differing} pixels differ"
    );
}

#[test]
fn amplitude_threshold_invalidates_weak_pixels_like_the_simulator() {
    let (image, magnitudes) = signal();
    let threshold_dn = 1400.0;
    let cfg = SensorConfig {
        electrons_per_unit: KAPPA,
        gain_e_per_dn: GAIN,
        noise: false,
        min_amplitude_dn: threshold_dn,
        ..SensorConfig::default()
    };
    let tof = sense(&image, &camera(), &[F_HZ], &cfg, 0, 0);
    let taps = taps(&image);
    let frame = FrameFormat::unpadded(PixelFormat::Y12, WIDTH, HEIGHT);
    let y12: Vec<Vec<u8>> = taps.iter().map(|t| y12_buffer(t, 2 * WIDTH)).collect();
    let p = PhaseParams {
        min_amplitude: threshold_dn as f32,
        ..params()
    };
    let decoded = demodulate_frames(&frame, [&y12[0], &y12[1], &y12[2], &y12[3]], &p).unwrap();
    let mut invalid = 0;
    for (i, &magnitude) in magnitudes.iter().enumerate() {
        let (v, u) = (i / WIDTH, i % WIDTH);
        let amplitude_dn = KAPPA * magnitude / GAIN;
        // Pixels within the quantisation error of the threshold may fall either way.
        if (amplitude_dn - threshold_dn).abs() < 1.0 {
            continue;
        }
        assert_eq!(
            decoded.radial[[v, u]] == 0.0,
            tof.radial[[v, u]] == 0.0,
            "pixel {i}, amplitude {amplitude_dn} DN"
        );
        invalid += usize::from(decoded.radial[[v, u]] == 0.0);
    }
    assert!(
        invalid > 0 && invalid < WIDTH * HEIGHT,
        "{invalid} invalid pixels"
    );
}
