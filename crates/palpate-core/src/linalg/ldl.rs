//! Sparse block LDL^T factorisation of a symmetric positive definite matrix made of 3x3 blocks
//! (one block row per free node), given by its upper block triangle in compressed columns and
//! already permuted by a fill-reducing order.
//!
//! The algorithm is the up-looking factorisation with an elimination tree of T. A. Davis,
//! "Algorithm 849: A concise sparse Cholesky factorization package" (ACM TOMS 31(4), 2005),
//! written afresh here for 3x3 blocks: `A = L D L^T` with `L` unit block-lower-triangular and `D`
//! block diagonal (3x3 SPD blocks, stored inverted). Working on nodes rather than scalars keeps
//! one index per 9 multiply-adds in the triangular solves, which dominate an implicit step.
//!
//! The symbolic phase (elimination tree, column counts) runs once per pattern; [`Ldl::factor`]
//! and [`Ldl::solve_in_place`] then work in preallocated storage and allocate nothing.

use super::supernodal::{Supernodal, SUPERNODAL_MIN_BLOCKS};
use crate::math::{Mat3, Vec3};

/// A factorisation failure: the matrix is not (numerically) positive definite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LdlError {
    /// Block column (in the permuted order) where the pivot block failed.
    pub column: usize,
    /// The smallest pivot of the failed 3x3 block's Cholesky factorisation.
    pub pivot: f64,
}

/// `L D L^T` factors of an `n x n`-block matrix with a fixed pattern.
#[derive(Debug, Clone)]
pub struct Ldl {
    n: usize,
    // Pattern of the input's upper block triangle (column k holds block rows i <= k).
    ap: Vec<usize>,
    ai: Vec<usize>,
    // Symbolic: elimination tree and column pointers of L.
    parent: Vec<usize>,
    lp: Vec<usize>,
    // Numeric factors: L by block columns (block rows > column), and D^-1.
    li: Vec<usize>,
    lx: Vec<Mat3>,
    d_inv: Vec<Mat3>,
    // Workspace.
    lnz: Vec<usize>,
    flag: Vec<usize>,
    pattern: Vec<usize>,
    y: Vec<Mat3>,
    // faer's supernodal numeric factorisation, for large factors (see `linalg/supernodal.rs`).
    supernodal: Option<Box<Supernodal>>,
}

const NONE: usize = usize::MAX;

/// Smallest Cholesky pivot of a symmetric 3x3 block (non-positive or NaN: not SPD).
fn min_cholesky_pivot(a: &Mat3) -> f64 {
    let d0 = a[(0, 0)];
    if !(d0 > 0.0) {
        return d0;
    }
    let l10 = a[(1, 0)] / d0.sqrt();
    let l20 = a[(2, 0)] / d0.sqrt();
    let d1 = a[(1, 1)] - l10 * l10;
    if !(d1 > 0.0) {
        return d1;
    }
    let l21 = (a[(2, 1)] - l20 * l10) / d1.sqrt();
    let d2 = a[(2, 2)] - l20 * l20 - l21 * l21;
    d0.min(d1).min(d2)
}

