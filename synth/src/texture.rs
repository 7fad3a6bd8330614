//! Lambertian materials with procedural solid textures: an RGB albedo and a *separate*
//! near-infrared albedo.
//!
//! Textures are evaluated at the object-local 3-D point (solid texturing), so every shape is
//! textured without UV maps and a pattern moves with its object. The IR albedo is related to
//! the RGB one but not equal: a material either shares the pattern with different contrast, or
//! shows it in RGB only (the two IR albedos are equal: the pattern vanishes in IR), or has its
//! own IR-only pattern. That way neither an RGB edge nor an amplitude edge implies a depth edge,
//! which is what the alignment network must learn.

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::math::Vec3;
use crate::rng::mix64;

/// A scalar pattern in `[0, 1]` over 3-D space.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Pattern {
    Uniform,
    /// 3-D checkerboard with cells of `size` metres.
    Checker {
        size: f64,
    },
    /// Parallel stripes across `axis` (unit), `period` metres, `duty` ∈ (0, 1) fraction on.
    Stripes {
        axis: Vec3,
        period: f64,
        duty: f64,
    },
    /// Fractal value noise (3 octaves) of base wavelength `scale` metres.
    Noise {
        scale: f64,
    },
    /// Irregular blotches: thresholded, domain-warped noise of wavelength `scale`.
    Patches {
        scale: f64,
        threshold: f64,
    },
}

