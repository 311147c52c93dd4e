//! The compiled particle body (immutable): its data, energies, forces and the rest-linearised
//! static solve. Built by [`super::ParticleModelBuilder`], stepped by [`super::step`].

use super::kernel::Kernel;
use super::pair_loop::{self, p4, v3, Cols, P4};
use crate::error::SolveError;
use crate::linalg::cg::{self, CgStop, CgWork};
use crate::material::{self, Material};
use crate::math::{is_finite3, Mat3, Vec3};

/// A compiled particle body (immutable).
#[derive(Debug, Clone)]
pub struct ParticleModel {
    pub(crate) rest: Vec<Vec3>,
    pub(crate) mass: Vec<f64>,
    pub(crate) inv_mass: Vec<f64>,
    pub(crate) density: Vec<f64>,
    pub(crate) volume: Vec<f64>,
    /// Neighbours of `i`: `nbr[ptr[i]..ptr[i+1]]` (and as `u32`, for the hot loop); per pair:
    /// rest vector `X_ij`, MLS gradient `g_ij`, weight `w_ij = V_j W_ij`.
    pub(crate) ptr: Vec<usize>,
    pub(crate) nbr: Vec<usize>,
    pub(crate) nbr32: Vec<u32>,
    pub(crate) xr: Vec<Vec3>,
    pub(crate) g: Vec<Vec3>,
    pub(crate) gsum: Vec<Vec3>,
    pub(crate) w: Vec<f64>,
    /// Per pair `q_ij = w_ij X_ij`, so that `g_ij = A_i^-1 q_ij`; per particle `Q_i = sum_j q_ij`,
    /// `A_i^-1`, the hourglass coefficient `c_i` and `gamma_i = c_i / V_i` (see [`pair_loop`]).
    pub(crate) q4: Vec<P4>,
    pub(crate) qsum4: Vec<P4>,
    pub(crate) r4: Vec<Cols>,
    pub(crate) hg_c: Vec<f64>,
    pub(crate) gamma: Vec<f64>,
    pub(crate) fixed: Vec<bool>,
    /// Particles held because their neighbours do not span 3D (`fix_unsupported`).
    pub(crate) unsupported: Vec<usize>,
    pub(crate) gravity: Vec3,
    pub(crate) material: Material,
    pub(crate) kernel: Kernel,
    pub(crate) support: f64,
    pub(crate) hourglass: f64,
    pub(crate) stable_dt: f64,
    pub(crate) omega_max: f64,
    pub(crate) damping_max: f64,
    /// Selective mass scaling applied at build (`mass_scaling.rs`).
    pub(crate) scaling: super::mass_scaling::MassScaling,
}

