//! The isotropic linear (St. Venant-Kirchhoff) law, paper eq. (3)-(11), written once.
//!
//! The law is written over a small [`Scalar`] trait, on 3x3 matrices stored as rows ([`M3`]), so
//! that the same functions serve one element or particle at a time (`f64`, the FEM element of
//! `fem/tet4.rs` through the [`Mat3`] wrappers below, and the portable particle loop) and several
//! particles side by side in SIMD lanes (the AVX2 copy of `meshfree/pair_loop`). A second tissue
//! law for both solids is written once the same way.

use super::Material;
use crate::math::Mat3;

/// The arithmetic the law needs, for one value (`f64`) or several side by side in SIMD lanes.
/// `madd` may be fused (one rounding) where the type says so (the AVX2 lanes); for `f64` it is not.
pub(crate) trait Scalar: Copy {
    fn splat(x: f64) -> Self;
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    /// `self * b + c`.
    fn madd(self, b: Self, c: Self) -> Self;
}

impl Scalar for f64 {
    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self + o
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self - o
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self * o
    }
    #[inline(always)]
    fn madd(self, b: Self, c: Self) -> Self {
        self * b + c
    }
}

/// A 3x3 matrix as rows, `m[a][b]`.
pub(crate) type M3<T> = [[T; 3]; 3];

/// `a b`.
#[inline(always)]
pub(crate) fn mm<T: Scalar>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut c = [[T::splat(0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][2].madd(b[2][j], a[i][1].madd(b[1][j], a[i][0].mul(b[0][j])));
        }
    }
    c
}

/// `det f` (the particles' and the FEM element loop's `det F`).
#[inline(always)]
pub(crate) fn det3<T: Scalar>(f: &M3<T>) -> T {
    let c0 = f[1][1].mul(f[2][2]).sub(f[1][2].mul(f[2][1]));
    let c1 = f[1][2].mul(f[2][0]).sub(f[1][0].mul(f[2][2]));
    let c2 = f[1][0].mul(f[2][1]).sub(f[1][1].mul(f[2][0]));
    f[0][0].mul(c0).add(f[0][1].mul(c1)).add(f[0][2].mul(c2))
}

/// `(a + a^T) / 2`.
#[inline(always)]
pub(crate) fn sym<T: Scalar>(a: &M3<T>) -> M3<T> {
    let half = T::splat(0.5);
    let mut s = *a;
    for i in 0..3 {
        for j in 0..3 {
            s[i][j] = half.mul(a[i][j].add(a[j][i]));
        }
    }
    s
}

/// `(a^T b + b^T a) / 2`.
#[inline(always)]
fn sym_atb<T: Scalar>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut d = [[T::splat(0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            d[i][j] = a[2][i].madd(b[2][j], a[1][i].madd(b[1][j], a[0][i].mul(b[0][j])));
        }
    }
    sym(&d)
}

/// Green strain `E = 1/2 (F^T F - I)` (eq. 3-4, `F` the deformation gradient).
#[inline(always)]
pub(crate) fn green_strain_of<T: Scalar>(f: &M3<T>) -> M3<T> {
    let half = T::splat(0.5);
    let mut e = sym_atb(f, f);
    for a in 0..3 {
        for b in 0..3 {
            e[a][b] = half.mul(e[a][b]);
        }
        e[a][a] = e[a][a].sub(half);
    }
    e
}

/// Strain rate `nu = dE/dt = 1/2 (F^T Fdot + Fdot^T F)` (palpate's convention for eq. 10; see
/// the module docs of [`crate::material`]).
#[inline(always)]
pub(crate) fn strain_rate_of<T: Scalar>(f: &M3<T>, f_dot: &M3<T>) -> M3<T> {
    sym_atb(f, f_dot)
}

/// `s += a tr(x) I + 2 b x`: the isotropic linear form of the elastic stress (eq. 9, `a, b =
/// lambda, mu` on the Green strain) and of the viscous stress (eq. 11, `a, b = phi, psi` on the
/// strain rate).
#[inline(always)]
fn add_isotropic<T: Scalar>(s: &mut M3<T>, x: &M3<T>, a: f64, b: f64) {
    let t = T::splat(a).mul(x[0][0].add(x[1][1]).add(x[2][2]));
    let two_b = T::splat(2.0 * b);
    for i in 0..3 {
        for j in 0..3 {
            s[i][j] = two_b.madd(x[i][j], s[i][j]);
        }
        s[i][i] = s[i][i].add(t);
    }
}

/// The constants of the St. Venant-Kirchhoff law with its viscous stress, read once per pass.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Svk {
    lambda: f64,
    mu: f64,
    /// `(phi, psi)` when damped.
    viscous: Option<(f64, f64)>,
}

impl Svk {
    pub(crate) fn of(m: &Material) -> Svk {
        let d = m.damping();
        Svk { lambda: m.lambda(), mu: m.mu(), viscous: if m.is_undamped() { None } else { Some((d.phi, d.psi)) } }
    }

