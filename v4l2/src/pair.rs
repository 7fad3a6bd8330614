//! Pairing two timestamped streams (ToF and RGB), as librealsense's syncer and Orbbec's frame
//! aggregator do in software: the devices run free, so each ToF frame is matched with the RGB
//! frame nearest in time, if within a tolerance.
//!
//! Timestamps are microseconds of `CLOCK_MONOTONIC`, as V4L2 stamps buffers. Frames arrive in
//! order within a stream, but the two streams interleave arbitrarily (each has its own capture
//! thread and queue). Two frames form a pair when each is the other's nearest remaining frame
//! and they are at most the tolerance apart; a frame that cannot be paired is dropped and
//! counted against its stream. A frame is decided as soon as later frames prove it: the head of
//! one stream is matched once the other stream has a frame after it, or a second frame that is
//! no nearer — so a pair waits at most one frame period of the stream whose frame came first.
//!
//! Memory is bounded: at most `capacity` frames wait per stream. When a stream stalls (a
//! camera stops, a USB transfer is lost), the other stream's oldest frame is decided with what
//! is known — paired with the stalled stream's head if within tolerance, else dropped — rather
//! than queued without end.

use std::collections::VecDeque;

/// Frames kept waiting per stream unless told otherwise: enough for a stream at four times
/// the other's rate, little enough that a stall costs only a few frames of memory.
pub const DEFAULT_CAPACITY: usize = 4;

/// Two frames taken together.
#[derive(Debug, Clone, PartialEq)]
pub struct Pair<A, B> {
    pub a: A,
    pub b: B,
    /// Timestamp of `a`, µs.
    pub ts_a_us: u64,
    /// Timestamp of `b`, µs.
    pub ts_b_us: u64,
}

/// What the pairer has done so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PairCounts {
    /// Pairs formed (handed out or ready to be).
    pub paired: u64,
    /// Frames of stream A (ToF, in the daemon) dropped without a partner.
    pub unpaired_a: u64,
    /// Frames of stream B (RGB, in the daemon) dropped without a partner.
    pub unpaired_b: u64,
}

/// Pairs frames of stream A (ToF) with frames of stream B (RGB) by timestamp; generic over the
/// payloads so the daemon pairs decoded frames and the tests pair numbers.
#[derive(Debug)]
pub struct Pairer<A, B> {
    tolerance_us: u64,
    capacity: usize,
    pending_a: VecDeque<(u64, A)>,
    pending_b: VecDeque<(u64, B)>,
    /// Pairs decided but not yet handed out (a push can decide more than one).
    ready: VecDeque<Pair<A, B>>,
    counts: PairCounts,
}

/// Which stream a frame belongs to, for the symmetric matching steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Side {
    A,
    B,
}

/// What the matching rule says about the two streams' oldest frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Decision {
    Pair,
    Drop(Side),
    /// The head of this stream needs the other stream's next frame to know its nearest.
    Wait,
}

impl<A, B> Pairer<A, B> {
    /// Pairs frames at most `tolerance_us` apart, keeping [`DEFAULT_CAPACITY`] frames per
    /// stream.
    pub fn new(tolerance_us: u64) -> Self {
        Self::with_capacity(tolerance_us, DEFAULT_CAPACITY)
    }

    /// The usual tolerance, half the slower stream's frame period (as librealsense's syncer):
    /// consecutive frames of the slower stream are a period apart, so any frame of the other
    /// stream is within tolerance of at most one of them and the pairing is unambiguous.
    pub fn for_frame_periods(period_a_us: u64, period_b_us: u64) -> Self {
        Self::new(period_a_us.max(period_b_us) / 2)
    }

    /// At most `capacity` (at least 1) frames wait per stream.
    pub fn with_capacity(tolerance_us: u64, capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Pairer {
            tolerance_us,
            capacity,
            pending_a: VecDeque::with_capacity(capacity + 1),
            pending_b: VecDeque::with_capacity(capacity + 1),
            ready: VecDeque::new(),
            counts: PairCounts::default(),
        }
    }

    pub fn tolerance_us(&self) -> u64 {
        self.tolerance_us
    }

    /// Adds a frame of stream A (timestamps non-decreasing within the stream) and returns the
    /// oldest pair now decided. A push can decide several pairs; [`Pairer::pop_ready`] hands
    /// out the rest, and the next push does too.
    pub fn push_a(&mut self, ts_us: u64, a: A) -> Option<Pair<A, B>> {
        self.pending_a.push_back((ts_us, a));
        if self.pending_a.len() > self.capacity {
            self.force(Side::A);
        }
        self.settle();
        self.ready.pop_front()
    }

