//! The compiled particle body, its state and the Verlet step (paper eq. 33). See the module
//! docs of [`crate::meshfree`] for the formulation.

use super::kernel::Kernel;
use super::neighbors::neighbours_within;
use super::pair_loop::{self, p4, v3, Cols, P4};
use crate::error::{MaterialError, ModelError, SolveError, StepError};
use crate::material::{self, Law, Material};
use crate::math::{is_finite3, Mat3, Vec3};

/// Default dimensionless hourglass-control stiffness `kappa` (see [`crate::meshfree`]).
pub const DEFAULT_HOURGLASS: f64 = 0.5;
/// Default relative kernel weight below which a neighbour is not paired.
pub const DEFAULT_MIN_WEIGHT: f64 = 1e-3;
/// Fraction of the critical time step used by the explicit sub-steps.
pub const STABILITY_SAFETY: f64 = 0.9;
/// Smallest accepted ratio of the moment matrix's eigenvalues (its conditioning).
const MIN_MOMENT_CONDITION: f64 = 1e-4;

/// Describes a particle body before compilation.
#[derive(Debug, Clone)]
pub struct ParticleModelBuilder {
    positions: Vec<Vec3>,
    masses: Vec<f64>,
    material: Material,
    support: f64,
    kernel: Kernel,
    fixed: Vec<usize>,
    gravity: Vec3,
    hourglass: f64,
    min_weight: f64,
}

impl ParticleModelBuilder {
    /// Particles at rest positions `positions` \[m\] with masses `masses` \[kg\], of `material`,
    /// interacting within the kernel support radius `support` \[m\] (typically 1.5 - 2 particle spacings).
    pub fn new(positions: Vec<Vec3>, masses: Vec<f64>, material: Material, support: f64) -> Self {
        ParticleModelBuilder { positions, masses, material, support, kernel: Kernel::default(), fixed: vec![], gravity: Vec3::zeros(), hourglass: DEFAULT_HOURGLASS, min_weight: DEFAULT_MIN_WEIGHT }
    }
    /// Kernel (default Wendland C2).
    pub fn kernel(mut self, k: Kernel) -> Self {
        self.kernel = k;
        self
    }
    /// Particles held at their rest position.
    pub fn fixed_particles(mut self, fixed: Vec<usize>) -> Self {
        self.fixed = fixed;
        self
    }
    /// Gravity \[m/s^2\].
    pub fn gravity(mut self, g: Vec3) -> Self {
        self.gravity = g;
        self
    }
    /// Neighbours whose kernel weight is below `w` times the kernel's peak are not paired
    /// (default [`DEFAULT_MIN_WEIGHT`]; 0 keeps every neighbour within the support).
    pub fn min_relative_weight(mut self, w: f64) -> Self {
        self.min_weight = w;
        self
    }
    /// Hourglass-control stiffness `kappa` \[-\] (0 disables the safeguard).
    pub fn hourglass(mut self, kappa: f64) -> Self {
        self.hourglass = kappa;
        self
    }

