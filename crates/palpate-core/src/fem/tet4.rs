//! The linear (4-node) tetrahedron, paper §3.1, as pure functions of plain values.
//!
//! **Rest data.** The paper precomputes `Gamma = B(u)^-1` (eq. 18-21), the inverse of the 4x4
//! matrix of rest coordinates padded with ones. Its rows are `[grad N_j^T | N_j(0)]`: only the
//! shape-function gradients matter for strain and force, so palpate stores the equivalent
//! `Dm^-1` with `Dm = [u1-u0, u2-u0, u3-u0]`, whose rows are `grad N_1 .. grad N_3`
//! (`grad N_0 = -(grad N_1 + grad N_2 + grad N_3)`), and the rest volume `V = det(Dm)/6` (eq. 17).
//!
//! **Kinematics** (eq. 21): `F = sum_j x_j grad N_j^T = Ds Dm^-1`, `Fdot = sum_j v_j grad N_j^T`.
//!
//! **Force convention.** The paper's eq. (22) carries `vol/2` from O'Brien & Hodgins, whose Green
//! strain lacks the 1/2 of eq. (4); combined, it would halve the stiffness. palpate implements
//! the energy-consistent nodal force
//!
//! ```text
//! f_i = -V F (S + S_v) grad N_i,      i = 0..3,
//! ```
//!
//! `S` the elastic stress of eq. (9), `S_v` the viscous stress of eq. (11). The elastic part is
//! exactly minus the gradient of the element's strain energy `V (mu E:E + lambda/2 tr(E)^2)`
//! (checked by finite differences in the tests), so small loads reproduce linear elasticity with
//! the same Lame constants, and the forces of an element sum to zero (momentum conservation).
//!
//! **Laws.** Every function dispatches on [`Material::law`] with one `match` per element (no
//! trait object, no allocation): St. Venant-Kirchhoff (above, the paper's law and the default) or
//! the compressible Neo-Hookean law of [`crate::material::neo_hookean`] (Bonet & Wood 2008, ch. 6;
//! FEBio's `neo-Hookean`), whose first Piola stress is `P = mu F + h'(J) cof F`, `J = det F`,
//! with `h` continued below `J_MIN = 0.1` by its second-order Taylor polynomial so that inverted
//! elements (`J <= 0`) get a finite restoring force (see that module for why 0.1). Its element
//! force is `f_i = -V (P + F S_v) grad N_i`, with the same viscous stress as SVK.

use crate::material::{self, neo_hookean, Law, Material};
use crate::math::{Mat3, Vec3};

/// Rest data of one tetrahedron.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TetRest {
    /// Rest volume \[m^3\] (positive for a positively oriented tet).
    pub volume: f64,
    /// `Dm^-1` \[1/m\]: its rows are the gradients of the shape functions N_1..N_3.
    pub dm_inv: Mat3,
}

impl TetRest {
    /// Rest data from the four rest positions \[m\]. The caller guarantees a non-degenerate tet.
    pub fn new(u: &[Vec3; 4]) -> TetRest {
        let dm = Mat3::from_columns(&[u[1] - u[0], u[2] - u[0], u[3] - u[0]]);
        let volume = dm.determinant() / 6.0;
        let dm_inv = dm.try_inverse().unwrap_or_else(Mat3::zeros);
        TetRest { volume, dm_inv }
    }

    /// Shape-function gradients `grad N_0 .. grad N_3` \[1/m\] (constant over the element).
    #[inline]
    pub fn grads(&self) -> [Vec3; 4] {
        let g1 = self.dm_inv.row(0).transpose();
        let g2 = self.dm_inv.row(1).transpose();
        let g3 = self.dm_inv.row(2).transpose();
        [-(g1 + g2 + g3), g1, g2, g3]
    }
}

/// Deformation gradient `F = Ds Dm^-1` of positions `x` (eq. 21). Applied to velocities it gives `Fdot`.
#[inline]
pub fn deformation_gradient(x: &[Vec3; 4], rest: &TetRest) -> Mat3 {
    let ds = Mat3::from_columns(&[x[1] - x[0], x[2] - x[0], x[3] - x[0]]);
    ds * rest.dm_inv
}

