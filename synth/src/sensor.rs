//! The AMCW sensor: 4-tap correlation samples with ambient offset, shot and read noise, then
//! phase, amplitude, phase unwrapping over several frequencies and radial → z conversion.
//!
//! For a pixel receiving the phasor `P = Σ w e^{iφ}` (DC level `S = Σ w`) and ambient `B`, tap
//! `k` (reference phase `ψ_k = k·π/2`) collects on average
//! `μ_k = κ·(B + S + Re(P·e^{−iψ_k}))` electrons (modulation contrast 1; `μ_k ≥ 0` since
//! `|P| ≤ S`). The electrons are Poisson distributed, the readout adds Gaussian noise of `σ_r`
//! electrons, and the ADC divides by the gain (electrons per DN). Demodulation:
//! `I = D₀ − D₂`, `Q = D₁ − D₃`, `φ = atan2(Q, I)`, amplitude `½√(I² + Q²)` (= `κ|P|/g`
//! without noise), radial distance `r = c·φ / (4π f)` modulo `c / 2f`.
//!
//! Noise model (used by the tests): `var(I) = var(Q) = μ₀ + μ₂ + 2σ_r² = 2κ(B + S) + 2σ_r²`
//! (electrons²), so the phase noise is `σ_φ ≈ √var(I) / (2κ|P|)` and the distance noise
//! `σ_r = c σ_φ / (4π f)` ([`predicted_range_std`]).

use ndarray::{Array2, Zip};
use rand::Rng;
use rand_distr::{Distribution, Normal, Poisson};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::math::Complex;
use crate::rng::{keyed_rng, Stream};
use crate::scene::Camera;
use crate::transport::{PixelSignal, SignalImage, SPEED_OF_LIGHT};

/// Sensor parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorConfig {
    /// Electrons collected per tap for a unit signal (a white surface 1 m away). Sets the
    /// exposure, hence the shot-noise level.
    pub electrons_per_unit: f64,
    /// Electrons per digital number (ADC gain).
    pub gain_e_per_dn: f64,
    /// Read noise per tap, electrons (rms).
    pub read_noise_e: f64,
    /// Simulate noise at all (off: the ideal demodulation, for physics tests).
    pub noise: bool,
    /// Pixels whose amplitude (DN) is below this are invalid (depth 0); 0 disables.
    pub min_amplitude_dn: f64,
    /// Largest distance considered when unwrapping several frequencies, metres.
    pub unwrap_max_range_m: f64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            electrons_per_unit: 20_000.0,
            gain_e_per_dn: 4.0,
            read_noise_e: 10.0,
            noise: true,
            min_amplitude_dn: 8.0,
            unwrap_max_range_m: 15.0,
        }
    }
}

/// The sensor's output for one frame.
#[derive(Debug, Clone)]
pub struct TofImage {
    /// Amplitude, DN (mean over frequencies).
    pub amplitude: Array2<f32>,
    /// Radial distance (unwrapped where several frequencies allow), metres; 0 = invalid.
    pub radial: Array2<f32>,
    /// z-depth, metres; 0 = invalid.
    pub depth: Array2<f32>,
}

/// Unambiguous range `c / 2f` of one frequency, metres.
pub fn unambiguous_range(f_hz: f64) -> f64 {
    SPEED_OF_LIGHT / (2.0 * f_hz)
}

/// Predicted standard deviation of the measured distance (metres) for a pixel with signal
/// `dc`, phasor magnitude `amp` (signal units) and ambient `ambient`, one frequency.
pub fn predicted_range_std(cfg: &SensorConfig, f_hz: f64, dc: f64, amp: f64, ambient: f64) -> f64 {
    let k = cfg.electrons_per_unit;
    let var_i = 2.0 * k * (ambient + dc) + 2.0 * cfg.read_noise_e * cfg.read_noise_e;
    let sigma_phi = var_i.sqrt() / (2.0 * k * amp);
    SPEED_OF_LIGHT * sigma_phi / (4.0 * std::f64::consts::PI * f_hz)
}

/// One noisy (or ideal) 4-tap measurement at one frequency: `(phase ∈ [0, 2π), amplitude DN)`.
fn measure<R: Rng>(
    cfg: &SensorConfig,
    phasor: Complex,
    dc: f64,
    ambient: f64,
    rng: &mut R,
) -> (f64, f64) {
    let k = cfg.electrons_per_unit;
    let mut taps = [0.0f64; 4];
    let read = Normal::new(0.0, cfg.read_noise_e.max(0.0)).expect("finite read noise");
    for (i, tap) in taps.iter_mut().enumerate() {
        // Re(P·e^{−iψ}) for ψ = 0, π/2, π, 3π/2.
        let corr = match i {
            0 => phasor.re,
            1 => phasor.im,
            2 => -phasor.re,
            _ => -phasor.im,
        };
        let mu = (k * (ambient + dc + corr)).max(0.0);
        let electrons = if cfg.noise {
            let shot = if mu > 0.0 {
                Poisson::new(mu).expect("positive mean").sample(rng)
            } else {
                0.0
            };
            shot + read.sample(rng)
        } else {
            mu
        };
        *tap = electrons / cfg.gain_e_per_dn;
    }
    let i = taps[0] - taps[2];
    let q = taps[1] - taps[3];
    let phase = q.atan2(i).rem_euclid(std::f64::consts::TAU);
    (phase, 0.5 * i.hypot(q))
}

