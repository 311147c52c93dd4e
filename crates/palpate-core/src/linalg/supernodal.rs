//! The numeric factorisation of large systems by faer's supernodal Cholesky, copied into the
//! block `L D L^T` storage of [`super::Ldl`].
//!
//! Why: the up-looking factorisation of [`super::Ldl`] works one 3x3 block at a time; from a few
//! thousand nodes on, most of its time goes to cache misses, not arithmetic. A supernodal
//! factorisation groups columns with the same pattern into dense panels and updates them with
//! dense matrix products. Measured on the protocol's step matrices (one thread, the project's
//! ordering for both, BENCHMARKS.md): faer's is as fast on lv_1350 (387 nodes), 2.5x faster on
//! lv_10k and 4x on lv_50k. Its triangular solves are not faster (they stream `L` once each
//! way, as ours do), and faer has no rank update: so only the numeric factorisation is faer's.
//! Its scalar Cholesky factor `C` (`A = C C^T`, in the same node order, each node's three
//! unknowns consecutive) is turned into the block factors: for block column `k`,
//! `D_k = C_kk C_kk^T` and `L_ik = C_ik C_kk^-1`; the solves, the rank updates and the
//! failure reports stay the block code's.
//!
//! The supernodes are faer's, relaxed (merged with explicit zeros): rows of its panels outside
//! the block pattern are exact zeros and are skipped.

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Par, Side};

use crate::math::Mat3;

/// Block factors with at least this many off-diagonal blocks are factorised by faer: below,
/// the block code is as fast (lv_1350: 9,396 blocks, the same time) and allocates less.
pub const SUPERNODAL_MIN_BLOCKS: usize = 40_000;

/// faer's symbolic supernodal factorisation of a block pattern and its preallocated buffers.
pub(super) struct Supernodal {
    symbolic: Arc<SymbolicCholesky<usize>>,
    // The scalar upper triangle of A in compressed columns (the block pattern's order), and for
    // each stored scalar the block (index into `ax`) and the entry in it it comes from.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    source: Vec<(u32, u8)>,
    values: Vec<f64>,
    l_values: Vec<f64>,
    stack: MemBuffer,
}

impl Clone for Supernodal {
    fn clone(&self) -> Self {
        Supernodal {
            symbolic: self.symbolic.clone(),
            col_ptr: self.col_ptr.clone(),
            row_idx: self.row_idx.clone(),
            source: self.source.clone(),
            values: self.values.clone(),
            l_values: self.l_values.clone(),
            stack: MemBuffer::new(self.symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())),
        }
    }
}

impl std::fmt::Debug for Supernodal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Supernodal").field("n", &(self.col_ptr.len() - 1)).field("l_values", &self.l_values.len()).finish()
    }
}

impl Supernodal {
    /// From the upper block pattern `(ap, ai)` of `n` block columns (column `k` holds block rows
    /// `i <= k`, sorted); `None` if faer refuses it (then the block code factorises).
    pub(super) fn new(n: usize, ap: &[usize], ai: &[usize]) -> Option<Supernodal> {
        let mut col_ptr = Vec::with_capacity(3 * n + 1);
        let mut row_idx = Vec::new();
        let mut source = Vec::new();
        col_ptr.push(0);
        for k in 0..n {
            let mut rows: Vec<usize> = (ap[k]..ap[k + 1]).filter(|&p| ai[p] <= k).collect();
            rows.sort_unstable_by_key(|&p| ai[p]);
            for c in 0..3 {
                for &p in &rows {
                    let i = ai[p];
                    for a in 0..3 {
                        if i == k && a > c {
                            break;
                        }
                        row_idx.push(3 * i + a);
                        // Mat3 is column-major: entry (a, c) is at 3 c + a.
                        source.push((p as u32, (3 * c + a) as u8));
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        let m = 3 * n;
        let sym = SymbolicSparseColMatRef::new_checked(m, m, &col_ptr, None, &row_idx);
        let params = CholeskySymbolicParams { supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL, ..Default::default() };
        let symbolic = factorize_symbolic_cholesky(sym, Side::Upper, SymmetricOrdering::Identity, params).ok()?;
        if !matches!(symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_)) {
            return None;
        }
        let stack = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()));
        let l_values = vec![0.0; symbolic.len_val()];
        let values = vec![0.0; row_idx.len()];
        Some(Supernodal { symbolic: Arc::new(symbolic), col_ptr, row_idx, source, values, l_values, stack })
    }

    /// Factorise the blocks `ax` and write the block factors: `lx` (column `j`'s blocks at
    /// `lp[j]..lp[j + 1]`, rows `li`, sorted) and `d_inv`. `false` if faer found the matrix not
    /// positive definite or anything came out non-finite (the block code then factorises again
    /// and reports where).
    pub(super) fn factor(&mut self, ax: &[Mat3], lp: &[usize], li: &[usize], lx: &mut [Mat3], d_inv: &mut [Mat3]) -> bool {
        for (v, &(p, e)) in self.values.iter_mut().zip(&self.source) {
            *v = ax[p as usize].as_slice()[e as usize];
        }
        if !self.values.iter().all(|v| v.is_finite()) {
            return false;
        }
        let m = self.col_ptr.len() - 1;
        let sym = SymbolicSparseColMatRef::new_checked(m, m, &self.col_ptr, None, &self.row_idx);
        let a = SparseColMatRef::new(sym, &self.values);
        let ok = self
            .symbolic
            .factorize_numeric_llt(&mut self.l_values, a, Side::Upper, Default::default(), Par::Seq, MemStack::new(&mut self.stack), Default::default())
            .is_ok();
        if !ok {
            return false;
        }
        let SymbolicCholeskyRaw::Supernodal(sn) = self.symbolic.raw() else {
            return false;
        };
        // Scatter C: its diagonal blocks (lower triangles) into d_inv, the others into lx.
        lx.iter_mut().for_each(|b| *b = Mat3::zeros());
        d_inv.iter_mut().for_each(|b| *b = Mat3::zeros());
        let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
        for s in 0..sn.n_supernodes() {
            let (b, e) = (begin[s], end[s]);
            let pattern = sn.supernode(s).pattern();
            let rows = e - b + pattern.len();
            let vals = &self.l_values[sn.col_ptr_for_val()[s]..][..rows * (e - b)];
            let row = |t: usize| if t < e - b { b + t } else { pattern[t - (e - b)] };
            for j in b..e {
                let (k, c) = (j / 3, j % 3);
                let col = &vals[(j - b) * rows..][..rows];
                let mut p = lp[k];
                for (t, &v) in col.iter().enumerate().skip(j - b) {
                    let r = row(t);
                    let (i, a) = (r / 3, r % 3);
                    if i == k {
                        d_inv[k][(a, c)] = v;
                        continue;
                    }
                    while p < lp[k + 1] && li[p] < i {
                        p += 1;
                    }
                    if p < lp[k + 1] && li[p] == i {
                        lx[p][(a, c)] = v;
                    }
                }
            }
        }
        // C to L D L^T, block column by block column.
        for k in 0..d_inv.len() {
            let c = d_inv[k];
            let Some(c_inv) = c.try_inverse() else {
                return false;
            };
            d_inv[k] = c_inv.transpose() * c_inv;
            for b in &mut lx[lp[k]..lp[k + 1]] {
                *b *= c_inv;
            }
            if !d_inv[k].iter().all(|v| v.is_finite()) {
                return false;
            }
        }
        true
    }
}
