//! Compressible Neo-Hookean law as pure functions of the deformation gradient `F`.
//!
//! Strain energy per unit rest volume (J. Bonet & R. D. Wood, *Nonlinear Continuum Mechanics for
//! Finite Element Analysis*, 2nd ed., Cambridge 2008, ch. 6, "compressible neo-Hookean
//! materials"; the same energy as the `neo-Hookean` material of the FEBio User's Manual; SOFA's
//! hyperelastic force fields also offer a Neo-Hookean material), with `J = det F`,
//! `I1 = tr(F^T F)`:
//!
//! ```text
//! psi(F) = mu/2 (I1 - 3) + h(J),      h(J) = -mu ln J + lambda/2 (ln J)^2     (J >= J_MIN)
//! ```
//!
//! `lambda` and `mu` are the same Lame constants as the St. Venant-Kirchhoff law's: at `F = I` the
//! stress is zero and the tangent is the linear-elastic one, `h'(1) = -mu`, `h''(1) = lambda + mu`.
//!
//! **Extension below `J_MIN`.** `ln J` is undefined for `J <= 0` (inverted elements) and `h`
//! grows without bound as `J -> 0+`, so a haptic press that pushes a node through its opposite face
//! in one step, or a Newton trial point, would produce NaN or an infinite force. Below
//! [`J_MIN`] palpate replaces `h` by its second-order Taylor polynomial about `J_MIN`:
//!
//! ```text
//! h(J) = h(J_MIN) + h'(J_MIN) (J - J_MIN) + h''(J_MIN)/2 (J - J_MIN)^2      (J < J_MIN)
//! ```
//!
//! so `psi` is C2 everywhere, finite for any `F` (including `J <= 0`), and `h` stays convex with a
//! restoring pressure `-h'(J) > 0` that keeps growing linearly as `J` decreases through 0: an
//! inverted element is pushed back toward positive volume instead of being released as SVK does.
//! (`h''(J) = (mu + lambda (1 - ln J)) / J^2 > 0` for `J < exp(1 + mu/lambda)` when `lambda >= 0`.)
//!
//! **Why `J_MIN = 0.1`.** It must be small enough that the extension never changes a physical
//! result: a volume ratio of 0.1 (90% volume loss) is far beyond what soft tissue (Poisson's
//! ratio 0.4 - 0.49, i.e. bulk modulus 5 - 50x the shear modulus) reaches under a press, which
//! changes its shape much more than its volume; so in every physical state the law is exactly
//! Bonet & Wood's, and only degenerate or inverted elements see the extension. It must be large enough that the extension
//! keeps the tangent bounded: the stiffness it freezes, `h''(J_MIN) = 100 (mu + 3.3 lambda)`, is
//! about 300x the rest value `lambda + mu` for nu = 0.4; with `J_MIN = 0.01` it would be ~5e4x,
//! which wrecks the conditioning of the implicit system (and the explicit stable step) as soon as
//! one element degenerates, for no physical benefit.
//!
//! First Piola-Kirchhoff stress: `P = dpsi/dF = mu F + h'(J) cof F`, with
//! `cof F = J F^-T` written as the matrix of cross products of `F`'s columns (defined also for
//! singular `F`). Its derivative is `dP[dF] = mu dF + h''(J) (cof F : dF) cof F + h'(J) F x dF`,
//! where `F x dF` is the tensor cross product (Bonet, Gil & Ortigosa 2015), the derivative of
//! `cof`. The element Jacobian blocks built from it are in `fem::tet4::jacobians`.

use super::Material;
use crate::math::{Mat3, Vec3};

/// Volume ratio below which `h(J)` is continued by its second-order Taylor polynomial (module docs).
pub const J_MIN: f64 = 0.1;

/// `(h(J), h'(J), h''(J))` of the volumetric term, with the `J < J_MIN` extension (module docs).
#[inline]
pub fn volumetric(lambda: f64, mu: f64, j: f64) -> (f64, f64, f64) {
    if j >= J_MIN {
        let l = j.ln();
        let h = (0.5 * lambda * l - mu) * l;
        let h1 = (lambda * l - mu) / j;
        let h2 = (mu + lambda * (1.0 - l)) / (j * j);
        (h, h1, h2)
    } else {
        let (h0, h1, h2) = volumetric(lambda, mu, J_MIN);
        let d = j - J_MIN;
        (h0 + d * (h1 + 0.5 * h2 * d), h1 + h2 * d, h2)
    }
}

/// `h'(J)` alone (the force needs no energy and no curvature).
#[inline]
pub fn volumetric_slope(lambda: f64, mu: f64, j: f64) -> f64 {
    if j >= J_MIN {
        (lambda * j.ln() - mu) / j
    } else {
        // h'(J_MIN) + h''(J_MIN) (J - J_MIN)
        let l = J_MIN.ln();
        (lambda * l - mu) / J_MIN + (mu + lambda * (1.0 - l)) / (J_MIN * J_MIN) * (j - J_MIN)
    }
}

/// Cofactor matrix `cof F = J F^-T`: its columns are `f2 x f3`, `f3 x f1`, `f1 x f2` for the
/// columns `f1, f2, f3` of `F` (defined, and smooth, for singular and inverted `F` too).
#[inline]
pub fn cofactor(f: &Mat3) -> Mat3 {
    let (c0, c1, c2) = (f.column(0), f.column(1), f.column(2));
    Mat3::from_columns(&[c1.cross(&c2), c2.cross(&c0), c0.cross(&c1)])
}

