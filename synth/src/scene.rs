//! Scenes: a camera, the ToF illuminator, the RGB lights, and textured objects in a room.
//!
//! Coordinates are those of the camera at rest: x right, y down, z forward (image axes), metres.
//! [`Scene::random`] draws a "ToF-FlyingThings" scene: a tilted box-shaped room (floor, ceiling,
//! four walls, each its own material) around the camera and 5–25 random objects mostly 0.3–4 m
//! away, at least one of them concave (open box, V-shaped plates or an L) so that multi-path
//! interference appears away from the room corners too.

use dear_capture::Calibration;
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::geometry::{Pose, Primitive, Ray, Shape};
use crate::math::{Mat3, Vec3};
use crate::rng::{keyed_rng, Stream};
use crate::texture::{random_unit, Material};

/// A pinhole camera. Both the ToF sensor and the RGB camera of an aligned sample use it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub width: usize,
    pub height: usize,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Camera → world.
    pub pose: Pose,
}

impl Camera {
    /// A centred pinhole with horizontal field of view `hfov_deg`, square pixels, at the origin
    /// looking along +z. Pixel centres are at integer coordinates, so the principal point of a
    /// `W×H` image is `((W−1)/2, (H−1)/2)`, as in `dear_pipeline`'s `Intrinsics::from_hfov`.
    pub fn from_hfov(width: usize, height: usize, hfov_deg: f64) -> Camera {
        let f = 0.5 * width as f64 / (0.5 * hfov_deg.to_radians()).tan();
        Camera {
            width,
            height,
            fx: f,
            fy: f,
            cx: 0.5 * width as f64 - 0.5,
            cy: 0.5 * height as f64 - 0.5,
            pose: Pose::IDENTITY,
        }
    }

    /// Direction (camera frame, not normalised, z = 1) through image point `(u, v)`.
    #[inline]
    pub fn dir_camera(&self, u: f64, v: f64) -> Vec3 {
        Vec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// The world ray through image point `(u, v)` (pixel centres at integers).
    #[inline]
    pub fn ray(&self, u: f64, v: f64) -> Ray {
        Ray {
            origin: self.pose.pos,
            dir: self.pose.rot.apply(self.dir_camera(u, v).normalized()),
        }
    }

    /// The factor converting radial distance to z-depth along the ray through `(u, v)`:
    /// `z = r · cos(angle to the optical axis) = r / |(x̂, ŷ, 1)|`.
    #[inline]
    pub fn radial_to_z(&self, u: f64, v: f64) -> f64 {
        1.0 / self.dir_camera(u, v).length()
    }

    /// z-depth (camera frame) of a world point.
    #[inline]
    pub fn z_of(&self, p: Vec3) -> f64 {
        self.pose.to_local(p).z
    }

    /// The RGB camera of a module whose RGB–ToF calibration is `p` when this camera is its ToF
    /// sensor: RGB pixel `q` then sees what ToF pixel `q + (t/z + c)` sees, at the same z.
    /// A point at camera-frame `(X, Y, Z)` projects to `f·X/Z + c₀` here and to
    /// `f·(X − d)/Z + c₀ − c` from a centre moved by `d` with the principal point moved by
    /// `−c`; their difference is `f·d/Z + c`, so `d = (t_x/f_x, t_y/f_y, 0)` (no rotation, no
    /// z offset: the flow model has neither).
    pub fn rgb_camera_of(&self, p: &Calibration) -> Camera {
        let d = Vec3::new(p.tx as f64 / self.fx, p.ty as f64 / self.fy, 0.0);
        Camera {
            cx: self.cx - p.cx as f64,
            cy: self.cy - p.cy as f64,
            pose: Pose::new(self.pose.rot, self.pose.to_world(d)),
            ..*self
        }
    }
}

/// An isotropic point light for the RGB image.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PointLight {
    pub position: Vec3,
    /// Radiant intensity per colour channel (irradiance at 1 m, normal incidence).
    pub intensity: Vec3,
}

