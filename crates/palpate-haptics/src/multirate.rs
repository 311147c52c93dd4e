//! Multirate rendering: the servo never waits for the physics.
//!
//! With [`crate::ServoConfig::physics_rate_hz`] set, the loop runs on two threads:
//! - the **physics thread** ticks the simulation on its own clock (1 ms nominal) with the tool at
//!   the proxy the servo last published, and after each tick publishes a [`LocalModel`]: the
//!   tissue's force on the tool, the tool's position, and the stiffness `K = -dF/dx` \[N/m\]
//!   (3x3, symmetric, positive semi-definite) that extrapolates it;
//! - the **servo thread** renders every period (250 Hz-4 kHz) from the latest model, whatever
//!   the physics is doing: the proxy moves against `F0 - K (x - x0)` through the virtual
//!   coupling, implicitly ([`crate::VirtualCoupling::step_local`]), then the safety layer.
//!
//! Neither thread ever blocks the other: the model and the proxy cross through seqlocks
//! ([`ModelCell`], [`crate::Vec3Cell`]); nothing in the servo's period allocates or locks.
//! This is the literature's multirate local model (Cavusoglu and Tendick 2000; Otaduy and Lin
//! 2005); SOFA's LCPForceFeedback and OpenSurgSim's device-side extrapolation are its relatives.
//!
//! # The stiffness: a secant of the physics itself
//! The physics' force at the tool depends on the tool through the contact (penalty springs of
//! 60 N/m a point, thousands of N/m summed) in series with the tissue under it (a few hundred).
//! The contact's analytic Jacobian is the stiffness of a *frozen* tissue: used as the local
//! model it would render a surface ten times too hard between physics ticks, then drop back at
//! each (a sawtooth the hand feels). What the model needs is what the physics will answer at the
//! next tick, so [`StiffnessEstimate`] takes it from the physics' own answers: a Broyden rank-one
//! update of `K` from each tick's change of tool position and force (`-dF = K dx`), made
//! symmetric and projected on `[0, k_max]` (positive semi-definite: a local model that is a
//! conservative spring cannot put energy into the hand between ticks; an underestimate would be
//! the zero-order hold's lag, which is active). Moves under [`SECANT_MIN_STEP`] are ignored (a
//! held press: the change of force is the tissue's relaxation, not a stiffness); out of contact
//! `K = 0`.
//!
//! # Fades ([`fade`])
//! - **Physics stall.** A model older than half the safety's `stall_timeout` (15 ms at the
//!   default 30 ms; two physics periods if that is longer, at most 90% of the timeout) fades linearly, force and stiffness, to zero at `stall_timeout`: a stalled
//!   physics thread leaves no force on the hand 30 ms after its last tick, and the servo keeps
//!   its period throughout. The next model restarts the safety ramp.
//! - **Device silence** (both loops, [`crate::HapticCore`]): no new device sample for the
//!   safety's `silence` (50 ms) fades the force to zero over [`SILENCE_FADE`] (30 ms); it is
//!   logged ([`crate::Fault::DeviceSilent`]); a device that comes back resumes through the ramp.
//!
//! # Determinism
//! The physics consumes the proxy positions in the order it read them: [`PhysicsLoop`] records
//! them (its `targets`), and the same targets through the same physics give the same models bit
//! for bit. Offline ([`crate::HapticCore::run_offline_multirate`]) the physics ticks every
//! `rate / physics_rate` servo ticks with the proxy of that tick and its model is seen by the
//! next servo tick, with no clock at all.

use palpate_core::{Mat3, Vec3};

use crate::physics::Physics;
use crate::servo::{Fault, FaultRecord, FAULT_LOG};
use crate::snapshot::SeqLock;

/// The fade of a device's silence to zero force \[s\], after the safety's `silence`.
pub const SILENCE_FADE: f64 = 0.030;

/// Moves of the tool shorter than this \[m\] between two physics ticks do not update the
/// stiffness (see the module docs).
pub const SECANT_MIN_STEP: f64 = 2e-6;

/// The largest stiffness a local model holds \[N/m\]: above any tissue's under a tool (a few
/// hundred to a few thousand N/m) and the device's renderable range; the coupling (300 N/m by
/// default) is what the hand feels in series with it.
pub const MAX_LOCAL_STIFFNESS: f64 = 2.0e4;

/// Physics rates accepted \[Hz\] (at most the servo's rate).
pub const MIN_PHYSICS_RATE_HZ: f64 = 100.0;

/// What the physics publishes after each of its ticks (SI units, world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalModel {
    /// The physics tick that made it (0: none yet).
    pub tick: u64,
    /// The simulated tool's centre at that tick \[m\].
    pub tool: Vec3,
    /// The tissue's force on the tool there \[N\].
    pub force: Vec3,
    /// `K = -dF/dx` \[N/m\]: symmetric, positive semi-definite.
    pub stiffness: Mat3,
    /// The physics' faults so far (a change tells the servo to take the fault path).
    pub faults: u64,
}

