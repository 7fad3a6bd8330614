//! Misaligned views rendered from the scene (`perturb::apply_rendered`) against the flow model
//! they claim: a plate 1.5 m in front of a wall 3 m away, calibrations chosen so that the flow
//! `t/z + c` is a whole number of pixels on both surfaces, so that every valid pixel of the
//! rendered view must show exactly what the aligned (ToF) view shows at `q + W(q)`.

use dear_capture::Calibration;
use dear_synth::geometry::Pose;
use dear_synth::math::{Mat3, Vec3};
use dear_synth::perturb::apply_rendered;
use dear_synth::scene::{Camera, Object, ObjectKind, PointLight, Scene};
use dear_synth::simulate::simulate;
use dear_synth::texture::Material;

mod common;
use common::direct_centre_rays;

const PLATE_Z: f64 = 1.5;
const WALL_Z: f64 = 3.0;

fn scene() -> Scene {
    let camera = Camera::from_hfov(64, 48, 60.0);
    let mut scene = Scene::empty(camera);
    scene.push(Object {
        kind: ObjectKind::Wall,
        pose: Pose::new(Mat3::looking_along(Vec3::Z), Vec3::new(0.0, 0.0, WALL_Z)),
        material: Material::uniform(0.3, 0.5),
    });
    scene.push(Object {
        kind: ObjectKind::Plate { hx: 0.4, hy: 0.3 },
        pose: Pose::new(Mat3::IDENTITY, Vec3::new(0.1, 0.0, PLATE_Z)),
        material: Material::uniform(0.8, 0.5),
    });
    // An off-axis light, so the shading varies across each surface and a view shifted by the
    // wrong amount shows different values.
    scene.rgb_lights.push(PointLight {
        position: Vec3::new(-1.0, -0.8, 0.2),
        intensity: Vec3::new(2.0, 1.6, 1.2),
    });
    scene.rgb_ambient = Vec3::new(0.05, 0.05, 0.05);
    scene
}

#[test]
fn every_valid_pixel_of_a_rendered_view_shows_what_the_tof_pixel_of_its_flow_sees() {
    let scene = scene();
    let cfg = direct_centre_rays();
    let aligned = simulate(&scene, &cfg, 5, 0).into_capture_sample(0, 0);
    let tof_gt = aligned.truth.depth.clone().unwrap();
    // Plate: 3.0/1.5 + 3 = 5 px across, −2 px down; wall: 3.0/3 + 3 = 4 px, −2 px.
    let p = Calibration {
        tx: 3.0,
        ty: 0.0,
        cx: 3.0,
        cy: -2.0,
    };
    let view = apply_rendered(&aligned, &scene, &cfg, 5, p).unwrap();
    let (depth, mask, flow) = (
        view.truth.depth.unwrap(),
        view.truth.mask.unwrap(),
        view.truth.flow.unwrap(),
    );
    let rgb = &view.frame.rgb;
    let (h, w) = depth.dim();

    // A camera sees something everywhere in this scene: no holes in the rendered view.
    assert!(
        depth.iter().all(|&z| z > 0.0),
        "the rendered view has holes"
    );
    let (mut valid, mut disoccluded) = (0, 0);
    for ((y, x), &z) in depth.indexed_iter() {
        let (u, v) = (flow.u[(y, x)], flow.v[(y, x)]);
        let expected = if (z as f64 - PLATE_Z).abs() < 1e-4 {
            5.0
        } else {
            assert!((z as f64 - WALL_Z).abs() < 1e-4, "({x},{y}) depth {z}");
            4.0
        };
        assert_eq!((u, v), (expected, -2.0), "flow at ({x},{y})");
        let (qx, qy) = (x as i64 + u as i64, y as i64 + v as i64);
        let inside = qx >= 0 && qy >= 0 && qx < w as i64 && qy < h as i64;
        let same_point = inside && tof_gt[(qy as usize, qx as usize)] == z;
        assert_eq!(mask[(y, x)], same_point, "mask at ({x},{y})");
        if !same_point {
            // The strip of wall the plate hides from the ToF sensor, or the border.
            disoccluded += usize::from(inside);
            continue;
        }
        valid += 1;
        for c in 0..3 {
            let (a, b) = (
                i32::from(rgb[(y, x, c)]),
                i32::from(aligned.frame.rgb[(qy as usize, qx as usize, c)]),
            );
            assert!((a - b).abs() <= 1, "({x},{y}) channel {c}: {a} vs {b}");
        }
    }
    assert!(valid > h * w / 2, "{valid} valid pixels");
    // The plate's 1 px larger shift uncovers a 1 px strip of wall beside it (its height in
    // rows, less the rows that left the image).
    assert!(disoccluded > 10, "{disoccluded} disoccluded pixels");
}