/// Strain energy of the element \[J\]: `V psi(F)`; for St. Venant-Kirchhoff
/// `V (mu E:E + lambda/2 tr(E)^2)`, for Neo-Hookean `V (mu/2 (I1 - 3) + h(J))`.
#[inline]
pub fn strain_energy(x: &[Vec3; 4], rest: &TetRest, m: &Material) -> f64 {
    let f = deformation_gradient(x, rest);
    match m.law() {
        Law::StVenantKirchhoff => rest.volume * material::energy_density(m, &material::green_strain(&f)),
        Law::NeoHookean => rest.volume * neo_hookean_energy(m, &f),
    }
}

/// Elastic first Piola-Kirchhoff stress `P(F)` \[Pa\] of the element at positions `x`, and its
/// strain energy density `psi(F)` \[J/m^3\] (per rest volume): for post-processing.
pub fn elastic_stress(x: &[Vec3; 4], rest: &TetRest, m: &Material) -> (Mat3, f64) {
    let f = deformation_gradient(x, rest);
    match m.law() {
        Law::StVenantKirchhoff => {
            let e = material::green_strain(&f);
            (f * material::stress(m, &e), material::energy_density(m, &e))
        }
        Law::NeoHookean => (neo_hookean_piola(m, &f), neo_hookean_energy(m, &f)),
    }
}

/// Von Mises equivalent stress \[Pa\] of a symmetric stress tensor: `sqrt(3/2 s:s)`, `s` its
/// deviatoric part.
pub fn von_mises(sigma: &Mat3) -> f64 {
    let s = sigma - Mat3::identity() * (sigma.trace() / 3.0);
    (1.5 * s.component_mul(&s).sum()).sqrt()
}

/// Viscous second Piola stress `S_v(nu)`, `nu = sym(F^T Fdot)`, of nodal velocities `v` (eq. 10-11).
#[inline]
fn viscous(f: &Mat3, v: &[Vec3; 4], rest: &TetRest, m: &Material) -> Mat3 {
    let f_dot = deformation_gradient(v, rest);
    material::viscous_stress(m, &material::strain_rate(f, &f_dot))
}

/// Nodal forces `[-(h1+h2+h3), h1, h2, h3]` from `H = -V P Dm^-T` (column j: the force on node j).
#[inline]
fn nodal_forces(p: &Mat3, rest: &TetRest) -> [Vec3; 4] {
    let h = -rest.volume * p * rest.dm_inv.transpose();
    let (h1, h2, h3) = (h.column(0).into_owned(), h.column(1).into_owned(), h.column(2).into_owned());
    [-(h1 + h2 + h3), h1, h2, h3]
}

/// Nodal forces \[N\] `f_i = -V (P + F S_v) grad N_i` of positions `x` \[m\] and velocities
/// `v` \[m/s\] (`P = F S` for St. Venant-Kirchhoff). Pass `v = None` for the elastic force alone.
#[inline]
pub fn forces(x: &[Vec3; 4], v: Option<&[Vec3; 4]>, rest: &TetRest, m: &Material) -> [Vec3; 4] {
    let f = deformation_gradient(x, rest);
    let s_v = v.map(|v| viscous(&f, v, rest, m));
    let p = match m.law() {
        Law::StVenantKirchhoff => {
            let mut s = material::stress(m, &material::green_strain(&f));
            if let Some(s_v) = s_v {
                s += s_v;
            }
            f * s
        }
        Law::NeoHookean => {
            let mut p = neo_hookean_piola(m, &f);
            if let Some(s_v) = s_v {
                p += f * s_v;
            }
            p
        }
    };
    nodal_forces(&p, rest)
}

/// `neo_hookean::piola`, kept out of line: inlined (with its `ln`, a libm call) into the
/// assembly loops, it made the St. Venant-Kirchhoff path of the same loops ~13% slower
/// (`Model::internal_forces`, 96k tets); out of line, SVK runs as fast as before the law option.
#[inline(never)]
fn neo_hookean_piola(m: &Material, f: &Mat3) -> Mat3 {
    neo_hookean::piola(m, f)
}

/// `neo_hookean::energy_density`, out of line for the same reason as [`neo_hookean_piola`].
#[inline(never)]
fn neo_hookean_energy(m: &Material, f: &Mat3) -> f64 {
    neo_hookean::energy_density(m, f)
}

/// `neo_hookean::energy_piola`, out of line for the same reason as [`neo_hookean_piola`].
#[inline(never)]
fn neo_hookean_energy_piola(m: &Material, f: &Mat3) -> (f64, Mat3, f64) {
    neo_hookean::energy_piola(m, f)
}