/// What an object is; decides its parts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ObjectKind {
    /// A room surface (infinite plane through the object's origin, normal = local z).
    Wall,
    Sphere {
        radius: f64,
    },
    Box {
        half: Vec3,
    },
    Cylinder {
        radius: f64,
        half_height: f64,
    },
    /// A thin square plate (local z normal).
    Plate {
        hx: f64,
        hy: f64,
    },
    /// Five thin plates: a box open towards local +z (concave).
    OpenBox {
        half: Vec3,
    },
    /// Two plates hinged along the local y axis, opening towards +z with `angle` radians
    /// between them (concave).
    VPlates {
        width: f64,
        height: f64,
        angle: f64,
    },
    /// Two boxes forming an L in the local xy plane (concave inner corner).
    LShape {
        arm: f64,
        thickness: f64,
        depth: f64,
    },
}

impl ObjectKind {
    pub fn is_concave(&self) -> bool {
        matches!(
            self,
            ObjectKind::OpenBox { .. } | ObjectKind::VPlates { .. } | ObjectKind::LShape { .. }
        )
    }

    /// The primitives (in object coordinates) the object is made of.
    pub fn parts(&self) -> Vec<(Shape, Pose)> {
        let at = |shape, rot, pos| (shape, Pose::new(rot, pos));
        match *self {
            ObjectKind::Wall => vec![at(Shape::Plane, Mat3::IDENTITY, Vec3::ZERO)],
            ObjectKind::Sphere { radius } => {
                vec![at(Shape::Sphere { radius }, Mat3::IDENTITY, Vec3::ZERO)]
            }
            ObjectKind::Box { half } => {
                vec![at(Shape::Cuboid { half }, Mat3::IDENTITY, Vec3::ZERO)]
            }
            ObjectKind::Cylinder {
                radius,
                half_height,
            } => vec![at(
                Shape::Cylinder {
                    radius,
                    half_height,
                },
                Mat3::IDENTITY,
                Vec3::ZERO,
            )],
            ObjectKind::Plate { hx, hy } => {
                vec![at(Shape::Quad { hx, hy }, Mat3::IDENTITY, Vec3::ZERO)]
            }
            ObjectKind::OpenBox { half: h } => {
                let ry = Mat3::rotation(Vec3::Y, std::f64::consts::FRAC_PI_2);
                let rx = Mat3::rotation(Vec3::X, -std::f64::consts::FRAC_PI_2);
                vec![
                    at(
                        Shape::Quad { hx: h.x, hy: h.y },
                        Mat3::IDENTITY,
                        Vec3::new(0.0, 0.0, -h.z),
                    ),
                    at(
                        Shape::Quad { hx: h.z, hy: h.y },
                        ry,
                        Vec3::new(h.x, 0.0, 0.0),
                    ),
                    at(
                        Shape::Quad { hx: h.z, hy: h.y },
                        ry,
                        Vec3::new(-h.x, 0.0, 0.0),
                    ),
                    at(
                        Shape::Quad { hx: h.x, hy: h.z },
                        rx,
                        Vec3::new(0.0, h.y, 0.0),
                    ),
                    at(
                        Shape::Quad { hx: h.x, hy: h.z },
                        rx,
                        Vec3::new(0.0, -h.y, 0.0),
                    ),
                ]
            }
            ObjectKind::VPlates {
                width,
                height,
                angle,
            } => {
                let (s, c) = (0.5 * angle).sin_cos();
                [1.0, -1.0]
                    .into_iter()
                    .map(|side| {
                        let u = Vec3::new(side * s, 0.0, c);
                        let rot = Mat3::from_cols(u, Vec3::Y, u.cross(Vec3::Y));
                        at(
                            Shape::Quad {
                                hx: 0.5 * width,
                                hy: 0.5 * height,
                            },
                            rot,
                            u * (0.5 * width),
                        )
                    })
                    .collect()
            }
            ObjectKind::LShape {
                arm,
                thickness,
                depth,
            } => {
                let off = Vec3::new(arm / 3.0, arm / 3.0, 0.0);
                vec![
                    at(
                        Shape::Cuboid {
                            half: Vec3::new(0.5 * arm, 0.5 * thickness, 0.5 * depth),
                        },
                        Mat3::IDENTITY,
                        Vec3::new(0.5 * arm, 0.5 * thickness, 0.0) - off,
                    ),
                    at(
                        Shape::Cuboid {
                            half: Vec3::new(0.5 * thickness, 0.5 * arm, 0.5 * depth),
                        },
                        Mat3::IDENTITY,
                        Vec3::new(0.5 * thickness, 0.5 * arm, 0.0) - off,
                    ),
                ]
            }
        }
    }
}

