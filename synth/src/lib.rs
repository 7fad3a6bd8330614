//! `dear-synth`: a physically based amplitude-modulated continuous-wave (AMCW) time-of-flight
//! simulator and the ToF-FlyingThings-style dataset generator of DEAR on device.
//!
//! Modules, in the order data flows through them:
//! - [`math`], [`rng`]: vectors, rotations, phasors; thread-count-independent randomness;
//! - [`geometry`]: rays and analytic ray–primitive intersection;
//! - [`texture`]: Lambertian materials with procedural RGB and separate near-IR albedos;
//! - [`scene`]: camera, lights, objects, the random room-and-objects generator;
//! - [`transport`]: ToF light transport (phasors over multi-bounce paths) and RGB shading;
//! - [`sensor`]: 4-tap correlation, shot/read noise, demodulation, unwrapping, radial → z;
//! - [`simulate`]: one aligned sample from a scene;
//! - [`dataset`]: writing capture directories (`generate`);
//! - [`classical`]: the classical refiner's output beside each frame, for training refiners
//!   that take it (`classical`);
//! - [`family`]: training and held-out families of sensor and scene settings (`family`);
//! - [`perturb`]: misaligned test/training sets with ground-truth flow;
//! - [`sequence`]: moving scenes with drifting calibration;
//! - [`preview`]: the preview panel (colour maps from `dear-picture`).

#![forbid(unsafe_code)]

pub mod classical;
pub mod dataset;
pub mod family;
pub mod geometry;
pub mod math;
pub mod perturb;
pub mod preview;
pub mod rng;
pub mod scene;
pub mod sensor;
pub mod sequence;
pub mod simulate;
pub mod texture;
pub mod transport;