/// Elastic energy \[J\], elastic nodal forces \[N\] and `det F` of positions `x` \[m\], in one pass
/// (the incremental-potential integrator evaluates all three at every trial point; `det F <= 0`
/// marks an inverted element).
#[inline]
pub fn elastic_energy_forces(x: &[Vec3; 4], rest: &TetRest, m: &Material) -> (f64, [Vec3; 4], f64) {
    let f = deformation_gradient(x, rest);
    match m.law() {
        Law::StVenantKirchhoff => {
            let e = material::green_strain(&f);
            let energy = rest.volume * material::energy_density(m, &e);
            let s = material::stress(m, &e);
            (energy, nodal_forces(&(f * s), rest), f.determinant())
        }
        Law::NeoHookean => {
            let (w, p, j) = neo_hookean_energy_piola(m, &f);
            (rest.volume * w, nodal_forces(&p, rest), j)
        }
    }
}

/// Force Jacobian blocks `K_ab = d f_a / d x_b` (3x3 each) of the elastic force at positions `x`,
/// and, if the material is damped, `D_ab = d f_a / d v_b` of the viscous force (its dependence on
/// `x` through `F` is not included).
///
/// With `g = grad N`, `S` the elastic stress and `F` the deformation gradient, for St. Venant-Kirchhoff:
/// `K_ab = -V [ (g_a . S g_b) I + lambda (F g_a)(F g_b)^T + mu (g_a . g_b) F F^T + mu (F g_b)(F g_a)^T ]`;
/// for Neo-Hookean (from `dP[dF] = mu dF + h'' (cof F : dF) cof F + h' F x dF`, see
/// [`crate::material::neo_hookean`]; `F x dF` the tensor cross product, the derivative of `cof`):
/// `K_ab = -V [ mu (g_a . g_b) I + h''(J) (cof F g_a)(cof F g_b)^T + h'(J) [F (g_b x g_a)]_x ]`,
/// `[w]_x` the cross-product matrix. For both laws `D_ab` is
/// `-V [ phi (F g_a)(F g_b)^T + psi (g_a . g_b) F F^T + psi (F g_b)(F g_a)^T ]`.
/// At rest (`F = I`) both `K` are the stiffness matrix of linear elasticity (negated).
pub fn jacobians(x: &[Vec3; 4], rest: &TetRest, m: &Material) -> ([[Mat3; 4]; 4], Option<[[Mat3; 4]; 4]>) {
    let f = deformation_gradient(x, rest);
    let g = rest.grads();
    let vol = rest.volume;
    let (lam, mu) = (m.lambda(), m.mu());
    let k = match m.law() {
        Law::StVenantKirchhoff => {
            let s = material::stress(m, &material::green_strain(&f));
            svk_form_blocks(&f, &s, lam, mu, rest, -vol)
        }
        Law::NeoHookean => {
            let cof = neo_hookean::cofactor(&f);
            let j = f.column(0).dot(&cof.column(0));
            let (_, h1, h2) = neo_hookean::volumetric(lam, mu, j);
            let cg: [Vec3; 4] = [cof * g[0], cof * g[1], cof * g[2], cof * g[3]];
            let mut k = [[Mat3::zeros(); 4]; 4];
            for a in 0..4 {
                for b in 0..4 {
                    let geo = neo_hookean::cross_matrix(&(f * g[b].cross(&g[a])));
                    k[a][b] = -vol * (Mat3::from_diagonal_element(mu * g[a].dot(&g[b])) + h2 * cg[a] * cg[b].transpose() + h1 * geo);
                }
            }
            k
        }
    };
    // The viscous stress F S_v has the St. Venant-Kirchhoff form for both laws, without stress term.
    let d = (!m.is_undamped()).then(|| {
        let dmp = m.damping();
        svk_form_blocks(&f, &Mat3::zeros(), dmp.phi, dmp.psi, rest, -vol)
    });
    (k, d)
}

