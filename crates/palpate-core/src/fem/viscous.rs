//! The viscous stress of eq. (11) as a discrete dissipation potential over one time step.
//!
//! Backward Euler written as a minimisation (`integrate/potential.rs`) needs the viscous force to
//! be the gradient of a function of the end-of-step positions. palpate takes the strain rate of
//! the step as the difference quotient of the Green strain,
//!
//! ```text
//! nu_h = (E(x) - E(x_n)) / h,        D(x) = h V [ phi/2 tr(nu_h)^2 + psi nu_h : nu_h ],
//! ```
//!
//! `x_n` the positions at the start of the step. Then `-dD/dx_i = -V F S_v(nu_h) grad N_i` is
//! exactly the viscous force of eq. (11) with that strain rate (same form as the elastic force,
//! `E -> E - E_n`, `(lambda, mu) -> (phi, psi) / h`). As `h -> 0`, `nu_h -> dE/dt`, palpate's
//! strain-rate convention (`material/mod.rs`). The discrete rate is objective: a rigid rotation
//! within the step has `E(x) = E(x_n)` and costs nothing (a rate `F^T Fdot` frozen at `x_n`
//! would not be).

use crate::fem::tet4::{deformation_gradient, svk_form_blocks, TetRest};
use crate::material::{self, Material};
use crate::math::{Mat3, Vec3};

/// Dissipation potential `D` \[J\] of one element over a step of `h` \[s\] from `x_n` to `x`
/// \[m\], and the viscous nodal forces `-dD/dx` \[N\]. The material must be damped (else both are 0).
#[inline]
pub fn step_dissipation(x: &[Vec3; 4], x_n: &[Vec3; 4], rest: &TetRest, m: &Material, h: f64) -> (f64, [Vec3; 4]) {
    let d = m.damping();
    let f = deformation_gradient(x, rest);
    let de = material::green_strain(&f) - material::green_strain(&deformation_gradient(x_n, rest));
    let tr = de.trace();
    let energy = rest.volume / h * (0.5 * d.phi * tr * tr + d.psi * de.norm_squared());
    // S_v(nu_h) = phi tr(nu_h) I + 2 psi nu_h, nu_h = dE / h.
    let s = (Mat3::from_diagonal_element(d.phi * tr) + 2.0 * d.psi * de) / h;
    let hm = -rest.volume * (f * s) * rest.dm_inv.transpose();
    let (h1, h2, h3) = (hm.column(0).into_owned(), hm.column(1).into_owned(), hm.column(2).into_owned());
    (energy, [-(h1 + h2 + h3), h1, h2, h3])
}

/// Hessian blocks `d^2 D / dx_a dx_b` (3x3 each, positive at rest) of [`step_dissipation`].
///
/// With `S = S_v(nu_h)` and `F` at `x` it is the St. Venant-Kirchhoff form
/// ([`svk_form_blocks`]) with `(phi, psi) / h` for Lame's constants.
pub fn step_dissipation_hessian(x: &[Vec3; 4], x_n: &[Vec3; 4], rest: &TetRest, m: &Material, h: f64) -> [[Mat3; 4]; 4] {
    let d = m.damping();
    let f = deformation_gradient(x, rest);
    let de = material::green_strain(&f) - material::green_strain(&deformation_gradient(x_n, rest));
    let s = (Mat3::from_diagonal_element(d.phi * de.trace()) + 2.0 * d.psi * de) / h;
    svk_form_blocks(&f, &s, d.phi / h, d.psi / h, rest, rest.volume)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Damping, Elasticity};

    fn mat() -> Material {
        Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping { phi: 3.0, psi: 7.0 }).unwrap()
    }

    fn tets() -> ([Vec3; 4], [Vec3; 4], [Vec3; 4]) {
        let u = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.011, 0.001, -0.002),
            Vec3::new(0.002, 0.009, 0.001),
            Vec3::new(-0.001, 0.002, 0.012),
        ];
        let a = Mat3::new(1.05, 0.02, -0.03, 0.01, 0.97, 0.04, -0.02, 0.03, 1.02);
        let b = Mat3::new(1.1, 0.05, -0.03, 0.02, 0.93, 0.08, -0.04, 0.06, 1.07);
        (u, u.map(|p| a * p), u.map(|p| b * p + Vec3::new(1e-4, 0.0, -2e-4)))
    }

    #[test]
    fn forces_are_minus_the_gradient_and_hessian_matches() {
        let (u, xn, x) = tets();
        let (r, m, h) = (TetRest::new(&u), mat(), 1e-3);
        let (_, f) = step_dissipation(&x, &xn, &r, &m, h);
        let hess = step_dissipation_hessian(&x, &xn, &r, &m, h);
        let scale_h = hess.iter().flatten().map(|b| b.norm()).fold(0.0, f64::max);
        let eps = 1e-8;
        for b in 0..4 {
            for c in 0..3 {
                let (mut xp, mut xm) = (x, x);
                xp[b][c] += eps;
                xm[b][c] -= eps;
                let (ep, fp) = step_dissipation(&xp, &xn, &r, &m, h);
                let (em, fm) = step_dissipation(&xm, &xn, &r, &m, h);
                let fd = -(ep - em) / (2.0 * eps);
                assert!((fd - f[b][c]).abs() <= 1e-6 * f[b].norm(), "force {b},{c}: {fd} vs {}", f[b][c]);
                for a in 0..4 {
                    let col = -(fp[a] - fm[a]) / (2.0 * eps);
                    let err = (col - hess[a][b].column(c)).norm();
                    assert!(err <= 1e-6 * scale_h, "H[{a}][{b}] col {c}: {err}");
                }
            }
        }
    }

    #[test]
    fn matches_the_viscous_stress_for_small_steps_and_ignores_rigid_rotation() {
        let (u, _, x) = tets();
        let (r, m) = (TetRest::new(&u), mat());
        // A velocity field v: over a tiny step the discrete rate tends to eq. (11)'s dE/dt.
        let v = [Vec3::new(0.1, -0.2, 0.05), Vec3::new(0.0, 0.1, 0.2), Vec3::new(-0.1, 0.0, 0.1), Vec3::new(0.2, 0.1, -0.1)];
        let h = 1e-7;
        let xn = [x[0] - h * v[0], x[1] - h * v[1], x[2] - h * v[2], x[3] - h * v[3]];
        let (_, fd) = step_dissipation(&x, &xn, &r, &m, h);
        let full = crate::fem::tet4::forces(&x, Some(&v), &r, &m);
        let elastic = crate::fem::tet4::forces(&x, None, &r, &m);
        for a in 0..4 {
            let fv = full[a] - elastic[a];
            assert!((fd[a] - fv).norm() <= 1e-5 * fv.norm(), "{a}: {} vs {}", fd[a], fv);
        }
        // A rigid rotation of the deformed element within the step dissipates nothing.
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 0.5).into_inner();
        let xr = x.map(|p| rot * p);
        let (e, f) = step_dissipation(&xr, &x, &r, &m, 1e-3);
        assert!(e.abs() < 1e-18 && f.iter().all(|f| f.norm() < 1e-12), "{e}");
    }
}