/// Hash of an integer lattice point to `[0, 1)`.
#[inline]
fn lattice(ix: i64, iy: i64, iz: i64, seed: u64) -> f64 {
    let h = mix64(
        (ix as u64).wrapping_mul(0x8da6_b343)
            ^ (iy as u64).wrapping_mul(0xd816_3841)
            ^ (iz as u64).wrapping_mul(0xcb1a_b31f)
            ^ seed,
    );
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Smooth 3-D value noise in `[0, 1]`.
fn value_noise(p: Vec3, seed: u64) -> f64 {
    let (fx, fy, fz) = (p.x.floor(), p.y.floor(), p.z.floor());
    let (ix, iy, iz) = (fx as i64, fy as i64, fz as i64);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (u, v, w) = (s(p.x - fx), s(p.y - fy), s(p.z - fz));
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let c = |dx, dy, dz| lattice(ix + dx, iy + dy, iz + dz, seed);
    lerp(
        lerp(
            lerp(c(0, 0, 0), c(1, 0, 0), u),
            lerp(c(0, 1, 0), c(1, 1, 0), u),
            v,
        ),
        lerp(
            lerp(c(0, 0, 1), c(1, 0, 1), u),
            lerp(c(0, 1, 1), c(1, 1, 1), u),
            v,
        ),
        w,
    )
}

fn fbm(p: Vec3, seed: u64) -> f64 {
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut q = p;
    let mut norm = 0.0;
    for o in 0..3u64 {
        sum += amp * value_noise(q, seed.wrapping_add(o * 0x1234_5678_9abc));
        norm += amp;
        amp *= 0.5;
        q = q * 2.03;
    }
    sum / norm
}

impl Pattern {
    /// The pattern value at the local point `p`; `seed` decorrelates materials.
    pub fn eval(&self, p: Vec3, seed: u64) -> f64 {
        match *self {
            Pattern::Uniform => 0.0,
            Pattern::Checker { size } => {
                let q = p / size;
                let s = q.x.floor() as i64 + q.y.floor() as i64 + q.z.floor() as i64;
                (s.rem_euclid(2)) as f64
            }
            Pattern::Stripes { axis, period, duty } => {
                let x = (p.dot(axis) / period).rem_euclid(1.0);
                if x < duty {
                    1.0
                } else {
                    0.0
                }
            }
            Pattern::Noise { scale } => {
                // Stretch the contrast: fBm clusters around 0.5.
                ((fbm(p / scale, seed) - 0.5) * 2.2 + 0.5).clamp(0.0, 1.0)
            }
            Pattern::Patches { scale, threshold } => {
                let q = p / scale;
                let warp = Vec3::new(
                    value_noise(q * 1.7, seed ^ 11),
                    value_noise(q * 1.7, seed ^ 12),
                    value_noise(q * 1.7, seed ^ 13),
                ) * 0.8;
                if value_noise(q + warp, seed) > threshold {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }

    /// A random pattern whose features are sized for an object of size `size` metres.
    pub fn random<R: Rng>(rng: &mut R, size: f64) -> Pattern {
        let s = size.max(0.05);
        match rng.random_range(0..5) {
            0 => Pattern::Uniform,
            1 => Pattern::Checker {
                size: s * rng.random_range(0.08..0.4),
            },
            2 => Pattern::Stripes {
                axis: random_unit(rng),
                period: s * rng.random_range(0.08..0.5),
                duty: rng.random_range(0.2..0.8),
            },
            3 => Pattern::Noise {
                scale: s * rng.random_range(0.1..0.6),
            },
            _ => Pattern::Patches {
                scale: s * rng.random_range(0.15..0.6),
                threshold: rng.random_range(0.35..0.65),
            },
        }
    }
}

/// A uniformly random unit vector.
pub fn random_unit<R: Rng>(rng: &mut R) -> Vec3 {
    let z: f64 = rng.random_range(-1.0..1.0);
    let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let r = (1.0 - z * z).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// A Lambertian material: albedo `mix(a, b, pattern)` in linear RGB and in near-infrared.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub rgb_pattern: Pattern,
    /// Linear-RGB albedos at pattern value 0 and 1.
    pub rgb: [Vec3; 2],
    pub ir_pattern: Pattern,
    /// Near-infrared albedos at pattern value 0 and 1.
    pub ir: [f64; 2],
    /// Decorrelates the noise of materials sharing a pattern type.
    pub seed: u64,
    /// Seed of the IR pattern: equal to `seed` when the IR shares the RGB pattern.
    pub ir_seed: u64,
}

/// How a random material's IR albedo relates to its RGB albedo (recorded for documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IrRelation {
    /// Same pattern; IR contrast derived from, but not equal to, the luminance contrast.
    Shared,
    /// The RGB pattern is invisible in IR.
    RgbOnly,
    /// An independent IR pattern.
    Independent,
}

impl Material {
    /// A uniform grey material (tests).
    pub fn uniform(rgb: f64, ir: f64) -> Material {
        Material {
            rgb_pattern: Pattern::Uniform,
            rgb: [Vec3::new(rgb, rgb, rgb); 2],
            ir_pattern: Pattern::Uniform,
            ir: [ir, ir],
            seed: 0,
            ir_seed: 0,
        }
    }

    #[inline]
    pub fn rgb_albedo(&self, p: Vec3) -> Vec3 {
        let t = self.rgb_pattern.eval(p, self.seed);
        self.rgb[0] * (1.0 - t) + self.rgb[1] * t
    }

    #[inline]
    pub fn ir_albedo(&self, p: Vec3) -> f64 {
        if self.ir[0] == self.ir[1] {
            return self.ir[0];
        }
        let t = self.ir_pattern.eval(p, self.ir_seed);
        self.ir[0] * (1.0 - t) + self.ir[1] * t
    }

    /// `(rgb_albedo(p), ir_albedo(p))`, evaluating a shared pattern once.
    #[inline]
    pub fn albedos(&self, p: Vec3) -> (Vec3, f64) {
        let t = self.rgb_pattern.eval(p, self.seed);
        let rgb = self.rgb[0] * (1.0 - t) + self.rgb[1] * t;
        let ir = if self.ir[0] == self.ir[1] {
            self.ir[0]
        } else if self.ir_pattern == self.rgb_pattern && self.ir_seed == self.seed {
            self.ir[0] * (1.0 - t) + self.ir[1] * t
        } else {
            self.ir_albedo(p)
        };
        (rgb, ir)
    }

    /// A random material for an object of size `size`.
    pub fn random<R: Rng>(rng: &mut R, size: f64) -> (Material, IrRelation) {
        let colour = |rng: &mut R| {
            Vec3::new(
                rng.random_range(0.03..0.9),
                rng.random_range(0.03..0.9),
                rng.random_range(0.03..0.9),
            )
        };
        let rgb = [colour(rng), colour(rng)];
        let rgb_pattern = Pattern::random(rng, size);
        // NIR reflectance of dyes correlates only loosely with visible luminance: start from the
        // luminance and add a material-specific offset.
        let lum = |c: Vec3| 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
        let ir_of =
            |rng: &mut R, c: Vec3| (lum(c) + rng.random_range(-0.25..0.35)).clamp(0.05, 0.95);
        let roll: f64 = rng.random();
        let (ir_pattern, ir, relation) = if roll < 0.5 {
            (
                rgb_pattern,
                [ir_of(rng, rgb[0]), ir_of(rng, rgb[1])],
                IrRelation::Shared,
            )
        } else if roll < 0.75 {
            let v = ir_of(rng, (rgb[0] + rgb[1]) * 0.5);
            (rgb_pattern, [v, v], IrRelation::RgbOnly)
        } else {
            (
                Pattern::random(rng, size),
                [rng.random_range(0.05..0.95), rng.random_range(0.05..0.95)],
                IrRelation::Independent,
            )
        };
        let seed: u64 = rng.random();
        let ir_seed = if relation == IrRelation::Independent {
            rng.random()
        } else {
            seed
        };
        (
            Material {
                rgb_pattern,
                rgb,
                ir_pattern,
                ir,
                seed,
                ir_seed,
            },
            relation,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn patterns_stay_in_range_and_vary() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        for _ in 0..50 {
            let pat = Pattern::random(&mut rng, 0.5);
            let vals: Vec<f64> = (0..400)
                .map(|i| {
                    let f = i as f64;
                    pat.eval(Vec3::new(f * 0.013, (f * 0.7).sin() * 0.3, f * 0.007), 9)
                })
                .collect();
            assert!(vals.iter().all(|v| (0.0..=1.0).contains(v)));
            if pat != Pattern::Uniform {
                let (lo, hi) = vals
                    .iter()
                    .fold((1.0f64, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
                assert!(hi - lo > 0.3, "{pat:?} barely varies: {lo}..{hi}");
            }
        }
    }

    #[test]
    fn rgb_only_patterns_vanish_in_ir() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        let mut seen = 0;
        for _ in 0..200 {
            let (m, rel) = Material::random(&mut rng, 0.5);
            assert!(m.ir.iter().all(|v| (0.05..=0.95).contains(v)));
            // `albedos` agrees with the two separate evaluations.
            let p = Vec3::new(0.3, -0.1, 0.2);
            let (rgb, ir) = m.albedos(p);
            assert_eq!((rgb, ir), (m.rgb_albedo(p), m.ir_albedo(p)));
            if rel == IrRelation::Shared && m.ir[0] != m.ir[1] {
                // The IR pattern is the RGB one: IR albedo is an affine function of the
                // pattern value, so it hits its extremes where the RGB albedo does.
                let t = m.rgb_pattern.eval(p, m.seed);
                assert!((ir - (m.ir[0] * (1.0 - t) + m.ir[1] * t)).abs() < 1e-12);
            }
            if rel == IrRelation::RgbOnly {
                seen += 1;
                let a = m.ir_albedo(Vec3::new(0.1, 0.2, 0.3));
                let b = m.ir_albedo(Vec3::new(-0.4, 0.05, 0.33));
                assert_eq!(a, b);
            }
        }
        assert!(seen > 20);
    }
}
