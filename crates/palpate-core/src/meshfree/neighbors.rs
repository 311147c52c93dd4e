//! Fixed-radius neighbour search in the reference configuration, once per model: a uniform cell
//! grid with cell size equal to the search radius, so that the neighbours of a point lie in its
//! 27 surrounding cells. `O(n)` to build and query for quasi-uniform particle sets, no dependency.

use crate::error::LimitError;
use crate::limits;
use crate::math::Vec3;
use crate::spatial::{Buckets, Grid3};

/// Neighbours of every point within `radius` (excluding itself), as compressed rows:
/// the neighbours of `i` are `idx[ptr[i]..ptr[i+1]]`, sorted.
pub fn neighbours_within(points: &[Vec3], radius: f64) -> (Vec<usize>, Vec<usize>) {
    // No budget on the pairs (0 bytes each): the caller sized the radius; the grid is bounded.
    match neighbours_within_limited(points, radius, 0.0) {
        Ok(r) => r,
        Err(_) => (vec![0], Vec::new()), // unreachable: a zero per-pair cost never exceeds the budget
    }
}

/// [`neighbours_within`], refusing (before it is taken) more memory than the budget of
/// [`crate::limits`] when each pair will cost its caller `bytes_per_pair` bytes: a support radius
/// far larger than the spacing makes `n^2` pairs.
///
/// The cell grid has cells of at least `radius` (the neighbours of a point then still lie in its
/// 27 surrounding cells) and at most about `4 n` cells: a tiny radius over a large box would
/// otherwise ask for 1e12 cells or overflow `usize`.
pub fn neighbours_within_limited(points: &[Vec3], radius: f64, bytes_per_pair: f64) -> Result<(Vec<usize>, Vec<usize>), LimitError> {
    let n = points.len();
    let mut ptr = Vec::with_capacity(n + 1);
    let mut idx = Vec::new();
    ptr.push(0);
    if n == 0 {
        return Ok((ptr, idx));
    }
    let mut lo = points[0];
    let mut hi = points[0];
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let max_cells = 4.0 * n as f64 + 64.0;
    let mut cell = radius;
    let cells_of = |c: f64| -> [f64; 3] { std::array::from_fn(|a| ((hi[a] - lo[a]) / c).floor() + 1.0) };
    // Doubling ends: after ~1100 doublings any finite extent fits in one cell.
    while cells_of(cell).iter().product::<f64>() > max_cells && cell.is_finite() {
        cell *= 2.0;
    }
    let grid = Grid3 { origin: lo, h: cell, dims: cells_of(cell).map(|d| (d as usize).max(1)) };
    let b = limits::budget();
    let budget = b.bytes as f64;
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
        if bytes_per_pair > 0.0 && (idx.len() + row.len()) as f64 * bytes_per_pair > budget {
            // Extrapolate from the rows seen so far: what the whole set would ask.
            let estimate = (idx.len() + row.len()) as f64 * n as f64 / (i + 1) as f64;
            return Err(LimitError {
                what: format!("neighbour pairs of {n} particles within the support radius {radius} m (found {} by particle {i}; the radius may be far larger than the spacing)", idx.len() + row.len()),
                count: estimate,
                bytes: estimate * bytes_per_pair,
                budget: b.bytes,
                budget_source: b.source,
            });
        }
        idx.extend_from_slice(&row);
        ptr.push(idx.len());
    }
    Ok((ptr, idx))
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