    /// Adds a frame of stream B; see [`Pairer::push_a`].
    pub fn push_b(&mut self, ts_us: u64, b: B) -> Option<Pair<A, B>> {
        self.pending_b.push_back((ts_us, b));
        if self.pending_b.len() > self.capacity {
            self.force(Side::B);
        }
        self.settle();
        self.ready.pop_front()
    }

    /// A pair decided by an earlier push and not yet handed out.
    pub fn pop_ready(&mut self) -> Option<Pair<A, B>> {
        self.ready.pop_front()
    }

    pub fn counts(&self) -> PairCounts {
        self.counts
    }

    /// Frames waiting for a partner, `(stream A, stream B)`.
    pub fn pending(&self) -> (usize, usize) {
        (self.pending_a.len(), self.pending_b.len())
    }

    /// Drops every waiting frame, counted as unpaired, and pairs not yet handed out (not
    /// counted again: they were paired): for a stream restart, after which timestamps need not
    /// continue the old ones.
    pub fn reset(&mut self) {
        self.counts.unpaired_a += self.pending_a.len() as u64;
        self.counts.unpaired_b += self.pending_b.len() as u64;
        self.pending_a.clear();
        self.pending_b.clear();
        self.ready.clear();
    }

    /// Applies the matching rule until it has to wait for a frame.
    fn settle(&mut self) {
        loop {
            match self.decide() {
                Some(Decision::Pair) => self.pair_heads(),
                Some(Decision::Drop(side)) => self.drop_head(side),
                Some(Decision::Wait) | None => return,
            }
        }
    }

    /// The matching rule for the two heads (`None`: a stream has nothing waiting).
    ///
    /// Say B's head is not later than A's (`tb₀ ≤ ta₀`; the other case is the mirror image).
    /// Every later A frame is later still, so a₀ is b₀'s nearest A frame. If they are more than
    /// the tolerance apart, b₀ can never pair: drop it. Otherwise b₀ is a₀'s nearest B frame
    /// unless b₁ is nearer, which needs b₁: without it, wait; with it, pair a₀ with b₀ if b₀ is
    /// at least as near (ties go to the earlier frame), else drop b₀, which a₀ does not want.
    fn decide(&self) -> Option<Decision> {
        let &(ta, _) = self.pending_a.front()?;
        let &(tb, _) = self.pending_b.front()?;
        let (early, t_early, t_late, next_early) = if tb <= ta {
            (Side::B, tb, ta, self.pending_b.get(1).map(|f| f.0))
        } else {
            (Side::A, ta, tb, self.pending_a.get(1).map(|f| f.0))
        };
        let gap = t_late - t_early;
        if gap > self.tolerance_us {
            return Some(Decision::Drop(early));
        }
        if gap == 0 {
            return Some(Decision::Pair);
        }
        Some(match next_early {
            None => Decision::Wait,
            Some(t_next) if t_next.abs_diff(t_late) < gap => Decision::Drop(early),
            Some(_) => Decision::Pair,
        })
    }

    /// Decides the head of the overfull stream `side` now: paired with the other stream's head
    /// if within tolerance (the best partner known), else dropped. Heads of `side` that are
    /// already decidable are settled first, so this only ever forces a waiting frame.
    fn force(&mut self, side: Side) {
        self.settle();
        let len = match side {
            Side::A => self.pending_a.len(),
            Side::B => self.pending_b.len(),
        };
        if len <= self.capacity {
            return;
        }
        let within = match (self.pending_a.front(), self.pending_b.front()) {
            (Some(&(ta, _)), Some(&(tb, _))) => ta.abs_diff(tb) <= self.tolerance_us,
            _ => false,
        };
        if within {
            self.pair_heads();
        } else {
            self.drop_head(side);
        }
    }

    fn pair_heads(&mut self) {
        if let (Some((ts_a_us, a)), Some((ts_b_us, b))) =
            (self.pending_a.pop_front(), self.pending_b.pop_front())
        {
            self.counts.paired += 1;
            self.ready.push_back(Pair {
                a,
                b,
                ts_a_us,
                ts_b_us,
            });
        }
    }

