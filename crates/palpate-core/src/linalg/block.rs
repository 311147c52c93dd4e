//! A symmetric 3x3-block sparsity pattern (block CSR, both triangles stored) over the free nodes.

use crate::math::{Mat3, Vec3};

/// Block-CSR pattern: row `i` holds columns `col[row_ptr[i]..row_ptr[i+1]]`, sorted, diagonal included.
#[derive(Debug, Clone)]
pub struct BlockPattern {
    pub row_ptr: Vec<usize>,
    pub col: Vec<usize>,
    /// Position of the diagonal block of each row.
    pub diag: Vec<usize>,
}

impl BlockPattern {
    /// Pattern of a node graph given as sorted adjacency lists (self loops added here).
    pub fn from_adjacency(adj: &[Vec<usize>]) -> BlockPattern {
        let n = adj.len();
        let mut row_ptr = Vec::with_capacity(n + 1);
        let mut col = Vec::new();
        let mut diag = Vec::with_capacity(n);
        row_ptr.push(0);
        for (i, nbrs) in adj.iter().enumerate() {
            let mut row: Vec<usize> = nbrs.iter().copied().filter(|&j| j != i).collect();
            row.push(i);
            row.sort_unstable();
            row.dedup();
            diag.push(col.len() + row.binary_search(&i).unwrap());
            col.extend_from_slice(&row);
            row_ptr.push(col.len());
        }
        BlockPattern { row_ptr, col, diag }
    }

    /// Number of block rows.
    pub fn n(&self) -> usize {
        self.diag.len()
    }
    /// Number of stored blocks.
    pub fn nnz(&self) -> usize {
        self.col.len()
    }

    /// Index of block (i, j), if stored.
    pub fn find(&self, i: usize, j: usize) -> Option<usize> {
        let r = &self.col[self.row_ptr[i]..self.row_ptr[i + 1]];
        r.binary_search(&j).ok().map(|k| self.row_ptr[i] + k)
    }

    /// `y = A x` for block values `a` on this pattern (`x`, `y` of length n).
    pub fn mul(&self, a: &[Mat3], x: &[Vec3], y: &mut [Vec3]) {
        for i in 0..self.n() {
            let mut s = Vec3::zeros();
            for k in self.row_ptr[i]..self.row_ptr[i + 1] {
                s += a[k] * x[self.col[k]];
            }
            y[i] = s;
        }
    }
}