impl Ldl {
    /// Symbolic analysis of the upper block-triangular pattern `(ap, ai)` (column k holds block
    /// rows `i <= k`, any order). Entries below the diagonal are ignored.
    pub fn symbolic(n: usize, ap: Vec<usize>, ai: Vec<usize>) -> Ldl {
        assert_eq!(ap.len(), n + 1);
        let mut parent = vec![NONE; n];
        let mut flag = vec![NONE; n];
        let mut lnz = vec![0usize; n];
        for k in 0..n {
            flag[k] = k;
            for &i0 in &ai[ap[k]..ap[k + 1]] {
                let mut i = i0;
                if i >= k {
                    continue;
                }
                // Walk from i up the elimination tree of L(0..k, 0..k) until a node already
                // marked for row k: every node on the path has L(k, node) nonzero.
                while flag[i] != k {
                    if parent[i] == NONE {
                        parent[i] = k;
                    }
                    lnz[i] += 1;
                    flag[i] = k;
                    i = parent[i];
                }
            }
        }
        let mut lp = vec![0usize; n + 1];
        for k in 0..n {
            lp[k + 1] = lp[k] + lnz[k];
        }
        let nnz = lp[n];
        let mut ldl = Ldl {
            n,
            ap,
            ai,
            parent,
            lp,
            li: vec![0; nnz],
            lx: vec![Mat3::zeros(); nnz],
            d_inv: vec![Mat3::zeros(); n],
            lnz,
            flag,
            pattern: vec![0; n],
            y: vec![Mat3::zeros(); n],
            supernodal: None,
        };
        if nnz >= SUPERNODAL_MIN_BLOCKS {
            ldl.fill_pattern();
            ldl.supernodal = Supernodal::new(n, &ldl.ap, &ldl.ai).map(Box::new);
        }
        ldl
    }

    /// The row indices of L (`li`), as [`Ldl::factor`] writes them: block row `k`'s pattern is
    /// the reach of its entries in the elimination tree; column `i` gets its rows in increasing
    /// order.
    fn fill_pattern(&mut self) {
        let (n, ap, ai, parent) = (self.n, &self.ap, &self.ai, &self.parent);
        let (lp, li, lnz, flag) = (&self.lp, &mut self.li, &mut self.lnz, &mut self.flag);
        for k in 0..n {
            flag[k] = k;
            lnz[k] = 0;
            for &i0 in &ai[ap[k]..ap[k + 1]] {
                let mut i = i0;
                if i > k {
                    continue;
                }
                while flag[i] != k {
                    flag[i] = k;
                    li[lp[i] + lnz[i]] = k;
                    lnz[i] += 1;
                    i = parent[i];
                }
            }
        }
    }

    /// The numeric factorisation by faer's supernodal Cholesky (`true`) or the block code
    /// (`false`), whatever the factor's size ([`Ldl::symbolic`] picks faer's from
    /// [`crate::linalg::SUPERNODAL_MIN_BLOCKS`] blocks on). For tests and benchmarks.
    pub fn with_supernodal(mut self, on: bool) -> Ldl {
        self.supernodal = if on {
            self.fill_pattern();
            Supernodal::new(self.n, &self.ap, &self.ai).map(Box::new)
        } else {
            None
        };
        self
    }

    /// Whether the numeric factorisation is faer's supernodal one (`linalg/supernodal.rs`).
    pub fn is_supernodal(&self) -> bool {
        self.supernodal.is_some()
    }

    /// Number of block rows.
    pub fn n(&self) -> usize {
        self.n
    }
    /// Number of off-diagonal blocks of L.
    pub fn nnz_l(&self) -> usize {
        self.lp[self.n]
    }
    /// Relative cost of a numeric factorisation, in units of one pair of triangular solves
    /// (block multiply-adds: `sum_k c_k^2` for the factorisation, `c_k` the column counts of L,
    /// against `2 nnz(L) + n` for the solves). A rough model, calibrated in BENCHMARKS.md.
    pub fn factor_to_solve_ratio(&self) -> f64 {
        let f: f64 = (0..self.n).map(|k| ((self.lp[k + 1] - self.lp[k]) as f64 + 1.0).powi(2)).sum();
        f / (2.0 * self.nnz_l() as f64 + self.n as f64).max(1.0)
    }
    /// Relative cost of a rank update ([`Ldl::update`]) from one block row, averaged over the
    /// rows, in units of a numeric factorisation (block multiply-adds: two per block of the
    /// columns on the row's path to the root, and about ten for each pivot block's inverses,
    /// against `sum_k (c_k + 1)^2`).
    pub fn update_to_factor_ratio(&self) -> f64 {
        let n = self.n;
        let col = |j: usize| 2.0 * (self.lp[j + 1] - self.lp[j]) as f64 + 10.0;
        // Path costs from the root down: a node's is its own column's plus its parent's.
        let mut path = vec![0.0; n];
        for j in (0..n).rev() {
            path[j] = col(j) + if self.parent[j] == NONE { 0.0 } else { path[self.parent[j]] };
        }
        let f: f64 = (0..n).map(|k| ((self.lp[k + 1] - self.lp[k]) as f64 + 1.0).powi(2)).sum();
        path.iter().sum::<f64>() / n.max(1) as f64 / f.max(1.0)
    }
    /// Number of stored input blocks (the length `ax` must have in [`Ldl::factor`]).
    pub fn nnz_a(&self) -> usize {
        self.ap[self.n]
    }

