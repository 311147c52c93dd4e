//! Scalar and small fixed-size linear-algebra aliases used across the core.

/// The floating-point type of every physical quantity.
pub type Real = f64;
/// A 3-vector (position \[m\], velocity \[m/s\], force \[N\] ...), world frame unless stated.
pub type Vec3 = nalgebra::Vector3<Real>;
/// A 3x3 matrix (deformation gradient, strain, stress, Jacobian block).
pub type Mat3 = nalgebra::Matrix3<Real>;

/// `true` if every component of `v` is finite.
#[inline]
pub fn is_finite3(v: &Vec3) -> bool {
    v.x.is_finite() && v.y.is_finite() && v.z.is_finite()
}