    /// Validate and precompute neighbours, volumes, MLS gradients, hourglass weights and the
    /// stable explicit time step.
    ///
    /// Errors: `ModelError::Material(MaterialError::UnsupportedLaw)` for a material whose law is
    /// not St. Venant-Kirchhoff (the only law of the particle hot loop for now); invalid particles,
    /// parameters, fixed indices or gravity.
    pub fn build(self) -> Result<ParticleModel, ModelError> {
        let ParticleModelBuilder { positions: rest, masses, material, support: h, kernel, fixed, gravity, hourglass, min_weight } = self;
        // The pair loop (pair_loop.rs, with its AVX2 copy) evaluates the St. Venant-Kirchhoff
        // stress only: refuse any other law rather than silently simulate SVK.
        if material.law() != Law::StVenantKirchhoff {
            return Err(MaterialError::UnsupportedLaw { law: material.law(), solver: "the particle solid (meshfree)" }.into());
        }
        let n = rest.len();
        if n == 0 {
            return Err(ModelError::Empty("no particles"));
        }
        if masses.len() != n {
            return Err(ModelError::Particle { particle: masses.len().min(n), reason: format!("{} masses for {n} particles", masses.len()) });
        }
        if !(h > 0.0 && h.is_finite()) {
            return Err(ModelError::Parameter { name: "support radius", value: h, reason: "must be positive and finite [m]" });
        }
        if !(0.0..0.5).contains(&min_weight) {
            return Err(ModelError::Parameter { name: "minimum relative kernel weight", value: min_weight, reason: "must lie in [0, 0.5)" });
        }
        if !(hourglass >= 0.0 && hourglass.is_finite()) {
            return Err(ModelError::Parameter { name: "hourglass kappa", value: hourglass, reason: "must be non-negative and finite" });
        }
        if !is_finite3(&gravity) {
            return Err(ModelError::Gravity(gravity.x, gravity.y, gravity.z));
        }
        for (i, (p, &m)) in rest.iter().zip(&masses).enumerate() {
            if !is_finite3(p) {
                return Err(ModelError::Particle { particle: i, reason: format!("non-finite position ({}, {}, {})", p.x, p.y, p.z) });
            }
            if !(m > 0.0 && m.is_finite()) {
                return Err(ModelError::Particle { particle: i, reason: format!("mass {m} kg must be positive and finite") });
            }
        }
        let mut is_fixed = vec![false; n];
        for &i in &fixed {
            if i >= n {
                return Err(ModelError::FixedOutOfRange { node: i, n_nodes: n });
            }
            is_fixed[i] = true;
        }

        let (ptr, nbr) = neighbours_within(&rest, h);
        // Drop the pairs whose kernel weight is negligible (on a cubic lattice with a support of
        // 1.8 spacings, the 8 corner neighbours at sqrt(3) spacings have W/W(0) = 1e-5: a third
        // of the pair work for nothing). W depends on the distance only, so the lists stay
        // symmetric.
        let (ptr, nbr) = if min_weight > 0.0 {
            let cut = min_weight * kernel.w(0.0, h);
            let mut p2 = Vec::with_capacity(n + 1);
            let mut n2 = Vec::with_capacity(nbr.len());
            p2.push(0);
            for i in 0..n {
                for &j in &nbr[ptr[i]..ptr[i + 1]] {
                    if kernel.w((rest[j] - rest[i]).norm(), h) >= cut {
                        n2.push(j);
                    }
                }
                p2.push(n2.len());
            }
            (p2, n2)
        } else {
            (ptr, nbr)
        };
        // Shepard-normalised kernel-sum density (eq. 25) and volumes.
        let rho0 = material.density();
        let mut density = vec![0.0; n];
        let mut volume = vec![0.0; n];
        for i in 0..n {
            let w0 = kernel.w(0.0, h);
            let (mut num, mut den) = (masses[i] * w0, masses[i] / rho0 * w0);
            for &j in &nbr[ptr[i]..ptr[i + 1]] {
                let w = kernel.w((rest[j] - rest[i]).norm(), h);
                num += masses[j] * w;
                den += masses[j] / rho0 * w;
            }
            density[i] = num / den;
            volume[i] = masses[i] / density[i];
        }
        // MLS gradients and hourglass weights per pair.
        let np = nbr.len();
        let mut xr = vec![Vec3::zeros(); np];
        let mut g = vec![Vec3::zeros(); np];
        let mut hw = vec![0.0; np];
        let mut gsum = vec![Vec3::zeros(); n];
        let mut q = vec![Vec3::zeros(); np];
        let mut qsum = vec![Vec3::zeros(); n];
        let mut r_inv = vec![Mat3::zeros(); n];
        let mut hg_c = vec![0.0; n];
        for i in 0..n {
            let (s, e) = (ptr[i], ptr[i + 1]);
            let mut a = Mat3::zeros();
            let mut second = 0.0;
            for p in s..e {
                let j = nbr[p];
                let x = rest[j] - rest[i];
                let w = volume[j] * kernel.w(x.norm(), h);
                xr[p] = x;
                hw[p] = w;
                a += w * x * x.transpose();
                second += w * x.norm_squared();
            }
            let eig = a.symmetric_eigenvalues();
            let (lo, hi) = (eig.min(), eig.max());
            if e - s < 3 || !(lo > MIN_MOMENT_CONDITION * hi) {
                return Err(ModelError::Particle {
                    particle: i,
                    reason: format!(
                        "its {} neighbours within the support radius {h} m do not span 3D (moment-matrix eigenvalue ratio {:.1e}); increase the support radius or the sampling density",
                        e - s,
                        if hi > 0.0 { lo / hi } else { 0.0 }
                    ),
                });
            }
            let a_inv = a.try_inverse().expect("checked positive definite");
            let c = hourglass * material.mu() * volume[i] / second;
            r_inv[i] = a_inv;
            hg_c[i] = c;
            for p in s..e {
                q[p] = hw[p] * xr[p];
                g[p] = a_inv * q[p];
                gsum[i] += g[p];
                qsum[i] += q[p];
            }
        }
        let gamma = (0..n).map(|i| hg_c[i] / volume[i]).collect();
        let nbr32 = nbr.iter().map(|&j| j as u32).collect();
        let mut model = ParticleModel {
            rest,
            inv_mass: masses.iter().map(|m| 1.0 / m).collect(),
            mass: masses,
            density,
            volume,
            ptr,
            nbr,
            xr,
            g,
            gsum,
            w: hw,
            nbr32,
            q4: to_p4(&q),
            qsum4: to_p4(&qsum),
            r4: r_inv.iter().map(|r| [p4(&r.column(0).into()), p4(&r.column(1).into()), p4(&r.column(2).into())]).collect(),
            hg_c,
            gamma,
            fixed: is_fixed,
            gravity,
            material,
            kernel,
            support: h,
            hourglass,
            stable_dt: 0.0,
            omega_max: 0.0,
        };
        model.compute_stable_dt();
        Ok(model)
    }
}

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
    pub(crate) gravity: Vec3,
    pub(crate) material: Material,
    pub(crate) kernel: Kernel,
    pub(crate) support: f64,
    pub(crate) hourglass: f64,
    pub(crate) stable_dt: f64,
    pub(crate) omega_max: f64,
}

