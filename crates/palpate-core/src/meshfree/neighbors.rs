//! Fixed-radius neighbour search in the reference configuration, once per model: a uniform cell
//! grid with cell size equal to the search radius, so that the neighbours of a point lie in its
//! 27 surrounding cells. `O(n)` to build and query for quasi-uniform particle sets, no dependency.

use crate::math::Vec3;
use crate::spatial::{Buckets, Grid3};

/// Neighbours of every point within `radius` (excluding itself), as compressed rows:
/// the neighbours of `i` are `idx[ptr[i]..ptr[i+1]]`, sorted.
pub fn neighbours_within(points: &[Vec3], radius: f64) -> (Vec<usize>, Vec<usize>) {
    let n = points.len();
    let mut ptr = Vec::with_capacity(n + 1);
    let mut idx = Vec::new();
    ptr.push(0);
    if n == 0 {
        return (ptr, idx);
    }
    let mut lo = points[0];
    let mut hi = points[0];
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let grid = Grid3 { origin: lo, h: radius, dims: std::array::from_fn(|a| (((hi[a] - lo[a]) / radius).floor() as usize + 1).max(1)) };
    // Counting sort of the points by cell.
    let cells = Buckets::build(grid.len(), n, |i| [grid.index_of(grid.cell_clamped(&points[i]))]);
    let r2 = radius * radius;
    let mut row = Vec::new();
    for (i, p) in points.iter().enumerate() {
        row.clear();
        let c = grid.cell_clamped(p);
        for dz in -1i64..=1 {
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let q = [c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz];
                    if (0..3).any(|a| q[a] < 0 || q[a] >= grid.dims[a] as i64) {
                        continue;
                    }
                    for &j in cells.get(grid.index(q[0] as usize, q[1] as usize, q[2] as usize)) {
                        let j = j as usize;
                        if j != i && (points[j] - p).norm_squared() < r2 {
                            row.push(j);
                        }
                    }
                }
            }
        }
        row.sort_unstable();
        idx.extend_from_slice(&row);
        ptr.push(idx.len());
    }
    (ptr, idx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_matches_brute_force() {
        // A jittered lattice.
        let mut pts = Vec::new();
        for k in 0..7 {
            for j in 0..6 {
                for i in 0..5 {
                    let jitter = ((i * 7 + j * 13 + k * 29) % 11) as f64 * 0.01;
                    pts.push(Vec3::new(i as f64 + jitter, j as f64 - jitter, k as f64 + 0.5 * jitter));
                }
            }
        }
        let r = 1.7;
        let (ptr, idx) = neighbours_within(&pts, r);
        for i in 0..pts.len() {
            let brute: Vec<usize> = (0..pts.len()).filter(|&j| j != i && (pts[j] - pts[i]).norm() < r).collect();
            assert_eq!(&idx[ptr[i]..ptr[i + 1]], &brute[..]);
        }
    }
}