/// A textured object at a pose.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Object {
    pub kind: ObjectKind,
    pub pose: Pose,
    pub material: Material,
}

/// Everything the renderer needs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Scene {
    pub camera: Camera,
    /// Position of the ToF illuminator in the camera frame (0 = at the camera centre).
    pub tof_light_offset: Vec3,
    /// Radiant intensity of the ToF illuminator. `π` makes a white (albedo 1) fronto-parallel
    /// surface 1 m away return a signal of 1.
    pub tof_light_intensity: f64,
    /// The illuminator emits only into the camera's field of view widened by this fraction
    /// (a diffuser shapes a VCSEL's beam to the sensor's view); outside it is dark. Without
    /// this, an isotropic source would flood the walls beside and behind the camera and
    /// produce far more MPI than a real module sees.
    pub tof_light_fov_margin: f64,
    /// Ambient near-infrared irradiance (sunlight, lamps), same units as the signal.
    pub ambient_ir: f64,
    pub rgb_lights: Vec<PointLight>,
    /// Ambient light for the RGB image (per channel).
    pub rgb_ambient: Vec3,
    pub objects: Vec<Object>,
    #[serde(skip)]
    prims: Vec<Primitive>,
}

/// Ranges of the random scene generator.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SceneConfig {
    pub min_objects: usize,
    pub max_objects: usize,
    /// Range of object distances (z, metres).
    pub min_depth: f64,
    pub max_depth: f64,
    /// Ambient IR irradiance range.
    pub ambient_ir: (f64, f64),
    /// Position of the ToF illuminator relative to the camera centre (camera frame, metres).
    /// Non-zero puts it beside the lens as on a real module; the sensor then measures half the
    /// path camera → surface → illuminator, which differs from the radial distance by up to
    /// about half the offset (a real module calibrates this; the simulator does not).
    #[serde(default)]
    pub light_offset: Vec3,
}

impl Default for SceneConfig {
    fn default() -> Self {
        SceneConfig {
            min_objects: 5,
            max_objects: 25,
            min_depth: 0.3,
            max_depth: 4.0,
            ambient_ir: (0.0, 0.05),
            light_offset: Vec3::ZERO,
        }
    }
}

impl Scene {
    /// A scene with no objects; add some with [`Scene::push`].
    pub fn empty(camera: Camera) -> Scene {
        Scene {
            camera,
            tof_light_offset: Vec3::ZERO,
            tof_light_intensity: std::f64::consts::PI,
            tof_light_fov_margin: 0.15,
            ambient_ir: 0.0,
            rgb_lights: Vec::new(),
            rgb_ambient: Vec3::new(1.0, 1.0, 1.0),
            objects: Vec::new(),
            prims: Vec::new(),
        }
    }

    pub fn push(&mut self, object: Object) {
        self.objects.push(object);
        self.rebuild();
    }

