//! The probe load and the probe run: the one definition of the benchmark protocol's load
//! (`shared/bench/PROTOCOL.md`: a total force shared evenly by the loaded nodes, ramped linearly
//! from zero) and of the run that steps a body under it and measures what the protocol reports.
//! The binding's `Body.run_probe`, the scene runner, the examples, the benches and the tests all
//! call these, so they sample the ramp at the same instants and agree on every statistic.
//!
//! **Ramp convention.** The step from `t` to `t + dt` carries the load at its *end*,
//! `t + dt`: backward Euler evaluates the forces at the end of the step, and the shared Python
//! protocol (`shared/bench/common.py`) does the same. A ramp starts at a stated time (a run's
//! start, so that a second run on a stepped body ramps again).
//!
//! The core has no clocks: a run is timed by a [`StepClock`] the caller passes in (the binding
//! and the examples pass a wall clock; tests pass [`NoClock`]), read just before and just after
//! each step so that the bookkeeping is not timed.

use crate::error::LoadError;
use crate::fem::{Model, State, Workspace};
use crate::integrate::{step, StepReport};
use crate::math::Vec3;

/// A linear ramp from zero at `start` to one at `start + duration` \[s\], one after.
/// A zero `duration` applies the load at once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ramp {
    /// When the ramp begins \[s\] (simulated time).
    pub start: f64,
    /// How long it takes to reach the full load \[s\], `>= 0`.
    pub duration: f64,
}

impl Ramp {
    /// The load factor in `[0, 1]` at time `t` \[s\].
    pub fn at(&self, t: f64) -> f64 {
        if self.duration > 0.0 {
            ((t - self.start) / self.duration).clamp(0.0, 1.0)
        } else if t >= self.start {
            1.0
        } else {
            0.0
        }
    }
}

/// A total force \[N\] (world frame) shared evenly by a set of nodes, ramped by a [`Ramp`].
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeLoad {
    nodes: Vec<usize>,
    total: Vec3,
    ramp: Ramp,
}

impl ProbeLoad {
    /// Checks the load against a body of `n_nodes` nodes: at least one node, every index in
    /// range, a finite force, a finite ramp with `duration >= 0`.
    pub fn new(n_nodes: usize, nodes: Vec<usize>, total_force: Vec3, ramp: Ramp) -> Result<ProbeLoad, LoadError> {
        if nodes.is_empty() {
            return Err(LoadError::NoNodes);
        }
        if let Some((index, &node)) = nodes.iter().enumerate().find(|(_, &i)| i >= n_nodes) {
            return Err(LoadError::NodeOutOfRange { index, node, n_nodes });
        }
        if !(total_force.x.is_finite() && total_force.y.is_finite() && total_force.z.is_finite()) {
            return Err(LoadError::NonFiniteForce);
        }
        if !crate::limits::force_in_bound(&total_force) {
            return Err(LoadError::ForceTooLarge { norm: crate::limits::force_magnitude(&total_force) });
        }
        if !(ramp.duration >= 0.0 && ramp.duration.is_finite() && ramp.start.is_finite()) {
            return Err(LoadError::BadRamp { start: ramp.start, duration: ramp.duration });
        }
        Ok(ProbeLoad { nodes, total: total_force, ramp })
    }

    /// The loaded nodes.
    pub fn nodes(&self) -> &[usize] {
        &self.nodes
    }

    /// The total force at full load \[N\].
    pub fn total_force(&self) -> Vec3 {
        self.total
    }

    /// The ramp.
    pub fn ramp(&self) -> Ramp {
        self.ramp
    }

    /// The force on each loaded node at time `t` \[N\].
    pub fn per_node(&self, t: f64) -> Vec3 {
        self.total * (self.ramp.at(t) / self.nodes.len() as f64)
    }

    /// Adds this load at time `t` to `f_ext` (`(n_nodes)`, \[N\]).
    pub fn add_to(&self, f_ext: &mut [Vec3], t: f64) {
        let f = self.per_node(t);
        for &i in &self.nodes {
            f_ext[i] += f;
        }
    }
}

