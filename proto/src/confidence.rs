//! What a confidence byte means when the frame's [`flags::CONFIDENCE_EXPECTED_ERROR`] is set:
//! an **expected-error code**, the refiner's expected absolute depth error on a log scale,
//!
//! ```text
//! E|depth − truth| = 1 mm · 2^((255 − v) / 16)        v = 1 … 255;  v = 0: no depth
//! ```
//!
//! so 255 is 1 mm, every 16 steps down doubles the error (239: 2 mm, 202: 1 cm, 149: 10 cm,
//! 96: 1 m) and 1 is 58 m or more. A client keeps the pixels it can use with one comparison:
//! `v >= code_for_error(0.05)` keeps those expected within 5 cm. The reliability table in
//! RESULTS.md measures how well the predicted errors hold on data the refiner never saw.
//!
//! Without the flag the byte is the heuristic score of `dear_pipeline::chain::confidence`
//! (support × agreement; 0 = no depth, 255 = measured on a smooth surface and kept).
//!
//! [`flags::CONFIDENCE_EXPECTED_ERROR`]: crate::flags::CONFIDENCE_EXPECTED_ERROR

/// The expected error of code 255, metres.
pub const ERROR_CODE_UNIT_M: f32 = 1e-3;
/// Code steps per doubling of the expected error.
pub const ERROR_CODE_STEPS_PER_DOUBLING: f32 = 16.0;

/// The expected absolute error (metres) that code `v` stands for; `None` for 0 (no depth).
pub fn expected_error_m(v: u8) -> Option<f32> {
    (v != 0)
        .then(|| ERROR_CODE_UNIT_M * ((255.0 - v as f32) / ERROR_CODE_STEPS_PER_DOUBLING).exp2())
}

/// The code of an expected error given by its natural logarithm (`ln` of metres): rounded to
/// the nearest step, clamped to 1 … 255 (a valid depth never reads as "no depth"); a NaN
/// (no estimate) gets 1, the least confident code.
#[inline]
pub fn code_for_log_error(ln_error_m: f32) -> u8 {
    // 255 − 16 · log2(e / unit), with log2(x) = ln(x) / ln 2.
    let steps = ERROR_CODE_STEPS_PER_DOUBLING / std::f32::consts::LN_2;
    let v = 255.0 - steps * (ln_error_m - ERROR_CODE_UNIT_M.ln());
    // `as u8` saturates (NaN → 0), so the clamp is applied to the float first.
    let v = if v.is_nan() { 1.0 } else { v.clamp(1.0, 255.0) };
    (v + 0.5) as u8
}

/// The code of an expected error in metres (see [`code_for_log_error`]).
pub fn code_for_error(error_m: f32) -> u8 {
    code_for_log_error(error_m.ln())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_and_errors_are_inverse_and_documented() {
        assert_eq!(expected_error_m(0), None);
        assert_eq!(expected_error_m(255), Some(1e-3));
        let close = |v: u8, m: f32| (expected_error_m(v).unwrap() / m - 1.0).abs() < 0.03;
        // The table in the module doc.
        assert!(close(239, 0.002) && close(202, 0.01) && close(149, 0.1) && close(96, 1.0));
        for v in 1..=255u8 {
            assert_eq!(code_for_error(expected_error_m(v).unwrap()), v, "code {v}");
        }
    }

    #[test]
    fn codes_are_monotone_and_clamped() {
        assert_eq!(code_for_error(1e-6), 255);
        assert_eq!(code_for_error(1e6), 1);
        assert_eq!(code_for_error(f32::INFINITY), 1);
        assert_eq!(code_for_log_error(f32::NAN), 1);
        let mut last = 255;
        for i in 0..2000 {
            let c = code_for_error(1e-4 * 1.01f32.powi(i));
            assert!(c <= last);
            last = c;
        }
    }
}
