//! The mutable state of a particle body, the scratch space of its step and the step's report
//! (as [`crate::State`] and [`crate::Workspace`] of the FEM body).

use super::model::ParticleModel;
use super::pair_loop::{Cols, P4};
use crate::math::Vec3;

/// What a particle step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParticleStepReport {
    /// Verlet sub-steps taken.
    pub substeps: usize,
    /// Their length \[s\].
    pub substep_dt: f64,
}

/// The mutable state of a particle body. Arrays are `(n_particles)`, SI, world frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ParticleState {
    /// Positions \[m\].
    pub x: Vec<Vec3>,
    /// Velocities \[m/s\] (at the half step, in the Verlet sense).
    pub v: Vec<Vec3>,
    /// Time \[s\].
    pub t: f64,
    /// External forces \[N\].
    pub f_ext: Vec<Vec3>,
    /// Indices of the active (simulated) particles; the others are frozen.
    pub active: Vec<usize>,
}

impl ParticleState {
    /// At rest, every particle active.
    pub fn rest(model: &ParticleModel) -> ParticleState {
        let n = model.n_particles();
        ParticleState { x: model.rest.clone(), v: vec![Vec3::zeros(); n], t: 0.0, f_ext: vec![Vec3::zeros(); n], active: (0..n).collect() }
    }
}

/// Scratch space of the particle step (sized once: stepping allocates nothing).
#[derive(Debug, Clone)]
pub struct ParticleWorkspace {
    pub(crate) force: Vec<P4>,
    pub(crate) b: Vec<Cols>,
    pub(crate) gamma: Vec<f64>,
    pub(crate) acc_ext: Vec<P4>,
    pub(crate) u_next: Vec<P4>,
    pub(crate) free: Vec<usize>,
    pub(crate) u: Vec<P4>,
    pub(crate) v: Vec<P4>,
    pub(crate) save: Vec<(Vec3, Vec3)>,
    pub(crate) touched: Vec<usize>,
    pub(crate) mark: Vec<u64>,
    pub(crate) stamp: u64,
}

impl ParticleWorkspace {
    /// Number of particles it was made for (every per-particle array has this length).
    pub(crate) fn len(&self) -> usize {
        let n = self.u.len();
        if [self.force.len(), self.v.len(), self.b.len(), self.gamma.len(), self.acc_ext.len(), self.u_next.len(), self.mark.len()].iter().all(|&l| l == n) {
            n
        } else {
            usize::MAX
        }
    }

    /// Scratch space for `model`.
    pub fn new(model: &ParticleModel) -> ParticleWorkspace {
        let n = model.n_particles();
        ParticleWorkspace {
            force: vec![[0.0; 4]; n],
            b: vec![[[0.0; 4]; 3]; n],
            gamma: vec![0.0; n],
            acc_ext: vec![[0.0; 4]; n],
            u_next: vec![[0.0; 4]; n],
            free: Vec::with_capacity(n),
            u: vec![[0.0; 4]; n],
            v: vec![[0.0; 4]; n],
            save: Vec::with_capacity(n),
            touched: Vec::with_capacity(n),
            mark: vec![0; n],
            stamp: 0,
        }
    }
}