impl ParticleModel {
    /// Number of particles.
    pub fn n_particles(&self) -> usize { self.rest.len() }
    /// Rest positions \[m\].
    pub fn rest_positions(&self) -> &[Vec3] { &self.rest }
    /// Masses \[kg\].
    pub fn masses(&self) -> &[f64] { &self.mass }
    /// Kernel-sum densities \[kg/m^3\] (eq. 25, Shepard-normalised).
    pub fn densities(&self) -> &[f64] { &self.density }
    /// Volumes `m / rho` \[m^3\].
    pub fn volumes(&self) -> &[f64] { &self.volume }
    /// Neighbours of particle `i` at rest.
    pub fn neighbours(&self, i: usize) -> &[usize] { &self.nbr[self.ptr[i]..self.ptr[i + 1]] }
    /// Total number of (directed) neighbour pairs.
    pub fn n_pairs(&self) -> usize { self.nbr.len() }
    /// Fixed flags.
    pub fn fixed(&self) -> &[bool] { &self.fixed }
    /// The material.
    pub fn material(&self) -> &Material { &self.material }
    /// The kernel.
    pub fn kernel(&self) -> Kernel { self.kernel }
    /// Support radius \[m\].
    pub fn support(&self) -> f64 { self.support }
    /// Hourglass-control stiffness `kappa` \[-\].
    pub fn hourglass(&self) -> f64 { self.hourglass }
    /// Largest explicit (Verlet) time step that is stable for this body \[s\], with safety factor
    /// [`STABILITY_SAFETY`] (from the largest eigenfrequency of the linearised system).
    pub fn stable_dt(&self) -> f64 { self.stable_dt }
    /// Largest angular eigenfrequency of the rest-linearised, undamped system \[rad/s\].
    pub fn omega_max(&self) -> f64 { self.omega_max }
    /// Sub-steps that [`ParticleModel::step`] takes for a caller step `dt` \[s\].
    pub fn substeps(&self, dt: f64) -> usize { (dt / self.stable_dt).ceil().max(1.0) as usize }

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
        let (lam, mu) = (self.material.lambda(), self.material.mu());
        let f = self.deformation_gradient(i, x);
        let e = material::green_strain(&f);
        let mut total = self.volume[i] * (mu * e.norm_squared() + 0.5 * lam * e.trace() * e.trace());
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

