//! The SDK's point cloud against the simulator's ground truth (issue 35): a tilted plate at a
//! known pose is rendered by dear-synth, its ground-truth z-depth back-projected by
//! `dear_client::points` through a frame header carrying the camera's intrinsics, and every
//! point compared with the scene's geometry computed here independently: the ray through the
//! pixel centre intersected with the plate's plane in f64.

use dear_client::points::{point_cloud, PointCloudOptions};
use dear_client::{CameraIntrinsics, FrameHeader};
use dear_synth::geometry::Pose;
use dear_synth::math::{Mat3, Vec3};
use dear_synth::scene::{Camera, Object, ObjectKind, Scene};
use dear_synth::simulate::simulate;
use dear_synth::texture::Material;

mod common;
use common::direct_centre_rays;

#[test]
fn back_projected_ground_truth_lies_on_the_rendered_plate() {
    // Non-square pixels and an off-centre principal point, so fx/fy or cx/cy mixed up fails.
    let camera = Camera {
        width: 96,
        height: 72,
        fx: 80.0,
        fy: 86.0,
        cx: 45.3,
        cy: 37.8,
        pose: Pose::IDENTITY,
    };
    let (hx, hy) = (0.45, 0.3);
    let rot = Mat3::rotation(Vec3::Y, 0.5) * Mat3::rotation(Vec3::X, -0.3);
    let centre = Vec3::new(0.1, -0.05, 1.5);
    let mut scene = Scene::empty(camera);
    scene.push(Object {
        kind: ObjectKind::Plate { hx, hy },
        pose: Pose::new(rot, centre),
        material: Material::uniform(0.6, 0.6),
    });
    let config = direct_centre_rays();
    let sample = simulate(&scene, &config, 3, 0);
    let gt = sample.gt_depth.as_slice().unwrap();

    let (w, h) = (camera.width, camera.height);
    let mut header = FrameHeader::new(0, w as u32, h as u32);
    header.set_intrinsics(Some(&CameraIntrinsics::pinhole(
        camera.fx as f32,
        camera.fy as f32,
        camera.cx as f32,
        camera.cy as f32,
    )));
    let rgb = sample.rgb.as_slice().unwrap();
    let confidence = vec![255u8; w * h];
    let options = PointCloudOptions {
        colors: true,
        confidence: false,
    };
    let cloud = point_cloud(&header, gt, rgb, &confidence, options).unwrap();

    // The plate's plane: normal = its local z, through its centre.
    let normal = rot.apply(Vec3::Z);
    let (mut on_plate, mut off_plate) = (0, 0);
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            let p = cloud.points[i];
            if gt[i] == 0.0 {
                // The ray misses the plate: no point, and not one at the origin.
                assert!(!cloud.valid[i], "pixel ({u}, {v}) without depth is valid");
                assert!(p.iter().all(|c| c.is_nan()), "pixel ({u}, {v}): {p:?}");
                off_plate += 1;
                continue;
            }
            assert!(cloud.valid[i], "pixel ({u}, {v}) with depth is not valid");
            on_plate += 1;
            let z = f64::from(gt[i]);
            // The formula, in f64 from the same z.
            let formula = [
                (u as f64 - camera.cx) * z / camera.fx,
                (v as f64 - camera.cy) * z / camera.fy,
                z,
            ];
            // The scene's point: the pixel's ray intersected with the plate's plane.
            let dir = Vec3::new(
                (u as f64 - camera.cx) / camera.fx,
                (v as f64 - camera.cy) / camera.fy,
                1.0,
            );
            let t = normal.dot(centre) / normal.dot(dir);
            let scene_point = dir * t;
            let p64 = Vec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            for c in 0..3 {
                let (got, want) = ([p64.x, p64.y, p64.z][c], formula[c]);
                assert!(
                    (got - want).abs() <= 2e-6 * want.abs().max(1.0),
                    "pixel ({u}, {v}) coordinate {c}: {got} vs formula {want}"
                );
            }
            let error = (p64 - scene_point).length();
            assert!(
                error < 2e-5,
                "pixel ({u}, {v}): point {p64:?} is {error} m from the scene's {scene_point:?}"
            );
            // On the plane, and inside the plate.
            let local = rot.apply_transpose(p64 - centre);
            assert!(
                local.z.abs() < 2e-5,
                "pixel ({u}, {v}) off the plane: {local:?}"
            );
            assert!(
                local.x.abs() <= hx + 0.02 && local.y.abs() <= hy + 0.02,
                "pixel ({u}, {v}) outside the plate: {local:?}"
            );
            // Its colour is the aligned RGB pixel's.
            let colour = cloud.colors.as_ref().unwrap()[i];
            assert_eq!(colour, [rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]]);
        }
    }
    // Both kinds of pixel are there: the checks above ran on something.
    assert!(
        on_plate > 500 && off_plate > 500,
        "{on_plate} on, {off_plate} off"
    );
    assert_eq!(cloud.valid_count(), on_plate);
}
