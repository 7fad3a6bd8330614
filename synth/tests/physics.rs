//! Physics checks of the ToF simulator: each test builds a small scene whose answer is known
//! analytically (or by independent quadrature) and compares the simulator against it.

use dear_synth::geometry::Pose;
use dear_synth::math::{Complex, Mat3, Vec3};
use dear_synth::scene::{Camera, Object, ObjectKind, Scene};
use dear_synth::sensor::{predicted_range_std, sense, unambiguous_range, SensorConfig};
use dear_synth::simulate::{simulate, SimConfig};
use dear_synth::texture::Material;
use dear_synth::transport::{render, render_pixel, RenderOptions, SPEED_OF_LIGHT};
use ndarray::Array2;

fn object(kind: ObjectKind, rot: Mat3, pos: Vec3, ir: f64) -> Object {
    Object {
        kind,
        pose: Pose::new(rot, pos),
        material: Material::uniform(0.5, ir),
    }
}

/// A wall (infinite plane) whose normal is `normal`, through `point`.
fn wall(normal: Vec3, point: Vec3, ir: f64) -> Object {
    object(ObjectKind::Wall, Mat3::looking_along(normal), point, ir)
}

fn ideal(opts: RenderOptions) -> SimConfig {
    SimConfig {
        render: RenderOptions { rgb: false, ..opts },
        sensor: SensorConfig {
            noise: false,
            min_amplitude_dn: 0.0,
            ..SensorConfig::default()
        },
        rgb_exposure: 1.0,
    }
}

fn amplitude_of_unit_signal(cfg: &SensorConfig) -> f64 {
    cfg.electrons_per_unit / cfg.gain_e_per_dn
}

/// A fronto-parallel plane has no MPI: depth exact to < 1 mm without noise (with sub-pixel
/// jitter and three bounces), and amplitude equal to `κ/g · ρ/π · I cosθ / r²` at every pixel
/// (rays through the pixel centres), at two distances.
#[test]
fn fronto_parallel_plane_is_exact_and_follows_inverse_square() {
    let cam = Camera::from_hfov(40, 30, 60.0);
    let full = ideal(RenderOptions {
        spp: 4,
        indirect_spp: 4,
        max_bounces: 3,
        ..RenderOptions::default()
    });
    let centres = ideal(RenderOptions {
        spp: 1,
        jitter: false,
        ..full.render.clone()
    });
    let unit = amplitude_of_unit_signal(&full.sensor);
    let mut centre_amp = Vec::new();
    for z in [1.2, 2.4] {
        let mut scene = Scene::empty(cam);
        scene.push(wall(Vec3::Z, Vec3::new(0.0, 0.0, z), 0.6));
        let s = simulate(&scene, &full, 1, 0);
        let c = simulate(&scene, &centres, 1, 0);
        for ((y, x), &d) in s.tof.depth.indexed_iter() {
            assert!((d as f64 - z).abs() < 1e-3, "({x},{y}) depth {d} vs {z}");
            assert!((s.gt_depth[(y, x)] as f64 - z).abs() < 1e-6);
            // r = z·|dir|, cosθ = z / r for a light at the camera centre.
            let r = z * cam.dir_camera(x as f64, y as f64).length();
            let expected = unit * 0.6 * (z / r) / (r * r);
            let a = c.tof.amplitude[(y, x)] as f64;
            assert!(
                (a / expected - 1.0).abs() < 1e-5,
                "({x},{y}) amp {a} vs {expected}"
            );
            // With jitter the amplitude is the footprint average: within 1 %.
            let aj = s.tof.amplitude[(y, x)] as f64;
            assert!(
                (aj / expected - 1.0).abs() < 0.01,
                "({x},{y}) amp {aj} vs {expected}"
            );
        }
        centre_amp.push(c.tof.amplitude[(15, 20)] as f64);
    }
    // Twice the distance: a quarter of the amplitude.
    assert!((centre_amp[0] / centre_amp[1] - 4.0).abs() < 1e-4);
}

