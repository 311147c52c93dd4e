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
        // Each tet in every cell its bounding box meets. (Bucketing it by two of its faces, as
        // before, missed the cells of its box that neither face's box meets: points inside a
        // tall, narrow tet, as a flat wall's core prisms give, were found in no tet.)
        let boxes = tets
            .iter()
            .map(|t| {
                let [a, b, c, d] = t.map(|k| points[k]);
                (a.inf(&b).inf(&c).inf(&d), a.sup(&b).sup(&c).sup(&d))
            })
            .collect();
        TetGrid { grid: TriangleGrid::from_boxes(boxes, cell), tets: tets.to_vec() }
    }

    /// A tetrahedron containing `p` (boundary included, with a relative tolerance), if any.
    pub fn locate(&self, points: &[Vec3], p: &Vec3) -> Option<usize> {
        let g = &self.grid;
        let cell = g.grid.index_of(g.grid.cell_of(p)?);
        for &f in g.cells.get(cell) {
            let t = self.tets[f as usize];
            let (a, b, cc, d) = (&points[t[0]], &points[t[1]], &points[t[2]], &points[t[3]]);
            let v = signed_volume(a, b, cc, d);
            let tol = -1e-12 * v.abs();
            let w = [signed_volume(p, b, cc, d), signed_volume(a, p, cc, d), signed_volume(a, b, p, d), signed_volume(a, b, cc, p)];
            if w.iter().all(|&x| x * v.signum() >= tol) {
                return Some(f as usize);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tall tet (a flat wall's core prism) whose centroid lies outside the bounding boxes of
    /// the faces `(0, 1, 2)` and `(1, 2, 3)` (the first is flat, the second has no extent along
    /// y): it is found, and a point beside it is not.
    #[test]
    fn a_point_inside_a_tall_narrow_tet_is_located() {
        let p = [Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.5, 0.0, 10.0)];
        let grid = TetGrid::new(&p, &[[0, 1, 2, 3]], 0.1);
        let centroid = (p[0] + p[1] + p[2] + p[3]) / 4.0;
        assert_eq!(grid.locate(&p, &centroid), Some(0));
        assert_eq!(grid.locate(&p, &Vec3::new(0.9, 0.9, 2.5)), None);
    }
}
