//! Sharing work between threads: below which sizes a loop stays on one thread, and [`Disjoint`], the
//! slice that threads write at indices no two of them share (the schedule's colouring guarantees it).

use std::marker::PhantomData;

/// Below this many particles a step runs on one thread. Tried at 1,024 (2026-12-03), so that Fig. 1's 1,526
/// particles use two threads: the bare step took 0.88× the time, but a run with its frames, images and
/// animation took 1.22× (its output threads then compete with two workers that wait on each other at every
/// stage, where on one thread they have the second core to themselves).
pub const PARALLEL_MIN: usize = 4096;
/// Smallest piece of a per-particle loop handed to one thread (see [`task_len`]).
pub const MIN_TASK: usize = 2048;
/// Smallest piece of a per-block loop handed to one thread (blocks of BLOCK^D nodes).
pub const MIN_BLOCKS: usize = 128;

/// Whether a step over `n` particles runs its loops on several threads: enough particles, and more than
/// one thread to run them (on one, the parallel forms only add their bookkeeping). Either way the results
/// are the same: every sum is taken in an order fixed by the particles, not by the threads.
pub fn worth_splitting(n: usize) -> bool {
    n >= PARALLEL_MIN && rayon::current_num_threads() > 1
}

/// Smallest piece of a loop over `n` particles handed to one thread: [`MIN_TASK`], or an eighth of the
/// loop where that is less, so that scenes of a few thousand particles split too.
pub fn task_len(n: usize) -> usize {
    MIN_TASK.min(n.div_ceil(8)).max(1)
}

/// A slice that several threads write at indices no two of them share.
#[derive(Clone, Copy)]
pub(crate) struct Disjoint<'a, T> {
    ptr: *mut T,
    len: usize,
    _slice: PhantomData<&'a mut [T]>,
}

// SAFETY: `Disjoint` only hands out access through `update`, whose callers promise that no two
// threads touch the same index; `T: Send` lets the values be written from another thread.
unsafe impl<T: Send> Send for Disjoint<'_, T> {}
unsafe impl<T: Send> Sync for Disjoint<'_, T> {}

impl<'a, T> Disjoint<'a, T> {
    pub(crate) fn new(slice: &'a mut [T]) -> Self {
        Self { ptr: slice.as_mut_ptr(), len: slice.len(), _slice: PhantomData }
    }

    /// Applies `f` to element `i`.
    ///
    /// # Safety
    /// No other thread may access element `i` while `self` is shared.
    #[inline(always)]
    pub(crate) unsafe fn update(&self, i: usize, f: impl FnOnce(&mut T)) {
        assert!(i < self.len, "index {i} out of a slice of {}", self.len);
        // SAFETY: in bounds (checked above); exclusive by the caller's promise.
        f(unsafe { &mut *self.ptr.add(i) });
    }

    /// Length of the slice.
    #[inline(always)]
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// As [`Self::update`], without the bounds check.
    ///
    /// # Safety
    /// `i < self.len()`, and no other thread may access element `i` while `self` is shared.
    #[inline(always)]
    pub(crate) unsafe fn update_unchecked(&self, i: usize, f: impl FnOnce(&mut T)) {
        debug_assert!(i < self.len);
        // SAFETY: the caller's promises.
        f(unsafe { &mut *self.ptr.add(i) });
    }
}

/// Asks the CPU to bring element `i` of `slice` into its caches ahead of use (a no-op past the end, and
/// on targets other than x86-64). Loops that visit particles by index in block order (P2G) read each of
/// their arrays at scattered addresses once the particles have mixed; the index a few places on in that
/// order is known, so its loads can be in flight while this particle is computed.
#[inline(always)]
pub(crate) fn prefetch<T>(slice: &[T], i: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(value) = slice.get(i) {
        // SAFETY: a prefetch reads nothing the program sees and cannot fault; the address is of a live
        // element (SSE, which the instruction needs, is in every x86-64 CPU).
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>((value as *const T).cast::<i8>())
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (slice, i);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A loop's pieces are an eighth of it, at most [`MIN_TASK`] and at least one particle.
    #[test]
    fn task_len_is_an_eighth_within_its_bounds() {
        assert_eq!(task_len(0), 1);
        assert_eq!(task_len(7), 1);
        assert_eq!(task_len(4096), 512);
        assert_eq!(task_len(4097), 513);
        assert_eq!(task_len(16_384), MIN_TASK);
        assert_eq!(task_len(1 << 20), MIN_TASK);
    }

    /// One thread never takes the parallel forms, whatever the size.
    #[test]
    fn a_pool_of_one_thread_does_not_split() {
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        assert!(!one.install(|| worth_splitting(1 << 20)));
        assert!(two.install(|| worth_splitting(PARALLEL_MIN)));
        assert!(!two.install(|| worth_splitting(PARALLEL_MIN - 1)));
    }
}