impl Default for LocalModel {
    fn default() -> Self {
        LocalModel { tick: 0, tool: Vec3::zeros(), force: Vec3::zeros(), stiffness: Mat3::zeros(), faults: 0 }
    }
}

impl LocalModel {
    /// The model's force on a tool at `x` \[m\]: `F0 - K (x - x0)` \[N\].
    pub fn force_at(&self, x: &Vec3) -> Vec3 {
        self.force - self.stiffness * (x - self.tool)
    }
}

const MODEL_WORDS: usize = 1 + 3 + 3 + 6 + 1;

/// A latest-only [`LocalModel`] (a seqlock: the physics writes, the servo reads, neither waits).
#[derive(Debug, Default)]
pub struct ModelCell(SeqLock<MODEL_WORDS>);

impl ModelCell {
    pub fn publish(&self, m: &LocalModel) {
        let k = &m.stiffness;
        let f = |v: f64| v.to_bits();
        self.0.write(&[
            m.tick,
            f(m.tool.x),
            f(m.tool.y),
            f(m.tool.z),
            f(m.force.x),
            f(m.force.y),
            f(m.force.z),
            f(k[(0, 0)]),
            f(k[(0, 1)]),
            f(k[(0, 2)]),
            f(k[(1, 1)]),
            f(k[(1, 2)]),
            f(k[(2, 2)]),
            m.faults,
        ]);
    }
    /// The latest model (tick 0 before the first).
    pub fn latest(&self) -> LocalModel {
        let (w, _) = self.0.read();
        let g = |i: usize| f64::from_bits(w[i]);
        let stiffness = Mat3::new(g(7), g(8), g(9), g(8), g(10), g(11), g(9), g(11), g(12));
        LocalModel { tick: w[0], tool: Vec3::new(g(1), g(2), g(3)), force: Vec3::new(g(4), g(5), g(6)), stiffness, faults: w[13] }
    }
}

/// A linear fade: 1 up to `start`, 0 from `end` \[s\], linear between.
pub fn fade(t: f64, start: f64, end: f64) -> f64 {
    if t <= start {
        1.0
    } else if t >= end {
        0.0
    } else {
        1.0 - (t - start) / (end - start)
    }
}

/// A weight that follows a [`fade`] down at once and back up no faster than the fade's own
/// slope: a model or a device back after a partial fade brings the force back over
/// milliseconds, not in a step (0.44-0.49 N in a period before, 2026-12-06).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Recovering {
    weight: f64,
}

impl Default for Recovering {
    fn default() -> Self {
        Recovering { weight: 1.0 }
    }
}

impl Recovering {
    /// The weight after a period of `dt` \[s\] whose fade value is `target` (0..1), for a fade
    /// that takes `duration` \[s\] from 1 to 0.
    pub fn follow(&mut self, target: f64, dt: f64, duration: f64) -> f64 {
        let w = if target < self.weight { target } else { target.min(self.weight + dt / duration) };
        self.weight = w;
        w
    }
}

/// The local stiffness from the physics' own answers (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffnessEstimate {
    k: Mat3,
    last: Option<(Vec3, Vec3)>,
    /// The upper bound of `K`'s eigenvalues \[N/m\].
    pub k_max: f64,
}

impl Default for StiffnessEstimate {
    fn default() -> Self {
        StiffnessEstimate { k: Mat3::zeros(), last: None, k_max: MAX_LOCAL_STIFFNESS }
    }
}

impl StiffnessEstimate {
    /// Forgets the history (after a fault).
    pub fn reset(&mut self) {
        (self.k, self.last) = (Mat3::zeros(), None);
    }

    /// The stiffness after a tick that left the tool at `tool` \[m\] with force `force` \[N\].
    pub fn update(&mut self, tool: &Vec3, force: &Vec3) -> Mat3 {
        if *force == Vec3::zeros() {
            // Out of contact: free space has no stiffness; the next contact starts from a secant
            // through this point (force zero).
            self.k = Mat3::zeros();
            self.last = Some((*tool, *force));
            return self.k;
        }
        if let Some((x0, f0)) = self.last {
            let dx = tool - x0;
            let n2 = dx.norm_squared();
            if n2 >= SECANT_MIN_STEP * SECANT_MIN_STEP {
                // Broyden: the smallest change of K that explains -dF = K dx.
                let r = -(force - f0) - self.k * dx;
                let k = self.k + r * dx.transpose() / n2;
                self.k = project(&(0.5 * (k + k.transpose())), self.k_max);
                self.last = Some((*tool, *force));
            }
            // A smaller move keeps the older point: the secant spans the moves' sum.
        } else {
            self.last = Some((*tool, *force));
        }
        self.k
    }
}