    /// Recomputes the primitive list from the objects (after moving them).
    pub fn rebuild(&mut self) {
        self.prims = self
            .objects
            .iter()
            .enumerate()
            .flat_map(|(i, o)| {
                o.kind.parts().into_iter().map(move |(shape, part)| {
                    Primitive::new(shape, o.pose.compose(&part), i as u32)
                })
            })
            .collect();
    }

    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }

    /// Whether the illuminator emits towards world point `p`.
    #[inline]
    pub fn tof_light_reaches(&self, p: Vec3) -> bool {
        let c = &self.camera;
        let q = c.pose.to_local(p) - self.tof_light_offset;
        if q.z <= 0.0 {
            return false;
        }
        let m = 1.0 + self.tof_light_fov_margin;
        let half_w = (c.cx + 0.5).max(c.width as f64 - 0.5 - c.cx) / c.fx;
        let half_h = (c.cy + 0.5).max(c.height as f64 - 0.5 - c.cy) / c.fy;
        (q.x / q.z).abs() <= m * half_w && (q.y / q.z).abs() <= m * half_h
    }

    /// World position of the ToF illuminator.
    pub fn tof_light(&self) -> Vec3 {
        self.camera.pose.to_world(self.tof_light_offset)
    }

    /// A random room-and-objects scene, fully determined by `(seed, index)`.
    pub fn random(camera: Camera, config: &SceneConfig, seed: u64, index: u64) -> Scene {
        let mut rng = keyed_rng(seed, Stream::Scene, index, 0);
        let mut scene = Scene::empty(camera);
        scene.tof_light_offset = config.light_offset;
        let room = random_room(&mut rng, &mut scene);
        scene.ambient_ir = rng.random_range(config.ambient_ir.0..=config.ambient_ir.1);
        let n = rng.random_range(config.min_objects..=config.max_objects.max(config.min_objects));
        for i in 0..n {
            // The first object is always concave so every scene has MPI off the room corners.
            let obj = random_object(&mut rng, &camera, config, &room, i == 0);
            scene.objects.push(obj);
        }
        scene.rebuild();
        scene
    }
}

/// The room's extent, for keeping objects inside it.
struct Room {
    /// Distance to the front wall along the camera axis (approximately; the room is tilted).
    front: f64,
}

fn random_room<R: Rng>(rng: &mut R, scene: &mut Scene) -> Room {
    // Room frame: tilted relative to the camera (yaw ±25°, pitch ±10°, roll ±5°).
    let rot = Mat3::from_euler(
        rng.random_range(-10f64..10.0).to_radians(),
        rng.random_range(-25f64..25.0).to_radians(),
        rng.random_range(-5f64..5.0).to_radians(),
    );
    // Distances chosen so that the farthest room corner stays within 6.6 m, inside the
    // 7.49 m unambiguous range of the default 20 MHz modulation.
    let front = rng.random_range(3.5..5.5);
    let back = rng.random_range(0.5..1.5);
    let left = rng.random_range(1.5..3.0);
    let right = rng.random_range(1.5..3.0);
    let floor = rng.random_range(0.8..1.5);
    let ceiling = rng.random_range(1.0..2.0);
    // (direction of the outward wall normal in the room frame, distance, size for textures)
    let walls = [
        (Vec3::Z, front, 2.0),
        (-Vec3::Z, back, 2.0),
        (-Vec3::X, left, 2.0),
        (Vec3::X, right, 2.0),
        (Vec3::Y, floor, 2.0),
        (-Vec3::Y, ceiling, 2.0),
    ];
    for (n, d, size) in walls {
        let nw = rot.apply(n);
        let (material, _) = Material::random(rng, size);
        scene.objects.push(Object {
            kind: ObjectKind::Wall,
            pose: Pose::new(Mat3::looking_along(nw), nw * d),
            material,
        });
    }
    // Two lamps near the ceiling, somewhere in front of the camera, warm and cool.
    for warm in [true, false] {
        let p = Vec3::new(
            rng.random_range(-0.8 * left..0.8 * right),
            -0.85 * ceiling,
            rng.random_range(0.0..0.8 * front),
        );
        let level = rng.random_range(0.4..1.0) * (1.0 + p.length_squared());
        let tint = if warm {
            Vec3::new(1.0, 0.9, 0.75)
        } else {
            Vec3::new(0.8, 0.9, 1.0)
        };
        scene.rgb_lights.push(PointLight {
            position: rot.apply(p),
            intensity: tint * level,
        });
    }
    let amb = rng.random_range(0.15..0.35);
    scene.rgb_ambient = Vec3::new(amb, amb, amb);
    Room { front }
}

