//! Pure stress kernels of the isotropic linear (St. Venant-Kirchhoff) law, paper eq. (3)-(11).

use super::Material;
use crate::math::Mat3;

/// Green strain `E = 1/2 (F^T F - I)` (paper eq. 3-4, with `F` the deformation gradient).
#[inline]
pub fn green_strain(f: &Mat3) -> Mat3 {
    0.5 * (f.transpose() * f - Mat3::identity())
}

/// Strain rate `nu = dE/dt = 1/2 (F^T Fdot + Fdot^T F)` (palpate's convention for eq. 10; see module docs).
#[inline]
pub fn strain_rate(f: &Mat3, f_dot: &Mat3) -> Mat3 {
    let a = f.transpose() * f_dot;
    0.5 * (a + a.transpose())
}

/// Elastic second Piola-Kirchhoff stress `S = lambda tr(E) I + 2 mu E` \[Pa\] (eq. 9).
#[inline]
pub fn stress(m: &Material, e: &Mat3) -> Mat3 {
    Mat3::from_diagonal_element(m.lambda() * e.trace()) + 2.0 * m.mu() * e
}

/// Viscous stress `S_v = phi tr(nu) I + 2 psi nu` \[Pa\] (eq. 11).
#[inline]
pub fn viscous_stress(m: &Material, nu: &Mat3) -> Mat3 {
    let d = m.damping();
    Mat3::from_diagonal_element(d.phi * nu.trace()) + 2.0 * d.psi * nu
}
