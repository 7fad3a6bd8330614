//! Pieces for loops over pixels that vectorise: scalar maths (the standard library's `exp` is
//! a call per value, and a float-to-integer `as` conversion, saturating with NaN → 0, was
//! converted one lane at a time; each function documents how its result relates to the exact
//! one), and the equal-length neighbour slices of a 3 × 3 window, over which a loop has no
//! bounds checks left.

/// `e^x` to about 10⁻⁶ relative error for `x` in `[−87, 88]` (clamped outside): range
/// reduction to `2^n · e^g`, `|g| ≤ ln2/2`, and a degree-6 Taylor polynomial.
// Used by the inference code (the refiner's tail, the confidence).
#[cfg_attr(not(feature = "inference"), allow(dead_code))]
#[inline(always)]
pub(crate) fn exp_fast(x: f32) -> f32 {
    // Comparisons, not f32::max/min: a NaN stays NaN (so a corrupt map is detected by the
    // caller), and they lower to SIMD compare + blend.
    #[allow(clippy::manual_clamp)]
    let x = if x < -87.0 {
        -87.0
    } else if x > 88.0 {
        88.0
    } else {
        x
    };
    // Round to nearest by the 1.5·2²³ trick (vectorises without SSE4.1's round).
    const MAGIC: f32 = 12_582_912.0;
    let shifted = x * std::f32::consts::LOG2_E + MAGIC;
    let n = shifted - MAGIC;
    // Cody–Waite: ln 2 in two parts, so that n·ln2 is exact enough for |n| up to 126.
    let g = (x - n * 0.693_359_4) + n * 2.121_944_4e-4;
    let p = 1.0
        + g * (1.0
            + g * (0.5
                + g * (1.0 / 6.0 + g * (1.0 / 24.0 + g * (1.0 / 120.0 + g * (1.0 / 720.0))))));
    // 2ⁿ from the bits of `shifted` = 1.5·2²³ + n, whose low mantissa bits hold n (|n| ≤ 127,
    // one binade): adding 127 and shifting by 23 wraps the magic's own bits away and leaves
    // the biased exponent n + 127 — the value `(n as i32 + 127) << 23` gives, but
    // `n as i32` (saturating, NaN → 0) was converted one lane at a time, which cost more than
    // the rest of the function. A NaN `x` still gives NaN (through `p`).
    f32::from_bits(shifted.to_bits().wrapping_add(127) << 23) * p
}

/// `ln x` to about 10⁻⁶ absolute error for normal, positive, finite `x` (anything else gives an
/// unspecified value): `x = 2^k · m` with `m` in `[1, 2)` from the bits, and
/// `ln m = 2·atanh(t)`, `t = (m − 1)/(m + 1)` in `[0, ⅓)`, by its odd series to `t⁹`.
#[cfg_attr(not(feature = "inference"), allow(dead_code))]
#[inline(always)]
pub(crate) fn ln_fast(x: f32) -> f32 {
    let bits = x.to_bits();
    // The biased exponent is below 255 for finite x: an integer conversion, which vectorises.
    let k = ((bits >> 23) & 0xff) as i32 - 127;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let series =
        t * (2.0 + t2 * (2.0 / 3.0 + t2 * (2.0 / 5.0 + t2 * (2.0 / 7.0 + t2 * (2.0 / 9.0)))));
    k as f32 * std::f32::consts::LN_2 + series
}

/// `⌊c⌋` for `0 ≤ c < 2²²` without a float-to-integer conversion (which the compiler converts
/// one lane at a time): `c + 1.5·2²³` rounds `c` to the nearest integer, held in the low bits
/// of the sum's representation; one less where that rounded up.
#[inline(always)]
pub(crate) fn floor_small(c: f32) -> u32 {
    const MAGIC: f32 = 12_582_912.0;
    let r = (c + MAGIC).to_bits().wrapping_sub(MAGIC.to_bits());
    r - u32::from(r as f32 > c)
}