    /// Viscous forces of the rest-linearised system for velocities `v` (F = I).
    fn add_linear_viscous(&self, i: usize, v: &[Vec3], out: &mut [Vec3]) {
        let (s, e) = (self.ptr[i], self.ptr[i + 1]);
        let mut l = Mat3::zeros();
        for p in s..e {
            l += (v[self.nbr[p]] - v[i]) * self.g[p].transpose();
        }
        let a = self.volume[i] * material::viscous_stress(&self.material, &(0.5 * (l + l.transpose())));
        out[i] += a * self.gsum[i];
        for p in s..e {
            out[self.nbr[p]] -= a * self.g[p];
        }
    }

    /// Largest eigenvalue of `M^-1 K` (or of `M^-1 D` with `viscous`) by power iteration with
    /// the mass inner product, over the free particles.
    fn max_eigenvalue(&self, viscous: bool) -> f64 {
        let n = self.n_particles();
        let mut u: Vec<Vec3> = (0..n)
            .map(|i| if self.fixed[i] { Vec3::zeros() } else { Vec3::new(((i * 7919) % 13) as f64 - 6.0, ((i * 104729) % 11) as f64 - 5.0, ((i * 31) % 7) as f64 - 3.0) })
            .collect();
        let mut f = vec![Vec3::zeros(); n];
        let mut lambda = 0.0;
        for _ in 0..200 {
            let norm = u.iter().zip(&self.mass).map(|(u, m)| m * u.norm_squared()).sum::<f64>().sqrt();
            if norm == 0.0 {
                return 0.0;
            }
            u.iter_mut().for_each(|u| *u /= norm);
            if viscous {
                f.iter_mut().for_each(|f| *f = Vec3::zeros());
                for i in 0..n {
                    self.add_linear_viscous(i, &u, &mut f);
                }
            } else {
                self.linearised_forces(&u, &mut f);
            }
            // Rayleigh quotient u^T (-f) with |u|_M = 1, then u <- M^-1 (-f).
            let next: f64 = (0..n).filter(|&i| !self.fixed[i]).map(|i| -f[i].dot(&u[i])).sum();
            for i in 0..n {
                u[i] = if self.fixed[i] { Vec3::zeros() } else { -f[i] / self.mass[i] };
            }
            if (next - lambda).abs() <= 1e-6 * next.abs() {
                lambda = next;
                break;
            }
            lambda = next;
        }
        lambda.max(0.0)
    }

    fn compute_stable_dt(&mut self) {
        // Power iteration converges from below: keep a 2% margin on the eigenvalue.
        let k_max = 1.02 * self.max_eigenvalue(false);
        let d_max = if self.material.is_undamped() { 0.0 } else { 1.02 * self.max_eigenvalue(true) };
        self.omega_max = k_max.sqrt();
        // Central differences with damping: dt <= 2/omega (sqrt(1 + zeta^2) - zeta), zeta = d/(2 omega);
        // with velocity-lagged damping alone, dt <= 2/d.
        let dt = if self.omega_max > 0.0 {
            let zeta = d_max / (2.0 * self.omega_max);
            2.0 / self.omega_max * ((1.0 + zeta * zeta).sqrt() - zeta)
        } else if d_max > 0.0 {
            2.0 / d_max
        } else {
            f64::INFINITY
        };
        self.stable_dt = STABILITY_SAFETY * dt;
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
        let dot = |a: &[Vec3], c: &[Vec3]| a.iter().zip(c).map(|(a, c)| a.dot(c)).sum::<f64>();
        let bnorm = dot(&b, &b).sqrt();
        let mut u = vec![Vec3::zeros(); n];
        if bnorm == 0.0 {
            return Ok(self.rest.clone());
        }
        let mut r = b.clone();
        let mut p = r.clone();
        let mut ap = vec![Vec3::zeros(); n];
        let mut rr = dot(&r, &r);
        for it in 0..max_iterations {
            // ap = K0 p = -f_lin(p)
            self.linearised_forces(&p, &mut ap);
            for i in 0..n {
                ap[i] = if free(i) { -ap[i] } else { Vec3::zeros() };
            }
            let pap = dot(&p, &ap);
            if !(pap > 0.0) {
                return Err(SolveError::Invalid(format!(
                    "the linearised stiffness is not positive definite on the free particles (CG iteration {it}); fix some particles"
                )));
            }
            let alpha = rr / pap;
            for i in 0..n {
                u[i] += alpha * p[i];
                r[i] -= alpha * ap[i];
            }
            let rr_new = dot(&r, &r);
            if rr_new.sqrt() <= tolerance * bnorm {
                return Ok((0..n).map(|i| self.rest[i] + u[i]).collect());
            }
            let beta = rr_new / rr;
            rr = rr_new;
            for i in 0..n {
                p[i] = r[i] + beta * p[i];
            }
        }
        Err(SolveError::NoConvergence { iterations: max_iterations, residual: rr.sqrt(), tolerance: tolerance * bnorm })
    }

