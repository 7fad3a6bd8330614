//! Dataset families: the space of sensors and scenes a training set covers, and a held-out
//! family of settings that training never samples (`dear-synth family`).
//!
//! A capture directory has one set of intrinsics and one modulation-frequency list, so a family
//! is rendered as *shards*: each shard is a capture directory whose sensor and scene settings
//! are drawn once from the family's ranges, and whose frames are random scenes under them. The
//! draws of every shard are in its `capture.json` (`source.details.params`).
//!
//! | setting | `train` | `broad` | `heldout` |
//! |---|---|---|---|
//! | horizontal field of view | 62–90° | 62–90° | 48–58° |
//! | electrons per unit signal (exposure) | 6,000–60,000 (log-uniform) | 6,000–200,000 (log-uniform) | 2,000–5,000 |
//! | read noise | 4–20 e⁻ | 4–20 e⁻ | 25–40 e⁻ |
//! | ambient IR, upper bound of the per-frame draw | 0–0.15 | 0–0.15 | 0.16–0.3 |
//! | modulation | one of 17–21.5 MHz (¾), or 20 MHz + one of 50–100 MHz (¼) | as `train` | one of 13–15.5 MHz |
//! | illuminator offset | −15…15 mm | −15…15 mm | 18–25 mm |
//! | longest path (bounces) | 1 (no MPI, 15 %), 2 (35 %), 3 (50 %) | 1 (30 %), 2 (30 %), 3 (40 %) | 3 |
//! | objects per scene | 3–8 up to 8–28 | 0–2 (near-empty rooms, ¼), else as `train` | 30–40 |
//!
//! `train` is what the refiners shipped before issue 33 were trained on; `broad` spans the ends
//! a module meets (bright, clean, single-bounce scenes and near-empty rooms as well as noisy
//! multi-path ones). Every held-out range lies outside the training range of the same setting,
//! so a model validated on `heldout` is measured on sensors and scenes it never saw.
//! Single-frequency training modulations stay at or below 21.5 MHz: their unambiguous range
//! (≥ 6.97 m) covers the farthest room corner the scene generator places (6.6 m), so no
//! training frame wraps.
//!
//! Evaluation families for the regimes a user's module does not announce (never trained on
//! except where the table above says so):
//!
//! | family | what it is |
//! |---|---|
//! | `clean` | bright (120,000–180,000 e⁻), low read noise (4–8 e⁻), little ambient light, single bounce (no multi-path): the measurement is already right, a refiner must leave it alone |
//! | `empty` | near-empty rooms (0–2 objects: walls, floor, corners), otherwise `train`'s sensor ranges: little texture to align on |
//! | `wide` | a wide-angle module, 95–110° field of view, the illuminator 30–45 mm beside the lens (both outside every training range), 3 bounces, 10–35 objects |
//! | `dual-low` | a dual-frequency 20 + 16 MHz module (no training shard has a second frequency below 50 MHz), 3 bounces |

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::dataset::GenerateParams;
use crate::math::Vec3;
use crate::rng::{keyed_rng, Stream};
use crate::scene::SceneConfig;
use crate::simulate::SimConfig;

/// A named region of sensor and scene settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
// The discriminants key each family's random draws and scene seeds: fixed, so that adding a
// family never changes what an existing one renders.
pub enum Family {
    /// What the refiners shipped before issue 33 were trained on.
    Train = 0,
    /// Settings outside every training range (validation and `RESULTS.md` only).
    Heldout = 1,
    /// `train` widened to the ends: bright single-bounce scenes and near-empty rooms too.
    Broad = 2,
    /// Bright, clean, single-bounce scenes (validation only).
    Clean = 3,
    /// Near-empty rooms, `train`'s sensor ranges (validation only).
    Empty = 4,
    /// A wide-angle module with a large illuminator offset (validation only).
    Wide = 5,
    /// A dual-frequency 20 + 16 MHz module (validation only).
    DualLow = 6,
}

