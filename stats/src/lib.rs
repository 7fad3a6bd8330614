//! The workspace's reporting statistics, defined once: percentiles, the median and a latency
//! summary, as the daemon's log, `dear watch`, `dear eval`'s timing column, the soak client,
//! `dear-ipc-bench`, the preview colour ranges and Python's `dear_train.stats` print them.
//!
//! # The definition: nearest rank
//!
//! The `q`-percentile (`q` in `[0, 1]`) of `n` values is the value of **1-based rank
//! `r = ⌈q·n⌉`, clamped to `[1, n]`**, in ascending order. So:
//!
//! - it is always one of the measured values (a latency that happened, a depth that was seen),
//!   never an interpolation between two;
//! - `q = 0` is the minimum, `q = 1` the maximum, and any `q` of one value is that value;
//! - the **median is the 0.5-percentile**: the middle value for an odd count, the *lower* of
//!   the two middle values for an even count (not their mean);
//! - `⌈q·n⌉` is taken as `⌈q·n − 10⁻⁹⌉`, so a product that floating point puts just above an
//!   integer (`0.07 · 100 = 7.000000000000001`) has the rank exact arithmetic gives (7, not 8).
//!   For the quantiles reported (0.01, 0.5, 0.95, 0.99) this changes no rank for any `n` up to
//!   200,000 (checked when it was chosen).
//!
//! Why nearest rank: the latency figures were already nearest rank in the daemon's log, the
//! soak client and the IPC bench; it needs no interpolation rule to agree on between Rust and
//! Python (`fixtures/stats/percentiles.json` checks both); and it is what an HDR histogram's
//! `value_at_quantile` reports, so a later move to `hdrhistogram` would keep the meaning (it
//! was not taken now: the samples are small — one statistics interval, one soak run — and
//! kept exactly, and a histogram would round them to its precision).
//!
//! # What is not this definition
//!
//! - [`upper_median`]: the element of 0-based rank `⌊n/2⌋`, which *computations* use (the
//!   online estimator's per-parameter median of calibrations and its fit quality, the
//!   fallback depth of static alignment, the simulator's perturbation scale). It is not a
//!   reported figure, and moving it to the lower median would change published calibrations
//!   and generated data sets; it lives here so that it, too, is written once.
//! - The amplitude normalisation's percentile (numpy's `linear`,
//!   `dear_pipeline::chain::preprocess::percentile_linear`): part of the model bundle contract,
//!   matched to the training code bit for bit.
//! - The evaluation's error classes (`dear_eval::metrics`, `train/dear_train/metrics.py`):
//!   the paper's protocol, shared with Python through `fixtures/metrics/`.

#![forbid(unsafe_code)]

use std::cmp::Ordering;

/// A value that can be ranked: a total order (floats by `total_cmp`, so NaN sorts last) and a
/// conversion to `f64` for means.
pub trait Sample: Copy {
    /// The total order values are ranked by.
    fn rank_cmp(&self, other: &Self) -> Ordering;
    /// The value as `f64` (for [`Summary::mean`]).
    fn to_f64(self) -> f64;
}

macro_rules! int_sample {
    ($($t:ty),*) => {$(
        impl Sample for $t {
            fn rank_cmp(&self, other: &Self) -> Ordering {
                self.cmp(other)
            }
            fn to_f64(self) -> f64 {
                self as f64
            }
        }
    )*};
}
int_sample!(u16, u32, u64, usize, i32, i64);

