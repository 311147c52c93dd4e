//! [`SpinPool`]: the servo's helper threads for the physics' passes (a [`Fork`] of the core,
//! [`palpate_core::parallel`]). The core keeps no threads; the haptic crate, which owns the
//! servo's clock and scheduling, owns these too.
//!
//! A tick of the hybrid model runs ~20 split passes of 10-50 us each (two per particle
//! sub-step), so a hand-off must cost well under a microsecond: a pool that sleeps between
//! passes (a condition variable, rayon's sleep) pays a wake-up of 5-50 us each time. The helpers
//! here spin on an atomic round counter while work may come ([`SpinPool::wake`] at the start of
//! a tick, then for [`SPIN`] after each pass) and park when it stops, so a stopped or paused
//! servo does not burn a core (under `SCHED_FIFO` they park between ticks: [`SPIN_REALTIME`]). A
//! pass whose part panics is re-raised on the calling thread after every part has returned (the
//! parts borrow the caller's data).
//!
//! **Measured (2026-11-26, the 2-core machine of BENCHMARKS.md; the runs are in
//! docs/history/benchmarks-log.md#2026-11-26-fourth-session-the-particle-passes-on-two-threads-do-not-pay-on-this-machine-load-09-14-1100-1140-utc).** Alone
//! (`examples/pool_tick.rs`), a Rodero tick took 13% and 16% less on two threads than on one in
//! two runs and 9% more in a third, on a busier minute (means, the helper spinning between
//! ticks; with 150 us spins it parked between ticks and the wake-up ate the gain). Inside the servo it did not pay on that machine: the process's other threads (the
//! watchdog, Python's) and the machine's own work preempt one of the two busy threads, and a
//! pass then waits for a descheduled helper for milliseconds (compute p99 1.6-1.7 ms against
//! 1.2-1.4 ms on one thread). Give the helpers cores that nothing else uses.

use std::any::Any;
use std::cell::UnsafeCell;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use palpate_core::parallel::{Fork, MAX_WAYS};

use crate::realtime::{make_current_thread_realtime, Realtime, SERVO_PRIORITY};

/// How long a helper spins for the next pass before it parks: 2 ms, longer than the gap between
/// two ticks at 500 Hz and more, so that a running servo's helpers never park (a wake-up from a
/// park cost more than the split saved: measured on Rodero, 150 us spins gave no gain).
pub const SPIN: Duration = Duration::from_millis(2);
/// The same under `SCHED_FIFO`, where a helper that never rests would meet the kernel's
/// real-time throttle ([`crate::realtime`]): it parks between ticks.
pub const SPIN_REALTIME: Duration = Duration::from_micros(150);

