//! Light transport of the ToF illuminator (AMCW phasors) and the shading of the RGB image.
//!
//! For every pixel, `spp` primary rays jitter over the pixel footprint (so a pixel straddling a
//! depth edge mixes both surfaces, which is where flying pixels come from). At each primary hit
//! the direct term is computed by next-event estimation towards the point illuminator (1/r²
//! falloff, Lambert cosines, shadow ray); `indirect_spp` of the primary samples then continue
//! as cosine-sampled paths with next-event estimation at every vertex, up to `max_bounces`
//! surface reflections in all. Each contribution `w` of a path with optical length `L`
//! (camera → surfaces → illuminator) is added, for every modulation frequency `f`, to the
//! phasor `Σ w·exp(i·2π f L / c)`; its total `Σ w` is the DC level of the correlation. No
//! transient is stored.
//!
//! The illuminator emits only into the camera's field of view (plus a margin), as a module's
//! diffuser does. Units: the illuminator has radiant intensity `I` and a Lambertian surface of albedo `ρ` at
//! distance `r` and incidence `θ` returns radiance `ρ/π · I cosθ / r²`; the sensor signal is that
//! radiance (no vignetting). With `I = π`, a white fronto-parallel surface at 1 m gives 1.

use std::f64::consts::{FRAC_1_PI, TAU};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::geometry::{intersect_all, occluded, Hit, Ray, SURFACE_EPS};
use crate::math::{Complex, Vec3};
use crate::rng::{hash_key, FastRng, Stream};
use crate::scene::Scene;

/// Speed of light, m/s.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// At most this many modulation frequencies.
pub const MAX_FREQUENCIES: usize = 4;

/// Rays that hit nothing within this distance escape (no wall there).
const FAR: f64 = 1e4;

/// Quality and physics switches of the renderer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderOptions {
    /// Primary samples per pixel (stratified sub-pixel jitter).
    pub spp: usize,
    /// How many of the primary samples continue into indirect (MPI) paths. Indirect light is
    /// smooth, so fewer paths than primary samples suffice; this is the main speed knob.
    pub indirect_spp: usize,
    /// Longest path, in surface reflections (1 = direct only; 3 = two indirect bounces).
    pub max_bounces: usize,
    /// Shortest path counted (tests set 2 to isolate the indirect term).
    pub min_bounces: usize,
    /// Sub-pixel jitter; without it every sample goes through the pixel centre.
    pub jitter: bool,
    /// Modulation frequencies, Hz.
    pub frequencies_hz: Vec<f64>,
    /// Also shade the RGB image (off in physics tests, which do not need it).
    pub rgb: bool,
    /// Radius (px) of the edge-aware average applied (twice) to the indirect (MPI) phasors in
    /// [`render`]; 0 disables it. See [`filter_indirect`].
    pub indirect_filter_radius: usize,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            spp: 4,
            indirect_spp: 2,
            max_bounces: 3,
            min_bounces: 1,
            jitter: true,
            frequencies_hz: vec![20e6],
            rgb: true,
            indirect_filter_radius: 3,
        }
    }
}

/// What the sensor receives at one pixel, before noise.
#[derive(Debug, Clone, Copy, Default)]
pub struct PixelSignal {
    /// `Σ w·exp(i·2π f L / c)` for each frequency (only the first `n` are used).
    pub phasor: [Complex; MAX_FREQUENCIES],
    /// `Σ w`: the modulated light's DC level.
    pub dc: f64,
    /// The part of `phasor` carried by paths of two or more bounces (included in `phasor`).
    pub indirect: [Complex; MAX_FREQUENCIES],
    /// The part of `dc` carried by paths of two or more bounces.
    pub indirect_dc: f64,
    /// Object seen through the pixel centre (`u32::MAX`: none), guide of the MPI filter.
    pub object: u32,
    /// Surface normal seen through the pixel centre.
    pub normal: Vec3,
    /// Ambient IR reflected into the pixel (unmodulated).
    pub ambient: f64,
    /// Linear RGB radiance (RGB lights and ambient, not the IR illuminator).
    pub rgb: Vec3,
    /// Ground-truth z-depth through the pixel centre, metres (0 = nothing hit).
    pub gt_z: f64,
}

