//! Rays and analytic ray–primitive intersection.
//!
//! Scenes hold at most a few hundred primitives, so a flat list with a world-space bounding-box
//! rejection per primitive beats building a BVH per frame (and keeps the code obviously
//! correct). Every surface is treated as two-sided: the shading normal is flipped to face the
//! incoming ray, which is exact for closed solids seen from outside and is what a thin plate is.

use serde::{Deserialize, Serialize};

use crate::math::{Mat3, Vec3};

/// Rays start this far (metres) off the surface they leave, along its normal, so they do not
/// re-hit it through rounding.
pub const SURFACE_EPS: f64 = 1e-7;

/// A ray `origin + t·dir`, `dir` of unit length.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
}

impl Ray {
    #[inline]
    pub fn at(&self, t: f64) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// A rigid pose: `world = rot · local + pos`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub rot: Mat3,
    pub pos: Vec3,
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        rot: Mat3::IDENTITY,
        pos: Vec3::ZERO,
    };

    pub fn new(rot: Mat3, pos: Vec3) -> Self {
        Pose { rot, pos }
    }
    #[inline]
    pub fn to_world(&self, p: Vec3) -> Vec3 {
        self.rot.apply(p) + self.pos
    }
    #[inline]
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        self.rot.apply_transpose(p - self.pos)
    }
    /// `self ∘ inner`: first `inner`, then `self`.
    pub fn compose(&self, inner: &Pose) -> Pose {
        Pose {
            rot: self.rot * inner.rot,
            pos: self.to_world(inner.pos),
        }
    }
}

/// Shapes in their local frame (centred at the origin).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Shape {
    /// The infinite plane `z = 0` (room walls).
    Plane,
    /// The rectangle `|x| ≤ hx, |y| ≤ hy, z = 0` (a thin plate).
    Quad {
        hx: f64,
        hy: f64,
    },
    Sphere {
        radius: f64,
    },
    /// The box `|x| ≤ h.x, |y| ≤ h.y, |z| ≤ h.z`.
    Cuboid {
        half: Vec3,
    },
    /// A capped cylinder around the z axis, `|z| ≤ half_height`.
    Cylinder {
        radius: f64,
        half_height: f64,
    },
}

/// An axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    /// Slab test: does the ray meet the box within `(0, tmax)`?
    #[inline]
    pub fn hit(&self, origin: Vec3, inv_dir: Vec3, tmax: f64) -> bool {
        let mut t0 = 0.0f64;
        let mut t1 = tmax;
        for a in 0..3 {
            let ta = (self.min[a] - origin[a]) * inv_dir[a];
            let tb = (self.max[a] - origin[a]) * inv_dir[a];
            let (lo, hi) = if ta < tb { (ta, tb) } else { (tb, ta) };
            // NaN (0·∞ on a slab boundary) must not reject: max/min ignore NaN operands.
            t0 = t0.max(lo);
            t1 = t1.min(hi);
            if t0 > t1 {
                return false;
            }
        }
        true
    }
}

/// A shape placed in the world, with the object (material, texture frame) it belongs to.
#[derive(Debug, Clone, Copy)]
pub struct Primitive {
    pub shape: Shape,
    pub pose: Pose,
    /// Index of the owning object in the scene.
    pub object: u32,
    /// World bounds; `None` for unbounded shapes.
    pub bounds: Option<Aabb>,
}

/// A ray–surface intersection.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    pub t: f64,
    pub point: Vec3,
    /// Unit geometric normal, facing the side the ray came from.
    pub normal: Vec3,
    pub object: u32,
}

impl Primitive {
    pub fn new(shape: Shape, pose: Pose, object: u32) -> Self {
        let local_half = match shape {
            Shape::Plane => None,
            Shape::Quad { hx, hy } => Some(Vec3::new(hx, hy, 0.0)),
            Shape::Sphere { radius } => Some(Vec3::new(radius, radius, radius)),
            Shape::Cuboid { half } => Some(half),
            Shape::Cylinder {
                radius,
                half_height,
            } => Some(Vec3::new(radius, radius, half_height)),
        };
        let bounds = local_half.map(|h| {
            // World extent of a rotated box: |R|·h per axis.
            let r = &pose.rot.cols;
            let ext = r[0].abs() * h.x + r[1].abs() * h.y + r[2].abs() * h.z;
            let pad = Vec3::new(1e-6, 1e-6, 1e-6);
            Aabb {
                min: pose.pos - ext - pad,
                max: pose.pos + ext + pad,
            }
        });
        Primitive {
            shape,
            pose,
            object,
            bounds,
        }
    }