    /// Numeric factorisation with input blocks `ax` (same layout as the symbolic pattern; the
    /// diagonal blocks are full symmetric 3x3 blocks). Fails, naming the block column, if a
    /// pivot block is not positive definite.
    pub fn factor(&mut self, ax: &[Mat3]) -> Result<(), LdlError> {
        if let Some(sn) = self.supernodal.as_mut() {
            if sn.factor(ax, &self.lp, &self.li, &mut self.lx, &mut self.d_inv) {
                return Ok(());
            }
            // Not positive definite, or not finite: the block code below finds where.
        }
        let n = self.n;
        let (ap, ai) = (&self.ap, &self.ai);
        let (lp, li, lx, d_inv) = (&self.lp, &mut self.li, &mut self.lx, &mut self.d_inv);
        let (parent, lnz, flag, pattern, y) = (&self.parent, &mut self.lnz, &mut self.flag, &mut self.pattern, &mut self.y);
        for k in 0..n {
            // Scatter block column k of A into y; the nonzero pattern of block row k of L is the
            // reach of its rows in the elimination tree, stored topologically in pattern[top..n].
            y[k] = Mat3::zeros();
            let mut top = n;
            flag[k] = k;
            lnz[k] = 0;
            for p in ap[k]..ap[k + 1] {
                let mut i = ai[p];
                if i > k {
                    continue;
                }
                y[i] += ax[p];
                let mut len = 0;
                while flag[i] != k {
                    pattern[len] = i;
                    len += 1;
                    flag[i] = k;
                    i = parent[i];
                }
                while len > 0 {
                    top -= 1;
                    len -= 1;
                    pattern[top] = pattern[len];
                }
            }
            // Sparse block triangular solve L Y = A(:, k); then L(k, i) = Y_i^T D_i^-1 and
            // D_k = A_kk - sum_i L(k, i) Y_i.
            let mut dk = y[k];
            y[k] = Mat3::zeros();
            while top < n {
                let i = pattern[top];
                top += 1;
                let yi = y[i];
                y[i] = Mat3::zeros();
                let end = lp[i] + lnz[i];
                for p in lp[i]..end {
                    y[li[p]] -= lx[p] * yi;
                }
                let l_ki = yi.transpose() * d_inv[i];
                dk -= l_ki * yi;
                li[end] = k;
                lx[end] = l_ki;
                lnz[i] += 1;
            }
            let dk = 0.5 * (dk + dk.transpose());
            let pivot = min_cholesky_pivot(&dk);
            let inv = if pivot > 0.0 && pivot.is_finite() { dk.try_inverse() } else { None };
            match inv {
                Some(inv) if inv.iter().all(|v| v.is_finite()) => d_inv[k] = inv,
                _ => return Err(LdlError { column: k, pivot }),
            }
        }
        Ok(())
    }