/// A rendered frame of pixel signals, row-major.
#[derive(Debug, Clone)]
pub struct SignalImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<PixelSignal>,
}

/// A cosine-distributed direction about the unit normal `n`.
#[inline]
fn sample_cosine(n: Vec3, rng: &mut FastRng) -> Vec3 {
    let (t, b) = n.basis();
    let u1 = rng.uniform();
    let u2 = rng.uniform();
    let r = u1.sqrt();
    let phi = TAU * u2;
    let (s, c) = phi.sin_cos();
    (t * (r * c) + b * (r * s) + n * (1.0 - u1).max(0.0).sqrt()).normalized()
}

/// Offsets a point off its surface towards the side of `n`.
#[inline]
fn lift(h: &Hit) -> Vec3 {
    h.point + h.normal * (SURFACE_EPS * (1.0 + h.point.length()))
}

struct Ctx<'a> {
    scene: &'a Scene,
    opts: &'a RenderOptions,
    light: Vec3,
    /// `2π f / c` per frequency.
    k: [f64; MAX_FREQUENCIES],
    nf: usize,
}

impl Ctx<'_> {
    fn new<'a>(scene: &'a Scene, opts: &'a RenderOptions) -> Ctx<'a> {
        assert!(
            !opts.frequencies_hz.is_empty() && opts.frequencies_hz.len() <= MAX_FREQUENCIES,
            "between 1 and {MAX_FREQUENCIES} modulation frequencies"
        );
        let mut k = [0.0; MAX_FREQUENCIES];
        for (k, f) in k.iter_mut().zip(&opts.frequencies_hz) {
            *k = TAU * f / SPEED_OF_LIGHT;
        }
        Ctx {
            scene,
            opts,
            light: scene.tof_light(),
            k,
            nf: opts.frequencies_hz.len(),
        }
    }

    #[inline]
    fn ir_albedo(&self, h: &Hit) -> f64 {
        let o = &self.scene.objects[h.object as usize];
        o.material.ir_albedo(o.pose.to_local(h.point))
    }

    /// Radiance towards the previous vertex from the illuminator via `h` (next-event
    /// estimation), divided by nothing: `ρ/π · I cosθ / d²`, and the distance to the light.
    #[inline]
    fn direct(&self, h: &Hit, albedo: f64) -> Option<(f64, f64)> {
        let to_light = self.light - h.point;
        let d2 = to_light.length_squared();
        let d = d2.sqrt();
        let wl = to_light / d;
        let cos = h.normal.dot(wl);
        if cos <= 0.0 || !self.scene.tof_light_reaches(h.point) {
            return None;
        }
        let origin = lift(h);
        let shadow = Ray {
            origin,
            dir: (self.light - origin).normalized(),
        };
        if occluded(self.scene.primitives(), &shadow, d * (1.0 - 1e-9)) {
            return None;
        }
        Some((
            albedo * FRAC_1_PI * self.scene.tof_light_intensity * cos / d2,
            d,
        ))
    }

    #[inline]
    fn add(&self, px: &mut PixelSignal, w: f64, length: f64, indirect: bool) {
        px.dc += w;
        if indirect {
            px.indirect_dc += w;
        }
        for f in 0..self.nf {
            let c = Complex::from_polar(w, self.k[f] * length);
            px.phasor[f] += c;
            if indirect {
                px.indirect[f] += c;
            }
        }
    }

    /// Bit `i` set: RGB light `i` is visible from the hit (shadow rays).
    fn rgb_visibility(&self, h: &Hit) -> u64 {
        let origin = lift(h);
        let mut mask = 0u64;
        for (i, l) in self.scene.rgb_lights.iter().enumerate().take(64) {
            let v = l.position - origin;
            let d = v.length();
            if h.normal.dot(v) > 0.0
                && !occluded(
                    self.scene.primitives(),
                    &Ray { origin, dir: v / d },
                    d * (1.0 - 1e-9),
                )
            {
                mask |= 1 << i;
            }
        }
        mask
    }

    /// RGB radiance of a primary hit of RGB albedo `albedo`: ambient plus point lights with
    /// Lambert cosines and hard shadows given by `visible` (see [`Ctx::rgb_visibility`]).
    fn shade_rgb(&self, h: &Hit, albedo: Vec3, visible: u64) -> Vec3 {
        let mut e = self.scene.rgb_ambient;
        for (i, l) in self.scene.rgb_lights.iter().enumerate().take(64) {
            if visible & (1 << i) == 0 {
                continue;
            }
            let v = l.position - h.point;
            let d2 = v.length_squared();
            let cos = h.normal.dot(v) / d2.sqrt();
            if cos > 0.0 {
                e += l.intensity * (cos / d2);
            }
        }
        albedo.mul_elem(e)
    }

    fn pixel(&self, x: usize, y: usize, key: u64) -> PixelSignal {
        let cam = &self.scene.camera;
        let prims = self.scene.primitives();
        let opts = self.opts;
        let mut rng = FastRng::new(key);
        let mut px = PixelSignal {
            object: u32::MAX,
            ..PixelSignal::default()
        };

        // Ground truth through the pixel centre.
        let centre = cam.ray(x as f64, y as f64);
        // RGB shadows are traced once, at the centre hit, and reused by the samples on the same
        // object (shadow edges inside a pixel alias; depth edges do not, as samples on another
        // object trace their own). This saves 3/4 of the RGB shadow rays.
        let mut centre_visibility = 0;
        if let Some(h) = intersect_all(prims, &centre, FAR) {
            px.gt_z = cam.z_of(h.point);
            px.object = h.object;
            px.normal = h.normal;
            if opts.rgb {
                centre_visibility = self.rgb_visibility(&h);
            }
        }

        let spp = opts.spp.max(1);
        let n_strata = (spp as f64).sqrt().ceil() as usize;
        let n_indirect = opts.indirect_spp.min(spp);
        // Random rotation of the stratum order, so the samples that continue into indirect
        // paths cover the pixel uniformly in expectation.
        let stratum_offset = (rng.next_u64() % spp as u64) as usize;
        let primary_weight = 1.0 / spp as f64;
        let indirect_weight = if n_indirect > 0 {
            1.0 / n_indirect as f64
        } else {
            0.0
        };
        let mut last_offset = (0.0, 0.0);
        for j in 0..spp {
            // Stratified jitter with antithetic pairs: odd samples mirror the previous one
            // through the pixel centre, so the footprint average has no first-order error (a
            // fronto-parallel plane reads its exact depth) while edges still mix surfaces.
            let (ju, jv) = if !opts.jitter {
                (0.0, 0.0)
            } else if j % 2 == 1 {
                (-last_offset.0, -last_offset.1)
            } else {
                let s = (j + stratum_offset) % spp;
                let (sx, sy) = (s % n_strata, s / n_strata);
                let rows = spp.div_ceil(n_strata);
                (
                    (sx as f64 + rng.uniform()) / n_strata as f64 - 0.5,
                    (sy as f64 + rng.uniform()) / rows as f64 - 0.5,
                )
            };
            last_offset = (ju, jv);
            let ray = cam.ray(x as f64 + ju, y as f64 + jv);
            let Some(hit) = intersect_all(prims, &ray, FAR) else {
                continue;
            };
            let albedo = if opts.rgb {
                let o = &self.scene.objects[hit.object as usize];
                let (rgb_albedo, ir) = o.material.albedos(o.pose.to_local(hit.point));
                let visible = if hit.object == px.object {
                    centre_visibility
                } else {
                    self.rgb_visibility(&hit)
                };
                px.rgb += self.shade_rgb(&hit, rgb_albedo, visible) * primary_weight;
                ir
            } else {
                self.ir_albedo(&hit)
            };
            px.ambient += primary_weight * self.scene.ambient_ir * albedo;
            let mut length = hit.t;
            if opts.min_bounces <= 1 {
                if let Some((w, d)) = self.direct(&hit, albedo) {
                    self.add(&mut px, w * primary_weight, length + d, false);
                }
            }
            if j >= n_indirect || opts.max_bounces < 2 {
                continue;
            }
            // Indirect paths: cosine sampling makes the throughput update just the albedo.
            let mut throughput = indirect_weight;
            let mut vertex = hit;
            let mut vertex_albedo = albedo;
            for bounce in 2..=opts.max_bounces {
                throughput *= vertex_albedo;
                let dir = sample_cosine(vertex.normal, &mut rng);
                let next_ray = Ray {
                    origin: lift(&vertex),
                    dir,
                };
                let Some(next) = intersect_all(prims, &next_ray, FAR) else {
                    break;
                };
                length += next.t;
                let a = self.ir_albedo(&next);
                if bounce >= opts.min_bounces {
                    if let Some((w, d)) = self.direct(&next, a) {
                        self.add(&mut px, throughput * w, length + d, true);
                    }
                }
                vertex = next;
                vertex_albedo = a;
            }
        }
        px
    }
}

