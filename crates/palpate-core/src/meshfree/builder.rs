//! The particle body before compilation: [`ParticleModelBuilder`] validates the particles and
//! precomputes, once, what the step reads (neighbours, volumes, MLS gradients, hourglass weights
//! and the stable explicit time step). See the module docs of [`crate::meshfree`].

use super::kernel::Kernel;
use super::model::{to_p4, ParticleModel};
use super::neighbors::neighbours_within_limited;
use super::pair_loop::p4;
use crate::error::{MaterialError, ModelError};
use crate::material::{Law, Material};
use crate::math::{is_finite3, Mat3, Vec3};

/// Default dimensionless hourglass-control stiffness `kappa` (see [`crate::meshfree`]).
pub const DEFAULT_HOURGLASS: f64 = 0.5;
/// Default relative kernel weight below which a neighbour is not paired.
pub const DEFAULT_MIN_WEIGHT: f64 = 1e-3;
/// Smallest accepted ratio of the moment matrix's eigenvalues (its conditioning).
const MIN_MOMENT_CONDITION: f64 = 1e-4;
/// What one neighbour pair costs the model in bytes (its index twice, kernel weight, rest offset,
/// gradient and hourglass vectors), for the memory budget ([`crate::limits`]).
const BYTES_PER_PAIR: f64 = 136.0;

/// With [`ParticleModelBuilder::fix_unsupported`], particles with fewer neighbours than this are
/// held (a least-squares gradient over fewer than 6 neighbours fits them almost exactly: little
/// stiffness against their own motion).
pub const HELD_BELOW_NEIGHBOURS: usize = 6;

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
    fix_unsupported: bool,
    mass_scaling: Option<f64>,
}

impl ParticleModelBuilder {
    /// Particles at rest positions `positions` \[m\] with masses `masses` \[kg\], of `material`,
    /// interacting within the kernel support radius `support` \[m\] (typically 1.5 - 2 particle spacings).
    pub fn new(positions: Vec<Vec3>, masses: Vec<f64>, material: Material, support: f64) -> Self {
        ParticleModelBuilder {
            positions,
            masses,
            material,
            support,
            kernel: Kernel::default(),
            fixed: vec![],
            gravity: Vec3::zeros(),
            hourglass: DEFAULT_HOURGLASS,
            min_weight: DEFAULT_MIN_WEIGHT,
            fix_unsupported: false,
            mass_scaling: None,
        }
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
    /// Hold, instead of refusing, the particles whose neighbours do not span 3D (a lattice's
    /// lone corners in a thin part of a shell): they get no stress and no hourglass term (their
    /// deformation gradient is undefined) and are fixed, so the step never moves them
    /// ([`ParticleModel::unsupported`] lists them). Off by default: a standalone body refuses them.
    pub fn fix_unsupported(mut self, on: bool) -> Self {
        self.fix_unsupported = on;
        self
    }
    /// Selective mass scaling (`mass_scaling.rs`, off by default): the free particles whose
    /// Gershgorin rate `G_i / m_i` is above the `quantile` (in (0, 1]) of all of them get the mass
    /// that brings them down to it, which bounds the body's `omega_max^2` by that rate and lengthens
    /// its stable step. [`ParticleModel::mass_scaling`] reports the mass added.
    pub fn mass_scaling(mut self, quantile: f64) -> Self {
        self.mass_scaling = Some(quantile);
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
        let ParticleModelBuilder {
            positions: rest,
            masses,
            material,
            support: h,
            kernel,
            fixed,
            gravity,
            hourglass,
            min_weight,
            fix_unsupported,
            mass_scaling,
        } = self;
        // The pair loop (pair_loop/, with its AVX2 copy) evaluates the St. Venant-Kirchhoff
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
        if let Some(q) = mass_scaling {
            if !(q > 0.0 && q <= 1.0) {
                return Err(ModelError::Parameter { name: "mass scaling quantile", value: q, reason: "must lie in (0, 1]" });
            }
            // Added mass is inertia, not weight: with gravity the scaled particles would weigh
            // more. Not needed by the hybrid shell (no gravity), so refused rather than half done.
            if gravity != Vec3::zeros() {
                return Err(ModelError::Parameter {
                    name: "mass scaling quantile",
                    value: q,
                    reason: "mass scaling with gravity is not supported (the added mass would weigh)",
                });
            }
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

        // Each pair costs the model ~130 bytes (index, weights, gradients, rest offsets), refused
        // over the memory budget before the lists grow (a radius of many spacings).
        let (ptr, nbr) = neighbours_within_limited(&rest, h, BYTES_PER_PAIR)?;
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
        let mut unsupported = Vec::new();
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
            // Held when asked: too few neighbours to span 3D, or so few (under
            // HELD_BELOW_NEIGHBOURS) that the fit passes through them exactly and the particle is
            // barely constrained (it drifts and, pressed, diverges; seen on lattice corners).
            if (e - s < HELD_BELOW_NEIGHBOURS || !(lo > MIN_MOMENT_CONDITION * hi)) && fix_unsupported {
                // No gradient, no stress, no hourglass term: r_inv, hg_c, g stay zero.
                is_fixed[i] = true;
                unsupported.push(i);
                for p in s..e {
                    q[p] = hw[p] * xr[p];
                    qsum[i] += q[p];
                }
                continue;
            }
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
            // The eigenvalue test above passes a matrix whose entries underflow or overflow (masses
            // near 1e-150 make volumes of 1e-153): an error, not a panic.
            let Some(a_inv) = a.try_inverse().filter(|m| m.iter().all(|v| v.is_finite())) else {
                return Err(ModelError::Particle {
                    particle: i,
                    reason: format!(
                        "its moment matrix cannot be inverted (volume {:e} m^3 from mass {:e} kg): masses and density must give volumes of a physical size",
                        volume[i], masses[i]
                    ),
                });
            };
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
            unsupported,
            gravity,
            material,
            kernel,
            support: h,
            hourglass,
            stable_dt: 0.0,
            omega_max: 0.0,
            damping_max: 0.0,
            scaling: Default::default(),
        };
        model.compute_stable_dt();
        if let Some(q) = mass_scaling {
            model.scale_masses_if_worth_it(q);
        }
        // An extreme stiffness or mass (E = 1e150 Pa) overflows the frequency bound to inf or
        // NaN, which made the stable step infinite: one sub-step of any dt, silently wrong.
        if !(model.stable_dt > 0.0 && model.stable_dt.is_finite() && model.omega_max.is_finite()) {
            return Err(ModelError::Parameter {
                name: "stable time step",
                value: model.stable_dt,
                reason: "not a positive finite number (the material's stiffness over the masses overflows or vanishes: check young, density and the masses)",
            });
        }
        Ok(model)
    }
}
