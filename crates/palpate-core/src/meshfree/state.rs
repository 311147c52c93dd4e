//! The mutable state of a particle body, the scratch space of its step and the step's report
//! (as [`crate::State`] and [`crate::Workspace`] of the FEM body).

use super::model::ParticleModel;
use super::pair_loop::{Cols, P4};
use crate::math::Vec3;

/// What the per-sub-step callback of [`super::step_with`] sees: the state at the start of
/// sub-step `index` (of the call's `substeps`), before its forces are evaluated.
#[derive(Debug, Clone, Copy)]
pub struct SubStep<'a> {
    /// Sub-step index within the call, from 0.
    pub index: usize,
    /// Time at the start of the sub-step \[s\] (`state.t + index * h`).
    pub t: f64,
    /// Sub-step length \[s\].
    pub h: f64,
    /// Positions \[m\] `(n_particles)`: current for every particle (active ones are written
    /// back before each callback; frozen ones do not move).
    pub x: &'a [Vec3],
    /// Velocities \[m/s\] `(n_particles)`: for a free active particle its leapfrog velocity
    /// `v_{s-1/2}` (the one the sub-step's kick will update), as in [`ParticleState::v`].
    pub v: &'a [Vec3],
    /// The active particles (`state.active`).
    pub active: &'a [usize],
}

/// What a particle step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParticleStepReport {
    /// Verlet sub-steps taken.
    pub substeps: usize,
    /// Their length \[s\].
    pub substep_dt: f64,
}

/// The mutable state of a particle body. Arrays are `(n_particles)`, SI, world frame.
/// `clone_from` reuses the destination's arrays.
#[derive(Debug, PartialEq)]
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

impl Clone for ParticleState {
    fn clone(&self) -> Self {
        ParticleState { x: self.x.clone(), v: self.v.clone(), t: self.t, f_ext: self.f_ext.clone(), active: self.active.clone() }
    }
    fn clone_from(&mut self, s: &Self) {
        let ParticleState { x, v, t, f_ext, active } = self;
        x.clone_from(&s.x);
        v.clone_from(&s.v);
        *t = s.t;
        f_ext.clone_from(&s.f_ext);
        active.clone_from(&s.active);
    }
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
    /// Whether the step's active list holds each particle once (`touch`): only then may its
    /// passes be split over threads (each part writes its own particles).
    pub(crate) unique: bool,
    /// Whether steps compute the ring ([`ParticleWorkspace::set_ring_forces`]).
    pub(crate) ring_on: bool,
    /// The ring (see [`ParticleWorkspace::ring`]) and its call-averaged forces.
    pub(crate) ring: Vec<usize>,
    pub(crate) ring_force: Vec<Vec3>,
    /// The active particles whose `B` and displacement the ring's gather reads (the ring's
    /// active neighbours and the fixed active particles), and their sums over the sub-steps
    /// (the three columns of `B`, then the displacement).
    pub(crate) rim: Vec<usize>,
    pub(crate) rim_sum: Vec<[P4; 4]>,
    /// External forces of the current sub-step, for [`super::step_with`]'s callback.
    pub(crate) f_sub: Vec<Vec3>,
}

impl ParticleWorkspace {
    /// Number of particles it was made for (every per-particle array has this length).
    pub(crate) fn len(&self) -> usize {
        let n = self.u.len();
        if [
            self.force.len(),
            self.v.len(),
            self.b.len(),
            self.gamma.len(),
            self.acc_ext.len(),
            self.u_next.len(),
            self.mark.len(),
            self.f_sub.len(),
        ]
        .iter()
        .all(|&l| l == n)
        {
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
            unique: false,
            ring_on: false,
            ring: Vec::with_capacity(n),
            ring_force: Vec::with_capacity(n),
            rim: Vec::with_capacity(n),
            rim_sum: Vec::with_capacity(n),
            f_sub: vec![Vec3::zeros(); n],
        }
    }

    /// Compute the ring's forces in the following steps (`on`), or not (the default). Off, a
    /// step does no ring work at all; on, it costs a few additions per sub-step for each active
    /// particle next to the ring and one gather per ring particle per call (measured on a 1 ms
    /// tick: +3% on a 600-particle block whose 81 fixed particles are the ring, +5% with 600
    /// active of 2,744 and a ring of about 200; nothing when the ring is empty). The motion is the
    /// same either way (bitwise).
    /// The hybrid runtime turns it on; a standalone particle body has no use for it.
    pub fn set_ring_forces(&mut self, on: bool) {
        self.ring_on = on;
    }

    /// Whether steps compute the ring's forces ([`ParticleWorkspace::set_ring_forces`]).
    pub fn ring_forces_enabled(&self) -> bool {
        self.ring_on
    }

    /// The ring of the last successful step (empty unless [`ParticleWorkspace::set_ring_forces`]
    /// turned it on): the particles on which the active particles'
    /// stresses (and hourglass control) act but which the step does not move, each once. These
    /// are the inactive neighbours of the active particles (frozen; in the hybrid model slaved to
    /// the FEM core) and the fixed active particles (held by their support). Empty when every
    /// particle is active and none is fixed (a standalone particle body), and after a failed step.
    ///
    /// Why it exists: the internal forces are pairwise equal and opposite (see
    /// [`crate::meshfree`]), so what the active particles push on the ring is exactly the
    /// momentum that leaves the active set. A caller that hands `dt * ring_forces()` to whatever
    /// moves the ring (the core nodes, with partition-of-unity weights) conserves linear momentum
    /// exactly: `sum_free m_i (v_i' - v_i) + dt * sum_ring f_r = dt * sum_free (f_ext,i + m_i g)`.
    pub fn ring(&self) -> &[usize] {
        &self.ring
    }

    /// Internal forces \[N\] on the particles of [`ParticleWorkspace::ring`] (parallel to it),
    /// averaged over the sub-steps of the last step: `sum_s h f_r(s) / dt`, so that `dt` times
    /// it is the impulse the ring received. For a frozen particle this is the reaction to the
    /// active particles' stresses and hourglass terms; for a fixed active particle, the whole
    /// internal force its support must hold (external forces and gravity on fixed particles are
    /// not included).
    pub fn ring_forces(&self) -> &[Vec3] {
        &self.ring_force
    }
}