/// A plane tilted by θ about the vertical axis, seen head-on at the image centre: amplitude
/// `∝ cosθ / r²` at two distances and two tilts.
#[test]
fn tilted_plane_amplitude_follows_cosine() {
    let cam = Camera::from_hfov(21, 21, 10.0);
    let cfg = ideal(RenderOptions {
        spp: 1,
        indirect_spp: 0,
        max_bounces: 1,
        jitter: false,
        ..RenderOptions::default()
    });
    let unit = amplitude_of_unit_signal(&cfg.sensor);
    for z in [1.0, 3.0] {
        for theta in [0f64, 50.0] {
            let t = theta.to_radians();
            let mut scene = Scene::empty(cam);
            let n = Vec3::new(t.sin(), 0.0, t.cos());
            scene.push(wall(n, Vec3::new(0.0, 0.0, z), 0.4));
            let s = simulate(&scene, &cfg, 2, 0);
            let a = s.tof.amplitude[(10, 10)] as f64;
            let expected = unit * 0.4 * t.cos() / (z * z);
            assert!(
                (a / expected - 1.0).abs() < 1e-6,
                "z {z} θ {theta}: {a} vs {expected}"
            );
            assert!((s.tof.depth[(10, 10)] as f64 - z).abs() < 1e-4);
        }
    }
}

/// Mean depth error (ToF − GT) of the columns whose distance to the crease column falls in
/// each 4-px band.
fn band_profile(err: &Array2<f64>, crease_x: f64, bands: usize) -> Vec<f64> {
    (0..bands)
        .map(|b| {
            let (lo, hi) = (4.0 * b as f64, 4.0 * (b + 1) as f64);
            let v: Vec<f64> = err
                .indexed_iter()
                .filter(|((_, x), _)| {
                    let d = (*x as f64 - crease_x).abs();
                    d >= lo && d < hi
                })
                .map(|(_, &e)| e)
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        })
        .collect()
}

/// A concave 90° corner: MPI makes the depth too far everywhere; the error peaks near the
/// crease (within ~0.3 m of it) and decays away from it. (Exactly at the crease
/// the detour through the other plate is short, so the error there is a little below the
/// peak: the extra path `√(a² + s²) − (s − a)/√2` grows with the distance `a` from the crease.)
#[test]
fn concave_corner_reads_too_far_most_near_the_crease() {
    // The view (50° wide) sees nothing but the two plates.
    let cam = Camera::from_hfov(48, 16, 50.0);
    let cfg = ideal(RenderOptions {
        spp: 4,
        indirect_spp: 32,
        max_bounces: 3,
        ..RenderOptions::default()
    });
    // Two 1.2 m square plates hinged along the vertical line x = 0, z = 2.5, each at 45° to
    // the view axis: the corner opens towards the camera.
    let mut scene = Scene::empty(cam);
    scene.push(object(
        ObjectKind::VPlates {
            width: 1.2,
            height: 1.2,
            angle: std::f64::consts::FRAC_PI_2,
        },
        Mat3::rotation(Vec3::Y, std::f64::consts::PI),
        Vec3::new(0.0, 0.0, 2.5),
        0.7,
    ));
    let sample = simulate(&scene, &cfg, 3, 0);
    assert!(sample.gt_depth.iter().all(|&z| z > 1.6 && z <= 2.5));
    let err = Array2::from_shape_fn(sample.gt_depth.dim(), |p| {
        sample.tof.depth[p] as f64 - sample.gt_depth[p] as f64
    });
    assert!(
        err.iter().all(|&e| e > 0.0),
        "MPI can only lengthen the paths: min error {}",
        err.iter().cloned().fold(f64::INFINITY, f64::min)
    );
    let bands = band_profile(&err, cam.cx, 6);
    eprintln!("corner MPI error by 4-px band from the crease (m): {bands:?}");
    let peak = (0..bands.len())
        .max_by(|&a, &b| bands[a].total_cmp(&bands[b]))
        .unwrap();
    // 8 px ≈ 0.3 m of plate at this distance.
    assert!(
        peak <= 1,
        "the error should peak near the crease: {bands:?}"
    );
    assert!(
        bands[peak] > 0.02,
        "MPI near the crease should be centimetres: {bands:?}"
    );
    // Beyond the peak it decays (MC noise of ~1 mm allows no finer steps than these).
    let outer = (bands[3] + bands[4] + bands[5]) / 3.0;
    assert!(
        bands[peak] > bands[2] && bands[2] > outer && outer < 0.8 * bands[peak],
        "error must decay away from the crease: {bands:?}"
    );
}

