//! [`Disjoint`]: a slice that the parts of a split pass write at disjoint indices (the particle
//! passes split over a [`crate::parallel::Fork`]). One of the crate's audited `unsafe` places.
//!
//! Soundness rests on the callers' contract of [`Disjoint::at`]: while parts run concurrently,
//! no index is reached by two of them. The passes give each part its own contiguous piece of
//! the active (or free) list, and those lists hold every particle once (checked every step:
//! `touch` in `step.rs` finds any repeat, and a list with one runs serially).

use std::marker::PhantomData;

/// Exclusive access to a slice for the duration of a split pass, shareable between its parts.
pub(crate) struct Disjoint<'a, T> {
    ptr: *mut T,
    len: usize,
    _borrow: PhantomData<&'a mut [T]>,
}

// SAFETY: a `Disjoint` only hands out `&mut T` at an index, under the contract of `at` (no two
// threads at one index), so sharing it between threads is sharing `&mut T`s of distinct
// elements: sound when `T` may be sent between threads.
#[allow(unsafe_code)]
unsafe impl<T: Send> Sync for Disjoint<'_, T> {}
#[allow(unsafe_code)]
unsafe impl<T: Send> Send for Disjoint<'_, T> {}

impl<'a, T> Disjoint<'a, T> {
    /// Borrow `s` exclusively for as long as the `Disjoint` lives.
    pub(crate) fn new(s: &'a mut [T]) -> Self {
        Disjoint { ptr: s.as_mut_ptr(), len: s.len(), _borrow: PhantomData }
    }

    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// The element at `i` (panics if out of range).
    ///
    /// # Safety
    /// No other reference to element `i` (from this `Disjoint`, on any thread) is alive while
    /// the returned one is.
    #[allow(unsafe_code, clippy::mut_from_ref)]
    #[inline(always)]
    pub(crate) unsafe fn at(&self, i: usize) -> &mut T {
        assert!(i < self.len);
        // SAFETY: in bounds (checked), the slice is borrowed exclusively for 'a, and the caller
        // guarantees no other reference to this element is alive.
        unsafe { &mut *self.ptr.add(i) }
    }
}
