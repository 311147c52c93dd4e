//! A uniform 3D grid of cubic cells: cell `(i, j, k)` spans `origin + [i, i+1) h` (and so on per
//! axis) and has the linear index `i + nx (j + ny k)` (x fastest).

use crate::math::Vec3;

/// A uniform grid of `dims` cubic cells of edge `h` from the corner `origin`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Grid3 {
    /// Corner of cell (0, 0, 0) \[m\].
    pub origin: Vec3,
    /// Cell edge \[m\].
    pub h: f64,
    /// Cells per axis.
    pub dims: [usize; 3],
}

impl Grid3 {
    /// Number of cells.
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }
    /// No cells?
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Linear index of `(i, j, k)`.
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }
    /// Linear index of a cell `[i, j, k]`.
    #[inline]
    pub fn index_of(&self, c: [usize; 3]) -> usize {
        self.index(c[0], c[1], c[2])
    }
    /// `(i, j, k)` of a linear index.
    #[inline]
    pub fn ijk(&self, v: usize) -> [usize; 3] {
        let (nx, ny) = (self.dims[0], self.dims[1]);
        [v % nx, (v / nx) % ny, v / (nx * ny)]
    }
    /// Centre of cell `v` \[m\].
    pub fn centre(&self, v: usize) -> Vec3 {
        let c = self.ijk(v);
        self.origin + Vec3::new(c[0] as f64 + 0.5, c[1] as f64 + 0.5, c[2] as f64 + 0.5) * self.h
    }
    /// The cell containing `p`, if inside the grid (`None` for a non-finite `p`).
    #[inline]
    pub fn cell_of(&self, p: &Vec3) -> Option<[usize; 3]> {
        let mut c = [0; 3];
        for a in 0..3 {
            let x = ((p[a] - self.origin[a]) / self.h).floor();
            if !(x >= 0.0 && x < self.dims[a] as f64) {
                return None;
            }
            c[a] = x as usize;
        }
        Some(c)
    }
    /// The cell containing `p`, clamped to the grid (a point outside takes the nearest cell).
    #[inline]
    pub fn cell_clamped(&self, p: &Vec3) -> [usize; 3] {
        std::array::from_fn(|a| (((p[a] - self.origin[a]) / self.h).floor() as isize).clamp(0, self.dims[a] as isize - 1) as usize)
    }
    /// The six face-neighbours of cell `v` in the order -x, +x, -y, +y, -z, +z (`None` past the
    /// grid's edge).
    pub fn face_neighbours(&self, v: usize) -> [Option<usize>; 6] {
        let c = self.ijk(v);
        let mut out = [None; 6];
        for a in 0..3 {
            for (m, s) in [-1isize, 1].into_iter().enumerate() {
                let x = c[a] as isize + s;
                if x >= 0 && x < self.dims[a] as isize {
                    let mut cc = c;
                    cc[a] = x as usize;
                    out[2 * a + m] = Some(self.index_of(cc));
                }
            }
        }
        out
    }
    /// Linear indices of the cells of the box `[lo, hi]` (inclusive), x fastest.
    pub fn cells_in(&self, lo: [usize; 3], hi: [usize; 3]) -> impl Iterator<Item = usize> + '_ {
        (lo[2]..=hi[2]).flat_map(move |k| (lo[1]..=hi[1]).flat_map(move |j| (lo[0]..=hi[0]).map(move |i| self.index(i, j, k))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_and_ijk_are_inverse_and_cells_clamp() {
        let g = Grid3 { origin: Vec3::new(-1.0, 0.0, 2.0), h: 0.5, dims: [3, 4, 5] };
        for v in 0..g.len() {
            assert_eq!(g.index_of(g.ijk(v)), v);
            assert_eq!(g.cell_of(&g.centre(v)), Some(g.ijk(v)));
            assert_eq!(g.cell_clamped(&g.centre(v)), g.ijk(v));
        }
        let far = Vec3::new(-5.0, 1.2, 99.0);
        assert_eq!(g.cell_of(&far), None);
        assert_eq!(g.cell_clamped(&far), [0, 2, 4]);
        assert_eq!(g.cell_of(&Vec3::new(f64::NAN, 0.0, 2.0)), None);
        let n = g.face_neighbours(g.index(0, 1, 4));
        assert_eq!(n, [None, Some(g.index(1, 1, 4)), Some(g.index(0, 0, 4)), Some(g.index(0, 2, 4)), Some(g.index(0, 1, 3)), None]);
        let boxed: Vec<usize> = g.cells_in([1, 1, 1], [2, 1, 2]).collect();
        assert_eq!(boxed, vec![g.index(1, 1, 1), g.index(2, 1, 1), g.index(1, 1, 2), g.index(2, 1, 2)]);
    }
}