    fn drop_head(&mut self, side: Side) {
        match side {
            Side::A => {
                if self.pending_a.pop_front().is_some() {
                    self.counts.unpaired_a += 1;
                }
            }
            Side::B => {
                if self.pending_b.pop_front().is_some() {
                    self.counts.unpaired_b += 1;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds both streams merged in timestamp order (A first on ties), collecting every pair
    /// as its `(a, b)` payloads.
    fn run(pairer: &mut Pairer<u32, u32>, a: &[(u64, u32)], b: &[(u64, u32)]) -> Vec<(u32, u32)> {
        let mut events: Vec<(u64, Side, u32)> = a
            .iter()
            .map(|&(t, p)| (t, Side::A, p))
            .chain(b.iter().map(|&(t, p)| (t, Side::B, p)))
            .collect();
        events.sort_by_key(|&(t, side, _)| (t, side == Side::B));
        collect(pairer, events)
    }

    /// Feeds `(timestamp, stream, payload)` events in the given order, collecting every pair.
    fn collect(pairer: &mut Pairer<u32, u32>, events: Vec<(u64, Side, u32)>) -> Vec<(u32, u32)> {
        let mut out = Vec::new();
        for (t, side, p) in events {
            let first = match side {
                Side::A => pairer.push_a(t, p),
                Side::B => pairer.push_b(t, p),
            };
            out.extend(first.map(|p| (p.a, p.b)));
            while let Some(p) = pairer.pop_ready() {
                out.push((p.a, p.b));
            }
        }
        out
    }

    /// `n` frames every `period` µs from `start`, payload = index.
    fn stream(start: u64, period: u64, n: u32) -> Vec<(u64, u32)> {
        (0..n).map(|i| (start + u64::from(i) * period, i)).collect()
    }

    const P30: u64 = 33_333;

    #[test]
    fn identical_timestamps_pair_immediately() {
        let mut p = Pairer::for_frame_periods(P30, P30);
        assert_eq!(p.tolerance_us(), P30 / 2);
        let got = p.push_a(1000, "tof");
        assert!(got.is_none());
        let got = p.push_b(1000, "rgb").expect("a pair");
        assert_eq!(
            (got.a, got.b, got.ts_a_us, got.ts_b_us),
            ("tof", "rgb", 1000, 1000)
        );
        assert_eq!(
            p.counts(),
            PairCounts {
                paired: 1,
                unpaired_a: 0,
                unpaired_b: 0
            }
        );
        assert_eq!(p.pending(), (0, 0));
    }

    #[test]
    fn jittered_streams_pair_frame_for_frame() {
        let a = stream(0, P30, 30);
        // B runs 5 ms late with ±3 ms jitter.
        let b: Vec<(u64, u32)> = stream(5_000, P30, 30)
            .into_iter()
            .map(|(t, i)| (t + [0, 3_000, 1_000, 6_000][i as usize % 4] - 3_000, i))
            .collect();
        let mut p = Pairer::for_frame_periods(P30, P30);
        let pairs = run(&mut p, &a, &b);
        // A 29 waits for A 30 to show that B 29 is its nearest; nothing is dropped.
        assert_eq!(pairs, (0..29).map(|i| (i, i)).collect::<Vec<_>>());
        assert_eq!(p.counts().unpaired_a + p.counts().unpaired_b, 0);
        assert_eq!(p.pending(), (1, 1));
    }

    #[test]
    fn arbitrary_interleaving_gives_the_same_pairs() {
        let a = stream(0, P30, 12);
        let b = stream(4_000, P30, 12);
        let mut in_order = Pairer::for_frame_periods(P30, P30);
        let expected = run(&mut in_order, &a, &b);
        // All of A's frames first, then all of B's (within capacity: 4 frames apart at most).
        let mut events = Vec::new();
        for chunk in 0..3 {
            let range = chunk * 4..chunk * 4 + 4;
            events.extend(a[range.clone()].iter().map(|&(t, i)| (t, Side::A, i)));
            events.extend(b[range].iter().map(|&(t, i)| (t, Side::B, i)));
        }
        let mut bursty = Pairer::for_frame_periods(P30, P30);
        assert_eq!(collect(&mut bursty, events), expected);
        assert_eq!(expected.len(), 11);
        assert_eq!(bursty.counts(), in_order.counts());
    }

    #[test]
    fn a_dropped_frame_leaves_its_partner_unpaired_and_later_pairs_form() {
        let a = stream(0, P30, 10);
        let mut b = stream(2_000, P30, 10);
        b.remove(4);
        let mut p = Pairer::for_frame_periods(P30, P30);
        let pairs = run(&mut p, &a, &b);
        // A 4 has no partner; A 9 waits for A 10 to show that B 9 is its nearest.
        let mut expected: Vec<(u32, u32)> = (0..9).map(|i| (i, i)).collect();
        expected.remove(4);
        assert_eq!(pairs, expected);
        assert_eq!(p.counts().unpaired_a, 1);
        assert_eq!(p.counts().unpaired_b, 0);
        assert_eq!(p.counts().paired, 8);
        assert_eq!(p.pending(), (1, 1));
    }

    #[test]
    fn a_half_rate_stream_pairs_with_every_other_frame() {
        // A at 30 fps, B at 15 fps, B 1 ms after every even A frame.
        let a = stream(0, P30, 20);
        let b = stream(1_000, 2 * P30, 10);
        let mut p = Pairer::for_frame_periods(P30, 2 * P30);
        let pairs = run(&mut p, &a, &b);
        assert_eq!(pairs, (0..10).map(|i| (2 * i, i)).collect::<Vec<_>>());
        // Odd A frames 1..=17 are dropped; A 19 is within tolerance of B 9 (32 ms) and waits
        // to learn whether B 10 is nearer.
        assert_eq!(p.counts().unpaired_a, 9);
        assert_eq!(p.counts().unpaired_b, 0);
        assert_eq!(p.pending(), (1, 0));
    }

    #[test]
    fn streams_further_apart_than_the_tolerance_pair_nothing() {
        // B is half a period late: 16.7 ms > 10 ms.
        let a = stream(0, P30, 10);
        let b = stream(P30 / 2, P30, 10);
        let mut p = Pairer::new(10_000);
        assert!(run(&mut p, &a, &b).is_empty());
        let c = p.counts();
        assert_eq!(c.paired, 0);
        // Everything but the two frames still waiting is counted; reset counts those too.
        assert_eq!(
            c.unpaired_a + c.unpaired_b + p.pending().0 as u64 + p.pending().1 as u64,
            20
        );
        p.reset();
        assert_eq!(p.counts().unpaired_a, 10);
        assert_eq!(p.counts().unpaired_b, 10);
        assert_eq!(p.pending(), (0, 0));
    }

    #[test]
    fn nearest_frame_wins_over_an_earlier_one_within_tolerance() {
        // B 0 at 80, B 1 at 115; A 0 at 100 prefers B 1 (15 < 20), so B 0 goes unpaired. B 1
        // in turn pairs once A 1 shows that A 0 is its nearest.
        let mut p = Pairer::new(30);
        assert!(p.push_b(80, 0u32).is_none());
        assert!(p.push_a(100, 0u32).is_none());
        assert!(p.push_b(115, 1).is_none());
        assert_eq!(p.counts().unpaired_b, 1);
        let pair = p.push_a(200, 1).expect("a pair");
        assert_eq!(
            (pair.a, pair.b, pair.ts_a_us, pair.ts_b_us),
            (0, 1, 100, 115)
        );
        assert_eq!(p.counts().paired, 1);
    }

    #[test]
    fn memory_stays_bounded_when_one_stream_stalls() {
        let mut p: Pairer<u32, u32> = Pairer::with_capacity(10_000, 3);
        for (t, i) in stream(0, P30, 100) {
            assert!(p.push_a(t, i).is_none());
            assert!(p.pending().0 <= 3);
        }
        assert_eq!(p.counts().unpaired_a, 97);
        // B comes back 0.5 ms after A 99: A 97 and A 98 are too far and dropped, A 99 waits
        // for A 100 to show that this B frame is its nearest.
        assert!(p.push_b(99 * P30 + 500, 0).is_none());
        assert_eq!(p.counts().unpaired_a, 99);
        let pair = p.push_a(100 * P30, 100).expect("a pair");
        assert_eq!((pair.a, pair.b), (99, 0));
        assert_eq!(p.pending(), (1, 0));
    }

    #[test]
    fn an_overfull_queue_forces_its_head_to_pair_with_the_best_known_partner() {
        // B 0 comes 1 ms before A 0 and waits for B 1 to show it is A 0's nearest, while A
        // bursts three frames into a queue of two: A 0 is forced into the pair with B 0, the
        // best partner known, rather than dropped.
        let mut p: Pairer<u32, u32> = Pairer::with_capacity(5_000, 2);
        assert!(p.push_b(9_000, 0).is_none());
        assert!(p.push_a(10_000, 0).is_none());
        assert!(p.push_a(10_100, 1).is_none());
        assert_eq!(p.pending(), (2, 1));
        let pair = p.push_a(10_200, 2).map(|p| (p.a, p.b));
        assert_eq!(pair, Some((0, 0)));
        assert_eq!(p.pending(), (2, 0));
        assert_eq!(p.counts().unpaired_a + p.counts().unpaired_b, 0);
    }
}