impl Family {
    pub fn name(self) -> &'static str {
        match self {
            Family::Train => "train",
            Family::Broad => "broad",
            Family::Heldout => "heldout",
            Family::Clean => "clean",
            Family::Empty => "empty",
            Family::Wide => "wide",
            Family::DualLow => "dual-low",
        }
    }

    /// The settings of shard `shard` of a family rendered with `seed`: `count` frames at
    /// `width × height`. Deterministic in `(self, seed, shard)`.
    pub fn draw(
        self,
        seed: u64,
        shard: u64,
        count: usize,
        width: usize,
        height: usize,
    ) -> GenerateParams {
        let mut rng = keyed_rng(seed, Stream::Family, shard, self as u64);
        let mut sim = SimConfig::default();
        let mut scene = SceneConfig::default();
        let hfov_deg;
        match self {
            Family::Train | Family::Broad | Family::Empty => {
                let broad = self == Family::Broad;
                hfov_deg = rng.random_range(62.0..=90.0);
                let brightest = if broad { 200_000.0 } else { 60_000.0 };
                sim.sensor.electrons_per_unit = log_uniform(&mut rng, 6_000.0, brightest);
                sim.sensor.read_noise_e = rng.random_range(4.0..=20.0);
                scene.ambient_ir = (0.0, rng.random_range(0.0..=0.15));
                sim.render.frequencies_hz = training_modulation(&mut rng);
                scene.light_offset = Vec3::new(rng.random_range(-0.015..=0.015), 0.0, 0.0);
                let u: f64 = rng.random();
                let (one, two) = if broad { (0.3, 0.6) } else { (0.15, 0.5) };
                sim.render.max_bounces = if u < one {
                    1
                } else if u < two {
                    2
                } else {
                    3
                };
                // Drawn for every family (so `train`'s draws stay what they were), then
                // replaced where the family asks for near-empty rooms.
                scene.min_objects = rng.random_range(3..=8);
                scene.max_objects = scene.min_objects + rng.random_range(5..=20);
                if self == Family::Empty || (broad && rng.random_bool(0.25)) {
                    scene.min_objects = 0;
                    scene.max_objects = 2;
                }
            }
            Family::Heldout => {
                hfov_deg = rng.random_range(48.0..=58.0);
                sim.sensor.electrons_per_unit = rng.random_range(2_000.0..=5_000.0);
                sim.sensor.read_noise_e = rng.random_range(25.0..=40.0);
                scene.ambient_ir = (0.0, rng.random_range(0.16..=0.3));
                sim.render.frequencies_hz = vec![rng.random_range(13.0..=15.5) * 1e6];
                let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                scene.light_offset = Vec3::new(side * rng.random_range(0.018..=0.025), 0.0, 0.0);
                sim.render.max_bounces = 3;
                scene.min_objects = 30;
                scene.max_objects = 40;
            }
            Family::Clean => {
                hfov_deg = rng.random_range(62.0..=90.0);
                sim.sensor.electrons_per_unit = rng.random_range(120_000.0..=180_000.0);
                sim.sensor.read_noise_e = rng.random_range(4.0..=8.0);
                scene.ambient_ir = (0.0, rng.random_range(0.0..=0.02));
                sim.render.frequencies_hz = vec![rng.random_range(17.0..=21.5) * 1e6];
                scene.light_offset = Vec3::new(rng.random_range(-0.01..=0.01), 0.0, 0.0);
                sim.render.max_bounces = 1;
            }
            Family::Wide => {
                hfov_deg = rng.random_range(95.0..=110.0);
                sim.sensor.electrons_per_unit = log_uniform(&mut rng, 8_000.0, 40_000.0);
                sim.sensor.read_noise_e = rng.random_range(4.0..=20.0);
                scene.ambient_ir = (0.0, rng.random_range(0.0..=0.15));
                sim.render.frequencies_hz = vec![rng.random_range(17.0..=21.5) * 1e6];
                let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                scene.light_offset = Vec3::new(side * rng.random_range(0.03..=0.045), 0.0, 0.0);
                sim.render.max_bounces = 3;
                scene.min_objects = 10;
                scene.max_objects = 35;
            }
            Family::DualLow => {
                hfov_deg = rng.random_range(62.0..=90.0);
                sim.sensor.electrons_per_unit = log_uniform(&mut rng, 6_000.0, 60_000.0);
                sim.sensor.read_noise_e = rng.random_range(4.0..=20.0);
                scene.ambient_ir = (0.0, rng.random_range(0.0..=0.15));
                sim.render.frequencies_hz = vec![20e6, 16e6];
                scene.light_offset = Vec3::new(rng.random_range(-0.015..=0.015), 0.0, 0.0);
                sim.render.max_bounces = 3;
                scene.min_objects = rng.random_range(5..=10);
                scene.max_objects = scene.min_objects + rng.random_range(5..=20);
            }
        }
        GenerateParams {
            width,
            height,
            hfov_deg,
            count,
            // Each shard renders its own scenes: a seed per (family seed, shard).
            seed: seed
                .wrapping_mul(1_000_003)
                .wrapping_add(shard)
                .wrapping_add(1 + self as u64),
            sim,
            scene,
        }
    }
}