impl Sample for f32 {
    fn rank_cmp(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}

impl Sample for f64 {
    fn rank_cmp(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
    fn to_f64(self) -> f64 {
        self
    }
}

/// Sorts `values` ascending in the order percentiles rank them by.
pub fn sort<T: Sample>(values: &mut [T]) {
    values.sort_unstable_by(T::rank_cmp);
}

/// The nearest rank of the `q`-percentile among `n > 0` values: `⌈q·n⌉` clamped to `[1, n]`,
/// **1-based** (see the crate docs). A `q` outside `[0, 1]` (or NaN) is clamped too.
///
/// # Panics
/// If `n` is 0.
pub fn nearest_rank(n: usize, q: f64) -> usize {
    assert!(n > 0, "nearest_rank of no values");
    let x = (q * n as f64 - 1e-9).ceil();
    // `as usize` saturates: negative and NaN become 0, then 1.
    (x as usize).clamp(1, n)
}

/// The nearest-rank `q`-percentile of `sorted` (ascending, see [`sort`]); `None` when empty.
pub fn percentile_nearest_rank<T: Copy>(sorted: &[T], q: f64) -> Option<T> {
    (!sorted.is_empty()).then(|| sorted[nearest_rank(sorted.len(), q) - 1])
}

/// The median of `sorted` (ascending): its nearest-rank 0.5-percentile, the lower middle value
/// for an even count. `None` when empty.
pub fn median<T: Copy>(sorted: &[T]) -> Option<T> {
    percentile_nearest_rank(sorted, 0.5)
}

/// The nearest-rank `q`-percentile of unsorted `values`, by selection (`O(n)`, reorders
/// `values`): the same value as sorting and calling [`percentile_nearest_rank`].
pub fn select_percentile<T: Sample>(values: &mut [T], q: f64) -> Option<T> {
    if values.is_empty() {
        return None;
    }
    let i = nearest_rank(values.len(), q) - 1;
    let (_, v, _) = values.select_nth_unstable_by(i, T::rank_cmp);
    Some(*v)
}

/// The element of 0-based rank `⌊n/2⌋` of unsorted `values` (the upper middle value for an
/// even count), by selection; reorders `values`. `None` when empty.
///
/// For computations that pick a representative value (see the crate docs), **not** for
/// reported figures: those use [`median`].
pub fn upper_median<T: Sample>(values: &mut [T]) -> Option<T> {
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    let (_, v, _) = values.select_nth_unstable_by(mid, T::rank_cmp);
    Some(*v)
}

/// A latency (or any) distribution in the one definition: nearest-rank p50 (the median), p95,
/// p99, the maximum, the mean and the count, in the sample's unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary<T> {
    pub count: usize,
    /// The median.
    pub p50: T,
    pub p95: T,
    pub p99: T,
    pub max: T,
    pub mean: f64,
}

impl<T: Sample> Summary<T> {
    /// Sorts `values` and summarises them; `None` when empty.
    pub fn of(values: &mut [T]) -> Option<Self> {
        sort(values);
        Self::of_sorted(values)
    }

    /// Summarises values already sorted ascending (see [`sort`]); `None` when empty.
    pub fn of_sorted(sorted: &[T]) -> Option<Self> {
        let at = |q| percentile_nearest_rank(sorted, q);
        Some(Summary {
            count: sorted.len(),
            p50: at(0.50)?,
            p95: at(0.95)?,
            p99: at(0.99)?,
            max: *sorted.last()?,
            mean: sorted.iter().map(|&v| v.to_f64()).sum::<f64>() / sorted.len() as f64,
        })
    }

