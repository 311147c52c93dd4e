//! Replay of a recorded interaction: the recorded device inputs, tick by tick, and a check of
//! the forces the loop renders from them against the recorded ones.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use palpate_core::Vec3;

use crate::device::{Device, DeviceInput, DeviceKind, ForceCell, ForceSink};
use crate::record::Recording;

/// Where a replay's forces first left the recording's (shared with the caller while it runs),
/// and what the recording says of why.
#[derive(Debug)]
pub struct ReplayCheck {
    /// The first tick whose sent force differs in any bit (`u64::MAX`: none yet).
    first: AtomicU64,
    /// The recording's first tick marked stalled, its fault count, its rate \[Hz\].
    first_stall: Option<usize>,
    faults: u64,
    rate_hz: f64,
}

impl ReplayCheck {
    /// The first tick whose force the replay did not reproduce bit for bit, if any.
    pub fn diverged_at(&self) -> Option<u64> {
        Some(self.first.load(Ordering::Relaxed)).filter(|&t| t != u64::MAX)
    }
    /// Where and why the replay left its recording (None: it did not).
    pub fn divergence(&self) -> Option<(u64, String)> {
        let tick = self.diverged_at()?;
        Some((tick, self.reason(tick)))
    }
    /// Why a replay that left its recording at `tick` did: a watchdog trip recorded at or before
    /// it (the physics stalled on the recording's machine, an event of its clock that no replay
    /// can reproduce), or nothing recorded to explain it.
    pub fn reason(&self, tick: u64) -> String {
        match self.first_stall.filter(|&k| k as u64 <= tick) {
            Some(k) => format!(
                "the recording's watchdog tripped at tick {k} (t = {:.4} s: the physics stalled on the machine that recorded it, which a replay cannot reproduce); the forces agree bit for bit before tick {tick}",
                k as f64 / self.rate_hz
            ),
            None if self.faults > 0 && self.first_stall.is_none() => format!(
                "the recording had {} fault(s) but marks none of its ticks (a recording made before 2026-12-06 does not say where its watchdog tripped); the forces agree bit for bit before tick {tick}",
                self.faults
            ),
            None => format!("nothing in the recording explains it (another build, model, or parameters than the recording's?); the forces agree bit for bit before tick {tick}"),
        }
    }
    fn note(&self, tick: u64) {
        let _ = self.first.compare_exchange(u64::MAX, tick, Ordering::Relaxed, Ordering::Relaxed);
    }
}

/// Gives a [`Recording`]'s inputs in order, and checks each force the loop sent against the
/// recorded one ([`Replay::check`]).
pub struct Replay {
    inputs: Vec<DeviceInput>,
    forces: Vec<Vec3>,
    sink: Arc<ForceCell>,
    check: Arc<ReplayCheck>,
}

impl Replay {
    pub fn new(recording: &Recording) -> Replay {
        Replay {
            inputs: recording.ticks.iter().map(|t| t.input).collect(),
            forces: recording.ticks.iter().map(|t| t.force).collect(),
            sink: Arc::new(ForceCell::default()),
            check: Arc::new(ReplayCheck {
                first: AtomicU64::new(u64::MAX),
                first_stall: recording.ticks.iter().position(|t| t.stalled),
                faults: recording.faults,
                rate_hz: recording.rate_hz,
            }),
        }
    }
    pub fn forces(&self) -> Arc<ForceCell> {
        self.sink.clone()
    }
    /// Where the replay's forces first differ from the recording's (read it after the run).
    pub fn check(&self) -> Arc<ReplayCheck> {
        self.check.clone()
    }
    /// Compares what the loop sent last (tick `tick`'s force, once `tick + 1` forces were sent)
    /// with the recording.
    fn compare(&self, tick: u64) {
        let bits = |v: &Vec3| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
        if let Some(recorded) = self.forces.get(tick as usize) {
            if self.sink.sent() == tick + 1 && bits(&self.sink.get()) != bits(recorded) {
                self.check.note(tick);
            }
        }
    }
}

impl Device for Replay {
    fn read(&mut self, tick: u64, _dt: f64) -> Option<DeviceInput> {
        if tick > 0 {
            self.compare(tick - 1);
        }
        // Past the end, hold the last sample (the servo stops there: `finished`).
        self.inputs.get(tick as usize).or(self.inputs.last()).copied()
    }
    fn sink(&self) -> Arc<dyn ForceSink> {
        self.sink.clone()
    }
    fn kind(&self) -> DeviceKind {
        DeviceKind::Simulated
    }
    fn finished(&self, ticks: u64, _dt: f64) -> bool {
        if ticks > 0 {
            self.compare(ticks - 1);
        }
        ticks as usize >= self.inputs.len()
    }
}