    /// `(lambda, mu)` \[Pa\].
    pub(crate) fn lame(&self) -> (f64, f64) {
        (self.lambda, self.mu)
    }

    /// The same law with no viscous stress.
    pub(crate) fn without_viscosity(self) -> Svk {
        Svk { viscous: None, ..self }
    }

    /// `true` when the viscous stress is not zero.
    pub(crate) fn is_damped(&self) -> bool {
        self.viscous.is_some()
    }

    /// Second Piola-Kirchhoff stress `S = lambda tr(E) I + 2 mu E` (eq. 9) of the Green strain
    /// `e`, plus, given the strain rate `nu` and when damped, the viscous
    /// `S_v = phi tr(nu) I + 2 psi nu` (eq. 11).
    #[inline(always)]
    pub(crate) fn stress<T: Scalar>(&self, e: &M3<T>, nu: Option<&M3<T>>) -> M3<T> {
        let mut s = [[T::splat(0.0); 3]; 3];
        add_isotropic(&mut s, e, self.lambda, self.mu);
        if let (Some(nu), Some((phi, psi))) = (nu, self.viscous) {
            add_isotropic(&mut s, nu, phi, psi);
        }
        s
    }

    /// The viscous stress alone, `S_v = phi tr(nu) I + 2 psi nu` (eq. 11; zero when undamped).
    #[inline(always)]
    pub(crate) fn viscous_stress<T: Scalar>(&self, nu: &M3<T>) -> M3<T> {
        let mut s = [[T::splat(0.0); 3]; 3];
        if let Some((phi, psi)) = self.viscous {
            add_isotropic(&mut s, nu, phi, psi);
        }
        s
    }
}

#[inline(always)]
fn rows(m: &Mat3) -> M3<f64> {
    [[m[(0, 0)], m[(0, 1)], m[(0, 2)]], [m[(1, 0)], m[(1, 1)], m[(1, 2)]], [m[(2, 0)], m[(2, 1)], m[(2, 2)]]]
}

#[inline(always)]
fn mat(r: &M3<f64>) -> Mat3 {
    Mat3::new(r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2])
}

/// Green strain `E = 1/2 (F^T F - I)` (paper eq. 3-4, with `F` the deformation gradient).
#[inline]
pub fn green_strain(f: &Mat3) -> Mat3 {
    mat(&green_strain_of(&rows(f)))
}

/// Strain rate `nu = dE/dt = 1/2 (F^T Fdot + Fdot^T F)` (palpate's convention for eq. 10; see module docs).
#[inline]
pub fn strain_rate(f: &Mat3, f_dot: &Mat3) -> Mat3 {
    mat(&strain_rate_of(&rows(f), &rows(f_dot)))
}

/// Elastic second Piola-Kirchhoff stress `S = lambda tr(E) I + 2 mu E` \[Pa\] (eq. 9).
#[inline]
pub fn stress(m: &Material, e: &Mat3) -> Mat3 {
    let elastic = Svk { viscous: None, ..Svk::of(m) };
    mat(&elastic.stress(&rows(e), None))
}

/// Elastic energy density `psi(E) = mu E:E + lambda/2 tr(E)^2` \[J/m^3\] of the law whose
/// stress is [`stress`] (`S = dpsi/dE`).
#[inline]
pub fn energy_density(m: &Material, e: &Mat3) -> f64 {
    let tr = e.trace();
    m.mu() * e.norm_squared() + 0.5 * m.lambda() * tr * tr
}

/// Viscous stress `S_v = phi tr(nu) I + 2 psi nu` \[Pa\] (eq. 11).
#[inline]
pub fn viscous_stress(m: &Material, nu: &Mat3) -> Mat3 {
    mat(&Svk::of(m).viscous_stress(&rows(nu)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Damping, Elasticity};

    /// The generic law gives, bit for bit, what the earlier nalgebra expressions gave (so the
    /// FEM's results did not move when the law was written once).
    #[test]
    fn generic_law_matches_the_nalgebra_expressions_bitwise() {
        let m = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping { phi: 3.0, psi: 7.0 }).unwrap();
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..2000 {
            let f = Mat3::identity() + Mat3::from_fn(|_, _| rnd());
            let fd = Mat3::from_fn(|_, _| rnd());
            let e_old = 0.5 * (f.transpose() * f - Mat3::identity());
            let a = f.transpose() * fd;
            let nu_old = 0.5 * (a + a.transpose());
            let d = m.damping();
            let s_old = Mat3::from_diagonal_element(m.lambda() * e_old.trace()) + 2.0 * m.mu() * e_old;
            let sv_old = Mat3::from_diagonal_element(d.phi * nu_old.trace()) + 2.0 * d.psi * nu_old;
            let bits = |x: Mat3| x.map(f64::to_bits);
            assert_eq!(bits(green_strain(&f)), bits(e_old));
            assert_eq!(bits(strain_rate(&f, &fd)), bits(nu_old));
            assert_eq!(stress(&m, &e_old), s_old);
            assert_eq!(viscous_stress(&m, &nu_old), sv_old);
        }
    }
}
