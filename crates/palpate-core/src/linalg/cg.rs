//! Preconditioned conjugate gradients (Hestenes and Stiefel 1952; Saad, *Iterative Methods for
//! Sparse Linear Systems*, alg. 9.1) for a symmetric positive definite operator given as a
//! closure, over vectors of `f64` or of [`Vec3`] (3 unknowns per node). Allocation-free: the
//! caller owns the solution and the four work vectors ([`CgWork`]), so a solve can sit in a
//! time step.

use crate::math::Vec3;

/// An entry of a CG vector: a scalar or a node's three unknowns.
pub trait CgEntry: Copy {
    /// The zero entry.
    const ZERO: Self;
    /// Euclidean inner product of two entries.
    fn dot(self, other: Self) -> f64;
    /// `self + a other`.
    fn add_scaled(self, a: f64, other: Self) -> Self;
    /// Exactly zero?
    fn is_zero(self) -> bool;
}

impl CgEntry for f64 {
    const ZERO: f64 = 0.0;
    #[inline]
    fn dot(self, other: f64) -> f64 {
        self * other
    }
    #[inline]
    fn add_scaled(self, a: f64, other: f64) -> f64 {
        self + a * other
    }
    #[inline]
    fn is_zero(self) -> bool {
        self == 0.0
    }
}

impl CgEntry for Vec3 {
    const ZERO: Vec3 = Vec3::new(0.0, 0.0, 0.0);
    #[inline]
    fn dot(self, other: Vec3) -> f64 {
        Vec3::dot(&self, &other)
    }
    #[inline]
    fn add_scaled(self, a: f64, other: Vec3) -> Vec3 {
        self + a * other
    }
    #[inline]
    fn is_zero(self) -> bool {
        self == Self::ZERO
    }
}

/// `sum_i a_i . b_i`, in index order.
pub fn dot<T: CgEntry>(a: &[T], b: &[T]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum::<f64>()
}

/// The work vectors of a solve of `n` entries: residual, preconditioned residual, search
/// direction and operator times direction.
#[derive(Debug, Clone)]
pub struct CgWork<T> {
    pub r: Vec<T>,
    pub z: Vec<T>,
    pub p: Vec<T>,
    pub ap: Vec<T>,
}

impl<T: CgEntry> CgWork<T> {
    /// Work vectors for `n` entries.
    pub fn new(n: usize) -> CgWork<T> {
        CgWork { r: vec![T::ZERO; n], z: vec![T::ZERO; n], p: vec![T::ZERO; n], ap: vec![T::ZERO; n] }
    }
}

/// When to stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgStop {
    /// Converged when `|r| / |b| <= tolerance` (`|b|` floored at 1e-300).
    pub tolerance: f64,
    /// At most this many iterations.
    pub max_iterations: usize,
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgReport {
    /// Iterations done.
    pub iterations: usize,
    /// Final `|r| / |b|`, and `|r|`, `|b|`.
    pub residual: f64,
    pub residual_norm: f64,
    pub rhs_norm: f64,
    /// Reached the tolerance?
    pub converged: bool,
    /// Stopped because `p . A p <= 0` (the operator is not positive definite on the iterates).
    pub breakdown: bool,
}

/// No preconditioner: `z = r`.
pub fn identity<T: Copy>(r: &[T], z: &mut [T]) {
    z.copy_from_slice(r)
}