    /// Nearest intersection with `t ∈ (tmin, tmax)`: `(t, local normal)` (not yet oriented).
    #[inline]
    fn intersect_local(&self, o: Vec3, d: Vec3, tmin: f64, tmax: f64) -> Option<(f64, Vec3)> {
        match self.shape {
            Shape::Plane => {
                if d.z == 0.0 {
                    return None;
                }
                let t = -o.z / d.z;
                (t > tmin && t < tmax).then_some((t, Vec3::Z))
            }
            Shape::Quad { hx, hy } => {
                if d.z == 0.0 {
                    return None;
                }
                let t = -o.z / d.z;
                if !(t > tmin && t < tmax) {
                    return None;
                }
                let p = o + d * t;
                (p.x.abs() <= hx && p.y.abs() <= hy).then_some((t, Vec3::Z))
            }
            Shape::Sphere { radius } => {
                let b = o.dot(d);
                let c = o.length_squared() - radius * radius;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                let t = if -b - s > tmin { -b - s } else { -b + s };
                (t > tmin && t < tmax).then(|| (t, (o + d * t) / radius))
            }
            Shape::Cuboid { half } => {
                let mut t0 = f64::NEG_INFINITY;
                let mut t1 = f64::INFINITY;
                let (mut a0, mut a1) = (0usize, 0usize);
                for a in 0..3 {
                    if d[a] == 0.0 {
                        if o[a].abs() > half[a] {
                            return None;
                        }
                        continue;
                    }
                    let inv = 1.0 / d[a];
                    let mut ta = (-half[a] - o[a]) * inv;
                    let mut tb = (half[a] - o[a]) * inv;
                    if ta > tb {
                        std::mem::swap(&mut ta, &mut tb);
                    }
                    if ta > t0 {
                        t0 = ta;
                        a0 = a;
                    }
                    if tb < t1 {
                        t1 = tb;
                        a1 = a;
                    }
                }
                if t0 > t1 {
                    return None;
                }
                let (t, axis) = if t0 > tmin { (t0, a0) } else { (t1, a1) };
                if !(t > tmin && t < tmax) {
                    return None;
                }
                let mut n = Vec3::ZERO;
                let p = o + d * t;
                match axis {
                    0 => n.x = p.x.signum(),
                    1 => n.y = p.y.signum(),
                    _ => n.z = p.z.signum(),
                }
                Some((t, n))
            }
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let mut best: Option<(f64, Vec3)> = None;
                let mut consider = |t: f64, n: Vec3| {
                    if t > tmin && t < tmax && best.is_none_or(|(bt, _)| t < bt) {
                        best = Some((t, n));
                    }
                };
                // Side: (ox + t dx)² + (oy + t dy)² = r².
                let a = d.x * d.x + d.y * d.y;
                if a > 0.0 {
                    let b = o.x * d.x + o.y * d.y;
                    let c = o.x * o.x + o.y * o.y - radius * radius;
                    let disc = b * b - a * c;
                    if disc >= 0.0 {
                        let s = disc.sqrt();
                        for t in [(-b - s) / a, (-b + s) / a] {
                            let p = o + d * t;
                            if p.z.abs() <= half_height {
                                consider(t, Vec3::new(p.x / radius, p.y / radius, 0.0));
                            }
                        }
                    }
                }
                // Caps.
                if d.z != 0.0 {
                    for zc in [-half_height, half_height] {
                        let t = (zc - o.z) / d.z;
                        let p = o + d * t;
                        if p.x * p.x + p.y * p.y <= radius * radius {
                            consider(t, Vec3::new(0.0, 0.0, zc.signum()));
                        }
                    }
                }
                best
            }
        }
    }

    /// Nearest intersection in `(tmin, tmax)`, normal facing the ray.
    #[inline]
    pub fn intersect(&self, ray: &Ray, inv_dir: Vec3, tmin: f64, tmax: f64) -> Option<Hit> {
        if let Some(b) = &self.bounds {
            if !b.hit(ray.origin, inv_dir, tmax) {
                return None;
            }
        }
        // Planes, plates and spheres are intersected in world space (no ray transform): they
        // are most of the tests, since room walls are always tested.
        let (t, mut normal) = match self.shape {
            Shape::Plane | Shape::Quad { .. } => {
                let n = self.pose.rot.cols[2];
                let denom = n.dot(ray.dir);
                if denom == 0.0 {
                    return None;
                }
                let t = n.dot(self.pose.pos - ray.origin) / denom;
                if !(t > tmin && t < tmax) {
                    return None;
                }
                if let Shape::Quad { hx, hy } = self.shape {
                    let q = ray.at(t) - self.pose.pos;
                    if q.dot(self.pose.rot.cols[0]).abs() > hx
                        || q.dot(self.pose.rot.cols[1]).abs() > hy
                    {
                        return None;
                    }
                }
                (t, n)
            }
            Shape::Sphere { radius } => {
                let oc = ray.origin - self.pose.pos;
                let b = oc.dot(ray.dir);
                let c = oc.length_squared() - radius * radius;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                let t = if -b - s > tmin { -b - s } else { -b + s };
                if !(t > tmin && t < tmax) {
                    return None;
                }
                (t, (oc + ray.dir * t) / radius)
            }
            _ => {
                let o = self.pose.to_local(ray.origin);
                let d = self.pose.rot.apply_transpose(ray.dir);
                let (t, n_local) = self.intersect_local(o, d, tmin, tmax)?;
                (t, self.pose.rot.apply(n_local))
            }
        };
        if normal.dot(ray.dir) > 0.0 {
            normal = -normal;
        }
        Some(Hit {
            t,
            point: ray.at(t),
            normal,
            object: self.object,
        })
    }

    /// The same intersection computed entirely in the local frame (reference for the tests).
    #[cfg(test)]
    fn intersect_reference(&self, ray: &Ray, tmin: f64, tmax: f64) -> Option<(f64, Vec3)> {
        let o = self.pose.to_local(ray.origin);
        let d = self.pose.rot.apply_transpose(ray.dir);
        self.intersect_local(o, d, tmin, tmax)
            .map(|(t, n)| (t, self.pose.rot.apply(n)))
    }
}