    /// Update the factors of `A` to those of `A + alpha (w (x) I)(w (x) I)^T`, `w` a block vector
    /// with entries `w[k]` at block rows `rows[k]` (permuted order; the pairs among them must lie
    /// in `A`'s pattern, so that `L`'s is unchanged), `alpha` of either sign (a downdate when
    /// negative). Block form of Gill, Golub, Murray and Saunders' method C1 ("Methods for
    /// modifying matrix factorizations", Math. Comp. 28, 1974), as Davis and Hager apply it to
    /// sparse factors ("Modifying a sparse Cholesky factorization", SIAM J. Matrix Anal. Appl. 20,
    /// 1999): only the block columns on the elimination tree's paths from `rows` to the root
    /// change. With `P = W_j` (the update's block row `j`, 3x3) and a 3x3 weight `S` (`alpha I` at
    /// first), along the path in increasing order:
    ///
    /// ```text
    /// D'_j = D_j + P S P^T,  G = S P^T D'_j^-1,  W_i -= L_ij P,  L'_ij = L_ij + W_i G,  S -= G P S
    /// ```
    ///
    /// Fails, naming the block column, if a pivot block stops being positive definite (a
    /// downdate past the matrix's definiteness); the factors are then partly updated and must be
    /// remade. Allocates nothing.
    pub fn update(&mut self, rows: &[usize], w: &[f64], alpha: f64) -> Result<(), LdlError> {
        const MARK: usize = usize::MAX - 1;
        let (lp, li, lx, d_inv) = (&self.lp, &self.li, &mut self.lx, &mut self.d_inv);
        let (parent, flag, path, y) = (&self.parent, &mut self.flag, &mut self.pattern, &mut self.y);
        let mut len = 0;
        for (&r, &wr) in rows.iter().zip(w) {
            y[r] += Mat3::from_diagonal_element(wr);
            let mut i = r;
            while i != NONE && flag[i] != MARK {
                flag[i] = MARK;
                path[len] = i;
                len += 1;
                i = parent[i];
            }
        }
        // Parents come after their children: increasing order is a topological one.
        path[..len].sort_unstable();
        let mut s = Mat3::from_diagonal_element(alpha);
        let mut result = Ok(());
        for &j in &path[..len] {
            flag[j] = NONE;
            let p = std::mem::replace(&mut y[j], Mat3::zeros());
            if result.is_err() || p == Mat3::zeros() {
                continue;
            }
            let d = d_inv[j].try_inverse().unwrap_or_else(Mat3::zeros);
            let d_new = d + p * s * p.transpose();
            let d_new = 0.5 * (d_new + d_new.transpose());
            let pivot = min_cholesky_pivot(&d_new);
            let inv = if pivot > 0.0 && pivot.is_finite() {
                d_new.try_inverse().filter(|m| m.iter().all(|v| v.is_finite()))
            } else {
                None
            };
            let Some(inv) = inv else {
                result = Err(LdlError { column: j, pivot });
                continue;
            };
            let g = s * p.transpose() * inv;
            for q in lp[j]..lp[j + 1] {
                let i = li[q];
                y[i] -= lx[q] * p;
                lx[q] += y[i] * g;
            }
            s -= g * p * s;
            d_inv[j] = inv;
        }
        result
    }