fn random_object<R: Rng>(
    rng: &mut R,
    camera: &Camera,
    config: &SceneConfig,
    room: &Room,
    force_concave: bool,
) -> Object {
    // Where: a random image location (slightly beyond the borders too) and a depth. Depth is
    // drawn uniformly in 1/z between the limits, which favours near objects as a scattered
    // scene seen in perspective does.
    let u = rng.random_range(-0.1..1.1) * camera.width as f64;
    let v = rng.random_range(-0.1..1.1) * camera.height as f64;
    let zmax = config
        .max_depth
        .min(0.85 * room.front)
        .max(config.min_depth + 0.1);
    let inv = rng.random_range(1.0 / zmax..1.0 / config.min_depth);
    let z = 1.0 / inv;
    let centre_cam = camera.dir_camera(u, v) * z;
    // Size proportional to the distance: 6–20° of view.
    let size = z * rng.random_range(0.1..0.35);
    let mut rot = {
        let axis = random_unit(rng);
        Mat3::rotation(axis, rng.random_range(0.0..std::f64::consts::TAU))
    };
    let kind_roll = if force_concave {
        rng.random_range(5..8)
    } else {
        rng.random_range(0..8)
    };
    let kind = match kind_roll {
        0 => ObjectKind::Sphere { radius: 0.5 * size },
        1 => ObjectKind::Box {
            half: Vec3::new(
                rng.random_range(0.2..0.5) * size,
                rng.random_range(0.2..0.5) * size,
                rng.random_range(0.2..0.5) * size,
            ),
        },
        2 => ObjectKind::Cylinder {
            radius: rng.random_range(0.15..0.4) * size,
            half_height: rng.random_range(0.2..0.5) * size,
        },
        3 => ObjectKind::Plate {
            hx: rng.random_range(0.25..0.5) * size,
            hy: rng.random_range(0.25..0.5) * size,
        },
        4 => ObjectKind::LShape {
            arm: size * 0.8,
            thickness: rng.random_range(0.15..0.35) * size,
            depth: rng.random_range(0.2..0.6) * size,
        },
        5 => ObjectKind::OpenBox {
            half: Vec3::new(
                rng.random_range(0.3..0.5) * size,
                rng.random_range(0.3..0.5) * size,
                rng.random_range(0.2..0.45) * size,
            ),
        },
        6 => ObjectKind::VPlates {
            width: rng.random_range(0.4..0.6) * size,
            height: rng.random_range(0.5..0.9) * size,
            angle: rng.random_range(50f64..130.0).to_radians(),
        },
        _ => ObjectKind::LShape {
            arm: size * 0.8,
            thickness: rng.random_range(0.15..0.35) * size,
            depth: rng.random_range(0.2..0.6) * size,
        },
    };
    if matches!(
        kind,
        ObjectKind::OpenBox { .. } | ObjectKind::VPlates { .. } | ObjectKind::LShape { .. }
    ) {
        // Turn the concave side roughly towards the camera (within ~45°), or MPI inside it is
        // mostly hidden.
        let to_cam = (-centre_cam).normalized();
        let jitter = random_unit(rng) * 0.7;
        let facing = Mat3::looking_along((to_cam + jitter).normalized());
        rot = facing * Mat3::rotation(Vec3::Z, rng.random_range(0.0..std::f64::consts::TAU));
    }
    let (material, _) = Material::random(rng, size);
    Object {
        kind,
        pose: camera.pose.compose(&Pose::new(rot, centre_cam)),
        material,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::intersect_all;

    #[test]
    fn random_scenes_are_closed_rooms_with_concave_objects() {
        let cam = Camera::from_hfov(64, 48, 70.0);
        for s in 0..20 {
            let scene = Scene::random(cam, &SceneConfig::default(), 42, s);
            let objs = scene.objects.len() - 6;
            assert!((5..=25).contains(&objs));
            assert!(scene.objects.iter().any(|o| o.kind.is_concave()));
            // Every camera ray hits something, within the unambiguous range.
            for v in (0..48).step_by(7) {
                for u in (0..64).step_by(7) {
                    let r = cam.ray(u as f64, v as f64);
                    let h = intersect_all(scene.primitives(), &r, 1e9).expect("closed room");
                    assert!(h.t < 7.0 && h.t > 0.05, "t = {}", h.t);
                }
            }
        }
        // Deterministic.
        let a = Scene::random(cam, &SceneConfig::default(), 7, 3);
        let b = Scene::random(cam, &SceneConfig::default(), 7, 3);
        assert_eq!(a.objects, b.objects);
    }
}