/// Nearest hit over a primitive list.
#[inline]
pub fn intersect_all(prims: &[Primitive], ray: &Ray, tmax: f64) -> Option<Hit> {
    let inv = Vec3::new(1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z);
    let mut best: Option<Hit> = None;
    let mut limit = tmax;
    for p in prims {
        if let Some(h) = p.intersect(ray, inv, 1e-9, limit) {
            limit = h.t;
            best = Some(h);
        }
    }
    best
}

/// Whether anything blocks the ray before `tmax` (shadow rays; stops at the first blocker).
#[inline]
pub fn occluded(prims: &[Primitive], ray: &Ray, tmax: f64) -> bool {
    let inv = Vec3::new(1.0 / ray.dir.x, 1.0 / ray.dir.y, 1.0 / ray.dir.z);
    prims
        .iter()
        .any(|p| p.intersect(ray, inv, 1e-9, tmax).is_some())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: Vec3, d: Vec3) -> Ray {
        Ray {
            origin: o,
            dir: d.normalized(),
        }
    }

    #[test]
    fn analytic_shapes_hit_where_expected() {
        let pose = Pose::new(Mat3::from_euler(0.4, 0.2, -0.3), Vec3::new(0.1, -0.2, 3.0));
        let shapes = [
            Shape::Sphere { radius: 0.5 },
            Shape::Cuboid {
                half: Vec3::new(0.3, 0.4, 0.5),
            },
            Shape::Cylinder {
                radius: 0.4,
                half_height: 0.3,
            },
            Shape::Quad { hx: 0.5, hy: 0.5 },
        ];
        for shape in shapes {
            let prim = Primitive::new(shape, pose, 0);
            // Shoot rays from many directions at the centre: every hit must lie on the surface
            // (checked in local coordinates) and the normal must face the ray.
            for k in 0..200 {
                let a = k as f64 * 0.731;
                let b = (k as f64 * 0.377).sin() * 1.4;
                let dir = Vec3::new(a.cos() * b.cos(), b.sin(), a.sin() * b.cos());
                let o = pose.pos - dir * 4.0;
                let r = ray(o, dir);
                let inv = Vec3::new(1.0 / r.dir.x, 1.0 / r.dir.y, 1.0 / r.dir.z);
                let Some(h) = prim.intersect(&r, inv, 1e-9, 100.0) else {
                    assert!(matches!(shape, Shape::Quad { .. }), "{shape:?} missed");
                    continue;
                };
                assert!(h.normal.dot(r.dir) <= 0.0);
                let l = pose.to_local(h.point);
                let on = match shape {
                    Shape::Sphere { radius } => (l.length() - radius).abs() < 1e-9,
                    Shape::Cuboid { half } => {
                        let q = l.abs() - half;
                        q.x.max(q.y).max(q.z).abs() < 1e-9
                    }
                    Shape::Cylinder {
                        radius,
                        half_height,
                    } => {
                        let rr = l.x.hypot(l.y);
                        ((rr - radius).abs() < 1e-9 && l.z.abs() <= half_height + 1e-9)
                            || ((l.z.abs() - half_height).abs() < 1e-9 && rr <= radius + 1e-9)
                    }
                    Shape::Quad { hx, hy } => {
                        l.z.abs() < 1e-9 && l.x.abs() <= hx + 1e-9 && l.y.abs() <= hy + 1e-9
                    }
                    Shape::Plane => true,
                };
                assert!(on, "{shape:?}: {l:?} not on the surface");
                // Nothing nearer: the ray origin is outside, so the hit is the entry point.
                assert!(h.t < 4.0 + 1e-9);
                // The world-space fast paths agree with the local-frame computation.
                let (tr, nr) = prim.intersect_reference(&r, 1e-9, 100.0).unwrap();
                assert!((tr - h.t).abs() < 1e-9 && (nr.dot(h.normal).abs() - 1.0).abs() < 1e-9);
            }
        }
    }
}