/// Solve `A x = b` from the guess in `x` (all zeros: `A` is not applied to it) by conjugate
/// gradients preconditioned by `precondition(r, z)` (`z = M^-1 r`, `M` symmetric positive
/// definite), `apply(p, ap)` setting `ap = A p`. Every slice has the length of `b`.
pub fn solve<T: CgEntry>(
    mut apply: impl FnMut(&[T], &mut [T]),
    mut precondition: impl FnMut(&[T], &mut [T]),
    b: &[T],
    x: &mut [T],
    work: &mut CgWork<T>,
    stop: CgStop,
) -> CgReport {
    let n = b.len();
    assert!(x.len() == n && work.r.len() == n && work.z.len() == n && work.p.len() == n && work.ap.len() == n, "CG: slices of different lengths");
    let CgWork { r, z, p, ap } = work;
    if x.iter().all(|v| v.is_zero()) {
        r.copy_from_slice(b);
    } else {
        apply(x, r);
        for i in 0..n {
            r[i] = b[i].add_scaled(-1.0, r[i]);
        }
    }
    let rhs_norm = dot(b, b).sqrt();
    let bnorm = rhs_norm.max(1e-300);
    let mut iterations = 0;
    let mut residual_norm = dot(r, r).sqrt();
    let mut breakdown = false;
    let mut rz = 0.0;
    if residual_norm / bnorm > stop.tolerance {
        precondition(r, z);
        p.copy_from_slice(z);
        rz = dot(r, z);
    }
    while residual_norm / bnorm > stop.tolerance && iterations < stop.max_iterations {
        apply(p, ap);
        let pap = dot(p, ap);
        if !(pap > 0.0) {
            // `z` still holds the preconditioned residual of the current iterate: a caller may
            // use it as a descent direction (truncated CG, Steihaug 1983).
            breakdown = true;
            break;
        }
        let alpha = rz / pap;
        for i in 0..n {
            x[i] = x[i].add_scaled(alpha, p[i]);
            r[i] = r[i].add_scaled(-alpha, ap[i]);
        }
        iterations += 1;
        residual_norm = dot(r, r).sqrt();
        // Stop before preconditioning a residual that will not be used (with a factorised
        // preconditioner, an application costs as much as the operator).
        if residual_norm / bnorm <= stop.tolerance || iterations >= stop.max_iterations {
            break;
        }
        precondition(r, z);
        let rz_new = dot(r, z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i].add_scaled(beta, p[i]);
        }
    }
    let residual = residual_norm / bnorm;
    CgReport { iterations, residual, residual_norm, rhs_norm, converged: !(residual > stop.tolerance), breakdown }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `D L D`: the 1D Laplacian `L` with Dirichlet ends, `(2, -1)`, scaled symmetrically by
    /// the diagonal `D` to make Jacobi matter.
    fn laplacian(scale: &[f64], x: &[f64], y: &mut [f64]) {
        let n = x.len();
        for i in 0..n {
            let l = if i > 0 { scale[i - 1] * x[i - 1] } else { 0.0 };
            let r = if i + 1 < n { scale[i + 1] * x[i + 1] } else { 0.0 };
            y[i] = scale[i] * (2.0 * scale[i] * x[i] - l - r);
        }
    }

    #[test]
    fn cg_solves_spd_systems_with_and_without_a_preconditioner() {
        let n = 50;
        let scale: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64).collect();
        let truth: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).sin()).collect();
        let mut b = vec![0.0; n];
        laplacian(&scale, &truth, &mut b);
        let stop = CgStop { tolerance: 1e-12, max_iterations: 500 };
        let diag: Vec<f64> = scale.iter().map(|s| 2.0 * s * s).collect();
        let mut work = CgWork::new(n);
        for guess in [0.0, 0.5] {
            let mut x = vec![guess; n];
            let rep =
                solve(|p, ap| laplacian(&scale, p, ap), |r, z| z.iter_mut().zip(r).zip(&diag).for_each(|((z, r), d)| *z = r / d), &b, &mut x, &mut work, stop);
            assert!(rep.converged && !rep.breakdown, "{rep:?}");
            assert!(x.iter().zip(&truth).all(|(a, t)| (a - t).abs() < 1e-9));
        }
        // Over nodes of three unknowns, no preconditioner: the same system on each axis.
        let b3: Vec<Vec3> = b.iter().map(|&v| Vec3::new(v, -v, 2.0 * v)).collect();
        let mut x3 = vec![Vec3::zeros(); n];
        let mut work3 = CgWork::new(n);
        let apply3 = |p: &[Vec3], ap: &mut [Vec3]| {
            for a in 0..3 {
                let (xs, mut ys): (Vec<f64>, Vec<f64>) = (p.iter().map(|v| v[a]).collect(), vec![0.0; n]);
                laplacian(&scale, &xs, &mut ys);
                ap.iter_mut().zip(&ys).for_each(|(q, y)| q[a] = *y);
            }
        };
        let rep = solve(apply3, identity, &b3, &mut x3, &mut work3, stop);
        assert!(rep.converged, "{rep:?}");
        assert!(x3.iter().zip(&truth).all(|(v, t)| (v - Vec3::new(*t, -t, 2.0 * t)).norm() < 1e-8));
        // An indefinite operator breaks down and says so.
        let rep = solve(|p: &[f64], ap: &mut [f64]| ap.iter_mut().zip(p).for_each(|(a, p)| *a = -p), identity, &b, &mut vec![0.0; n], &mut work, stop);
        assert!(rep.breakdown && !rep.converged && rep.iterations == 0);
    }
}