/// Sets `f_ext` to the sum of `loads` for the step that ends at `t_end` \[s\] (the ramp
/// convention of this module); nodes under no load get zero.
pub fn apply_loads(loads: &[ProbeLoad], f_ext: &mut [Vec3], t_end: f64) {
    f_ext.iter_mut().for_each(|f| *f = Vec3::zeros());
    for load in loads {
        load.add_to(f_ext, t_end);
    }
}

/// A clock read around each step of a run \[s\]; any origin.
pub trait StepClock {
    /// Seconds since an arbitrary origin.
    fn now(&mut self) -> f64;
}

/// A clock that never advances: runs untimed (tests, or runs whose time is not wanted).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoClock;

impl StepClock for NoClock {
    fn now(&mut self) -> f64 {
        0.0
    }
}

/// How a probe run goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeOptions {
    /// Steps to take.
    pub steps: usize,
    /// Time step \[s\].
    pub dt: f64,
    /// A run is called unstable once any node's displacement reaches this \[m\] (it goes on).
    pub stable_limit: f64,
    /// A run stops once any node's displacement exceeds this \[m\] (a blow-up).
    pub blow_up: f64,
    /// A run stops once its stepping time exceeds this \[s\] (by the run's clock).
    pub max_wall_s: Option<f64>,
}

impl ProbeOptions {
    /// A blow-up is a displacement over 1 m: no soft-tissue press gets there.
    pub const BLOW_UP: f64 = 1.0;

    /// `steps` steps of `dt`, stable below `stable_limit` \[m\], no wall-clock cap.
    pub fn new(steps: usize, dt: f64, stable_limit: f64) -> ProbeOptions {
        ProbeOptions { steps, dt, stable_limit, blow_up: Self::BLOW_UP, max_wall_s: None }
    }
}

/// Sums of [`StepReport`]s over several steps.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepTotals {
    /// Steps taken.
    pub steps: usize,
    /// Nonlinear iterations, summed, and the most in one step.
    pub iterations: usize,
    pub max_iterations: usize,
    /// Force evaluations, summed.
    pub evaluations: usize,
    /// Sparse factorisations, summed.
    pub factorizations: usize,
    /// Solves with the factorised matrix, summed.
    pub solves: usize,
    /// Steps that did not meet their tolerance.
    pub unconverged: usize,
    /// The largest final relative gradient.
    pub max_residual: f64,
    /// The most inverted elements after a step.
    pub max_inverted: usize,
    /// The last step's report.
    pub last: StepReport,
}

impl StepTotals {
    /// Adds one step's report.
    pub fn add(&mut self, r: &StepReport) {
        self.steps += 1;
        self.iterations += r.iterations;
        self.max_iterations = self.max_iterations.max(r.iterations);
        self.evaluations += r.evaluations;
        self.factorizations += r.factorizations;
        self.solves += r.solves;
        self.unconverged += !r.converged as usize;
        self.max_residual = self.max_residual.max(r.residual);
        self.max_inverted = self.max_inverted.max(r.inverted);
        self.last = *r;
    }

    /// Mean iterations per step (NaN before any step).
    pub fn mean_iterations(&self) -> f64 {
        if self.steps > 0 {
            self.iterations as f64 / self.steps as f64
        } else {
            f64::NAN
        }
    }
}

/// How many steps' records [`run_probe`] reserves before its first step (the usual benchmark runs
/// fit, so their steps do not allocate); further records grow the arrays as steps are taken.
pub const RESERVE_STEPS: usize = 1 << 16;

/// Why a run stopped before its last step.
#[derive(Debug, Clone, PartialEq)]
pub enum ProbeStop {
    /// A step failed (the state is as it was before that step).
    Step { step: usize, steps: usize, error: crate::error::StepError },
    /// A displacement was non-finite or over [`ProbeOptions::blow_up`].
    BlewUp { step: usize, steps: usize, max_disp: f64 },
    /// The stepping time passed [`ProbeOptions::max_wall_s`].
    WallCap { step: usize, steps: usize, cap: f64 },
    /// The per-step records would have grown past the memory budget
    /// ([`crate::limits::max_memory`], `PALPATE_MAX_MEMORY`): a run of billions of steps stops
    /// with the steps it took rather than abort the process when memory runs out.
    RecordBudget { step: usize, steps: usize, budget: u64 },
}

