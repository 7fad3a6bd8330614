//! Frames a client missed and publisher restarts, from each header's `(run_id, sequence)`:
//! one rule for every client that counts them (`dear watch`, `dear view`).
//!
//! A publisher's `sequence` has no gaps on its side within one `run_id`, so a gap of `n` is
//! `n` frames this client never got; a new `run_id` is a restarted publisher whose sequence
//! starts again (nothing counted lost across it); a `run_id` of 0 means the publisher numbers
//! nothing, so no loss can be counted.

use dear_proto::FrameHeader;

/// What one frame's numbering says against the frames seen before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceStep {
    /// The first numbered frame this tracker sees.
    First,
    /// The same publisher instance as the previous numbered frame; `lost` frames came between
    /// (0 in order; a repeat or step back, which the protocol rules out, counts as 0).
    Next { lost: u64 },
    /// A new `run_id`: the publisher restarted.
    Restart,
    /// `run_id` 0: a publisher that numbers nothing (the tracker keeps its last numbered frame).
    Unnumbered,
}

/// The last numbered frame's `(run_id, sequence)`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SequenceTracker {
    last: Option<(u64, u64)>,
}

impl SequenceTracker {
    /// Steps to `header`'s frame.
    pub fn see(&mut self, header: &FrameHeader) -> SequenceStep {
        if header.run_id == 0 {
            return SequenceStep::Unnumbered;
        }
        let step = match self.last {
            Some((run, seq)) if run == header.run_id => SequenceStep::Next {
                lost: header.sequence.saturating_sub(seq).saturating_sub(1),
            },
            Some(_) => SequenceStep::Restart,
            None => SequenceStep::First,
        };
        self.last = Some((header.run_id, header.sequence));
        step
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(run_id: u64, sequence: u64) -> FrameHeader {
        let mut h = FrameHeader::new(0, 4, 2);
        (h.run_id, h.sequence) = (run_id, sequence);
        h
    }

    #[test]
    fn gaps_within_a_run_are_lost_and_a_new_run_is_a_restart() {
        let mut t = SequenceTracker::default();
        let steps: Vec<_> = [
            (7, 10),
            (7, 11),
            (7, 14),
            (0, 99),
            (7, 14),
            (7, 13),
            (9, 0),
            (9, 2),
        ]
        .into_iter()
        .map(|(run, seq)| t.see(&header(run, seq)))
        .collect();
        use SequenceStep::*;
        assert_eq!(
            steps,
            [
                First,
                Next { lost: 0 },
                Next { lost: 2 },
                Unnumbered,
                Next { lost: 0 },
                Next { lost: 0 },
                Restart,
                Next { lost: 1 },
            ]
        );
    }
}
