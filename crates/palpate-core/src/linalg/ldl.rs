//! Sparse LDL^T factorisation of a symmetric matrix given by its upper triangle in compressed
//! columns, already permuted by a fill-reducing order.
//!
//! The algorithm is the up-looking factorisation with an elimination tree of T. A. Davis,
//! "Algorithm 849: A concise sparse Cholesky factorization package" (ACM TOMS 31(4), 2005),
//! written afresh here: the symbolic phase (elimination tree and column counts) runs once per
//! pattern; [`Ldl::factor`] and [`Ldl::solve_in_place`] then work in preallocated storage and
//! allocate nothing, as the step loop requires.

/// A factorisation failure: the matrix is not (numerically) positive definite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LdlError {
    /// Column (in the permuted order) where the pivot failed.
    pub column: usize,
    /// The pivot value found.
    pub pivot: f64,
}

/// `L D L^T` factors of an `n x n` matrix with a fixed pattern.
#[derive(Debug, Clone)]
pub struct Ldl {
    n: usize,
    // Pattern of the input's upper triangle (column k holds rows i <= k).
    ap: Vec<usize>,
    ai: Vec<usize>,
    // Symbolic: elimination tree and column pointers of L.
    parent: Vec<usize>,
    lp: Vec<usize>,
    // Numeric factors: unit lower-triangular L by columns (rows > column), and D.
    li: Vec<usize>,
    lx: Vec<f64>,
    d: Vec<f64>,
    // Workspace.
    lnz: Vec<usize>,
    flag: Vec<usize>,
    pattern: Vec<usize>,
    y: Vec<f64>,
}

const NONE: usize = usize::MAX;

impl Ldl {
    /// Symbolic analysis of the upper-triangular pattern `(ap, ai)` (column k holds rows `i <= k`,
    /// any order). Entries below the diagonal are ignored.
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
                // Follow the path from i to the root of its subtree in the etree of L(0..k, 0..k).
                while flag[i] != k {
                    if parent[i] == NONE {
                        parent[i] = k;
                    }
                    lnz[i] += 1; // L(k, i) is nonzero
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
        Ldl {
            n,
            ap,
            ai,
            parent,
            lp,
            li: vec![0; nnz],
            lx: vec![0.0; nnz],
            d: vec![0.0; n],
            lnz,
            flag,
            pattern: vec![0; n],
            y: vec![0.0; n],
        }
    }

    /// Dimension.
    pub fn n(&self) -> usize { self.n }
    /// Number of off-diagonal nonzeros of L.
    pub fn nnz_l(&self) -> usize { self.lp[self.n] }
    /// Number of stored input entries (the length `ax` must have in [`Ldl::factor`]).
    pub fn nnz_a(&self) -> usize { self.ap[self.n] }
    /// The input pattern (column pointers, row indices).
    pub fn pattern_a(&self) -> (&[usize], &[usize]) { (&self.ap, &self.ai) }

    /// Numeric factorisation with input values `ax` (same layout as the symbolic pattern).
    /// Fails, naming the column, if a pivot is not positive and finite.
    pub fn factor(&mut self, ax: &[f64]) -> Result<(), LdlError> {
        let n = self.n;
        let (ap, ai) = (&self.ap, &self.ai);
        let (lp, li, lx, d) = (&self.lp, &mut self.li, &mut self.lx, &mut self.d);
        let (parent, lnz, flag, pattern, y) = (&self.parent, &mut self.lnz, &mut self.flag, &mut self.pattern, &mut self.y);
        for k in 0..n {
            // Scatter column k of A's upper triangle into y and find the nonzero pattern of
            // row k of L (a topological order of the reach in the etree), stored in pattern[top..n].
            y[k] = 0.0;
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
            // Sparse triangular solve for row k of L, and the pivot D(k).
            let mut dk = y[k];
            y[k] = 0.0;
            while top < n {
                let i = pattern[top];
                top += 1;
                let yi = y[i];
                y[i] = 0.0;
                let end = lp[i] + lnz[i];
                for p in lp[i]..end {
                    y[li[p]] -= lx[p] * yi;
                }
                let l_ki = yi / d[i];
                dk -= l_ki * yi;
                li[end] = k;
                lx[end] = l_ki;
                lnz[i] += 1;
            }
            if !(dk > 0.0 && dk.is_finite()) {
                return Err(LdlError { column: k, pivot: dk });
            }
            d[k] = dk;
        }
        Ok(())
    }

    /// Solve `L D L^T x = b` in place (`b` of length n, in the permuted order). No allocation.
    pub fn solve_in_place(&self, x: &mut [f64]) {
        let n = self.n;
        let (lp, li, lx, d) = (&self.lp, &self.li, &self.lx, &self.d);
        for j in 0..n {
            let xj = x[j];
            if xj != 0.0 {
                for p in lp[j]..lp[j + 1] {
                    x[li[p]] -= lx[p] * xj;
                }
            }
        }
        for j in 0..n {
            x[j] /= d[j];
        }
        for j in (0..n).rev() {
            let mut s = x[j];
            for p in lp[j]..lp[j + 1] {
                s -= lx[p] * x[li[p]];
            }
            x[j] = s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dense SPD test matrix with a sparse pattern: a 1D Laplacian plus a few long-range couplings.
    fn test_matrix(n: usize) -> Vec<Vec<f64>> {
        let mut a = vec![vec![0.0; n]; n];
        for i in 0..n {
            a[i][i] = 4.0 + i as f64 * 0.01;
            if i + 1 < n {
                a[i][i + 1] = -1.0;
                a[i + 1][i] = -1.0;
            }
            if i + 7 < n && i % 3 == 0 {
                a[i][i + 7] = 0.5;
                a[i + 7][i] = 0.5;
            }
        }
        a
    }

    fn upper_csc(a: &[Vec<f64>]) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
        let n = a.len();
        let (mut ap, mut ai, mut ax) = (vec![0], vec![], vec![]);
        for k in 0..n {
            for i in 0..=k {
                if a[i][k] != 0.0 {
                    ai.push(i);
                    ax.push(a[i][k]);
                }
            }
            ap.push(ai.len());
        }
        (ap, ai, ax)
    }

    #[test]
    fn solves_match_dense_matrix_vector_product() {
        let n = 40;
        let a = test_matrix(n);
        let (ap, ai, ax) = upper_csc(&a);
        let mut f = Ldl::symbolic(n, ap, ai);
        f.factor(&ax).unwrap();
        let x_true: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut b: Vec<f64> = (0..n).map(|i| (0..n).map(|j| a[i][j] * x_true[j]).sum()).collect();
        f.solve_in_place(&mut b);
        for i in 0..n {
            assert!((b[i] - x_true[i]).abs() < 1e-12, "{i}: {} vs {}", b[i], x_true[i]);
        }
    }

    #[test]
    fn indefinite_matrix_is_reported() {
        let mut a = test_matrix(10);
        a[5][5] = -3.0;
        let (ap, ai, ax) = upper_csc(&a);
        let mut f = Ldl::symbolic(10, ap, ai);
        assert_eq!(f.factor(&ax).unwrap_err().column, 5);
    }
}