impl ParticleModel {
    /// Number of particles.
    pub fn n_particles(&self) -> usize {
        self.rest.len()
    }
    /// Rest positions \[m\].
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest
    }
    /// Masses \[kg\].
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }
    /// Kernel-sum densities \[kg/m^3\] (eq. 25, Shepard-normalised).
    pub fn densities(&self) -> &[f64] {
        &self.density
    }
    /// Volumes `m / rho` \[m^3\].
    pub fn volumes(&self) -> &[f64] {
        &self.volume
    }
    /// Neighbours of particle `i` at rest.
    pub fn neighbours(&self, i: usize) -> &[usize] {
        &self.nbr[self.ptr[i]..self.ptr[i + 1]]
    }
    /// Total number of (directed) neighbour pairs.
    pub fn n_pairs(&self) -> usize {
        self.nbr.len()
    }
    /// Particles the builder held because their neighbours do not span 3D (empty unless
    /// [`super::ParticleModelBuilder::fix_unsupported`]).
    pub fn unsupported(&self) -> &[usize] {
        &self.unsupported
    }
    /// Fixed flags.
    pub fn fixed(&self) -> &[bool] {
        &self.fixed
    }
    /// The material.
    pub fn material(&self) -> &Material {
        &self.material
    }
    /// The kernel.
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }
    /// Support radius \[m\].
    pub fn support(&self) -> f64 {
        self.support
    }
    /// Hourglass-control stiffness `kappa` \[-\].
    pub fn hourglass(&self) -> f64 {
        self.hourglass
    }
    /// Largest explicit (Verlet) time step that is stable for this body \[s\], with safety factor
    /// [`super::STABILITY_SAFETY`] (from the largest eigenfrequency of the linearised system).
    pub fn stable_dt(&self) -> f64 {
        self.stable_dt
    }
    /// Largest angular eigenfrequency of the rest-linearised, undamped system \[rad/s\].
    pub fn omega_max(&self) -> f64 {
        self.omega_max
    }
    /// Largest eigenvalue of the rest-linearised `M^-1 D` (the viscous stress's rate) \[1/s\]; 0
    /// for an undamped material.
    pub fn damping_max(&self) -> f64 {
        self.damping_max
    }
    /// Sub-steps that [`super::step`] takes for a caller step `dt` \[s\].
    pub fn substeps(&self, dt: f64) -> usize {
        (dt / self.stable_dt).ceil().max(1.0) as usize
    }

    /// Deformation gradient of particle `i` at positions `x` (the MLS fit).
    pub fn deformation_gradient(&self, i: usize, x: &[Vec3]) -> Mat3 {
        let ui = x[i] - self.rest[i];
        let mut f = Mat3::identity();
        for p in self.ptr[i]..self.ptr[i + 1] {
            let j = self.nbr[p];
            f += (x[j] - self.rest[j] - ui) * self.g[p].transpose();
        }
        f
    }

    /// Elastic energy \[J\]: `sum_i V_i psi(F_i)` plus the hourglass-control energy.
    pub fn strain_energy(&self, x: &[Vec3]) -> f64 {
        (0..self.n_particles()).map(|i| self.particle_energy(i, x)).sum()
    }

    /// The part of [`ParticleModel::strain_energy`] that particle `i` carries \[J\]:
    /// `V_i psi(F_i)` plus its hourglass-control energy `c_i/2 sum_j w_ij |x_ij - F_i X_ij|^2`.
    /// The force on a particle is minus the gradient of the sum of these over the *active*
    /// particles (frozen ones carry no stress).
    pub fn particle_energy(&self, i: usize, x: &[Vec3]) -> f64 {
        let f = self.deformation_gradient(i, x);
        let mut total =
            self.volume[i] * (material::energy_density(&self.material, &material::green_strain(&f)) + barrier_energy_density(&self.material, f.determinant()));
        let ui = x[i] - self.rest[i];
        let hmat = f - Mat3::identity();
        for p in self.ptr[i]..self.ptr[i + 1] {
            let j = self.nbr[p];
            let err = x[j] - self.rest[j] - ui - hmat * self.xr[p];
            total += 0.5 * self.hg_c[i] * self.w[p] * err.norm_squared();
        }
        total
    }

    /// Kinetic energy \[J\].
    pub fn kinetic_energy(&self, v: &[Vec3]) -> f64 {
        0.5 * v.iter().zip(&self.mass).map(|(v, m)| m * v.norm_squared()).sum::<f64>()
    }

    /// Linear momentum \[kg m/s\].
    pub fn momentum(&self, v: &[Vec3]) -> Vec3 {
        v.iter().zip(&self.mass).map(|(v, m)| v * *m).sum()
    }

    /// Internal forces \[N\] of all particles at positions `x` (and velocities `v` for the viscous
    /// part) into `out` (overwritten).
    pub fn internal_forces(&self, x: &[Vec3], v: Option<&[Vec3]>, out: &mut [Vec3]) {
        let u: Vec<P4> = x.iter().zip(&self.rest).map(|(x, x0)| p4(&(x - x0))).collect();
        let v4 = v.map(to_p4);
        self.forces_of(&u, v4.as_deref(), false, out);
    }

    /// Forces \[N\] of the rest-linearised system (small-strain stress, `F = I`, plus hourglass
    /// control) for displacements `u` \[m\] into `out` (overwritten): `out = -K0 u`.
    pub fn linearised_forces(&self, u: &[Vec3], out: &mut [Vec3]) {
        self.forces_of(&to_p4(u), None, true, out);
    }

    fn forces_of(&self, u: &[P4], v: Option<&[P4]>, linear: bool, out: &mut [Vec3]) {
        let n = self.n_particles();
        let mut b: Vec<Cols> = vec![[[0.0; 4]; 3]; n];
        let mut gamma = vec![0.0; n];
        let mut f = vec![[0.0; 4]; n];
        pair_loop::all_forces(self, u, v, linear, &mut b, &mut gamma, &mut f);
        for (o, f) in out.iter_mut().zip(&f) {
            *o = v3(f);
        }
    }

    /// Static equilibrium of the rest-linearised body (small loads) under external forces `f_ext`
    /// \[N\] `(n_particles)` and gravity: solves `K0 u = f` over the free particles by conjugate
    /// gradients, matrix-free (each product is one linearised force evaluation), to a relative
    /// residual `tolerance`. Returns the positions \[m\]. Fails if `K0` is not positive definite
    /// on the free particles (e.g. nothing is fixed) or CG does not converge.
    pub fn static_solve_linear(&self, f_ext: &[Vec3], tolerance: f64, max_iterations: usize) -> Result<Vec<Vec3>, SolveError> {
        let n = self.n_particles();
        if f_ext.len() != n {
            return Err(SolveError::Invalid(format!("f_ext has {} rows, the body has {n} particles", f_ext.len())));
        }
        if let Some(i) = f_ext.iter().position(|f| !is_finite3(f)) {
            return Err(SolveError::NonFinite { what: "external force", node: i });
        }
        let free = |i: usize| !self.fixed[i];
        let b: Vec<Vec3> = (0..n).map(|i| if free(i) { f_ext[i] + self.mass[i] * self.gravity } else { Vec3::zeros() }).collect();
        if b.iter().all(|f| *f == Vec3::zeros()) {
            return Ok(self.rest.clone());
        }
        let mut u = vec![Vec3::zeros(); n];
        // K0 p = -f_lin(p) on the free particles, zero on the fixed ones.
        let apply = |p: &[Vec3], ap: &mut [Vec3]| {
            self.linearised_forces(p, ap);
            for (i, a) in ap.iter_mut().enumerate() {
                *a = if free(i) { -*a } else { Vec3::zeros() };
            }
        };
        let rep = cg::solve(apply, cg::identity, &b, &mut u, &mut CgWork::new(n), CgStop { tolerance, max_iterations });
        if rep.breakdown {
            return Err(SolveError::Invalid(format!(
                "the linearised stiffness is not positive definite on the free particles (CG iteration {}); fix some particles",
                rep.iterations
            )));
        }
        if !rep.converged {
            return Err(SolveError::NoConvergence { iterations: max_iterations, residual: rep.residual_norm, tolerance: tolerance * rep.rhs_norm });
        }
        Ok((0..n).map(|i| self.rest[i] + u[i]).collect())
    }
}

pub(crate) fn to_p4(v: &[Vec3]) -> Vec<P4> {
    v.iter().map(p4).collect()
}

/// The compression barrier's energy density \[J/m^3\] at `J = det F`:
/// `kappa/2 (J_c - J)^2` below `J_c` ([`super::COMPRESSION_FLOOR`]), `kappa = lambda + 2 mu`.
pub fn barrier_energy_density(m: &Material, j: f64) -> f64 {
    let d = (super::COMPRESSION_FLOOR - j).max(0.0);
    0.5 * (m.lambda() + 2.0 * m.mu()) * d * d
}