/// Pixel-sampling key: the same `(seed, frame, pixel)` always draws the same paths.
#[inline]
fn pixel_key(seed: u64, frame: u64, x: usize, y: usize, width: usize) -> u64 {
    hash_key(seed, Stream::Pixel, frame, (y * width + x) as u64)
}

/// Renders one pixel alone (tests, debugging); identical to the pixel of [`render`] before
/// [`filter_indirect`].
pub fn render_pixel(
    scene: &Scene,
    opts: &RenderOptions,
    seed: u64,
    frame: u64,
    x: usize,
    y: usize,
) -> PixelSignal {
    let ctx = Ctx::new(scene, opts);
    ctx.pixel(x, y, pixel_key(seed, frame, x, y, scene.camera.width))
}

/// Renders every pixel, in parallel over rows.
pub fn render(scene: &Scene, opts: &RenderOptions, seed: u64, frame: u64) -> SignalImage {
    let ctx = Ctx::new(scene, opts);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut pixels = vec![PixelSignal::default(); w * h];
    pixels.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, p) in row.iter_mut().enumerate() {
            *p = ctx.pixel(x, y, pixel_key(seed, frame, x, y, w));
        }
    });
    let mut image = SignalImage {
        width: w,
        height: h,
        pixels,
    };
    if opts.indirect_filter_radius > 0 && opts.max_bounces >= 2 {
        filter_indirect(
            &mut image,
            opts.indirect_filter_radius,
            opts.frequencies_hz.len(),
        );
    }
    image
}