/// A convex object alone in free space cannot see itself: no path has a second bounce, and
/// the depth is exact away from its silhouette.
#[test]
fn convex_objects_in_free_space_have_no_mpi() {
    let cam = Camera::from_hfov(48, 48, 30.0);
    let kinds = [
        ObjectKind::Sphere { radius: 0.4 },
        ObjectKind::Box {
            half: Vec3::new(0.3, 0.25, 0.35),
        },
        ObjectKind::Cylinder {
            radius: 0.3,
            half_height: 0.3,
        },
    ];
    for kind in kinds {
        let mut scene = Scene::empty(cam);
        scene.push(object(
            kind,
            Mat3::from_euler(0.5, 0.7, 0.2),
            Vec3::new(0.0, 0.0, 2.0),
            0.8,
        ));
        let indirect_only = RenderOptions {
            spp: 4,
            indirect_spp: 16,
            max_bounces: 3,
            min_bounces: 2,
            rgb: false,
            ..RenderOptions::default()
        };
        let sig = render(&scene, &indirect_only, 4, 0);
        assert!(
            sig.pixels.iter().all(|p| p.dc == 0.0),
            "{kind:?}: a convex object received indirect light"
        );
        let sample = simulate(
            &scene,
            &ideal(RenderOptions {
                max_bounces: 3,
                indirect_spp: 4,
                ..RenderOptions::default()
            }),
            4,
            0,
        );
        let (h, w) = sample.gt_depth.dim();
        let mut checked = 0;
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                // Away from the silhouette and from the object's own edges (where one pixel's
                // footprint folds over two faces), the depth is exact: require the 3×3 ground
                // truth to be valid and locally linear (second differences < 2 mm).
                let g = |dy: usize, dx: usize| sample.gt_depth[(y + dy - 1, x + dx - 1)];
                let valid = (0..9).all(|k| g(k / 3, k % 3) > 0.0);
                let flat = (g(1, 0) + g(1, 2) - 2.0 * g(1, 1)).abs() < 2e-3
                    && (g(0, 1) + g(2, 1) - 2.0 * g(1, 1)).abs() < 2e-3;
                if valid && flat {
                    let e = (sample.tof.depth[(y, x)] - sample.gt_depth[(y, x)]).abs();
                    assert!(e < 1e-3, "{kind:?} ({x},{y}): error {e}");
                    checked += 1;
                }
            }
        }
        assert!(checked > 50);
    }
}

/// Flying pixels (mixed foreground/background phasors) appear at depth discontinuities and
/// nowhere else, with depths between the two surfaces.
#[test]
fn flying_pixels_only_at_depth_discontinuities() {
    let cam = Camera::from_hfov(40, 30, 50.0);
    let cfg = ideal(RenderOptions {
        spp: 16,
        indirect_spp: 0,
        max_bounces: 1,
        ..RenderOptions::default()
    });
    let mut scene = Scene::empty(cam);
    scene.push(wall(Vec3::Z, Vec3::new(0.0, 0.0, 3.0), 0.5));
    // A tilted square plate in front (its edges cross pixels at all sub-pixel offsets).
    scene.push(object(
        ObjectKind::Plate { hx: 0.25, hy: 0.25 },
        Mat3::rotation(Vec3::Z, 0.3),
        Vec3::new(0.05, 0.02, 1.0),
        0.5,
    ));
    let s = simulate(&scene, &cfg, 5, 0);
    let (h, w) = s.gt_depth.dim();
    let near_edge = |y: usize, x: usize| {
        let z = s.gt_depth[(y, x)];
        (y.saturating_sub(1)..(y + 2).min(h)).any(|yy| {
            (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| (s.gt_depth[(yy, xx)] - z).abs() > 0.1)
        })
    };
    let mut flying = 0;
    for y in 0..h {
        for x in 0..w {
            let d = s.tof.depth[(y, x)];
            if (d - s.gt_depth[(y, x)]).abs() > 0.02 {
                flying += 1;
                assert!(
                    near_edge(y, x),
                    "flying pixel at ({x},{y}) away from any edge"
                );
                let radial_scale = cam.radial_to_z(x as f64, y as f64) as f32;
                assert!(
                    d > 0.99 * radial_scale && d < 3.01,
                    "a mixed pixel lies between the surfaces: {d}"
                );
            }
        }
    }
    eprintln!("{flying} flying pixels");
    assert!(
        flying >= 20,
        "a 0.5 m plate at 1 m must produce mixed pixels: {flying}"
    );
}

