//! The mutable simulation state and the preallocated scratch space of the step.

use super::model::Model;
use crate::error::StepError;
use crate::integrate::factor::{self, DtCache};
use crate::integrate::{CgWorkspace, Integrator, Lbfgs, PotentialWorkspace, StiffnessTerm};
use crate::linalg::Ldl;
use crate::math::{Mat3, Vec3};

/// Everything that changes while simulating: positions, velocities, time and applied forces.
/// All arrays are `(n_nodes)`, world frame, SI. `clone_from` reuses the destination's arrays (a
/// checkpoint of a running simulation allocates nothing).
#[derive(Debug, PartialEq)]
pub struct State {
    /// Node positions \[m\].
    pub x: Vec<Vec3>,
    /// Node velocities \[m/s\].
    pub v: Vec<Vec3>,
    /// Simulated time \[s\].
    pub t: f64,
    /// External force on each node \[N\], held constant over a step.
    pub f_ext: Vec<Vec3>,
}

impl Clone for State {
    fn clone(&self) -> Self {
        State { x: self.x.clone(), v: self.v.clone(), t: self.t, f_ext: self.f_ext.clone() }
    }
    fn clone_from(&mut self, s: &Self) {
        let State { x, v, t, f_ext } = self;
        x.clone_from(&s.x);
        v.clone_from(&s.v);
        *t = s.t;
        f_ext.clone_from(&s.f_ext);
    }
}

impl State {
    /// The body at rest: rest positions, zero velocity, zero time and no external force.
    pub fn rest(model: &Model) -> State {
        let n = model.n_nodes();
        State { x: model.rest_positions().to_vec(), v: vec![Vec3::zeros(); n], t: 0.0, f_ext: vec![Vec3::zeros(); n] }
    }

    /// Displacements from the rest positions \[m\].
    pub fn displacements(&self, model: &Model) -> Vec<Vec3> {
        self.x.iter().zip(model.rest_positions()).map(|(x, x0)| x - x0).collect()
    }
}

/// What a step carries over to the next besides [`State`] (the integrator's memory): which matrix
/// the workspace holds factorised and the quasi-Newton refresh rule's count. With the [`State`] it
/// makes the steps that follow bit-identical: [`Workspace::memory`] reads it,
/// [`Workspace::restore_memory`] remakes the factor from it. (The L-BFGS pairs and the CG vectors
/// start afresh every step, so they are not part of it.)
#[derive(Debug, Clone, PartialEq)]
pub struct StepMemory {
    /// The `dt` \[s\] the factor in use was made for (NaN: none yet).
    pub factored_dt: f64,
    /// Positions \[m\] `(n_nodes)`, world frame, at which the factor in use was refreshed with the
    /// definite tangent (`integrate/factor.rs`); `None`: it is the rest matrix for `factored_dt`.
    pub refreshed_at: Option<Vec<Vec3>>,
    /// Surplus iterations since the last factorisation (the refresh rule's count).
    pub excess_iterations: usize,
    /// The stiffness terms of the caller's potential ([`crate::integrate::CorePotential::stiffness_terms`])
    /// held in the factor when it was made (a refresh at `refreshed_at`, or, with it `None`, the
    /// rest matrix remade with them; empty for the rest factor as made), by increasing id, and
    /// the rank updates applied to it since, in order (`true`: the term added, `false`:
    /// removed). The terms the factor holds now are the first list changed by the second.
    pub base_terms: Vec<StiffnessTerm>,
    pub term_updates: Vec<(StiffnessTerm, bool)>,
}

/// Scratch space of [`crate::step`]: buffers and numeric factorisations, sized once for a model
/// so that stepping allocates nothing once each `dt` in use has been seen. The factor is remade
/// when `dt` changes (from the cache of [`crate::integrate::DT_CACHE_SIZE`] recently used `dt`'s
/// rest factors when it holds it) or when the quasi-Newton / Newton refresh rule pays.
#[derive(Debug, Clone)]
pub struct Workspace {
    pub(crate) force: Vec<Vec3>,
    pub(crate) x_save: Vec<Vec3>,
    pub(crate) v_save: Vec<Vec3>,
    pub(crate) x_trial: Vec<Vec3>,
    pub(crate) rhs: Vec<Vec3>,
    pub(crate) a_values: Vec<Mat3>,
    pub(crate) k: Vec<Mat3>,
    pub(crate) d: Vec<Mat3>,
    pub(crate) ldl: Ldl,
    /// `dt` the current factorisation / per-node inverses were made for (NaN: none yet).
    pub(crate) factored_dt: f64,
    /// Minimising integrators: the surplus iterations since the last factorisation (`integrate/factor.rs`).
    pub(crate) excess_iterations: usize,
    /// Sparse factorisations done so far (the step reports its own).
    pub(crate) factor_count: u64,
    /// Whether `ldl` holds a definite tangent refreshed at `refresh_x` (else the rest matrix).
    pub(crate) refreshed: bool,
    /// Positions of the last refresh, `(n_nodes)`: a saved state remakes that factor from them.
    pub(crate) refresh_x: Vec<Vec3>,
    /// The caller's stiffness terms the factor holds (`integrate/factor.rs`): now (by increasing
    /// id), when it was made, and the rank updates since (see [`StepMemory::base_terms`]); and a
    /// scratch list for the terms of the step being taken.
    pub(crate) held_terms: Vec<StiffnessTerm>,
    pub(crate) base_terms: Vec<StiffnessTerm>,
    pub(crate) term_updates: Vec<(StiffnessTerm, bool)>,
    pub(crate) step_terms: Vec<StiffnessTerm>,
    /// Rest factors of recently used `dt` (`integrate/factor.rs`).
    pub(crate) dt_cache: DtCache,
    /// Semi-implicit scheme: per-node `(I - dt/m D_ii - dt^2/m J_ii)^-1`.
    pub(crate) node_inv: Vec<Mat3>,
    /// Minimising integrators: the incremental potential's buffers and cache.
    pub(crate) potential: PotentialWorkspace,
    /// Quasi-Newton integrator: the L-BFGS pairs.
    pub(crate) lbfgs: Lbfgs,
    /// Newton integrator: the conjugate-gradient vectors.
    pub(crate) cg: CgWorkspace,
}