/// The St. Venant-Kirchhoff-form stiffness blocks, with `g = grad N` and a factor `c`:
/// `c [ (g_a . S g_b) I + l (F g_a)(F g_b)^T + m (g_a . g_b) F F^T + m (F g_b)(F g_a)^T ]`
/// (`c = V`: a Hessian, positive at rest; `c = -V`: a force Jacobian).
/// The one place this form is written: the SVK tangent is `-` it with the stress `S` and Lame's
/// `(l, m)`; the viscous Jacobian with `S = 0` and the viscosities `(phi, psi)`; the step's
/// dissipation Hessian (`viscous.rs`) and the definite tangent (`tangent.rs`) use it too.
pub fn svk_form_blocks(f: &Mat3, s: &Mat3, l: f64, m: f64, rest: &TetRest, c: f64) -> [[Mat3; 4]; 4] {
    svk_blocks(f, s, l, m, &rest.grads(), c)
}

/// [`svk_form_blocks`] for any element's shape-function gradients `g` at one point (`c` its
/// weight or minus it): the linear tet's with its four, a quadrature point of the quadratic
/// tet's (`fem/tet10.rs`) with its ten.
pub fn svk_blocks<const N: usize>(f: &Mat3, s: &Mat3, l: f64, m: f64, g: &[Vec3; N], c: f64) -> [[Mat3; N]; N] {
    let fg: [Vec3; N] = std::array::from_fn(|a| f * g[a]);
    let sg: [Vec3; N] = std::array::from_fn(|a| s * g[a]);
    let fft = f * f.transpose();
    let mut out = [[Mat3::zeros(); N]; N];
    for a in 0..N {
        for b in 0..N {
            let gg = g[a].dot(&g[b]);
            out[a][b] = c * (Mat3::from_diagonal_element(g[a].dot(&sg[b])) + l * fg[a] * fg[b].transpose() + (m * gg) * fft + m * fg[b] * fg[a].transpose());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Damping, Elasticity};

    fn mat(damped: bool) -> Material {
        let d = if damped { Damping { phi: 3.0, psi: 7.0 } } else { Damping::NONE };
        Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, d).unwrap()
    }

    fn rest_tet() -> [Vec3; 4] {
        [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.011, 0.001, -0.002),
            Vec3::new(0.002, 0.009, 0.001),
            Vec3::new(-0.001, 0.002, 0.012),
        ]
    }

    fn deformed() -> [Vec3; 4] {
        let u = rest_tet();
        let a = Mat3::new(1.1, 0.05, -0.03, 0.02, 0.93, 0.08, -0.04, 0.06, 1.07);
        let w = [Vec3::new(1e-4, -2e-4, 3e-4), Vec3::new(-3e-4, 1e-4, 2e-4), Vec3::new(2e-4, 2e-4, -1e-4), Vec3::new(0.0, -1e-4, 1e-4)];
        [a * u[0] + w[0], a * u[1] + w[1], a * u[2] + w[2], a * u[3] + w[3]]
    }

    #[test]
    fn gamma_equivalence_rest_volume_and_gradients() {
        let u = rest_tet();
        let r = TetRest::new(&u);
        // grad N_j . (u_k - u_0) = delta_jk - delta_j0 (shape functions interpolate the nodes).
        let g = r.grads();
        for j in 0..4 {
            for k in 0..4 {
                let expect = (j == k) as i32 as f64 - (j == 0) as i32 as f64;
                assert!((g[j].dot(&(u[k] - u[0])) - expect).abs() < 1e-12);
            }
        }
        let vol = crate::mesh::signed_volume(&u[0], &u[1], &u[2], &u[3]);
        assert!((r.volume - vol).abs() < 1e-20);
    }

    #[test]
    fn force_is_minus_energy_gradient() {
        let m = mat(false);
        let r = TetRest::new(&rest_tet());
        let x = deformed();
        let f = forces(&x, None, &r, &m);
        let h = 1e-8;
        for a in 0..4 {
            for c in 0..3 {
                let (mut xp, mut xm) = (x, x);
                xp[a][c] += h;
                xm[a][c] -= h;
                let fd = -(strain_energy(&xp, &r, &m) - strain_energy(&xm, &r, &m)) / (2.0 * h);
                assert!((fd - f[a][c]).abs() <= 1e-6 * f[a].norm().max(1e-12), "node {a} comp {c}: fd {fd} vs {}", f[a][c]);
            }
        }
    }

    /// `K_ab` and `D_ab` of [`jacobians`] against central differences of [`forces`] at `x`, `v`
    /// (position step 1e-8 m; velocity step `hv`: the viscous force is linear in `v`, so a large
    /// step is exact and keeps the difference above the round-off of a large elastic force).
    pub(super) fn check_jacobians_fd(x: &[Vec3; 4], v: &[Vec3; 4], r: &TetRest, m: &Material, hv: f64, name: &str) {
        let (k, d) = jacobians(x, r, m);
        let d = d.expect("a damped material");
        let h = 1e-8;
        let elastic = |x: &[Vec3; 4]| forces(x, None, r, m);
        let viscous = |v: &[Vec3; 4]| {
            let fv = forces(x, Some(v), r, m);
            let fe = forces(x, None, r, m);
            [fv[0] - fe[0], fv[1] - fe[1], fv[2] - fe[2], fv[3] - fe[3]]
        };
        let scale_k = k.iter().flatten().map(|b| b.norm()).fold(0.0, f64::max);
        let scale_d = d.iter().flatten().map(|b| b.norm()).fold(0.0, f64::max);
        for b in 0..4 {
            for c in 0..3 {
                let (mut xp, mut xm) = (*x, *x);
                xp[b][c] += h;
                xm[b][c] -= h;
                let (fp, fm) = (elastic(&xp), elastic(&xm));
                let (mut vp, mut vm) = (*v, *v);
                vp[b][c] += hv;
                vm[b][c] -= hv;
                let (gp, gm) = (viscous(&vp), viscous(&vm));
                for a in 0..4 {
                    let col = (fp[a] - fm[a]) / (2.0 * h);
                    let err = (col - k[a][b].column(c)).norm();
                    assert!(err <= 1e-6 * scale_k, "{name}: K[{a}][{b}] col {c}: {err:e} of {scale_k:e}");
                    let col = (gp[a] - gm[a]) / (2.0 * hv);
                    let err = (col - d[a][b].column(c)).norm();
                    assert!(err <= 1e-6 * scale_d, "{name}: D[{a}][{b}] col {c}: {err:e}");
                }
            }
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let v = [Vec3::new(0.1, -0.2, 0.05), Vec3::new(0.0, 0.1, 0.2), Vec3::new(-0.1, 0.0, 0.1), Vec3::new(0.2, 0.1, -0.1)];
        check_jacobians_fd(&deformed(), &v, &TetRest::new(&rest_tet()), &mat(true), 1e-8, "SVK");
    }

    #[test]
    fn rigid_motion_gives_zero_force_and_rigid_velocity_zero_viscous_force() {
        let m = mat(true);
        let u = rest_tet();
        let r = TetRest::new(&u);
        let rot = nalgebra::Rotation3::from_euler_angles(0.7, -1.1, 2.3).into_inner();
        let t = Vec3::new(0.3, -0.2, 0.5);
        let x = u.map(|p| rot * p + t);
        // Rigid velocity field v = w x (x - c) + v0 at the rotated configuration.
        let w = Vec3::new(1.5, -0.4, 2.0);
        let v = x.map(|p| w.cross(&p) + Vec3::new(0.1, 0.2, -0.3));
        let f = forces(&x, Some(&v), &r, &m);
        let scale = r.volume * m.lambda() / 0.01; // force of a unit strain on this element
        for fi in f {
            assert!(fi.norm() <= 1e-10 * scale, "{}", fi.norm());
        }
    }

    #[test]
    fn element_forces_sum_to_zero() {
        let m = mat(true);
        let r = TetRest::new(&rest_tet());
        let x = deformed();
        let v = x.map(|p| Vec3::new(p.y, -p.z, p.x) * 10.0);
        let f = forces(&x, Some(&v), &r, &m);
        let s: Vec3 = f.iter().sum();
        assert!(s.norm() <= 1e-12 * f[0].norm());
    }
}