/// Noise falls as the amplitude rises, as the shot + read noise model predicts.
#[test]
fn noise_follows_the_shot_noise_model() {
    let cam = Camera::from_hfov(48, 48, 4.0);
    let opts = RenderOptions {
        spp: 1,
        indirect_spp: 0,
        max_bounces: 1,
        jitter: false,
        rgb: false,
        ..RenderOptions::default()
    };
    let cfg = SensorConfig {
        min_amplitude_dn: 0.0,
        ..SensorConfig::default()
    };
    let f = opts.frequencies_hz[0];
    let mut stds = Vec::new();
    for (z, albedo) in [(1.0, 0.8), (2.5, 0.3), (4.0, 0.1)] {
        let mut scene = Scene::empty(cam);
        scene.ambient_ir = 0.02;
        scene.push(wall(Vec3::Z, Vec3::new(0.0, 0.0, z), albedo));
        let sig = render(&scene, &opts, 6, 0);
        let tof = sense(&sig, &cam, &opts.frequencies_hz, &cfg, 6, 0);
        let mut errs = Vec::new();
        let mut predicted = 0.0;
        for (i, p) in sig.pixels.iter().enumerate() {
            let truth = p.phasor[0].arg().rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU
                * unambiguous_range(f);
            errs.push(tof.radial[(i / sig.width, i % sig.width)] as f64 - truth);
            predicted += predicted_range_std(&cfg, f, p.dc, p.phasor[0].abs(), p.ambient);
        }
        let n = errs.len() as f64;
        predicted /= n;
        let mean = errs.iter().sum::<f64>() / n;
        let std = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        eprintln!("z {z} ρ {albedo}: std {std:.5} m, predicted {predicted:.5} m, bias {mean:.5}");
        assert!(
            (std / predicted - 1.0).abs() < 0.08,
            "std {std} vs predicted {predicted}"
        );
        assert!(mean.abs() < 4.0 * predicted / n.sqrt(), "biased: {mean}");
        stds.push(std);
    }
    assert!(stds[0] < stds[1] && stds[1] < stds[2]);
}

/// Beyond `c / 2f` one frequency wraps; two frequencies unwrap.
#[test]
fn distances_wrap_with_one_frequency_and_unwrap_with_two() {
    let cam = Camera::from_hfov(8, 8, 10.0);
    let z = 9.0;
    let mut scene = Scene::empty(cam);
    scene.push(wall(Vec3::Z, Vec3::new(0.0, 0.0, z), 0.9));
    let base = RenderOptions {
        spp: 1,
        indirect_spp: 0,
        max_bounces: 1,
        jitter: false,
        ..RenderOptions::default()
    };
    let one = simulate(&scene, &ideal(base.clone()), 7, 0);
    let range = SPEED_OF_LIGHT / (2.0 * 20e6);
    let r_centre = one.tof.radial[(4, 4)] as f64;
    let truth = z * cam.dir_camera(4.0, 4.0).length();
    assert!(
        (r_centre - (truth - range)).abs() < 1e-3,
        "wrapped {r_centre}"
    );
    let two = simulate(
        &scene,
        &ideal(RenderOptions {
            frequencies_hz: vec![20e6, 16e6],
            ..base
        }),
        7,
        0,
    );
    for (p, &d) in two.tof.depth.indexed_iter() {
        assert!((d as f64 - z).abs() < 1e-3, "{p:?}: unwrapped {d}");
    }
}