impl Workspace {
    /// Scratch space sized for `model`.
    pub fn new(model: &Model) -> Workspace {
        let n = model.n_nodes();
        let nf = model.free_nodes.len();
        Workspace {
            force: vec![Vec3::zeros(); n],
            x_save: vec![Vec3::zeros(); n],
            v_save: vec![Vec3::zeros(); n],
            x_trial: vec![Vec3::zeros(); n],
            rhs: vec![Vec3::zeros(); nf],
            a_values: vec![Mat3::zeros(); model.ldl.nnz_a()],
            k: vec![Mat3::zeros(); model.pattern.nnz()],
            d: vec![Mat3::zeros(); model.pattern.nnz()],
            ldl: model.ldl.clone(),
            factored_dt: f64::NAN,
            excess_iterations: 0,
            factor_count: 0,
            refreshed: false,
            refresh_x: vec![Vec3::zeros(); n],
            held_terms: Vec::new(),
            base_terms: Vec::new(),
            term_updates: Vec::with_capacity(crate::integrate::factor::MAX_TERM_UPDATES),
            step_terms: Vec::new(),
            dt_cache: DtCache::new(),
            node_inv: vec![Mat3::identity(); n],
            potential: PotentialWorkspace::new(n, nf),
            lbfgs: Lbfgs::new(nf, model.integrator.history()),
            cg: CgWorkspace::new(if matches!(model.integrator, Integrator::BackwardEulerNewton { .. }) { nf } else { 0 }),
        }
    }
}

impl Workspace {
    /// The integrator's memory (see [`StepMemory`]).
    pub fn memory(&self) -> StepMemory {
        StepMemory {
            factored_dt: self.factored_dt,
            refreshed_at: (self.refreshed && self.factored_dt.is_finite()).then(|| self.refresh_x.clone()),
            excess_iterations: self.excess_iterations,
            base_terms: if self.factored_dt.is_finite() { self.base_terms.clone() } else { Vec::new() },
            term_updates: if self.factored_dt.is_finite() { self.term_updates.clone() } else { Vec::new() },
        }
    }

    /// Bring the workspace to `mem` (from [`Workspace::memory`] of a workspace of the same
    /// `model`): remakes the factor it records (one factorisation, unless it is in use or
    /// cached), so that stepping from the matching [`State`] repeats the original steps bit for
    /// bit. Errors: `refreshed_at` not `(n_nodes)`, a stiffness term with a node out of range or a
    /// non-finite or non-positive value, a non-positive `factored_dt`, a failed factorisation.
    pub fn restore_memory(&mut self, model: &Model, mem: &StepMemory) -> Result<(), StepError> {
        if let Some(x) = &mem.refreshed_at {
            let n = model.n_nodes();
            if x.len() != n {
                return Err(StepError::StateShape { nodes: n, x: x.len(), v: n, f_ext: n });
            }
        }
        let n = model.n_nodes();
        for t in mem.base_terms.iter().chain(mem.term_updates.iter().map(|(t, _)| t)) {
            if let Some(a) = t.nodes.iter().find(|&&a| a >= n) {
                return Err(StepError::Snapshot(format!("stiffness term {}: node {a} out of range for {n} nodes", t.id)));
            }
            if !(t.stiffness > 0.0 && t.stiffness.is_finite() && t.weights.iter().all(|w| w.is_finite())) {
                return Err(StepError::Snapshot(format!(
                    "stiffness term {}: stiffness {} and weights {:?} must be finite, the stiffness positive",
                    t.id, t.stiffness, t.weights
                )));
            }
        }
        factor::restore(model, self, mem)
    }

    /// Room for `n` stiffness terms of a caller's potential
    /// ([`crate::integrate::CorePotential::stiffness_terms`]): with it, steps whose potentials offer
    /// at most `n` terms allocate nothing (without it the term lists grow on first use).
    pub fn reserve_stiffness_terms(&mut self, n: usize) {
        for v in [&mut self.held_terms, &mut self.base_terms, &mut self.step_terms] {
            v.reserve(n.saturating_sub(v.len()));
        }
    }

    /// Factorise the rest matrix for `dt` \[s\] ahead of the first step at that `dt` and keep it
    /// in the cache of recently used `dt` (the one in use is unchanged, and so are the results
    /// of later steps: only their cost). Returns whether it factorised (false: already held).
    /// The semi-implicit scheme needs no factor: a no-op.
    pub fn prepare(&mut self, model: &Model, dt: f64) -> Result<bool, StepError> {
        if matches!(model.integrator, Integrator::SemiImplicit { .. }) {
            return Ok(false);
        }
        factor::prepare(model, self, dt)
    }
}
