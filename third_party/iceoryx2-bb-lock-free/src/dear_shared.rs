// DEAR PATCH (issue 34 of DEAR-on-device; see third_party/README.md): a process-wide table of
// the memory ranges this process mapped from files that *other processes write* (iceoryx2's
// dynamic storages: a service's `*.dynamic`, a connection's `*.connection`, ...). A container
// that lives in such a range reads its own geometry (relocatable pointers, capacity) from
// memory another process may have overwritten; before it uses them it checks with
// [`contains`] that everything they name lies inside the mapping that holds the container.
// Memory not in the table (process-local containers, the stack, the heap) is not shared with
// anyone and is trusted as before.
//
// Lock-free and allocation-free (the crate is `no_std`): a fixed table; a range that does not
// fit is not checked (logged once by the caller that registers it).

use core::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

const SLOTS: usize = 256;

/// `start` of each registered range (0: free) and its end (exclusive).
static STARTS: [AtomicUsize; SLOTS] = [const { AtomicUsize::new(0) }; SLOTS];
static ENDS: [AtomicUsize; SLOTS] = [const { AtomicUsize::new(0) }; SLOTS];

/// Registers the mapping `[start, start + len)`; returns false when the table is full.
pub fn register(start: usize, len: usize) -> bool {
    if start == 0 {
        return false;
    }
    let end = start.saturating_add(len);
    for n in 0..SLOTS {
        // The end is published before the start: a reader that sees the start sees its end.
        if STARTS[n].load(Ordering::Acquire) == 0 {
            ENDS[n].store(end, Ordering::Release);
            if STARTS[n]
                .compare_exchange(0, start, Ordering::AcqRel, Ordering::Relaxed)
                .is_ok()
            {
                return true;
            }
        }
    }
    false
}

/// Forgets the mapping that starts at `start` (before it is unmapped).
pub fn unregister(start: usize) {
    for slot in &STARTS {
        if slot
            .compare_exchange(start, 0, Ordering::AcqRel, Ordering::Relaxed)
            .is_ok()
        {
            return;
        }
    }
}

/// The registered mapping that holds `address`, if any, as `(start, end)`.
pub fn mapping_of(address: usize) -> Option<(usize, usize)> {
    for n in 0..SLOTS {
        let start = STARTS[n].load(Ordering::Acquire);
        if start != 0 && start <= address {
            let end = ENDS[n].load(Ordering::Acquire);
            if address < end {
                return Some((start, end));
            }
        }
    }
    None
}

/// Whether `[start, start + len)` may be used by a container at `owner`: it lies in the
/// mapping that holds `owner`, is aligned to `align` and does not wrap; always true when
/// `owner` is not in shared memory this process registered.
pub fn contains(owner: usize, start: usize, len: usize, align: usize) -> bool {
    if align == 0 || !start.is_multiple_of(align) {
        return false;
    }
    let Some(end) = start.checked_add(len) else {
        return false;
    };
    match mapping_of(owner) {
        None => true,
        Some((low, high)) => low <= start && end <= high,
    }
}

static CORRUPTIONS: AtomicU64 = AtomicU64::new(0);

/// Counts a shared header found corrupted (a container refused to use it).
pub fn note_corruption() {
    CORRUPTIONS.fetch_add(1, Ordering::Relaxed);
}

/// How many shared headers this process found corrupted so far: a service watching its own
/// records (DEAR's daemon) compares it between checks and makes the records again.
pub fn corruptions() -> u64 {
    CORRUPTIONS.load(Ordering::Relaxed)
}