/// Neo-Hookean element checks. What each catches:
/// * `nh_forces_are_minus_energy_gradient`: a Piola stress that is not `dpsi/dF` (wrong `h'`,
///   `F^-T` for `cof F`, a sign error, a missing `mu F`), or an extension below `J_MIN` whose
///   slope does not match its energy; at a mild stretch, a strong compression (J ~ 0.3), below
///   `J_MIN` (J ~ 0.05) and an inverted element (J < 0).
/// * `nh_jacobians_match_finite_differences`: a wrong or missing term of `K_ab` (the `h''` rank-one
///   term, the `h' [F (g_b x g_a)]_x` term with the wrong order of the cross product, i.e. its
///   transpose, or the SVK geometric term left in), at the same four states, with damping on.
/// * `nh_rest_and_rigid_rotation_are_stress_free`: `h'(1) != -mu` (a residual pressure at rest),
///   or a law that is not frame-invariant.
/// * `nh_rest_stiffness_equals_svk`: Lame constants used differently from SVK (e.g. `lambda/2`,
///   or `h''(1) != lambda + mu`), which would change every small-load result.
/// * `nh_small_strain_forces_agree_with_svk_to_second_order`: a law that differs from SVK at
///   first order in the strain (then the difference would scale like the force, not its square).
/// * `nh_element_forces_sum_to_zero`: a force that is not `-V P grad N_i` for all four nodes.
#[cfg(test)]
mod neo_hookean_tests {
    use super::*;
    use crate::material::{Damping, Elasticity, Law};