/// The cross-product matrix `[w]_x` (`[w]_x v = w x v`).
#[inline]
pub fn cross_matrix(w: &Vec3) -> Mat3 {
    Mat3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// Strain energy density `psi(F)` \[J/m^3 = Pa\].
#[inline]
pub fn energy_density(m: &Material, f: &Mat3) -> f64 {
    let (h, _, _) = volumetric(m.lambda(), m.mu(), f.determinant());
    0.5 * m.mu() * (f.norm_squared() - 3.0) + h
}

/// First Piola-Kirchhoff stress `P = mu F + h'(J) cof F` \[Pa\].
#[inline]
pub fn piola(m: &Material, f: &Mat3) -> Mat3 {
    let cof = cofactor(f);
    // J = f1 . (f2 x f3) = column 0 of F . column 0 of cof F.
    let j = f.column(0).dot(&cof.column(0));
    m.mu() * f + volumetric_slope(m.lambda(), m.mu(), j) * cof
}

/// Energy density \[Pa\], first Piola stress \[Pa\] and `J = det F` in one pass.
#[inline]
pub fn energy_piola(m: &Material, f: &Mat3) -> (f64, Mat3, f64) {
    let cof = cofactor(f);
    let j = f.column(0).dot(&cof.column(0));
    let (h, h1, _) = volumetric(m.lambda(), m.mu(), j);
    let mu = m.mu();
    (0.5 * mu * (f.norm_squared() - 3.0) + h, mu * f + h1 * cof, j)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Damping, Elasticity, Law};

    fn mat() -> Material {
        Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE)
            .unwrap()
            .with_law(Law::NeoHookean)
    }

    /// A fixed F with `det F = j` (a generic shear/stretch scaled to the volume ratio; `j < 0`
    /// reflects one axis).
    fn f_with_det(j: f64) -> Mat3 {
        let a = Mat3::new(1.1, 0.2, -0.1, 0.05, 0.9, 0.15, -0.08, 0.1, 1.05);
        let a = a / a.determinant().cbrt();
        let s = j.abs().cbrt();
        let mut f = s * a;
        if j < 0.0 {
            f.set_column(2, &(-f.column(2)));
        }
        f
    }

    /// What it catches: a wrong sign or factor in `h'` or `h''`, an extension that does not match
    /// `h` in value, slope or curvature at `J_MIN` (C0/C1/C2 jumps of the order of `h''(J_MIN)`).
    #[test]
    fn volumetric_is_c2_at_j_min_and_derivatives_match() {
        let (lam, mu) = (mat().lambda(), mat().mu());
        let below = volumetric(lam, mu, J_MIN * (1.0 - 1e-12));
        let above = volumetric(lam, mu, J_MIN);
        for (b, a) in [(below.0, above.0), (below.1, above.1), (below.2, above.2)] {
            assert!((b - a).abs() <= 1e-9 * a.abs().max(1.0), "{b} vs {a}");
        }
        for j in [1.7, 1.0, 0.6, 0.3, 0.1 + 1e-3, 0.05, 0.0, -0.4] {
            let e = 1e-6;
            let (h, h1, h2) = volumetric(lam, mu, j);
            let (hp, h1p, _) = volumetric(lam, mu, j + e);
            let (hm, h1m, _) = volumetric(lam, mu, j - e);
            assert!(((hp - hm) / (2.0 * e) - h1).abs() <= 1e-6 * h1.abs().max(mu), "h' at J = {j}");
            assert!(((h1p - h1m) / (2.0 * e) - h2).abs() <= 1e-6 * h2.abs(), "h'' at J = {j}");
            assert!(h.is_finite() && h2 > 0.0, "J = {j}");
            assert!((volumetric_slope(lam, mu, j) - h1).abs() <= 1e-12 * h1.abs().max(mu));
        }
        assert_eq!(volumetric(lam, mu, 1.0), (0.0, -mu, mu + lam));
    }

    /// What it catches: a cofactor with swapped columns / transposed, or the wrong sign for an
    /// inverted F; `P` not the derivative of `psi` (e.g. `F^-T` instead of `J F^-T`, `mu F^-T`
    /// missing) at a mild, strong, extended and inverted deformation.
    #[test]
    fn piola_is_energy_derivative_and_cofactor_is_j_f_inv_t() {
        let m = mat();
        for j in [1.15, 0.3, 0.05, -0.2] {
            let f = f_with_det(j);
            assert!((f.determinant() - j).abs() < 1e-12);
            let cof = cofactor(&f);
            assert!((cof - j * f.try_inverse().unwrap().transpose()).norm() <= 1e-12 * cof.norm());
            let p = piola(&m, &f);
            let (w, p2, j2) = energy_piola(&m, &f);
            assert!((p2 - p).norm() <= 1e-12 * p.norm() && (j2 - j).abs() < 1e-12);
            assert!((w - energy_density(&m, &f)).abs() <= 1e-12 * w.abs());
            let e = 1e-7;
            for r in 0..3 {
                for c in 0..3 {
                    let (mut fp, mut fm) = (f, f);
                    fp[(r, c)] += e;
                    fm[(r, c)] -= e;
                    let fd = (energy_density(&m, &fp) - energy_density(&m, &fm)) / (2.0 * e);
                    assert!((fd - p[(r, c)]).abs() <= 1e-6 * p.norm(), "J = {j}, P[{r}{c}]: fd {fd} vs {}", p[(r, c)]);
                }
            }
        }
    }
}
