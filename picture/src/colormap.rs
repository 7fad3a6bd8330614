//! The colour maps of every picture. The simulator used to draw its own polynomial turbo over
//! the whole range and the SDK colorous' turbo from a tenth on; now both use [`depth_turbo`].

/// Where the used part of turbo starts: its darkest tenth is almost black and would read as
/// invalid depth (drawn black everywhere), so near depth starts at a clearly blue-violet.
pub const TURBO_START: f64 = 0.1;

/// Colour of invalid depth (0, negative or non-finite) in every picture.
pub const INVALID: [u8; 3] = [0, 0, 0];

/// The depth colour for `t` in `[0, 1]` (near → far, clamped): turbo from [`TURBO_START`].
/// Turbo rather than viridis because its larger lightness and hue range separates nearby
/// depths better, while, unlike jet, it has no false bands.
pub fn depth_turbo(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let c = colorous::TURBO.eval_continuous(TURBO_START + (1.0 - TURBO_START) * t);
    [c.r, c.g, c.b]
}

/// The colour of depth `z` on a `[near, far]` scale (clamped; `far > near`).
pub fn depth_color(z: f32, near: f32, far: f32) -> [u8; 3] {
    depth_turbo(f64::from((z - near) / (far - near)))
}

/// Diverging blue – white – red for signed errors, `t` in `[−1, 1]` (clamped): blue too near,
/// red too far.
pub fn diverging(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(-1.0, 1.0) };
    let (r, g, b) = if t < 0.0 {
        (1.0 + t, 1.0 + t * 0.6, 1.0)
    } else {
        (1.0, 1.0 - t * 0.8, 1.0 - t)
    };
    [r, g, b].map(|v: f64| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_runs_from_blue_violet_to_red_and_is_never_the_invalid_black() {
        let near = depth_turbo(0.0);
        let far = depth_turbo(1.0);
        assert!(near[2] > near[0], "near is blue: {near:?}");
        assert!(far[0] > far[2], "far is red: {far:?}");
        for i in 0..=100 {
            let c = depth_turbo(f64::from(i) / 100.0);
            assert!(c.iter().any(|&v| v > 40), "{i}: {c:?} reads as invalid");
        }
        assert_eq!(depth_turbo(-3.0), near);
        assert_eq!(depth_turbo(f64::NAN), near);
        assert_eq!(depth_color(2.0, 1.0, 3.0), depth_turbo(0.5));
    }

    #[test]
    fn diverging_is_white_at_zero_and_saturates() {
        assert_eq!(diverging(0.0), [255, 255, 255]);
        assert!(diverging(1.0)[2] == 0 && diverging(-1.0)[0] == 0);
        assert_eq!(diverging(5.0), diverging(1.0));
    }
}