impl std::fmt::Display for ProbeStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ProbeStop::Step { step, steps, error } => write!(f, "step {step} of {steps}: {error}"),
            ProbeStop::BlewUp { step, steps, max_disp } => write!(f, "blew up at step {step} of {steps}: max |u| = {max_disp:.3e} m"),
            ProbeStop::WallCap { step, steps, cap } => write!(f, "stopped after {step} of {steps} steps: wall-clock cap of {cap} s reached"),
            ProbeStop::RecordBudget { step, steps, budget } => write!(
                f,
                "stopped after {step} of {steps} steps: the per-step records would grow past the memory budget of {} (raise it with PALPATE_MAX_MEMORY, or run fewer steps at a time)",
                crate::limits::human_bytes(*budget as f64)
            ),
        }
    }
}

/// What a probe run measured. Displacements are from the rest positions \[m\].
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeRun {
    /// Steps taken.
    pub steps: usize,
    /// Stepping time by the run's clock \[s\] (bookkeeping excluded).
    pub wall_s: f64,
    /// Each step's time \[s\], `(steps)`.
    pub step_s: Vec<f64>,
    /// No displacement reached `stable_limit` and every one stayed finite.
    pub stable: bool,
    /// The largest node displacement over the run \[m\].
    pub max_disp: f64,
    /// Mean displacement magnitude of the loaded nodes after each step \[m\], `(steps)`.
    pub probe_disp: Vec<f64>,
    /// Mean of `probe_disp` over the second half of the steps taken \[m\] (NaN with none).
    pub probe_disp_avg: f64,
    /// Mean displacement of each node over the second half of the requested steps \[m\],
    /// `(n_nodes)` (the load is constant there in the protocol).
    pub mean_disp: Vec<Vec3>,
    /// The step reports, summed.
    pub totals: StepTotals,
    /// Why the run stopped early, if it did.
    pub stop: Option<ProbeStop>,
}

