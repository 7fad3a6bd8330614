//! The bounded hand-over between the capture thread and the processing thread.
//!
//! A live camera cannot wait: when processing falls behind, the *oldest* waiting frame is
//! dropped (and counted) so the daemon always works on the freshest input. A replay "as fast as
//! possible" must not lose frames, so the producer waits instead. The policy is chosen per
//! queue.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// What to do when the queue is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overflow {
    DropOldest,
    Block,
}

/// A bounded multi-producer, multi-consumer queue with a drop counter and a close flag.
#[derive(Debug)]
pub struct FrameQueue<T> {
    state: Mutex<State<T>>,
    changed: Condvar,
    capacity: usize,
    overflow: Overflow,
}

#[derive(Debug)]
struct State<T> {
    items: VecDeque<T>,
    dropped: u64,
    closed: bool,
}

impl<T> FrameQueue<T> {
    pub fn new(capacity: usize, overflow: Overflow) -> Self {
        assert!(capacity > 0, "queue capacity must be positive");
        FrameQueue {
            state: Mutex::new(State {
                items: VecDeque::with_capacity(capacity),
                dropped: 0,
                closed: false,
            }),
            changed: Condvar::new(),
            capacity,
            overflow,
        }
    }

    /// Adds an item (dropping the oldest or waiting when full). `is_droppable` says whether a
    /// queued item may be dropped (end-of-stream markers must not be). Returns `false` if the
    /// queue was closed.
    pub fn push(&self, item: T, is_droppable: impl Fn(&T) -> bool) -> bool {
        let mut state = self.state.lock().expect("queue lock");
        loop {
            if state.closed {
                return false;
            }
            if state.items.len() < self.capacity {
                break;
            }
            match self.overflow {
                Overflow::DropOldest => match state.items.iter().position(&is_droppable) {
                    Some(i) => {
                        state.items.remove(i);
                        state.dropped += 1;
                    }
                    None => state = self.changed.wait(state).expect("queue lock"),
                },
                Overflow::Block => state = self.changed.wait(state).expect("queue lock"),
            }
        }
        state.items.push_back(item);
        self.changed.notify_all();
        true
    }

    /// Takes the oldest item, waiting up to `timeout`.
    pub fn pop(&self, timeout: Duration) -> Option<T> {
        let state = self.state.lock().expect("queue lock");
        let (mut state, _) = self
            .changed
            .wait_timeout_while(state, timeout, |s| s.items.is_empty() && !s.closed)
            .expect("queue lock");
        let item = state.items.pop_front();
        if item.is_some() {
            self.changed.notify_all();
        }
        item
    }

    /// Items dropped so far.
    pub fn dropped(&self) -> u64 {
        self.state.lock().expect("queue lock").dropped
    }

    /// Wakes everyone; later pushes are refused.
    pub fn close(&self) {
        self.state.lock().expect("queue lock").closed = true;
        self.changed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn drop_oldest_keeps_the_newest_and_counts() {
        let q = FrameQueue::new(2, Overflow::DropOldest);
        for i in 0..5 {
            assert!(q.push(i, |_| true));
        }
        assert_eq!(q.dropped(), 3);
        assert_eq!(q.pop(Duration::ZERO), Some(3));
        assert_eq!(q.pop(Duration::ZERO), Some(4));
        assert_eq!(q.pop(Duration::from_millis(1)), None);
    }

    #[test]
    fn undroppable_items_survive_overflow() {
        let q = FrameQueue::new(2, Overflow::DropOldest);
        q.push(-1, |_| true);
        q.push(0, |_| true);
        q.push(1, |&v| v >= 0);
        // -1 is the oldest but not droppable: 0 goes.
        assert_eq!(q.pop(Duration::ZERO), Some(-1));
        assert_eq!(q.pop(Duration::ZERO), Some(1));
    }

    #[test]
    fn block_waits_for_the_consumer_and_loses_nothing() {
        let q = Arc::new(FrameQueue::new(1, Overflow::Block));
        let producer = {
            let q = q.clone();
            std::thread::spawn(move || (0..100).all(|i| q.push(i, |_| true)))
        };
        let got: Vec<i32> = (0..100)
            .map(|_| q.pop(Duration::from_secs(5)).unwrap())
            .collect();
        assert!(producer.join().unwrap());
        assert_eq!(got, (0..100).collect::<Vec<_>>());
        assert_eq!(q.dropped(), 0);
    }

    #[test]
    fn close_refuses_pushes_and_wakes_consumers() {
        let q = FrameQueue::<i32>::new(1, Overflow::Block);
        q.close();
        assert!(!q.push(1, |_| true));
        assert_eq!(q.pop(Duration::from_secs(5)), None);
    }
}
