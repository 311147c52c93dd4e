//! Smoothing kernels `W(r, h)` with compact support, normalised in 3D (`int W dV = 1`).
//!
//! **Convention:** `h` is the *support radius* for every kernel here: `W(r, h) = 0` for `r >= h`.
//! (The paper writes the support as `2h` with a smoothing length `h`; palpate's `h` is that `2h`.)
//!
//! * [`Kernel::WendlandC2`] (default): `W = 21 / (2 pi h^3) (1 - q)^4 (1 + 4 q)`, `q = r/h`.
//!   Smooth (C2), positive, no pairing instability; Wendland 1995, Dehnen & Aly 2012.
//! * [`Kernel::CubicSpline`]: the M4 spline (Monaghan 1992) with smoothing length `s = h/2`,
//!   `W = 1/(pi s^3) [1 - 3/2 q^2 + 3/4 q^3]` for `q = r/s < 1`, `1/(pi s^3) (2 - q)^3 / 4` for `1 <= q < 2`.
//! * [`Kernel::LinearLennardJones`]: the paper's "linear approximation of the Lennard-Jones
//!   potential" (eq. 24 and the text after it), which the paper does not spell out. palpate uses
//!   the straight line through the potential's value at contact and zero at the support radius,
//!   normalised: `W = 3 / (pi h^3) (1 - r/h)` for `r < h` (a tent). It is continuous but has a
//!   kink at `r = 0` and `r = h`; it is offered for comparison with the paper, not as a default.

use std::f64::consts::PI;

/// A smoothing kernel (see the module docs for the exact forms).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kernel {
    /// Wendland C2 (default).
    #[default]
    WendlandC2,
    /// Cubic (M4) spline.
    CubicSpline,
    /// The paper-style linearised Lennard-Jones tent kernel.
    LinearLennardJones,
}

impl Kernel {
    /// `W(r, h)` \[1/m^3\] for distance `r` \[m\] and support radius `h` \[m\].
    #[inline]
    pub fn w(&self, r: f64, h: f64) -> f64 {
        let q = r / h;
        if !(q < 1.0) {
            return 0.0;
        }
        let h3 = h * h * h;
        match self {
            Kernel::WendlandC2 => {
                let a = 1.0 - q;
                21.0 / (2.0 * PI * h3) * a * a * a * a * (1.0 + 4.0 * q)
            }
            Kernel::CubicSpline => {
                // smoothing length s = h/2, q2 = r/s in [0, 2)
                let q2 = 2.0 * q;
                let sigma = 8.0 / (PI * h3);
                if q2 < 1.0 {
                    sigma * (1.0 - 1.5 * q2 * q2 + 0.75 * q2 * q2 * q2)
                } else {
                    let b = 2.0 - q2;
                    sigma * 0.25 * b * b * b
                }
            }
            Kernel::LinearLennardJones => 3.0 / (PI * h3) * (1.0 - q),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `int_0^h 4 pi r^2 W(r) dr` by Simpson's rule.
    fn integral(k: Kernel, h: f64) -> f64 {
        let n = 20000;
        let dr = h / n as f64;
        let f = |r: f64| 4.0 * PI * r * r * k.w(r, h);
        let mut s = f(0.0) + f(h);
        for i in 1..n {
            s += f(i as f64 * dr) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * dr / 3.0
    }

    #[test]
    fn kernels_are_normalised_and_compact() {
        for k in [Kernel::WendlandC2, Kernel::CubicSpline, Kernel::LinearLennardJones] {
            for h in [1e-3, 0.7] {
                assert!((integral(k, h) - 1.0).abs() < 1e-8, "{k:?} h={h}: {}", integral(k, h));
                assert_eq!(k.w(h, h), 0.0);
                assert_eq!(k.w(1.5 * h, h), 0.0);
                assert!(k.w(0.5 * h, h) > 0.0);
            }
        }
    }

    #[test]
    fn kernels_decrease_with_distance() {
        for k in [Kernel::WendlandC2, Kernel::CubicSpline, Kernel::LinearLennardJones] {
            let mut prev = f64::INFINITY;
            for i in 0..100 {
                let w = k.w(i as f64 / 100.0, 1.0);
                assert!(w <= prev);
                prev = w;
            }
        }
    }
}
