//! Latest-only snapshots the servo thread publishes and any number of readers (a viewer, Python,
//! a status line, logs) take without ever blocking the writer: a seqlock over atomic words.
//!
//! Why a seqlock, not a mutex or a channel: the writer never waits (a mutex held by a reader
//! that the OS preempted would stall the servo tick), publishing costs a few relaxed stores, and
//! a reader gets the newest consistent record or retries (it never sees half of one tick and
//! half of the next). Written with atomics only, so the crate stays free of `unsafe`: each word is
//! an `AtomicU64` (an `f64` by its bits); the sequence is odd while a write is in progress.

use std::sync::atomic::{fence, AtomicU64, Ordering};
use std::sync::Mutex;

use palpate_core::Vec3;

/// A seqlock over `N` 64-bit words: any writers, any readers. One writer is the rule (the servo);
/// a second (the watchdog zeroing the force while the servo is stuck in a tick) is allowed: a
/// writer claims the record by moving the sequence from even to odd with a compare-and-swap, so
/// two writes never interleave (with plain stores, two racing writers could leave the sequence odd
/// for good, and every reader would spin forever).
#[derive(Debug)]
pub struct SeqLock<const N: usize> {
    seq: AtomicU64,
    words: [AtomicU64; N],
}

impl<const N: usize> Default for SeqLock<N> {
    fn default() -> Self {
        SeqLock { seq: AtomicU64::new(0), words: std::array::from_fn(|_| AtomicU64::new(0)) }
    }
}

impl<const N: usize> SeqLock<N> {
    /// Publishes `words`. With a single writer the claim never waits; a second writer waits only
    /// for the first one's `N` stores.
    pub fn write(&self, words: &[u64; N]) {
        let mut spins = 0u32;
        let s = loop {
            let s = self.seq.load(Ordering::Relaxed);
            if s & 1 == 0 && self.seq.compare_exchange_weak(s, s.wrapping_add(1), Ordering::Relaxed, Ordering::Relaxed).is_ok() {
                break s;
            }
            spins += 1;
            if spins > 64 {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
        };
        // The odd sequence must be visible before any new word.
        fence(Ordering::Release);
        for (w, &v) in self.words.iter().zip(words) {
            w.store(v, Ordering::Relaxed);
        }
        self.seq.store(s.wrapping_add(2), Ordering::Release);
    }

    /// The last complete record and its sequence number (even; 0: nothing published yet).
    /// Retries while a write is in progress, yielding after a few spins (a reader may be
    /// preempted; the writer never is on its behalf).
    pub fn read(&self) -> ([u64; N], u64) {
        let mut spins = 0u32;
        loop {
            let s1 = self.seq.load(Ordering::Acquire);
            if s1 & 1 == 0 {
                let out: [u64; N] = std::array::from_fn(|i| self.words[i].load(Ordering::Relaxed));
                fence(Ordering::Acquire);
                if self.seq.load(Ordering::Relaxed) == s1 {
                    return (out, s1);
                }
            }
            spins += 1;
            if spins > 64 {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
        }
    }
}

/// A published vector cell (e.g. the simulated hand's target that a viewer drags), world frame.
#[derive(Debug, Default)]
pub struct Vec3Cell(SeqLock<3>);

impl Vec3Cell {
    pub fn new(v: Vec3) -> Vec3Cell {
        let c = Vec3Cell::default();
        c.set(&v);
        c
    }
    /// Sets the value.
    pub fn set(&self, v: &Vec3) {
        self.0.write(&[v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]);
    }
    pub fn get(&self) -> Vec3 {
        let (w, _) = self.0.read();
        Vec3::new(f64::from_bits(w[0]), f64::from_bits(w[1]), f64::from_bits(w[2]))
    }
}

/// What the servo publishes each tick (world frame of the model; SI units).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Snapshot {
    /// Ticks done, and the simulated time \[s\] (`tick * dt`).
    pub tick: u64,
    pub time: f64,
    /// The device's position \[m\].
    pub device: Vec3,
    /// The simulated tool (the coupling's proxy) \[m\].
    pub tool: Vec3,
    /// The force sent to the device \[N\] (after the safety layer), and the coupling's force
    /// before it.
    pub force: Vec3,
    pub raw_force: Vec3,
    /// The tissue's force on the simulated tool \[N\].
    pub tissue_force: Vec3,
    /// The last tick's period (start to start) and compute time \[s\].
    pub period: f64,
    pub compute: f64,
    /// Overruns so far (ticks that ended after their deadline) and faults so far.
    pub overruns: u64,
    pub faults: u64,
    /// The device's buttons (bit mask).
    pub buttons: u32,
    /// The multirate loop's physics ticks so far (its rate: their change over the wall time);
    /// the single-rate loop's are its ticks.
    pub physics_ticks: u64,
}

/// Words in a [`Snapshot`].
pub const SNAPSHOT_WORDS: usize = 24;

impl Snapshot {
    pub(crate) fn to_words(self) -> [u64; SNAPSHOT_WORDS] {
        let mut w = [0u64; SNAPSHOT_WORDS];
        w[0] = self.tick;
        w[1] = self.time.to_bits();
        for (k, v) in [&self.device, &self.tool, &self.force, &self.raw_force, &self.tissue_force].into_iter().enumerate() {
            for i in 0..3 {
                w[2 + 3 * k + i] = v[i].to_bits();
            }
        }
        w[17] = self.period.to_bits();
        w[18] = self.compute.to_bits();
        w[19] = self.overruns;
        w[20] = self.faults;
        w[21] = self.buttons as u64;
        w[22] = self.physics_ticks;
        w
    }