/// The one-bounce indirect term of a two-plane scene against an independent quadrature of the
/// same integral. Plane A: `z = 2` (facing the camera); plate B: `x = 0.5`, `|y| ≤ 0.5`,
/// `1 ≤ z ≤ 2`, facing the optical axis. Camera and illuminator at the origin; the pixel looks
/// at `x_A = (0, 0, 2)`. The indirect phasor is
/// `∫_B ρ_A/π · ρ_B/π · I cosθ_l / d_l² · cosθ_x cosθ_y / |x−y|² · e^{ik(|x| + |x−y| + d_l)} dA`.
/// Tolerance: 1.5 % of its magnitude (the Monte Carlo estimate with 400k paths has ~0.3 %
/// standard error; midpoint quadrature on 500² cells is converged to < 0.01 %).
#[test]
fn one_bounce_indirect_matches_quadrature() {
    let cam = Camera::from_hfov(9, 9, 20.0);
    let (rho_a, rho_b) = (0.6, 0.8);
    let mut scene = Scene::empty(cam);
    // An isotropic illuminator: the plate lies outside this narrow view.
    scene.tof_light_fov_margin = f64::INFINITY;
    scene.push(wall(Vec3::Z, Vec3::new(0.0, 0.0, 2.0), rho_a));
    scene.push(object(
        ObjectKind::Plate { hx: 0.5, hy: 0.5 },
        Mat3::looking_along(Vec3::X),
        Vec3::new(0.5, 0.0, 1.5),
        rho_b,
    ));
    let n = 400_000;
    let f = 20e6;
    let opts = RenderOptions {
        spp: n,
        indirect_spp: n,
        max_bounces: 2,
        min_bounces: 2,
        jitter: false,
        frequencies_hz: vec![f],
        rgb: false,
        indirect_filter_radius: 0,
    };
    let mc = render_pixel(&scene, &opts, 8, 0, 4, 4);

    let k = std::f64::consts::TAU * f / SPEED_OF_LIGHT;
    let intensity = scene.tof_light_intensity;
    let x = Vec3::new(0.0, 0.0, 2.0);
    let n_a = Vec3::new(0.0, 0.0, -1.0);
    let n_b = Vec3::new(-1.0, 0.0, 0.0);
    let light = Vec3::ZERO;
    let cells = 500;
    let (du, dv) = (1.0 / cells as f64, 1.0 / cells as f64);
    let mut quad = Complex::ZERO;
    let mut quad_dc = 0.0;
    for i in 0..cells {
        for j in 0..cells {
            let y = Vec3::new(
                0.5,
                -0.5 + (i as f64 + 0.5) * du,
                1.0 + (j as f64 + 0.5) * dv,
            );
            let xy = y - x;
            let dxy = xy.length();
            let cos_x = n_a.dot(xy) / dxy;
            let cos_y = n_b.dot(-xy) / dxy;
            let yl = light - y;
            let dl = yl.length();
            let cos_l = n_b.dot(yl) / dl;
            if cos_x <= 0.0 || cos_y <= 0.0 || cos_l <= 0.0 {
                continue;
            }
            let radiance_b = rho_b / std::f64::consts::PI * intensity * cos_l / (dl * dl);
            let w =
                rho_a / std::f64::consts::PI * radiance_b * cos_x * cos_y / (dxy * dxy) * du * dv;
            quad += Complex::from_polar(w, k * (x.length() + dxy + dl));
            quad_dc += w;
        }
    }
    let rel = (mc.phasor[0] - quad).abs() / quad.abs();
    eprintln!(
        "indirect phasor: MC {:?} quadrature {:?} (|Δ|/|P| = {rel:.4}); DC {} vs {quad_dc}",
        mc.phasor[0], quad, mc.dc
    );
    assert!(
        quad.abs() > 1e-3,
        "the test geometry must have a sizeable indirect term"
    );
    assert!(rel < 0.015, "MC vs quadrature: {rel}");
    assert!((mc.dc / quad_dc - 1.0).abs() < 0.015);
}

/// Same seed, same images, whatever the thread count.
#[test]
fn deterministic_whatever_the_thread_count() {
    let cam = Camera::from_hfov(32, 24, 70.0);
    let scene = Scene::random(cam, &Default::default(), 11, 0);
    let cfg = SimConfig::default();
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| simulate(&scene, &cfg, 11, 0))
    };
    let (a, b) = (run(1), run(3));
    assert_eq!(a.rgb, b.rgb);
    assert_eq!(a.tof.depth, b.tof.depth);
    assert_eq!(a.tof.amplitude, b.tof.amplitude);
    assert_eq!(a.gt_depth, b.gt_depth);
}
