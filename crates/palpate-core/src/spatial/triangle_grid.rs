//! Nearest-triangle queries: closest points on triangles and a uniform bucket grid of
//! triangles (each bucketed by its bounding box).

use super::{Buckets, Grid3};
use crate::math::Vec3;

/// Closest point to `p` on triangle `(a, b, c)` and its barycentric coordinates (Ericson,
/// *Real-Time Collision Detection*, 5.1.5): all in `[0, 1]`, summing to 1.
pub fn closest_on_triangle(p: &Vec3, a: &Vec3, b: &Vec3, c: &Vec3) -> (Vec3, [f64; 3]) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + v * ab, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + w * ac, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + w * (c - b), [0.0, 1.0 - w, w]);
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

/// The answer of [`TriangleGrid::nearest`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nearest {
    /// The nearest triangle.
    pub triangle: usize,
    /// Its point closest to the query point \[m\], and that point's barycentric coordinates.
    pub point: Vec3,
    pub bary: [f64; 3],
    /// Distance from the query point \[m\].
    pub distance: f64,
}

/// A uniform bucket grid over a set of triangles (each bucketed by its bounding box).
#[derive(Debug, Clone)]
pub struct TriangleGrid {
    pub(super) grid: Grid3,
    pub(super) cells: Buckets,
    /// Per triangle: its bounding box (a cheap lower bound on the distance to it).
    boxes: Vec<(Vec3, Vec3)>,
}

impl TriangleGrid {
    /// Bucket `tris` (indices into `points`) with cells of about `cell` \[m\].
    pub fn new(points: &[Vec3], tris: &[[usize; 3]], cell: f64) -> TriangleGrid {
        let boxes: Vec<(Vec3, Vec3)> = tris
            .iter()
            .map(|t| {
                let (a, b, c) = (points[t[0]], points[t[1]], points[t[2]]);
                (a.inf(&b).inf(&c), a.sup(&b).sup(&c))
            })
            .collect();
        TriangleGrid::from_boxes(boxes, cell)
    }

    /// Bucket items by their bounding boxes `(min, max)` \[m\] with cells of about `cell` \[m\]
    /// (the grid of [`super::TetGrid`], whose items are tetrahedra).
    pub(super) fn from_boxes(boxes: Vec<(Vec3, Vec3)>, cell: f64) -> TriangleGrid {
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for (a, b) in &boxes {
            lo = lo.inf(a);
            hi = hi.sup(b);
        }
        if boxes.is_empty() {
            lo = Vec3::zeros();
            hi = Vec3::zeros();
        }
        let ext = hi - lo;
        let mut h = cell.max(1e-12);
        // Keep the grid at most ~2 million cells.
        while (ext.x / h + 1.0) * (ext.y / h + 1.0) * (ext.z / h + 1.0) > 2e6 {
            h *= 1.5;
        }
        let grid = Grid3 { origin: lo, h, dims: [(ext.x / h) as usize + 1, (ext.y / h) as usize + 1, (ext.z / h) as usize + 1] };
        let ranges: Vec<([usize; 3], [usize; 3])> = boxes.iter().map(|(a, b)| (grid.cell_clamped(a), grid.cell_clamped(b))).collect();
        let cells = Buckets::build(grid.len(), boxes.len(), |t| grid.cells_in(ranges[t].0, ranges[t].1));
        TriangleGrid { grid, cells, boxes }
    }

    /// The triangle (of those bucketed, passing `keep`) nearest to `p`, ties to the lowest index.
    pub fn nearest(&self, points: &[Vec3], tris: &[[usize; 3]], p: &Vec3, keep: impl Fn(usize) -> bool) -> Option<Nearest> {
        let (g, n) = (&self.grid, self.grid.dims);
        let c: [isize; 3] = std::array::from_fn(|a| (((p[a] - g.origin[a]) / g.h).floor() as isize).clamp(-1, n[a] as isize));
        let mut best: Option<Nearest> = None;
        let max_r = n[0].max(n[1]).max(n[2]) as isize + 1;
        for r in 0..=max_r {
            for k in c[2] - r..=c[2] + r {
                for j in c[1] - r..=c[1] + r {
                    for i in c[0] - r..=c[0] + r {
                        let on_shell = (i - c[0]).abs() == r || (j - c[1]).abs() == r || (k - c[2]).abs() == r;
                        if !on_shell || i < 0 || j < 0 || k < 0 || i >= n[0] as isize || j >= n[1] as isize || k >= n[2] as isize {
                            continue;
                        }
                        for &t in self.cells.get(g.index(i as usize, j as usize, k as usize)) {
                            let t = t as usize;
                            if let Some(b) = &best {
                                // Skip a triangle whose box is farther than the best so far.
                                let (lo, hi) = &self.boxes[t];
                                let d = (lo - p).sup(&Vec3::zeros()) + (p - hi).sup(&Vec3::zeros());
                                if d.norm_squared() > b.distance * b.distance {
                                    continue;
                                }
                            }
                            if !keep(t) {
                                continue;
                            }
                            let tri = tris[t];
                            let (q, bary) = closest_on_triangle(p, &points[tri[0]], &points[tri[1]], &points[tri[2]]);
                            let d = (q - p).norm();
                            if best.as_ref().is_none_or(|b| d < b.distance || (d == b.distance && t < b.triangle)) {
                                best = Some(Nearest { triangle: t, point: q, bary, distance: d });
                            }
                        }
                    }
                }
            }
            // Everything in the cube of cells [c - r, c + r] has been seen; anything else is at
            // least as far as the nearest face of that cube.
            if let Some(b) = &best {
                let mut reach = f64::INFINITY;
                for a in 0..3 {
                    let lo_face = g.origin[a] + (c[a] - r) as f64 * g.h;
                    let hi_face = g.origin[a] + (c[a] + r + 1) as f64 * g.h;
                    reach = reach.min(p[a] - lo_face).min(hi_face - p[a]);
                }
                if b.distance <= reach {
                    break;
                }
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::ellipsoid_surface;

    #[test]
    fn nearest_matches_brute_force() {
        let s = ellipsoid_surface([0.02, 0.03, 0.04], 4);
        let (p, t) = (s.points(), s.triangles());
        for cell in [0.001, 0.004, 0.02] {
            let g = TriangleGrid::new(p, t, cell);
            for k in 0..300 {
                let q = Vec3::new(((k * 37) % 101) as f64 / 1000.0 - 0.05, ((k * 53) % 89) as f64 / 1000.0 - 0.045, ((k * 17) % 97) as f64 / 1000.0 - 0.05);
                let keep = |i: usize| !i.is_multiple_of(3);
                let Nearest { triangle: bt, distance: bd, .. } = g.nearest(p, t, &q, keep).unwrap();
                let brute = (0..t.len())
                    .filter(|&i| keep(i))
                    .map(|i| (closest_on_triangle(&q, &p[t[i][0]], &p[t[i][1]], &p[t[i][2]]).0 - q).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!((bd - brute).abs() < 1e-15, "cell {cell} point {k}: grid {bd} (tri {bt}) vs brute {brute}");
            }
        }
    }
}