    /// The summary with every value mapped (a unit conversion, e.g. ns → ms).
    pub fn map<U>(self, f: impl Fn(T) -> U, mean: impl Fn(f64) -> f64) -> Summary<U> {
        Summary {
            count: self.count,
            p50: f(self.p50),
            p95: f(self.p95),
            p99: f(self.p99),
            max: f(self.max),
            mean: mean(self.mean),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_by_hand() {
        // n = 1: every q is the one value.
        for q in [0.0, 0.01, 0.5, 0.95, 1.0] {
            assert_eq!(nearest_rank(1, q), 1);
        }
        // q = 0 is the minimum, q = 1 the maximum; out of range and NaN are clamped.
        assert_eq!(nearest_rank(10, 0.0), 1);
        assert_eq!(nearest_rank(10, 1.0), 10);
        assert_eq!(nearest_rank(10, -0.5), 1);
        assert_eq!(nearest_rank(10, 7.0), 10);
        assert_eq!(nearest_rank(10, f64::NAN), 1);
        // Even n: the median is the lower middle one.
        assert_eq!(nearest_rank(4, 0.5), 2);
        assert_eq!(nearest_rank(5, 0.5), 3);
        // Floating point puts 0.07 · 100 just above 7: the rank stays 7.
        assert_eq!(nearest_rank(100, 0.07), 7);
        assert_eq!(nearest_rank(20, 0.95), 19);
        assert_eq!(nearest_rank(100, 0.99), 99);
        assert_eq!(nearest_rank(101, 0.99), 100);
    }

    #[test]
    #[should_panic(expected = "no values")]
    fn no_rank_of_nothing() {
        nearest_rank(0, 0.5);
    }

    /// The daemon's former `percentile` cases (nearest rank of 1..=20).
    #[test]
    fn daemon_cases() {
        let v: Vec<u32> = (1..=20).collect();
        assert_eq!(percentile_nearest_rank(&v, 0.5), Some(10));
        assert_eq!(percentile_nearest_rank(&v, 0.95), Some(19));
        assert_eq!(percentile_nearest_rank(&[7u32], 0.95), Some(7));
        assert_eq!(percentile_nearest_rank::<u32>(&[], 0.5), None);
    }

    /// The former `dear watch` median cases, now nearest rank (the even case moved from 2.5).
    #[test]
    fn medians_by_hand() {
        let m = |mut v: Vec<f64>| {
            sort(&mut v);
            median(&v)
        };
        assert_eq!(m(vec![]), None);
        assert_eq!(m(vec![3.0]), Some(3.0));
        assert_eq!(m(vec![5.0, 1.0, 3.0]), Some(3.0));
        assert_eq!(m(vec![4.0, 1.0, 3.0, 2.0]), Some(2.0));
        assert_eq!(m(vec![2.0, 1.0]), Some(1.0));
    }

    /// The soak client's former cases: 1..=100 ms reversed.
    #[test]
    fn summary_by_hand() {
        let mut v: Vec<u64> = (1..=100).rev().map(|ms| ms * 1_000_000).collect();
        let s = Summary::of(&mut v).unwrap();
        assert_eq!(
            (s.count, s.p50, s.p95, s.p99, s.max),
            (100, 50_000_000, 95_000_000, 99_000_000, 100_000_000)
        );
        assert_eq!(s.mean, 50.5e6);
        let ms = s.map(|ns| ns as f64 / 1e6, |ns| ns / 1e6);
        assert_eq!((ms.p50, ms.p99, ms.mean), (50.0, 99.0, 50.5));
        assert_eq!(Summary::<u64>::of(&mut []), None);
        let one = Summary::of(&mut [7_000_000u64]).unwrap();
        assert_eq!(
            (one.p50, one.p95, one.p99, one.max),
            (7_000_000, 7_000_000, 7_000_000, 7_000_000)
        );
        // Even n = 4: p50 is the 2nd value, p95 and p99 the 4th.
        let s = Summary::of(&mut [4.0f32, 1.0, 3.0, 2.0]).unwrap();
        assert_eq!(
            (s.p50, s.p95, s.p99, s.max, s.mean),
            (2.0, 4.0, 4.0, 4.0, 2.5)
        );
    }

    #[test]
    fn selection_equals_sorting() {
        let mut state = 12345u64;
        for n in 1..60 {
            let values: Vec<f32> = (0..n)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 40) as f32 / 1000.0
                })
                .collect();
            let mut sorted = values.clone();
            sort(&mut sorted);
            for q in [0.0, 0.01, 0.25, 0.5, 0.95, 0.99, 1.0] {
                let mut v = values.clone();
                assert_eq!(
                    select_percentile(&mut v, q),
                    percentile_nearest_rank(&sorted, q)
                );
            }
            let mut v = values.clone();
            assert_eq!(upper_median(&mut v), Some(sorted[n / 2]));
        }
        assert_eq!(select_percentile::<f32>(&mut [], 0.5), None);
        assert_eq!(upper_median::<f32>(&mut []), None);
    }

    #[test]
    fn upper_median_by_hand() {
        assert_eq!(upper_median(&mut [3.0f32]), Some(3.0));
        assert_eq!(upper_median(&mut [5.0f32, 1.0, 3.0]), Some(3.0));
        assert_eq!(upper_median(&mut [4.0f32, 1.0, 3.0, 2.0]), Some(3.0));
        // NaN ranks last (total order), so it is never the median of mostly finite values.
        assert_eq!(upper_median(&mut [f32::NAN, 1.0, 2.0]), Some(2.0));
    }
}
