//! Work split over threads that the caller owns: the core never starts a thread, reads a clock
//! or waits on another thread by itself (a haptic servo must control every one of those). A
//! caller with cores to spare passes a [`Fork`] (`palpate-haptics`' spinning pool is one), and
//! the hot loops that can split ([`crate::runtime::tick_with`], the particle sub-steps of
//! [`crate::meshfree::step_with_fork`]) run their passes in that many parts at once. The parts
//! write disjoint particles, and each particle's arithmetic is the same whichever part computes
//! it, so the result is bitwise that of [`Serial`] (tests/parallel.rs).

/// Runs a job in `ways()` parts at once.
///
/// # Safety
/// The passes give part `k` exclusive access to its particles, so an implementation must call
/// `job(k)` exactly once for each `k < ways()` per [`Fork::fork`], and return only after every
/// call has returned (the job borrows the caller's data). Calls may run on any threads, in any
/// order, at once.
#[allow(unsafe_code)]
pub unsafe trait Fork: Sync {
    /// Parts a job is split into (at least 1).
    fn ways(&self) -> usize;
    /// Call `job(k)` once for every `k < ways()`, concurrently, and return when all have
    /// returned. The core's jobs do not panic; a `Fork` need not survive one that does.
    fn fork(&self, job: &(dyn Fn(usize) + Sync));
}

/// One part, on the calling thread: the default.
#[derive(Debug, Clone, Copy, Default)]
pub struct Serial;

// SAFETY: one call, `job(0)`, on this thread, returned before `fork` returns.
#[allow(unsafe_code)]
unsafe impl Fork for Serial {
    fn ways(&self) -> usize {
        1
    }
    fn fork(&self, job: &(dyn Fn(usize) + Sync)) {
        job(0)
    }
}

/// Most parts a split uses (more ways are used as this many).
pub const MAX_WAYS: usize = 8;

/// The `k`-th of `ways` near-equal contiguous parts of `0..len`.
#[inline]
pub(crate) fn part(len: usize, ways: usize, k: usize) -> std::ops::Range<usize> {
    (k * len / ways)..((k + 1) * len / ways)
}

#[cfg(test)]
mod tests {
    #[test]
    fn parts_tile_the_range() {
        for len in [0, 1, 5, 17, 400] {
            for ways in 1..=super::MAX_WAYS {
                let mut next = 0;
                for k in 0..ways {
                    let r = super::part(len, ways, k);
                    assert_eq!(r.start, next);
                    next = r.end;
                }
                assert_eq!(next, len);
            }
        }
    }
}