    pub(crate) fn from_words(w: &[u64; SNAPSHOT_WORDS]) -> Snapshot {
        let v = |k: usize| Vec3::new(f64::from_bits(w[2 + 3 * k]), f64::from_bits(w[3 + 3 * k]), f64::from_bits(w[4 + 3 * k]));
        Snapshot {
            tick: w[0],
            time: f64::from_bits(w[1]),
            device: v(0),
            tool: v(1),
            force: v(2),
            raw_force: v(3),
            tissue_force: v(4),
            period: f64::from_bits(w[17]),
            compute: f64::from_bits(w[18]),
            overruns: w[19],
            faults: w[20],
            buttons: w[21] as u32,
            physics_ticks: w[22],
        }
    }
}

/// The servo's published [`Snapshot`].
#[derive(Debug, Default)]
pub struct SnapshotCell(SeqLock<SNAPSHOT_WORDS>);

impl SnapshotCell {
    pub(crate) fn publish(&self, s: &Snapshot) {
        self.0.write(&s.to_words());
    }
    /// The latest snapshot (`None` before the first tick).
    pub fn latest(&self) -> Option<Snapshot> {
        let (w, seq) = self.0.read();
        (seq != 0).then(|| Snapshot::from_words(&w))
    }
}

/// A latest-only mailbox for a large snapshot (the organ's surface, or its core and active
/// particles, for a viewer): the writer copies into the shared slot only if no reader holds it
/// (`try_lock`), so it never waits; a reader clones the slot out. A publish a reader is copying
/// from is skipped (the next one lands): the loop's rule is that it never blocks, not that every
/// frame is seen. Reads are counted ([`Mailbox::reads`]), so that the writer can tell whether
/// anyone is looking (the servo publishes rarely when nobody is: see `ServoConfig::surface_every`).
#[derive(Debug, Default)]
pub struct Mailbox {
    slot: Mutex<Slot>,
    /// Any length up to the capacity ([`Mailbox::up_to`]), or exactly it ([`Mailbox::new`]).
    variable: bool,
    reads: AtomicU64,
}

#[derive(Debug, Default)]
struct Slot {
    tick: u64,
    len: usize,
    points: Vec<Vec3>,
}

impl Mailbox {
    /// A mailbox for exactly `n` points (allocated now: a publish only copies); before the first
    /// publish it holds `n` zeros.
    pub fn new(n: usize) -> Mailbox {
        Mailbox { slot: Mutex::new(Slot { tick: 0, len: n, points: vec![Vec3::zeros(); n] }), variable: false, reads: AtomicU64::new(0) }
    }
    /// A mailbox for up to `capacity` points (allocated now); empty before the first publish.
    pub fn up_to(capacity: usize) -> Mailbox {
        Mailbox {
            slot: Mutex::new(Slot { tick: 0, len: 0, points: vec![Vec3::zeros(); capacity] }),
            variable: true,
            reads: AtomicU64::new(0),
        }
    }
    /// Publishes `points` as of tick `tick` unless a reader holds the slot or the length does not
    /// fit (not the mailbox's length, or over its capacity); returns whether it did. Never blocks,
    /// never allocates.
    pub fn publish(&self, tick: u64, points: &[Vec3]) -> bool {
        match self.slot.try_lock() {
            Ok(mut g) if points.len() == g.points.len() || (self.variable && points.len() <= g.points.len()) => {
                g.tick = tick;
                g.len = points.len();
                g.points[..points.len()].copy_from_slice(points);
                true
            }
            _ => false,
        }
    }
    /// Publishes what `fill` writes straight into the slot (no copy of the writer's own):
    /// `fill` gets the whole slot (the mailbox's length, or its capacity) and returns how many
    /// points it wrote (a fixed-length mailbox publishes the whole slot whatever it returns).
    /// Skipped, `fill` not called, when a reader holds the slot. Never blocks, never allocates.
    pub fn publish_with(&self, tick: u64, fill: impl FnOnce(&mut [Vec3]) -> usize) -> bool {
        match self.slot.try_lock() {
            Ok(mut g) => {
                let n = fill(&mut g.points);
                g.len = if self.variable { n.min(g.points.len()) } else { g.points.len() };
                g.tick = tick;
                true
            }
            Err(_) => false,
        }
    }
    /// The last published points and their tick (tick 0: nothing published yet).
    pub fn latest(&self) -> (u64, Vec<Vec3>) {
        self.reads.fetch_add(1, Ordering::Relaxed);
        let g = self.slot.lock().unwrap_or_else(|e| e.into_inner());
        (g.tick, g.points[..g.len].to_vec())
    }
    /// How many times [`Mailbox::latest`] has been called.
    pub fn reads(&self) -> u64 {
        self.reads.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A torn read would see words from two writes: each record here has all words equal.
    #[test]
    fn readers_never_see_a_torn_record() {
        let lock = Arc::new(SeqLock::<16>::default());
        let w = lock.clone();
        let writer = std::thread::spawn(move || {
            for k in 1..=200_000u64 {
                w.write(&[k; 16]);
            }
        });
        let mut last = 0;
        while !writer.is_finished() {
            let (words, _) = lock.read();
            assert!(words.iter().all(|&x| x == words[0]), "torn read: {words:?}");
            assert!(words[0] >= last, "went back in time");
            last = words[0];
        }
        writer.join().unwrap();
        assert_eq!(lock.read().0, [200_000; 16]);
    }

    /// Two writers (the servo and the watchdog both send forces): with plain stores, one writer
    /// reading the other's odd sequence and both adding 2 left it odd for good (every reader then
    /// spun forever). Each record is whole, and the sequence ends even, 2 per write.
    #[test]
    fn two_writers_never_leave_the_lock_half_written() {
        let lock = Arc::new(SeqLock::<4>::default());
        let writers: Vec<_> = (0..2u64)
            .map(|id| {
                let w = lock.clone();
                std::thread::spawn(move || {
                    for k in 0..100_000u64 {
                        w.write(&[2 * k + id; 4]);
                    }
                })
            })
            .collect();
        while !writers.iter().all(|w| w.is_finished()) {
            let (words, seq) = lock.read();
            assert!(words.iter().all(|&x| x == words[0]), "torn read: {words:?}");
            assert_eq!(seq % 2, 0);
        }
        for w in writers {
            w.join().unwrap();
        }
        assert_eq!(lock.seq.load(Ordering::Acquire), 2 * 200_000, "a write was lost or left half done");
    }

    #[test]
    fn mailbox_never_blocks_the_writer() {
        let m = Mailbox::new(4);
        assert_eq!(m.latest().0, 0);
        assert!(m.publish(3, &[Vec3::x(); 4]));
        let held = m.slot.lock().unwrap();
        assert!(!m.publish(4, &[Vec3::y(); 4]), "a reader holds the slot: skip, do not wait");
        drop(held);
        assert_eq!(m.latest(), (3, vec![Vec3::x(); 4]));
        assert!(!m.publish(5, &[Vec3::y(); 3]), "wrong length: refused");
    }

    #[test]
    fn a_variable_mailbox_holds_any_length_up_to_its_capacity() {
        let m = Mailbox::up_to(4);
        assert_eq!(m.latest(), (0, vec![]));
        assert!(m.publish(1, &[Vec3::x(); 3]));
        assert_eq!(m.latest(), (1, vec![Vec3::x(); 3]));
        assert!(m.publish(2, &[Vec3::y(); 1]), "shorter than the last: only its points are read");
        assert_eq!(m.latest(), (2, vec![Vec3::y()]));
        assert!(!m.publish(3, &[Vec3::z(); 5]), "over the capacity: refused");
        assert_eq!(m.latest().0, 2);
    }

    #[test]
    fn snapshot_round_trips() {
        let s = Snapshot {
            tick: 7,
            time: 0.007,
            device: Vec3::new(1.0, 2.0, 3.0),
            tool: Vec3::new(-1.0, 0.5, 1e-9),
            force: Vec3::new(0.1, 0.2, 0.3),
            raw_force: Vec3::new(4.0, 5.0, 6.0),
            tissue_force: Vec3::new(7.0, 8.0, 9.0),
            period: 1e-3,
            compute: 2e-4,
            overruns: 3,
            faults: 1,
            buttons: 5,
            physics_ticks: 11,
        };
        assert_eq!(Snapshot::from_words(&s.to_words()), s);
    }
}