/// Whether two pixels' centre samples lie on the same smooth surface (same object, normals
/// within ~25°, depths within 3 %).
#[inline]
fn same_surface(a: &PixelSignal, b: &PixelSignal) -> bool {
    a.object == b.object
        && a.object != u32::MAX
        && a.normal.dot(b.normal) > 0.9
        && (a.gt_z - b.gt_z).abs() < 0.03 * a.gt_z
}

/// Replaces each pixel's indirect phasors by their average over the `(2r+1)²` neighbours on
/// the same surface.
///
/// Why: with one or two indirect paths per pixel the Monte Carlo estimate of the MPI term is
/// noisy (its relative standard deviation is ~100 %), whereas the true MPI varies smoothly
/// along a surface. Averaging the unbiased per-pixel estimates over a small same-surface
/// neighbourhood is a standard path-tracing denoiser: it divides the variance by up to
/// `(2r+1)²` and only blurs the MPI term over `r` pixels, never across depth edges. The direct
/// term (and so every depth edge and flying pixel) is untouched.
pub fn filter_indirect(image: &mut SignalImage, radius: usize, nf: usize) {
    let (w, h) = (image.width, image.height);
    let src = image.pixels.clone();
    image
        .pixels
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let centre = &src[y * w + x];
                if centre.object == u32::MAX {
                    continue;
                }
                let mut sum = [Complex::ZERO; MAX_FREQUENCIES];
                let mut sum_dc = 0.0;
                let mut count = 0.0;
                for yy in y.saturating_sub(radius)..(y + radius + 1).min(h) {
                    for xx in x.saturating_sub(radius)..(x + radius + 1).min(w) {
                        let n = &src[yy * w + xx];
                        if same_surface(centre, n) {
                            for (acc, c) in sum.iter_mut().zip(&n.indirect).take(nf) {
                                *acc += *c;
                            }
                            sum_dc += n.indirect_dc;
                            count += 1.0;
                        }
                    }
                }
                let inv = 1.0 / count;
                for ((total, indirect), acc) in out
                    .phasor
                    .iter_mut()
                    .zip(out.indirect.iter_mut())
                    .zip(&sum)
                    .take(nf)
                {
                    let filtered = acc.scale(inv);
                    *total = *total - *indirect + filtered;
                    *indirect = filtered;
                }
                out.dc = out.dc - out.indirect_dc + sum_dc * inv;
                out.indirect_dc = sum_dc * inv;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The MPI filter averages within a surface and never across objects or depth edges.
    #[test]
    fn indirect_filter_stays_on_its_surface() {
        let (w, h) = (12, 6);
        let mut rng = FastRng::new(3);
        let mut pixels = Vec::new();
        for _y in 0..h {
            for x in 0..w {
                // Left half: object 0 at 1 m with noisy indirect light around 1; right half:
                // object 1 at 2 m with none.
                let left = x < w / 2;
                let v = if left { 2.0 * rng.uniform() } else { 0.0 };
                let mut p = PixelSignal {
                    object: if left { 0 } else { 1 },
                    normal: Vec3::Z,
                    gt_z: if left { 1.0 } else { 2.0 },
                    dc: 1.0 + v,
                    indirect_dc: v,
                    ..PixelSignal::default()
                };
                p.indirect[0] = Complex::new(v, 0.0);
                p.phasor[0] = Complex::new(1.0 + v, 0.0);
                pixels.push(p);
            }
        }
        let before: Vec<f64> = pixels.iter().map(|p| p.indirect_dc).collect();
        let mut img = SignalImage {
            width: w,
            height: h,
            pixels,
        };
        filter_indirect(&mut img, 2, 1);
        let var = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64
        };
        let left = |v: &Vec<f64>| -> Vec<f64> {
            v.iter()
                .enumerate()
                .filter(|(i, _)| i % w < w / 2)
                .map(|(_, &x)| x)
                .collect()
        };
        let after: Vec<f64> = img.pixels.iter().map(|p| p.indirect_dc).collect();
        for (i, p) in img.pixels.iter().enumerate() {
            if i % w >= w / 2 {
                assert_eq!(p.indirect_dc, 0.0, "light leaked across the edge");
                assert_eq!(p.phasor[0].re, 1.0);
            } else {
                // Direct part untouched: total − indirect is still 1.
                assert!((p.phasor[0].re - p.indirect[0].re - 1.0).abs() < 1e-12);
                assert!((p.dc - p.indirect_dc - 1.0).abs() < 1e-12);
            }
        }
        assert!(var(&left(&after)) < 0.3 * var(&left(&before)));
    }
}