/// The nine neighbours of the interior pixels of a row as equal-length slices, row-major (up-left,
/// up, up-right, left, centre, right, down-left, down, down-right): `rows` are the rows above,
/// at and below, and pixel `i` of each slice belongs to column `i + 1`. Of length `w − 2` for
/// the shortest row's `w` (empty below 3).
#[inline(always)]
pub(crate) fn window3x3<'a>(rows: [&'a [f32]; 3]) -> [&'a [f32]; 9] {
    let n = rows
        .iter()
        .map(|r| r.len())
        .min()
        .unwrap_or(0)
        .saturating_sub(2);
    let [up, centre, down] = rows.map(|r| &r[..(n + 2).min(r.len())]);
    let shifted = |r: &'a [f32], dx: usize| &r[dx..dx + n];
    [
        shifted(up, 0),
        shifted(up, 1),
        shifted(up, 2),
        shifted(centre, 0),
        shifted(centre, 1),
        shifted(centre, 2),
        shifted(down, 0),
        shifted(down, 1),
        shifted(down, 2),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_fast_matches_std() {
        for i in 0..=20_000 {
            // 1e-6 to 1e6, and every binade's ends.
            let x = 10f32.powf(-6.0 + 12.0 * i as f32 / 20_000.0);
            assert!(
                (ln_fast(x) - x.ln()).abs() < 2e-6,
                "ln {x}: {} vs {}",
                ln_fast(x),
                x.ln()
            );
        }
        for k in -20..20 {
            let x = 2f32.powi(k);
            for x in [x, f32::from_bits(x.to_bits() - 1)] {
                assert!((ln_fast(x) - x.ln()).abs() < 2e-6, "ln {x}");
            }
        }
    }

    #[test]
    fn exp_fast_matches_std() {
        let mut worst = 0.0f32;
        let mut x = -80.0f32;
        while x < 80.0 {
            worst = worst.max((exp_fast(x) - x.exp()).abs() / x.exp());
            x += 0.0137;
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
    }

    /// The scale 2ⁿ taken from the bits of the rounding sum is the one `n as i32` builds, bit
    /// for bit, over the whole clamped range, past both clamps, at the rounding ties and for
    /// NaN (which stays NaN).
    #[test]
    fn exp_fast_scale_from_bits_is_the_integer_conversion() {
        let reference = |x: f32| {
            #[allow(clippy::manual_clamp)]
            let x = if x < -87.0 {
                -87.0
            } else if x > 88.0 {
                88.0
            } else {
                x
            };
            const MAGIC: f32 = 12_582_912.0;
            let n = (x * std::f32::consts::LOG2_E + MAGIC) - MAGIC;
            let g = (x - n * 0.693_359_4) + n * 2.121_944_4e-4;
            let p = 1.0
                + g * (1.0
                    + g * (0.5
                        + g * (1.0 / 6.0
                            + g * (1.0 / 24.0 + g * (1.0 / 120.0 + g * (1.0 / 720.0))))));
            f32::from_bits(((n as i32 + 127) as u32) << 23) * p
        };
        let ties = (-126..=127).map(|n| (n as f32 + 0.5) * std::f32::consts::LN_2);
        let sweep = (-1_000_000..=1_000_000).map(|i| i as f32 * 1e-4);
        let specials = [
            0.0,
            -0.0,
            1e30,
            -1e30,
            f32::INFINITY,
            f32::NEG_INFINITY,
            87.9,
            -86.9,
        ];
        for x in sweep.chain(ties).chain(specials) {
            assert_eq!(exp_fast(x).to_bits(), reference(x).to_bits(), "x = {x}");
        }
        assert!(exp_fast(f32::NAN).is_nan() && reference(f32::NAN).is_nan());
    }

    #[test]
    fn floor_small_is_floor() {
        let sweep = (0..4_000_000).map(|i| i as f32 * 0.731_3);
        let edges = (0..1000).flat_map(|k| {
            let k = k as f32;
            [
                k,
                k + 0.5,
                k.next_down(),
                k.next_up(),
                k + 0.5f32.next_down(),
            ]
        });
        for c in sweep
            .chain(edges)
            .filter(|c| *c >= 0.0 && *c < (1 << 22) as f32)
        {
            assert_eq!(floor_small(c), c.floor() as u32, "c = {c}");
        }
    }

    #[test]
    fn window3x3_is_the_neighbourhood_of_each_interior_pixel() {
        let rows: [Vec<f32>; 3] =
            std::array::from_fn(|r| (0..6).map(|x| (10 * r + x) as f32).collect());
        let window = window3x3([&rows[0], &rows[1], &rows[2]]);
        for i in 0..4 {
            let expected: Vec<f32> = (0..9).map(|k| rows[k / 3][i + 1 + k % 3 - 1]).collect();
            let got: Vec<f32> = window.iter().map(|s| s[i]).collect();
            assert_eq!(got, expected, "column {}", i + 1);
        }
        assert!(window.iter().all(|s| s.len() == 4));
        // The shortest row sets the length; below three columns there is no interior.
        let short = [0.0f32; 5];
        assert!(window3x3([&rows[0], &short, &rows[2]])
            .iter()
            .all(|s| s.len() == 3));
        assert!(window3x3([&[1.0, 2.0], &[3.0, 4.0], &[5.0, 6.0]])
            .iter()
            .all(|s| s.is_empty()));
    }
}