/// Unwraps wrapped distances `d[m] ∈ [0, R_m)` of several frequencies: the candidate
/// `d₀ + n·R₀` (up to `max_range`) whose best matches `d_m + n_m·R_m` in the other frequencies
/// agree best wins; the result is the precision-weighted mean (weights `(f·a)²`).
pub fn unwrap(distances: &[f64], ranges: &[f64], weights: &[f64], max_range: f64) -> f64 {
    if distances.len() == 1 {
        return distances[0];
    }
    let mut best = (f64::INFINITY, distances[0]);
    let mut n0 = 0.0;
    loop {
        let cand = distances[0] + n0 * ranges[0];
        if cand > max_range {
            break;
        }
        let mut cost = 0.0;
        let mut sum = weights[0] * cand;
        let mut wsum = weights[0];
        for m in 1..distances.len() {
            let n = ((cand - distances[m]) / ranges[m]).round().max(0.0);
            let dm = distances[m] + n * ranges[m];
            cost += (dm - cand) * (dm - cand);
            sum += weights[m] * dm;
            wsum += weights[m];
        }
        if cost < best.0 {
            best = (cost, sum / wsum);
        }
        n0 += 1.0;
    }
    best.1
}

/// Applies the sensor to a rendered signal image. Noise is keyed by `(seed, frame, pixel)`.
pub fn sense(
    signal: &SignalImage,
    camera: &Camera,
    frequencies_hz: &[f64],
    cfg: &SensorConfig,
    seed: u64,
    frame: u64,
) -> TofImage {
    let (w, h) = (signal.width, signal.height);
    let nf = frequencies_hz.len();
    let ranges: Vec<f64> = frequencies_hz
        .iter()
        .map(|&f| unambiguous_range(f))
        .collect();
    let measure_pixel = |idx: usize, px: &PixelSignal| -> (f32, f32, f32) {
        let mut rng = keyed_rng(seed, Stream::Sensor, frame, idx as u64);
        let mut dist = [0.0; 4];
        let mut weight = [0.0; 4];
        let mut amp_sum = 0.0;
        for m in 0..nf {
            let (phase, amp) = measure(cfg, px.phasor[m], px.dc, px.ambient, &mut rng);
            dist[m] = phase / std::f64::consts::TAU * ranges[m];
            weight[m] = (frequencies_hz[m] * amp).powi(2) + 1e-300;
            amp_sum += amp;
        }
        let amp = amp_sum / nf as f64;
        let r = unwrap(&dist[..nf], &ranges, &weight[..nf], cfg.unwrap_max_range_m);
        let (x, y) = (idx % w, idx / w);
        let valid = amp >= cfg.min_amplitude_dn && amp > 0.0 && r > 0.0;
        let z = if valid {
            r * camera.radial_to_z(x as f64, y as f64)
        } else {
            0.0
        };
        (amp as f32, if valid { r as f32 } else { 0.0 }, z as f32)
    };
    let results: Vec<(f32, f32, f32)> = signal
        .pixels
        .par_iter()
        .enumerate()
        .map(|(i, p)| measure_pixel(i, p))
        .collect();
    let mut amplitude = Array2::zeros((h, w));
    let mut radial = Array2::zeros((h, w));
    let mut depth = Array2::zeros((h, w));
    Zip::from(&mut amplitude)
        .and(&mut radial)
        .and(&mut depth)
        .and(&Array2::from_shape_vec((h, w), results).expect("w×h results"))
        .for_each(|a, r, d, &(aa, rr, dd)| {
            *a = aa;
            *r = rr;
            *d = dd;
        });
    TofImage {
        amplitude,
        radial,
        depth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ideal_demodulation_recovers_phase_and_amplitude() {
        let cfg = SensorConfig {
            noise: false,
            ..SensorConfig::default()
        };
        let mut rng = keyed_rng(1, Stream::Sensor, 0, 0);
        for &phi in &[0.1, 1.0, 3.0, 5.5] {
            let p = Complex::from_polar(0.3, phi);
            let (ph, amp) = measure(&cfg, p, 0.5, 0.2, &mut rng);
            assert!((ph - phi).abs() < 1e-12);
            let expected = 0.3 * cfg.electrons_per_unit / cfg.gain_e_per_dn;
            assert!((amp - expected).abs() < 1e-9 * expected);
        }
    }

    #[test]
    fn unwrapping_finds_the_consistent_distance() {
        let f = [20e6, 16e6];
        let r: Vec<f64> = f.iter().map(|&f| unambiguous_range(f)).collect();
        for &truth in &[0.4, 3.0, 7.6, 9.0, 12.3, 14.9] {
            let d: Vec<f64> = r.iter().map(|&r| truth % r).collect();
            let got = unwrap(&d, &r, &[1.0, 1.0], 15.0);
            assert!((got - truth).abs() < 1e-9, "{truth} → {got}");
        }
    }
}