    /// Advance by `dt` \[s\] with the position-Verlet scheme of eq. (33), in as many equal
    /// sub-steps as stability needs ([`ParticleModel::substeps`]), only over the active particles.
    ///
    /// Eq. (33), `x+ = 2x - x- + dt^2 F/m`, is run in its velocity form (`v+1/2 = v-1/2 + dt F/m`,
    /// `x+ = x + dt v+1/2`: algebraically the same sequence of positions), which lets the sub-step
    /// size change between calls and gives the viscous stress a velocity. Inactive particles are
    /// frozen: they shape their active neighbours' deformation gradients but do not move.
    /// Errors leave the state unchanged.
    pub fn step(&self, state: &mut ParticleState, ws: &mut ParticleWorkspace, dt: f64) -> Result<ParticleStepReport, StepError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(StepError::BadTimeStep(dt));
        }
        self.step_with_substeps(state, ws, dt, self.substeps(dt))
    }

    /// [`ParticleModel::step`] with a caller-chosen number of sub-steps (for stability studies
    /// and benchmarks; fewer than [`ParticleModel::substeps`] may be unstable).
    pub fn step_with_substeps(&self, state: &mut ParticleState, ws: &mut ParticleWorkspace, dt: f64, substeps: usize) -> Result<ParticleStepReport, StepError> {
        if !(dt > 0.0 && dt.is_finite()) || substeps == 0 {
            return Err(StepError::BadTimeStep(dt));
        }
        let n = self.n_particles();
        if state.x.len() != n || state.v.len() != n || state.f_ext.len() != n {
            return Err(StepError::StateShape { nodes: n, x: state.x.len(), v: state.v.len(), f_ext: state.f_ext.len() });
        }
        if ws.len() != n {
            return Err(StepError::WorkspaceShape { nodes: n, workspace: ws.len() });
        }
        for &i in &state.active {
            if i >= n {
                return Err(StepError::ActiveOutOfRange { index: i, n });
            }
            if !is_finite3(&state.f_ext[i]) {
                return Err(StepError::NonFiniteForce { node: i });
            }
        }
        ws.save.clear();
        ws.save.extend(state.active.iter().map(|&i| (state.x[i], state.v[i])));
        // Displacements of the active particles and their (possibly frozen) neighbours, and the
        // list of those particles (each once: `mark` holds a per-call stamp).
        ws.stamp = ws.stamp.wrapping_add(1);
        ws.touched.clear();
        for &i in &state.active {
            for &j in std::iter::once(&i).chain(self.neighbours(i)) {
                if ws.mark[j] != ws.stamp {
                    ws.mark[j] = ws.stamp;
                    ws.touched.push(j);
                    ws.u[j] = p4(&(state.x[j] - self.rest[j]));
                    ws.v[j] = p4(&state.v[j]);
                }
            }
        }
        let h = dt / substeps as f64;
        pair_loop::run_substeps(self, state, ws, h, substeps);
        let bad = state.active.iter().copied().find(|&i| !is_finite3(&state.x[i]) || !is_finite3(&state.v[i]));
        if let Some(node) = bad {
            for (k, &i) in state.active.iter().enumerate() {
                (state.x[i], state.v[i]) = ws.save[k];
            }
            return Err(StepError::NonFinite { what: "particle position or velocity", node, time: state.t });
        }
        state.t += dt;
        Ok(ParticleStepReport { substeps, substep_dt: h })
    }
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
    fn len(&self) -> usize {
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

fn to_p4(v: &[Vec3]) -> Vec<P4> {
    v.iter().map(p4).collect()
}