/// Steps `state` `opts.steps` times under `loads` (every other external force is zeroed), the
/// load of each step taken at its end (module docs), and measures the run. Never panics: a
/// failing step, a blow-up or the wall-clock cap stops the run and is reported in
/// [`ProbeRun::stop`]. The per-step records grow as the steps are taken (reserved up to
/// [`RESERVE_STEPS`] ahead): a requested count of 1e11 steps costs nothing until it is run
/// (reserving it up front aborted the process), a run stopped by its wall-clock cap holds only
/// the steps it took, and records that would outgrow the memory budget stop the run
/// ([`ProbeStop::RecordBudget`]) instead of exhausting memory.
pub fn run_probe(model: &Model, state: &mut State, ws: &mut Workspace, loads: &[ProbeLoad], opts: &ProbeOptions, clock: &mut dyn StepClock) -> ProbeRun {
    let steps = opts.steps;
    let rest = model.mesh().points();
    let loaded: Vec<usize> = loads.iter().flat_map(|l| l.nodes.iter().copied()).collect();
    let half = steps / 2;
    let mut out = ProbeRun {
        steps: 0,
        wall_s: 0.0,
        step_s: Vec::with_capacity(steps.min(RESERVE_STEPS)),
        stable: true,
        max_disp: 0.0,
        probe_disp: Vec::with_capacity(steps.min(RESERVE_STEPS)),
        probe_disp_avg: f64::NAN,
        mean_disp: vec![Vec3::zeros(); model.n_nodes()],
        totals: StepTotals::default(),
        stop: None,
    };
    let mut n_mean = 0usize;
    for k in 0..steps {
        // The records grow by doubling: before a growth, check that the doubled arrays fit the
        // memory budget (a check per doubling, not per step), else stop as a wall-clock cap does.
        if out.step_s.len() == out.step_s.capacity() {
            // Two records (`step_s`, `probe_disp`) of f64, each about to double.
            if let Err(e) = crate::limits::check("the run's per-step records", 4.0 * out.step_s.capacity().max(1) as f64, 8.0) {
                out.stop = Some(ProbeStop::RecordBudget { step: k, steps, budget: e.budget });
                break;
            }
        }
        apply_loads(loads, &mut state.f_ext, state.t + opts.dt);
        let t0 = clock.now();
        let r = step(model, state, ws, opts.dt);
        let elapsed = clock.now() - t0;
        out.wall_s += elapsed;
        let r = match r {
            Ok(r) => r,
            Err(error) => {
                out.stop = Some(ProbeStop::Step { step: k + 1, steps, error });
                out.stable = false;
                break;
            }
        };
        out.step_s.push(elapsed);
        out.totals.add(&r);
        out.steps += 1;
        let mut umax: f64 = 0.0;
        let mut finite = true;
        for (x, x0) in state.x.iter().zip(rest) {
            let u = (x - x0).norm();
            finite &= u.is_finite();
            umax = umax.max(u);
        }
        let probe = if loaded.is_empty() {
            0.0
        } else {
            loaded.iter().map(|&i| (state.x[i] - rest[i]).norm()).sum::<f64>() / loaded.len() as f64
        };
        out.probe_disp.push(probe);
        out.max_disp = out.max_disp.max(umax);
        if !finite || !(umax < opts.stable_limit) {
            out.stable = false;
        }
        if k >= half {
            for ((m, x), x0) in out.mean_disp.iter_mut().zip(&state.x).zip(rest) {
                *m += x - x0;
            }
            n_mean += 1;
        }
        if !finite || umax > opts.blow_up {
            out.stop = Some(ProbeStop::BlewUp { step: k + 1, steps, max_disp: umax });
            break;
        }
        if let Some(cap) = opts.max_wall_s {
            if out.wall_s > cap && k + 1 < steps {
                out.stop = Some(ProbeStop::WallCap { step: k + 1, steps, cap });
                break;
            }
        }
    }
    if n_mean > 0 {
        out.mean_disp.iter_mut().for_each(|m| *m /= n_mean as f64);
    }
    let second = &out.probe_disp[out.probe_disp.len() / 2..];
    if !second.is_empty() {
        out.probe_disp_avg = second.iter().sum::<f64>() / second.len() as f64;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_is_linear_from_its_start_and_held_after() {
        let r = Ramp { start: 0.5, duration: 0.1 };
        assert_eq!(r.at(0.4), 0.0);
        assert_eq!(r.at(0.5), 0.0);
        assert!((r.at(0.55) - 0.5).abs() < 1e-12);
        assert!((r.at(0.6) - 1.0).abs() < 1e-12);
        assert_eq!(r.at(9.0), 1.0);
        let now = Ramp { start: 0.0, duration: 0.0 };
        assert_eq!(now.at(0.0), 1.0);
        assert_eq!(now.at(-1e-9), 0.0);
    }

    #[test]
    fn load_is_shared_evenly_and_checked() {
        let l = ProbeLoad::new(5, vec![1, 3], Vec3::new(0.0, 0.0, -2.0), Ramp { start: 0.0, duration: 0.2 }).unwrap();
        let mut f = vec![Vec3::new(1.0, 0.0, 0.0); 5];
        apply_loads(std::slice::from_ref(&l), &mut f, 0.1);
        assert_eq!(f[0], Vec3::zeros());
        assert_eq!(f[1], Vec3::new(0.0, 0.0, -0.5));
        assert_eq!(f[3], Vec3::new(0.0, 0.0, -0.5));
        assert_eq!(f.iter().sum::<Vec3>(), Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(ProbeLoad::new(5, vec![], Vec3::zeros(), l.ramp()), Err(LoadError::NoNodes));
        assert_eq!(ProbeLoad::new(5, vec![0, 5], Vec3::zeros(), l.ramp()), Err(LoadError::NodeOutOfRange { index: 1, node: 5, n_nodes: 5 }));
        assert_eq!(ProbeLoad::new(5, vec![0], Vec3::new(f64::NAN, 0.0, 0.0), l.ramp()), Err(LoadError::NonFiniteForce));
        assert!(matches!(ProbeLoad::new(5, vec![0], Vec3::zeros(), Ramp { start: 0.0, duration: -1.0 }), Err(LoadError::BadRamp { .. })));
    }
}
