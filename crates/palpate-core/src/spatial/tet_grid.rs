//! Point location in a tet mesh: a uniform bucket grid over the tets.

use super::TriangleGrid;
use crate::math::Vec3;
use crate::mesh::signed_volume;

/// A uniform bucket grid over tetrahedra, for point location.
#[derive(Debug, Clone)]
pub struct TetGrid {
    grid: TriangleGrid,
    tets: Vec<[usize; 4]>,
}

impl TetGrid {
    /// Bucket `tets` with cells of about `cell` \[m\].
    pub fn new(points: &[Vec3], tets: &[[usize; 4]], cell: f64) -> TetGrid {
        // Bucket each tet by two triangles spanning its four vertices' bounding box.
        let faces: Vec<[usize; 3]> = tets.iter().flat_map(|t| [[t[0], t[1], t[2]], [t[1], t[2], t[3]]]).collect();
        TetGrid { grid: TriangleGrid::new(points, &faces, cell), tets: tets.to_vec() }
    }

    /// A tetrahedron containing `p` (boundary included, with a relative tolerance), if any.
    pub fn locate(&self, points: &[Vec3], p: &Vec3) -> Option<usize> {
        let g = &self.grid;
        let cell = g.grid.index_of(g.grid.cell_of(p)?);
        for &f in g.cells.get(cell) {
            let t = self.tets[f as usize / 2];
            let (a, b, cc, d) = (&points[t[0]], &points[t[1]], &points[t[2]], &points[t[3]]);
            let v = signed_volume(a, b, cc, d);
            let tol = -1e-12 * v.abs();
            let w = [signed_volume(p, b, cc, d), signed_volume(a, p, cc, d), signed_volume(a, b, p, d), signed_volume(a, b, cc, p)];
            if w.iter().all(|&x| x * v.signum() >= tol) {
                return Some(f as usize / 2);
            }
        }
        None
    }
}