/// A job pointer with its borrow's lifetime erased: valid from the round's publication until
/// every helper has counted itself done (the caller waits for that before `fork` returns).
type JobPtr = *const (dyn Fn(usize) + Sync + 'static);

struct Shared {
    /// The current round's job, written by the caller before `round` is bumped (release) and
    /// read by the helpers after they see the bump (acquire).
    job: UnsafeCell<Option<JobPtr>>,
    round: AtomicU64,
    /// Helpers done with the current round.
    done: AtomicUsize,
    /// Helper `k` is parked or about to (the caller must unpark it).
    asleep: Vec<AtomicBool>,
    /// Until this instant (ns since `epoch`) the helpers spin rather than park.
    spin_until: AtomicU64,
    /// [`SPIN`] or [`SPIN_REALTIME`] \[ns\].
    spin_ns: u64,
    epoch: Instant,
    stop: AtomicBool,
    panic: Mutex<Option<Box<dyn Any + Send>>>,
}

// SAFETY: `job` is written only by the thread in `fork` (one at a time: `busy`), and only while
// no helper reads it: before the round is published, or after every helper counted itself done.
// The job it points to is `Sync`.
unsafe impl Sync for Shared {}
unsafe impl Send for Shared {}

/// Helper threads that run the parts of a split pass (`ways - 1` helpers; the caller runs part 0).
pub struct SpinPool {
    shared: Arc<Shared>,
    helpers: Vec<JoinHandle<()>>,
    ways: usize,
    busy: AtomicBool,
    realtime: Realtime,
}

impl SpinPool {
    /// A pool splitting passes `ways` ways (1 to [`MAX_WAYS`]; 1 starts no thread), its helpers
    /// under `SCHED_FIFO` when `realtime` (as the servo; refused silently to ordinary
    /// scheduling, which [`SpinPool::realtime`] reports).
    pub fn new(ways: usize, realtime: bool) -> std::io::Result<SpinPool> {
        let ways = ways.clamp(1, MAX_WAYS);
        let shared = Arc::new(Shared {
            job: UnsafeCell::new(None),
            round: AtomicU64::new(0),
            done: AtomicUsize::new(0),
            asleep: (0..ways).map(|_| AtomicBool::new(false)).collect(),
            spin_until: AtomicU64::new(0),
            spin_ns: if realtime { SPIN_REALTIME } else { SPIN }.as_nanos() as u64,
            epoch: Instant::now(),
            stop: AtomicBool::new(false),
            panic: Mutex::new(None),
        });
        let (tx, rx) = std::sync::mpsc::channel();
        let mut helpers = Vec::new();
        for k in 1..ways {
            let (s, tx) = (shared.clone(), tx.clone());
            helpers.push(std::thread::Builder::new().name(format!("palpate-pool-{k}")).spawn(move || {
                let rt = if realtime { make_current_thread_realtime(SERVO_PRIORITY) } else { Realtime::Off };
                let _ = tx.send(rt);
                helper(&s, k)
            })?);
        }
        drop(tx);
        let realtime = rx.iter().take(ways - 1).fold(if realtime { Realtime::Granted(SERVO_PRIORITY) } else { Realtime::Off }, |acc, r| {
            if acc.granted() && !r.granted() {
                r
            } else {
                acc
            }
        });
        Ok(SpinPool { shared, helpers, ways, busy: AtomicBool::new(false), realtime })
    }

    /// Whether the helpers run under `SCHED_FIFO` (all of them), as asked at [`SpinPool::new`].
    pub fn realtime(&self) -> &Realtime {
        &self.realtime
    }

    /// Work is coming: the helpers spin (unparked) for the next [`SPIN`] and after each pass.
    /// Call it at the start of a tick, so that the wake-up overlaps the tick's own serial work.
    pub fn wake(&self) {
        let s = &self.shared;
        s.spin_until.store(now_ns(s) + s.spin_ns, Ordering::SeqCst);
        self.unpark_sleepers();
    }

    /// Unpark the helpers that parked or are about to.
    fn unpark_sleepers(&self) {
        for (k, h) in self.helpers.iter().enumerate() {
            if self.shared.asleep[k + 1].load(Ordering::SeqCst) {
                h.thread().unpark();
            }
        }
    }
}

fn now_ns(s: &Shared) -> u64 {
    s.epoch.elapsed().as_nanos() as u64
}

fn helper(s: &Shared, k: usize) {
    let mut seen = 0u64;
    loop {
        // Wait for a new round: spin while work may come, else park.
        loop {
            if s.stop.load(Ordering::Acquire) {
                return;
            }
            let r = s.round.load(Ordering::Acquire);
            if r != seen {
                seen = r;
                break;
            }
            if now_ns(s) < s.spin_until.load(Ordering::Relaxed) {
                std::hint::spin_loop();
                continue;
            }
            // Announce the park, then look once more (the caller bumps `round` and then reads
            // `asleep`, both sequentially consistent: one of the two sees the other).
            s.asleep[k].store(true, Ordering::SeqCst);
            if s.round.load(Ordering::SeqCst) == seen && !s.stop.load(Ordering::SeqCst) && now_ns(s) >= s.spin_until.load(Ordering::SeqCst) {
                // The timeout bounds the cost of any missed wake-up.
                std::thread::park_timeout(Duration::from_millis(2));
            }
            s.asleep[k].store(false, Ordering::SeqCst);
        }
        // SAFETY: the round was published after `job` was written (acquire above), and the
        // caller does not touch `job` or the data it borrows until this helper counts itself
        // done below.
        let job = unsafe { (*s.job.get()).expect("a published round has a job") };
        // SAFETY: as above: the pointee outlives the round.
        let result = catch_unwind(AssertUnwindSafe(|| unsafe { (*job)(k) }));
        if let Err(p) = result {
            if let Ok(mut slot) = s.panic.lock() {
                slot.get_or_insert(p);
            }
        }
        s.spin_until.fetch_max(now_ns(s) + s.spin_ns, Ordering::Relaxed);
        s.done.fetch_add(1, Ordering::Release);
    }
}

// SAFETY: `fork` calls `job(k)` exactly once for each `k < ways` (part 0 on the calling thread,
// part `k` on helper `k`, each of which runs each round once) and returns only after every
// helper has counted itself done with the round (and part 0 has returned), panicking or not.
unsafe impl Fork for SpinPool {
    fn ways(&self) -> usize {
        self.ways
    }

    fn fork(&self, job: &(dyn Fn(usize) + Sync)) {
        if self.ways == 1 || self.busy.swap(true, Ordering::Acquire) {
            // One way, or called from two threads at once (not the servo's use): run serially.
            for k in 0..self.ways {
                job(k);
            }
            return;
        }
        let s = &*self.shared;
        // SAFETY: erasing the borrow's lifetime; the pointer is used only until every helper is
        // done with this round, which this function waits for before it returns.
        let ptr: JobPtr = unsafe { std::mem::transmute::<*const (dyn Fn(usize) + Sync + '_), JobPtr>(job as *const _) };
        // SAFETY: no helper reads `job` now (the last round is done, the next not published).
        unsafe { *s.job.get() = Some(ptr) };
        s.done.store(0, Ordering::Relaxed);
        s.spin_until.fetch_max(now_ns(s) + s.spin_ns, Ordering::Relaxed);
        s.round.fetch_add(1, Ordering::SeqCst);
        self.unpark_sleepers();
        let mine = catch_unwind(AssertUnwindSafe(|| job(0)));
        while s.done.load(Ordering::Acquire) < self.ways - 1 {
            std::hint::spin_loop();
        }
        // SAFETY: every helper is done with the round: nobody reads `job`.
        unsafe { *s.job.get() = None };
        self.busy.store(false, Ordering::Release);
        if let Err(p) = mine {
            resume_unwind(p);
        }
        let theirs = s.panic.lock().ok().and_then(|mut slot| slot.take());
        if let Some(p) = theirs {
            resume_unwind(p);
        }
    }
}

impl Drop for SpinPool {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        for h in &self.helpers {
            h.thread().unpark();
        }
        for h in self.helpers.drain(..) {
            let _ = h.join();
        }
    }
}

impl std::fmt::Debug for SpinPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpinPool").field("ways", &self.ways).field("realtime", &self.realtime).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn every_part_runs_once_per_fork_and_the_fork_waits_for_them() {
        let pool = SpinPool::new(3, false).unwrap();
        let hits: Vec<AtomicUsize> = (0..3).map(|_| AtomicUsize::new(0)).collect();
        for round in 0..2000 {
            if round % 500 == 0 {
                // Let the helpers park, then wake them with a fork.
                std::thread::sleep(Duration::from_millis(3));
            }
            pool.fork(&|k| {
                std::hint::black_box((0..50).sum::<usize>());
                hits[k].fetch_add(1, Ordering::Relaxed);
            });
            // The fork returned: every part of this round has run.
            for h in &hits {
                assert_eq!(h.load(Ordering::Relaxed), round + 1);
            }
        }
    }

    #[test]
    fn a_panicking_part_is_raised_on_the_caller_and_the_pool_goes_on() {
        let pool = SpinPool::new(2, false).unwrap();
        let r = catch_unwind(AssertUnwindSafe(|| pool.fork(&|k| assert!(k != 1, "part one fails"))));
        assert!(r.is_err());
        let n = AtomicUsize::new(0);
        pool.fork(&|_| {
            n.fetch_add(1, Ordering::Relaxed);
        });
        assert_eq!(n.load(Ordering::Relaxed), 2);
    }
}
