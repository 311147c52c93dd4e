//! A positive semi-definite approximation of the element's elastic stiffness at a deformed state,
//! for the quasi-Newton integrator's refreshed initial Hessian (`integrate/quasi_newton.rs`):
//! it is factorised, so it must be positive definite however the element is deformed, even
//! inverted; it need not be exact (the L-BFGS corrections and the line search take care of that).
//!
//! * **St. Venant-Kirchhoff**: the tangent splits into a material part `P_mat` (the linear map
//!   `dF -> dF S + F C : sym(F^T dF)`'s second term, `J^T C J` with `C` the positive isotropic
//!   elasticity tensor: always positive semi-definite) and a geometric part `(g_a . S g_b) I`,
//!   indefinite where the stress `S` is compressive. Here `S` is replaced by its positive part
//!   `S+` (eigenvalues clamped at 0), the usual Gauss-Newton-like fix (e.g. Teran et al. 2005).
//! * **Neo-Hookean**: `mu (g_a . g_b) I + max(h'', 0) (cof F g_a)(cof F g_b)^T`, positive
//!   semi-definite; the cofactor-derivative term `h'(J) [F (g_b x g_a)]_x` is dropped: its blocks
//!   are skew, so it is indefinite on its own, and under compression `|h'|` grows like `lambda/J`
//!   and makes the whole tangent indefinite. (At rest this approximation has `(lambda + mu)
//!   g_a g_b^T` where the exact tangent has `lambda g_a g_b^T + mu g_b g_a^T`: the refresh only
//!   happens far from rest.)
//!
//! Blocks are returned with palpate's sign convention for `df/dx` (negative semi-definite).

use crate::fem::tet4::{deformation_gradient, svk_form_blocks, TetRest};
use crate::material::{self, neo_hookean, Law, Material};
use crate::math::{Mat3, Vec3};

/// The positive part of a symmetric stress (its eigenvalues clamped at 0): the geometric
/// term's stress in the definite tangent (module docs), the linear tet's and the quadratic's.
pub(crate) fn positive_part(s: &Mat3) -> Mat3 {
    let eig = s.symmetric_eigen();
    let clamped = eig.eigenvalues.map(|l| l.max(0.0));
    eig.eigenvectors * Mat3::from_diagonal(&clamped) * eig.eigenvectors.transpose()
}

/// Negative semi-definite approximation of `d f / d x` (3x3 blocks) at positions `x` \[m\].
pub fn definite_jacobian(x: &[Vec3; 4], rest: &TetRest, m: &Material) -> [[Mat3; 4]; 4] {
    let f = deformation_gradient(x, rest);
    let (lam, mu) = (m.lambda(), m.mu());
    match m.law() {
        Law::StVenantKirchhoff => {
            let s = material::stress(m, &material::green_strain(&f));
            svk_form_blocks(&f, &positive_part(&s), lam, mu, rest, -rest.volume)
        }
        Law::NeoHookean => {
            let g = rest.grads();
            let cof = neo_hookean::cofactor(&f);
            let j = f.column(0).dot(&cof.column(0));
            let h2 = neo_hookean::volumetric(lam, mu, j).2.max(0.0);
            let cg: [Vec3; 4] = [cof * g[0], cof * g[1], cof * g[2], cof * g[3]];
            let mut k = [[Mat3::zeros(); 4]; 4];
            for a in 0..4 {
                for b in 0..4 {
                    k[a][b] = -rest.volume * (Mat3::from_diagonal_element(mu * g[a].dot(&g[b])) + h2 * cg[a] * cg[b].transpose());
                }
            }
            k
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Damping, Elasticity};
    use nalgebra::DMatrix;

    fn to_dense(k: &[[Mat3; 4]; 4]) -> DMatrix<f64> {
        DMatrix::from_fn(12, 12, |r, c| k[r / 3][c / 3][(r % 3, c % 3)])
    }

    /// At rest the St. Venant-Kirchhoff approximation is the exact (linear-elastic) stiffness, and
    /// for both laws, in any state, compressed or inverted, the approximation is negative
    /// semi-definite (what the factorisation needs) where the exact tangent is not.
    #[test]
    fn exact_at_rest_and_semidefinite_everywhere() {
        use crate::fem::tet4::jacobians;
        let u = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.011, 0.001, -0.002),
            Vec3::new(0.002, 0.009, 0.001),
            Vec3::new(-0.001, 0.002, 0.012),
        ];
        let r = TetRest::new(&u);
        let base = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap();
        for law in [Law::StVenantKirchhoff, Law::NeoHookean] {
            let m = base.with_law(law);
            let exact = to_dense(&jacobians(&u, &r, &m).0);
            let approx = to_dense(&definite_jacobian(&u, &r, &m));
            if law == Law::StVenantKirchhoff {
                assert!((&exact - &approx).norm() <= 1e-9 * approx.norm(), "{law:?} at rest");
            }
            for a in [
                Mat3::new(0.5, 0.1, 0.0, 0.0, 0.6, 0.1, 0.0, 0.0, 0.4),  // strong compression
                Mat3::new(1.4, 0.2, 0.0, 0.0, 1.1, -0.1, 0.1, 0.0, 0.3), // mixed
                Mat3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -0.3), // inverted
            ] {
                let x = u.map(|p| a * p);
                let k = to_dense(&definite_jacobian(&x, &r, &m));
                let emax = k.clone().symmetric_eigen().eigenvalues.max();
                let scale = k.norm();
                assert!(emax <= 1e-10 * scale, "{law:?}: eigenvalue {emax:e} > 0 (scale {scale:e})");
                let exact = to_dense(&jacobians(&x, &r, &m).0);
                let emax_exact = exact.symmetric_eigen().eigenvalues.max();
                println!("{law:?}: exact tangent's largest eigenvalue {emax_exact:.3e}, approximation's {emax:.3e}");
            }
        }
    }
}