/// A training shard's modulation: one of 17–21.5 MHz (¾), or 20 MHz + one of 50–100 MHz (¼).
fn training_modulation<R: Rng>(rng: &mut R) -> Vec<f64> {
    if rng.random_bool(0.75) {
        vec![rng.random_range(17.0..=21.5) * 1e6]
    } else {
        vec![20e6, rng.random_range(50.0..=100.0) * 1e6]
    }
}

fn log_uniform<R: Rng>(rng: &mut R, lo: f64, hi: f64) -> f64 {
    (rng.random_range(lo.ln()..=hi.ln())).exp()
}

/// The directory name of shard `i` inside a family's output directory.
pub fn shard_dir_name(i: usize) -> String {
    format!("shard-{i:03}")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draws(family: Family) -> Vec<GenerateParams> {
        (0..400).map(|s| family.draw(7, s, 10, 64, 48)).collect()
    }

    #[test]
    fn draws_are_deterministic_and_differ_between_shards() {
        let a = Family::Train.draw(3, 5, 10, 64, 48);
        let b = Family::Train.draw(3, 5, 10, 64, 48);
        let c = Family::Train.draw(3, 6, 10, 64, 48);
        assert_eq!(
            serde_json::to_string(&a).unwrap(),
            serde_json::to_string(&b).unwrap()
        );
        assert_ne!(
            serde_json::to_string(&a).unwrap(),
            serde_json::to_string(&c).unwrap()
        );
        assert_ne!(a.seed, c.seed);
    }

    type Getter = Box<dyn Fn(&GenerateParams) -> f64>;

    fn range(v: &[GenerateParams], f: &dyn Fn(&GenerateParams) -> f64) -> (f64, f64) {
        v.iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            })
    }

    /// Asserts that `family` draws every one of `settings` outside `training`'s range.
    fn assert_outside(family: Family, training: Family, settings: Vec<(&str, Getter)>) {
        let (train, held) = (draws(training), draws(family));
        for (name, get) in settings {
            let (tlo, thi) = range(&train, &*get);
            let (hlo, hhi) = range(&held, &*get);
            assert!(
                hhi < tlo || hlo > thi,
                "{name}: {} [{hlo}, {hhi}] overlaps {} [{tlo}, {thi}]",
                family.name(),
                training.name()
            );
        }
    }

    /// The held-out family's promise: every setting it varies lies outside the range training
    /// samples (either training family), so no training shard can coincide with a held-out one.
    #[test]
    fn heldout_settings_lie_outside_every_training_range() {
        for training in [Family::Train, Family::Broad] {
            let settings: Vec<(&str, Getter)> = vec![
                ("hfov", Box::new(|p| p.hfov_deg)),
                ("electrons", Box::new(|p| p.sim.sensor.electrons_per_unit)),
                ("read noise", Box::new(|p| p.sim.sensor.read_noise_e)),
                ("ambient", Box::new(|p| p.scene.ambient_ir.1)),
                (
                    "lowest frequency",
                    Box::new(|p| p.sim.render.frequencies_hz[0]),
                ),
                ("light offset", Box::new(|p| p.scene.light_offset.x.abs())),
                ("max objects", Box::new(|p| p.scene.max_objects as f64)),
            ];
            assert_outside(Family::Heldout, training, settings);
        }
    }

    /// `wide` and `dual-low` are modules no training family samples.
    #[test]
    fn new_module_families_lie_outside_the_training_ranges() {
        for training in [Family::Train, Family::Broad] {
            let wide: Vec<(&str, Getter)> = vec![
                ("hfov", Box::new(|p| p.hfov_deg)),
                ("light offset", Box::new(|p| p.scene.light_offset.x.abs())),
            ];
            assert_outside(Family::Wide, training, wide);
            // Training's second frequencies are 50–100 MHz; dual-low's is 16 MHz.
            let dual: Vec<(&str, Getter)> = vec![(
                "second frequency",
                Box::new(|p| p.sim.render.frequencies_hz.get(1).copied().unwrap_or(1e9)),
            )];
            assert_outside(Family::DualLow, training, dual);
        }
        assert!(draws(Family::DualLow)
            .iter()
            .all(|p| p.sim.render.frequencies_hz == [20e6, 16e6]));
    }

    #[test]
    fn clean_and_empty_families_are_what_they_say() {
        for p in draws(Family::Clean) {
            assert_eq!(p.sim.render.max_bounces, 1);
            assert!(p.sim.sensor.electrons_per_unit >= 120_000.0);
        }
        for p in draws(Family::Empty) {
            assert!(p.scene.max_objects <= 2);
        }
        let broad = draws(Family::Broad);
        assert!(broad.iter().any(|p| p.scene.max_objects <= 2));
        assert!(broad
            .iter()
            .any(|p| p.sim.sensor.electrons_per_unit > 120_000.0));
        assert!(broad.iter().any(|p| p.sim.render.max_bounces == 1));
    }

    /// Adding families must not change what `train` renders (the shipped refiners' recipe).
    #[test]
    fn train_draws_are_unchanged() {
        let p = Family::Train.draw(100, 0, 80, 320, 240);
        assert_eq!(p.seed, 100u64.wrapping_mul(1_000_003).wrapping_add(1));
        let h = Family::Heldout.draw(9002, 0, 80, 320, 240);
        assert_eq!(h.seed, 9002u64.wrapping_mul(1_000_003).wrapping_add(2));
    }

    #[test]
    fn training_covers_mpi_free_and_dual_frequency_shards() {
        for family in [Family::Train, Family::Broad] {
            training_family_covers_mpi_free_and_dual_frequency_shards(family);
        }
    }

    fn training_family_covers_mpi_free_and_dual_frequency_shards(family: Family) {
        let train = draws(family);
        let bounces: Vec<usize> = train.iter().map(|p| p.sim.render.max_bounces).collect();
        for b in 1..=3 {
            assert!(bounces.contains(&b), "no training shard with {b} bounce(s)");
        }
        assert!(train.iter().any(|p| p.sim.render.frequencies_hz.len() == 2));
        // No single-frequency training shard wraps inside the scene generator's 6.6 m.
        for p in &train {
            if p.sim.render.frequencies_hz.len() == 1 {
                let range = crate::sensor::unambiguous_range(p.sim.render.frequencies_hz[0]);
                assert!(range > 6.6, "{range} m");
            }
        }
    }
}