    /// Solve `L D L^T x = b` in place (`b`: one 3-vector per block row, permuted order).
    /// Allocates nothing.
    pub fn solve_in_place(&self, x: &mut [Vec3]) {
        let n = self.n;
        let (lp, li, lx) = (&self.lp, &self.li, &self.lx);
        for j in 0..n {
            let xj = x[j];
            for p in lp[j]..lp[j + 1] {
                x[li[p]] -= lx[p] * xj;
            }
        }
        for j in 0..n {
            x[j] = self.d_inv[j] * x[j];
        }
        for j in (0..n).rev() {
            let mut s = x[j];
            for p in lp[j]..lp[j + 1] {
                s -= lx[p].tr_mul(&x[li[p]]);
            }
            x[j] = s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dense SPD block matrix with a sparse block pattern (block path plus long-range couplings).
    fn test_matrix(n: usize) -> Vec<Vec<Option<Mat3>>> {
        let mut a = vec![vec![None; n]; n];
        for i in 0..n {
            let s = i as f64 * 0.01;
            a[i][i] = Some(Mat3::new(6.0 + s, 0.5, 0.2, 0.5, 5.0, -0.3, 0.2, -0.3, 7.0 - s));
            let mut couple = |j: usize, b: Mat3| {
                a[i][j] = Some(b);
                a[j][i] = Some(b.transpose());
            };
            if i + 1 < n {
                couple(i + 1, Mat3::new(-1.0, 0.1, 0.0, 0.2, -1.0, 0.3, 0.0, -0.1, -1.0));
            }
            if i + 5 < n && i % 3 == 0 {
                couple(i + 5, Mat3::new(0.3, -0.2, 0.1, 0.0, 0.4, 0.1, 0.2, 0.0, -0.5));
            }
        }
        a
    }

    fn upper(a: &[Vec<Option<Mat3>>]) -> (Vec<usize>, Vec<usize>, Vec<Mat3>) {
        let (mut ap, mut ai, mut ax) = (vec![0], vec![], vec![]);
        for k in 0..a.len() {
            for i in 0..=k {
                if let Some(b) = a[i][k] {
                    ai.push(i);
                    ax.push(b);
                }
            }
            ap.push(ai.len());
        }
        (ap, ai, ax)
    }

    /// A rank update, then the downdate that undoes it, against fresh factorisations of the
    /// updated and original matrices: the solves agree to round-off. (A wrong path, order or
    /// weight update would leave errors of the update's own size.)
    #[test]
    fn updates_and_downdates_match_a_fresh_factorisation() {
        let n = 30;
        let a = test_matrix(n);
        let (ap, ai, ax) = upper(&a);
        let mut f = Ldl::symbolic(n, ap.clone(), ai.clone());
        f.factor(&ax).unwrap();
        // Nodes 3, 4 and 8 are coupled pairwise in the pattern (3-4 and 3-8 directly, 4-8 by fill).
        let (rows, w, alpha) = ([3usize, 4, 8], [0.5, 0.3, 0.2], 40.0);
        assert!(a[3][4].is_some() && a[3][8].is_some());
        let mut b = a.clone();
        for (&r, &wr) in rows.iter().zip(&w) {
            for (&c, &wc) in rows.iter().zip(&w) {
                if let Some(blk) = b[r][c].as_mut() {
                    *blk += Mat3::from_diagonal_element(alpha * wr * wc);
                } else {
                    b[r][c] = Some(Mat3::from_diagonal_element(alpha * wr * wc));
                }
            }
        }
        // The updated matrix's pattern holds 4-8 (fill of the original's L): factor it on a
        // symbolic analysis of its own for the reference.
        let (bp, bi, bx) = upper(&b);
        let mut fresh = Ldl::symbolic(n, bp, bi);
        fresh.factor(&bx).unwrap();
        let rhs: Vec<Vec3> = (0..n).map(|i| Vec3::new((i as f64).sin(), 1.0, (0.3 * i as f64).cos())).collect();
        let solve = |f: &Ldl| {
            let mut x = rhs.clone();
            f.solve_in_place(&mut x);
            x
        };
        f.update(&rows, &w, alpha).unwrap();
        let (x1, x2) = (solve(&f), solve(&fresh));
        let err = x1.iter().zip(&x2).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
        assert!(err < 1e-12, "updated: {err:e}");
        f.update(&rows, &w, -alpha).unwrap();
        let mut orig = Ldl::symbolic(n, ap, ai);
        orig.factor(&ax).unwrap();
        let (x1, x2) = (solve(&f), solve(&orig));
        let err = x1.iter().zip(&x2).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
        assert!(err < 1e-12, "downdated: {err:e}");
        // A downdate past definiteness is refused.
        assert!(f.update(&[5], &[1.0], -1e3).is_err());
    }

    #[test]
    fn solves_match_matrix_vector_product() {
        let n = 30;
        let a = test_matrix(n);
        let (ap, ai, ax) = upper(&a);
        let mut f = Ldl::symbolic(n, ap, ai);
        f.factor(&ax).unwrap();
        let x_true: Vec<Vec3> = (0..n).map(|i| Vec3::new((i as f64).sin(), (2.0 * i as f64).cos(), 0.1 * i as f64)).collect();
        let mut b: Vec<Vec3> = (0..n).map(|i| (0..n).filter_map(|j| a[i][j].map(|m| m * x_true[j])).sum()).collect();
        f.solve_in_place(&mut b);
        for i in 0..n {
            assert!((b[i] - x_true[i]).norm() < 1e-12, "{i}: {} vs {}", b[i], x_true[i]);
        }
    }

    /// faer's supernodal factorisation, turned into block factors, gives the block code's factors
    /// (to round-off), solves, rank updates and failure reports.
    #[test]
    fn supernodal_factors_match_the_block_code() {
        let n = 120;
        let a = test_matrix(n);
        let (ap, ai, ax) = upper(&a);
        let mut blocks = Ldl::symbolic(n, ap.clone(), ai.clone()).with_supernodal(false);
        let mut sn = Ldl::symbolic(n, ap.clone(), ai.clone()).with_supernodal(true);
        assert!(sn.is_supernodal() && !blocks.is_supernodal());
        blocks.factor(&ax).unwrap();
        sn.factor(&ax).unwrap();
        assert_eq!(blocks.li, sn.li);
        let scale = blocks.lx.iter().chain(&blocks.d_inv).map(|m| m.amax()).fold(0.0, f64::max);
        let err = blocks.lx.iter().zip(&sn.lx).chain(blocks.d_inv.iter().zip(&sn.d_inv)).map(|(a, b)| (a - b).amax()).fold(0.0, f64::max);
        assert!(err < 1e-13 * scale, "factors differ by {err:e} (scale {scale:e})");
        // An update of the supernodal factor, against the block one's.
        let rhs: Vec<Vec3> = (0..n).map(|i| Vec3::new((i as f64).sin(), 1.0, (0.3 * i as f64).cos())).collect();
        for f in [&mut blocks, &mut sn] {
            f.update(&[3, 4], &[0.5, 0.3], 40.0).unwrap();
        }
        let (mut x1, mut x2) = (rhs.clone(), rhs.clone());
        blocks.solve_in_place(&mut x1);
        sn.solve_in_place(&mut x2);
        let err = x1.iter().zip(&x2).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
        assert!(err < 1e-12, "updated solves differ by {err:e}");
        // Not positive definite, or not finite: the block code's report.
        let mut bad = a.clone();
        bad[57][57] = Some(Mat3::from_diagonal(&Vec3::new(3.0, -2.0, 3.0)));
        let (_, _, bx) = upper(&bad);
        let e = sn.factor(&bx).unwrap_err();
        assert_eq!((e.column, e.pivot <= 0.0), (57, true));
        let mut nan = ax.clone();
        nan[ap[80]][(1, 1)] = f64::NAN;
        assert!(sn.factor(&nan).is_err());
        // And it recovers on the good matrix.
        sn.factor(&ax).unwrap();
        let mut x3 = rhs.clone();
        sn.solve_in_place(&mut x3);
        blocks.factor(&ax).unwrap();
        let mut x4 = rhs;
        blocks.solve_in_place(&mut x4);
        let err = x3.iter().zip(&x4).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
        assert!(err < 1e-12, "{err:e}");
    }

    #[test]
    fn indefinite_matrix_is_reported() {
        let mut a = test_matrix(10);
        a[4][4] = Some(Mat3::from_diagonal(&Vec3::new(3.0, -2.0, 3.0)));
        let (ap, ai, ax) = upper(&a);
        let mut f = Ldl::symbolic(10, ap, ai);
        let e = f.factor(&ax).unwrap_err();
        assert_eq!(e.column, 4);
        assert!(e.pivot <= 0.0);
    }
}