/// The symmetric `k` with its eigenvalues clamped to `[0, k_max]` (zero for non-finite input).
fn project(k: &Mat3, k_max: f64) -> Mat3 {
    if !k.iter().all(|v| v.is_finite()) {
        return Mat3::zeros();
    }
    let e = k.symmetric_eigen();
    let d = e.eigenvalues.map(|l| l.clamp(0.0, k_max));
    let k = e.eigenvectors * Mat3::from_diagonal(&d) * e.eigenvectors.transpose();
    // Exactly symmetric (the product is only to round-off): the model crosses threads as its
    // upper triangle, and a replay must render from the same bits.
    0.5 * (k + k.transpose())
}

/// The physics side of the multirate loop: the simulation, its checkpoints, the stiffness
/// estimate and the targets it consumed.
pub struct PhysicsLoop {
    pub(crate) physics: Box<dyn Physics>,
    dt: f64,
    tick: u64,
    checkpoint_every: u64,
    estimate: StiffnessEstimate,
    faults: u64,
    fault_log: Vec<FaultRecord>,
    pub(crate) targets: Vec<Vec3>,
    targets_cap: usize,
    model: LocalModel,
}

impl PhysicsLoop {
    /// Ticks `physics` at `rate_hz`, a checkpoint every `checkpoint_every` ticks without a fault,
    /// recording up to `record` targets.
    pub fn new(mut physics: Box<dyn Physics>, rate_hz: f64, checkpoint_every: u64, record: usize) -> PhysicsLoop {
        // The first tick's factorisation now, not in the loop (a failure there is the first
        // tick's, which makes it again and counts the fault).
        let _ = physics.prepare(1.0 / rate_hz);
        PhysicsLoop {
            physics,
            dt: 1.0 / rate_hz,
            tick: 0,
            checkpoint_every: checkpoint_every.max(1),
            estimate: StiffnessEstimate::default(),
            faults: 0,
            fault_log: Vec::with_capacity(FAULT_LOG),
            targets: Vec::with_capacity(record),
            targets_cap: record,
            model: LocalModel::default(),
        }
    }

    /// One physics tick with the tool at `target` \[m\]: the model to publish. A failed or
    /// non-finite tick restores the last good state and gives a model with no force, its fault
    /// counted (the servo then zeroes the force and ramps again).
    pub fn tick(&mut self, target: &Vec3) -> LocalModel {
        self.tick += 1;
        if self.targets.len() < self.targets_cap {
            self.targets.push(*target);
        }
        let fault = match self.physics.tick(target, self.dt) {
            Ok(f) if f.iter().all(|c| c.is_finite()) => {
                let tool = self.physics.tool().unwrap_or(*target);
                let k = self.estimate.update(&tool, &f);
                self.model = LocalModel { tick: self.tick, tool, force: f, stiffness: k, faults: self.faults };
                return self.model;
            }
            Ok(_) => Fault::NonFinite,
            Err(e) => Fault::Step(e),
        };
        self.fault(fault, target)
    }

    /// The rest of the tick (the physics' `finish`), then a checkpoint when due. `Some` when that
    /// failed (or the state was found non-finite): the model to publish in place of the tick's.
    pub fn finish(&mut self) -> Option<LocalModel> {
        let target = self.model.tool;
        if let Err(e) = self.physics.finish() {
            return Some(self.fault(Fault::Step(e), &target));
        }
        if self.tick.is_multiple_of(self.checkpoint_every) && self.model.faults == self.faults {
            if !self.physics.is_finite() {
                return Some(self.fault(Fault::NonFinite, &target));
            }
            self.physics.checkpoint();
        }
        None
    }

    fn fault(&mut self, fault: Fault, target: &Vec3) -> LocalModel {
        self.physics.restore();
        self.estimate.reset();
        self.faults += 1;
        if self.fault_log.len() < FAULT_LOG {
            self.fault_log.push(FaultRecord { tick: self.tick, time: self.tick as f64 * self.dt, fault, counted: true });
        }
        let tool = self.physics.tool().unwrap_or(*target);
        self.model = LocalModel { tick: self.tick, tool, force: Vec3::zeros(), stiffness: Mat3::zeros(), faults: self.faults };
        self.model
    }