    fn mat(law: Law, damped: bool) -> Material {
        let d = if damped { Damping { phi: 3.0, psi: 7.0 } } else { Damping::NONE };
        Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, d).unwrap().with_law(law)
    }

    fn rest_tet() -> [Vec3; 4] {
        [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.011, 0.001, -0.002),
            Vec3::new(0.002, 0.009, 0.001),
            Vec3::new(-0.001, 0.002, 0.012),
        ]
    }

    /// Positions `A u + w` with `A` a generic stretch/shear scaled to `det A = j` (one axis
    /// reflected for `j < 0`) and small nodal offsets `w`; returns them with the element's `det F`.
    fn configuration(j: f64) -> ([Vec3; 4], f64) {
        let u = rest_tet();
        let a = Mat3::new(1.1, 0.05, -0.03, 0.02, 0.93, 0.08, -0.04, 0.06, 1.07);
        let mut a = a * (j.abs() / a.determinant()).cbrt();
        if j < 0.0 {
            a.set_row(2, &(-a.row(2)));
        }
        let w = [Vec3::new(1e-5, -2e-5, 3e-5), Vec3::new(-3e-5, 1e-5, 2e-5), Vec3::new(2e-5, 2e-5, -1e-5), Vec3::new(0.0, -1e-5, 1e-5)];
        let x = [a * u[0] + w[0], a * u[1] + w[1], a * u[2] + w[2], a * u[3] + w[3]];
        let det = deformation_gradient(&x, &TetRest::new(&u)).determinant();
        (x, det)
    }

    /// (name, target J, accepted range of the actual det F).
    const STATES: [(&str, f64, (f64, f64)); 4] = [
        ("mild (J ~ 1.05)", 1.05, (0.95, 1.15)),
        ("strong compression (J ~ 0.3)", 0.3, (0.25, 0.35)),
        ("below J_MIN (J ~ 0.05)", 0.05, (0.02, 0.08)),
        ("inverted (J ~ -0.2)", -0.2, (-0.3, -0.1)),
    ];

    #[test]
    fn nh_forces_are_minus_energy_gradient() {
        let m = mat(Law::NeoHookean, false);
        let r = TetRest::new(&rest_tet());
        for (name, j, (lo, hi)) in STATES {
            let (x, det) = configuration(j);
            assert!(det > lo && det < hi, "{name}: set-up gives det F = {det}");
            let f = forces(&x, None, &r, &m);
            let (w, f2, det2) = elastic_energy_forces(&x, &r, &m);
            assert!((w - strain_energy(&x, &r, &m)).abs() <= 1e-12 * w.abs() && (det2 - det).abs() <= 1e-12);
            let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
            let h = 1e-8;
            for a in 0..4 {
                assert!((f2[a] - f[a]).norm() <= 1e-12 * scale, "{name}: elastic_energy_forces != forces");
                for c in 0..3 {
                    let (mut xp, mut xm) = (x, x);
                    xp[a][c] += h;
                    xm[a][c] -= h;
                    let fd = -(strain_energy(&xp, &r, &m) - strain_energy(&xm, &r, &m)) / (2.0 * h);
                    assert!((fd - f[a][c]).abs() <= 1e-6 * scale, "{name}: node {a} comp {c}: fd {fd} vs {}", f[a][c]);
                }
            }
        }
    }

    #[test]
    fn nh_jacobians_match_finite_differences() {
        let m = mat(Law::NeoHookean, true);
        let r = TetRest::new(&rest_tet());
        let v = [Vec3::new(0.1, -0.2, 0.05), Vec3::new(0.0, 0.1, 0.2), Vec3::new(-0.1, 0.0, 0.1), Vec3::new(0.2, 0.1, -0.1)];
        for (name, j, _) in STATES {
            let (x, _) = configuration(j);
            super::tests::check_jacobians_fd(&x, &v, &r, &m, 1.0, name);
        }
    }

    #[test]
    fn nh_rest_and_rigid_rotation_are_stress_free() {
        let m = mat(Law::NeoHookean, false);
        assert_eq!(neo_hookean::piola(&m, &Mat3::identity()), Mat3::zeros());
        assert_eq!(neo_hookean::energy_density(&m, &Mat3::identity()), 0.0);
        let u = rest_tet();
        let r = TetRest::new(&u);
        let scale = r.volume * m.lambda() / 0.01; // force of a unit strain on this element
        for fi in forces(&u, None, &r, &m) {
            assert!(fi.norm() <= 1e-12 * scale, "rest: {}", fi.norm());
        }
        let rot = nalgebra::Rotation3::from_euler_angles(0.7, -1.1, 2.3).into_inner();
        let x = u.map(|p| rot * p + Vec3::new(0.3, -0.2, 0.5));
        for fi in forces(&x, None, &r, &m) {
            assert!(fi.norm() <= 1e-10 * scale, "rotated: {}", fi.norm());
        }
        assert!(strain_energy(&x, &r, &m).abs() <= 1e-12 * scale * 0.01);
    }

    #[test]
    fn nh_rest_stiffness_equals_svk() {
        let u = rest_tet();
        let r = TetRest::new(&u);
        let (k_nh, d_nh) = jacobians(&u, &r, &mat(Law::NeoHookean, true));
        let (k_svk, d_svk) = jacobians(&u, &r, &mat(Law::StVenantKirchhoff, true));
        let scale = k_svk.iter().flatten().map(|b| b.norm()).fold(0.0, f64::max);
        for a in 0..4 {
            for b in 0..4 {
                assert!((k_nh[a][b] - k_svk[a][b]).norm() <= 1e-12 * scale, "K[{a}][{b}]");
                assert_eq!(d_nh.unwrap()[a][b], d_svk.unwrap()[a][b]);
            }
        }
    }

    #[test]
    fn nh_small_strain_forces_agree_with_svk_to_second_order() {
        let u = rest_tet();
        let r = TetRest::new(&u);
        let (nh, svk) = (mat(Law::NeoHookean, false), mat(Law::StVenantKirchhoff, false));
        let g = Mat3::new(0.3, -0.5, 0.2, 0.4, -0.1, 0.6, -0.2, 0.3, 0.5); // generic, not symmetric
        let diff = |eps: f64| {
            let a = Mat3::identity() + eps * g;
            let x = u.map(|p| a * p);
            let (fn_, fs) = (forces(&x, None, &r, &nh), forces(&x, None, &r, &svk));
            let d = (0..4).map(|i| (fn_[i] - fs[i]).norm()).fold(0.0, f64::max);
            let size = (0..4).map(|i| fs[i].norm()).fold(0.0, f64::max);
            (d, size)
        };
        let (d1, s1) = diff(1e-3);
        let (d2, s2) = diff(1e-4);
        // Forces scale like eps, their difference like eps^2: ratios 10 and 100.
        assert!((s1 / s2 - 10.0).abs() < 0.1, "force ratio {}", s1 / s2);
        assert!(d1 / d2 > 80.0 && d1 / d2 < 120.0, "difference ratio {} (second order: 100)", d1 / d2);
        assert!(d1 <= 1e-2 * s1, "relative difference {} at strain 1e-3", d1 / s1);
    }

    #[test]
    fn nh_element_forces_sum_to_zero() {
        let m = mat(Law::NeoHookean, true);
        let r = TetRest::new(&rest_tet());
        for (name, j, _) in STATES {
            let (x, _) = configuration(j);
            let v = x.map(|p| Vec3::new(p.y, -p.z, p.x) * 10.0);
            let f = forces(&x, Some(&v), &r, &m);
            let s: Vec3 = f.iter().sum();
            let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
            assert!(s.norm() <= 1e-12 * scale, "{name}: {}", s.norm());
        }
    }
}
