//! The stable explicit time step of a particle body: the largest eigenvalues of its
//! rest-linearised stiffness and damping (power iteration) and the central-difference limit.

use super::model::ParticleModel;
use crate::material;
use crate::math::{Mat3, Vec3};

/// Fraction of the critical time step used by the explicit sub-steps.
pub const STABILITY_SAFETY: f64 = 0.9;

impl ParticleModel {
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
            .map(|i| {
                if self.fixed[i] {
                    Vec3::zeros()
                } else {
                    Vec3::new(((i * 7919) % 13) as f64 - 6.0, ((i * 104729) % 11) as f64 - 5.0, ((i * 31) % 7) as f64 - 3.0)
                }
            })
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

    pub(super) fn compute_stable_dt(&mut self) {
        // Power iteration converges from below: keep a 2% margin on the eigenvalue.
        let k_max = 1.02 * self.max_eigenvalue(false);
        let d_max = if self.material.is_undamped() { 0.0 } else { 1.02 * self.max_eigenvalue(true) };
        self.omega_max = k_max.sqrt();
        self.damping_max = d_max;
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
}