    /// The physics' ticks so far, and their length \[s\].
    pub fn ticks(&self) -> u64 {
        self.tick
    }
    pub fn dt(&self) -> f64 {
        self.dt
    }
    /// The last model made.
    pub fn model(&self) -> LocalModel {
        self.model
    }
    pub fn faults(&self) -> u64 {
        self.faults
    }
    pub fn fault_log(&self) -> &[FaultRecord] {
        &self.fault_log
    }
    /// The tool targets the physics consumed, in order (up to the recording's size): the same
    /// targets through the same physics give the same models bit for bit.
    pub fn targets(&self) -> &[Vec3] {
        &self.targets
    }
    pub fn physics(&self) -> &dyn Physics {
        self.physics.as_ref()
    }
    pub fn physics_mut(&mut self) -> &mut dyn Physics {
        self.physics.as_mut()
    }
    /// The proxy's largest speed \[m/s\] that keeps it one point with the simulated tool.
    pub fn tool_speed(&self) -> f64 {
        self.physics.max_tool_speed()
    }
}

/// The physics thread's timing summary (seconds).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PhysicsStats {
    /// The nominal rate \[Hz\] and the ticks per second achieved.
    pub rate_hz: f64,
    pub achieved_hz: f64,
    pub ticks: u64,
    pub elapsed: f64,
    /// A tick's compute (its tick and finish, with the checkpoint), wall clock.
    pub compute_p50: f64,
    pub compute_p99: f64,
    pub compute_max: f64,
    /// Ticks that started after their deadline (caught up: run at once) and deadlines dropped
    /// (a whole period or more behind: the schedule restarts from now, the rate lowered).
    pub late: u64,
    pub skipped: u64,
    /// How far behind its schedule a tick started \[s\]: p99 and largest.
    pub lag_p99: f64,
    pub lag_max: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_secant_finds_a_linear_spring_and_stays_psd() {
        // F = -K x with an anisotropic K: after moves in three directions the estimate is K.
        let k = Mat3::new(500.0, 50.0, 0.0, 50.0, 300.0, 0.0, 0.0, 0.0, 100.0);
        let mut e = StiffnessEstimate::default();
        let pts = [
            Vec3::new(1e-3, 0.0, 0.0),
            Vec3::new(1e-3, 1e-3, 0.0),
            Vec3::new(1e-3, 1e-3, 1e-3),
            Vec3::new(0.0, 1e-3, 1e-3),
            Vec3::new(2e-3, 0.0, 1e-3),
            Vec3::new(1e-3, 2e-3, 0.0),
        ];
        let mut est = Mat3::zeros();
        for _ in 0..30 {
            for p in &pts {
                est = e.update(p, &(-k * p + Vec3::new(0.0, 0.0, 0.2)));
            }
        }
        assert!((est - k).norm() < 1e-6 * k.norm(), "{est}");
        // A force that grows as the tool leaves (negative stiffness) is clamped to zero.
        let mut e = StiffnessEstimate::default();
        let f = |x: f64| Vec3::new(0.0, 0.0, 1.0 + 100.0 * x);
        e.update(&Vec3::new(0.0, 0.0, 0.0), &f(0.0));
        let est = e.update(&Vec3::new(0.0, 0.0, 1e-3), &f(1e-3));
        assert!(est.symmetric_eigenvalues().iter().all(|&l| l >= -1e-9), "{est}");
        // Tiny moves (a held press) leave it as it was; out of contact it is zero.
        let mut e = StiffnessEstimate::default();
        e.update(&Vec3::zeros(), &Vec3::new(0.0, 0.0, 0.5));
        let k1 = e.update(&Vec3::new(0.0, 0.0, -1e-4), &Vec3::new(0.0, 0.0, 0.52));
        assert!((k1[(2, 2)] - 200.0).abs() < 1e-6);
        let k2 = e.update(&Vec3::new(0.0, 0.0, -1.001e-4), &Vec3::new(0.0, 0.0, 0.49));
        assert_eq!(k1, k2);
        assert_eq!(e.update(&Vec3::zeros(), &Vec3::zeros()), Mat3::zeros());
    }

    #[test]
    fn the_model_cell_round_trips() {
        let c = ModelCell::default();
        assert_eq!(c.latest().tick, 0);
        let m = LocalModel {
            tick: 7,
            tool: Vec3::new(1.0, 2.0, 3.0),
            force: Vec3::new(-0.1, 0.2, 0.3),
            stiffness: Mat3::new(1.0, 2.0, 3.0, 2.0, 4.0, 5.0, 3.0, 5.0, 6.0),
            faults: 2,
        };
        c.publish(&m);
        assert_eq!(c.latest(), m);
        assert_eq!(m.force_at(&(m.tool + Vec3::new(0.0, 0.0, 1.0))), m.force - Vec3::new(3.0, 5.0, 6.0));
    }

    #[test]
    fn fades_are_linear_and_end_at_zero() {
        assert_eq!(fade(0.005, 0.01, 0.03), 1.0);
        assert!((fade(0.02, 0.01, 0.03) - 0.5).abs() < 1e-12);
        assert_eq!(fade(0.03, 0.01, 0.03), 0.0);
    }
}
