//! The mutable simulation state and the preallocated scratch space of the step.

use super::model::Model;
use crate::integrate::{CgWorkspace, Integrator, Lbfgs, PotentialWorkspace};
use crate::linalg::Ldl;
use crate::math::{Mat3, Vec3};

/// Everything that changes while simulating: positions, velocities, time and applied forces.
/// All arrays are `(n_nodes)`, world frame, SI.
#[derive(Debug, Clone, PartialEq)]
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

impl State {
    /// The body at rest: rest positions, zero velocity, zero time and no external force.
    pub fn rest(model: &Model) -> State {
        let n = model.n_nodes();
        State { x: model.mesh().points().to_vec(), v: vec![Vec3::zeros(); n], t: 0.0, f_ext: vec![Vec3::zeros(); n] }
    }

    /// Displacements from the rest positions \[m\].
    pub fn displacements(&self, model: &Model) -> Vec<Vec3> {
        self.x.iter().zip(model.mesh().points()).map(|(x, x0)| x - x0).collect()
    }
}

/// Scratch space of [`crate::step`]: buffers and numeric factorisations, sized once for a model
/// so that stepping allocates nothing. A factorisation is refreshed only when `dt` changes
/// (rest-linearised schemes) or every Newton iteration (Newton scheme).
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
            node_inv: vec![Mat3::identity(); n],
            potential: PotentialWorkspace::new(n, nf),
            lbfgs: Lbfgs::new(nf, model.integrator.history()),
            cg: CgWorkspace::new(if matches!(model.integrator, Integrator::BackwardEulerNewton { .. }) { nf } else { 0 }),
        }
    }
}
