//! A space-filling order (Morton, or Z-order): points close in space get close ranks, so that
//! arrays stored in this order keep a neighbourhood in few cache lines and pages. The hybrid
//! build stores its outer surface and particles so (`hybrid/order.rs`, which says why).

use crate::math::Vec3;

/// Bits per axis of the code (3 x 21 = 63 bits of a `u64`).
const BITS: u32 = 21;

/// The Morton code of `p` in the box `[lo, lo + extent]` (each axis quantised to 2^21 cells;
/// points outside are clamped to it).
pub fn code(p: &Vec3, lo: &Vec3, extent: f64) -> u64 {
    let cells = (1u64 << BITS) as f64;
    let q = |x: f64, l: f64| -> u64 {
        let t = if extent > 0.0 { (x - l) / extent } else { 0.0 };
        // A NaN stays NaN through the clamp and casts to 0.
        (t.clamp(0.0, 1.0) * (cells - 1.0)) as u64
    };
    spread(q(p.x, lo.x)) | (spread(q(p.y, lo.y)) << 1) | (spread(q(p.z, lo.z)) << 2)
}

/// The 21 low bits of `x` spread to every third bit.
fn spread(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// The permutation that lists `points` in Morton order: `order[k]` is the index of the `k`-th
/// point along the curve (ties keep their input order, so the result is deterministic).
pub fn order(points: &[Vec3]) -> Vec<usize> {
    let (mut lo, mut hi) = (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY));
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let extent = (hi - lo).max();
    let mut keyed: Vec<(u64, usize)> = points.iter().enumerate().map(|(i, p)| (code(p, &lo, extent), i)).collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_interleaves_and_codes_follow_the_z_curve() {
        assert_eq!(spread(0b111), 0b1001001);
        assert_eq!(spread(0x1f_ffff).count_ones(), 21);
        let lo = Vec3::zeros();
        // The 8 corners of a unit cube: x is the lowest bit, then y, then z.
        let c = |x: f64, y: f64, z: f64| code(&Vec3::new(x, y, z), &lo, 1.0) >> 60;
        assert_eq!((c(0.0, 0.0, 0.0), c(1.0, 0.0, 0.0), c(0.0, 1.0, 0.0), c(0.0, 0.0, 1.0)), (0, 1, 2, 4));
    }

    #[test]
    fn order_is_a_permutation_that_keeps_neighbours_close() {
        // A shuffled 16^3 lattice: in Morton order, consecutive points are mostly lattice
        // neighbours, and a cube of 4^3 takes exactly 64 consecutive ranks.
        let n = 16;
        let mut pts: Vec<Vec3> = (0..n * n * n).map(|k| Vec3::new((k % n) as f64, ((k / n) % n) as f64, (k / (n * n)) as f64)).collect();
        let mut s = 12345u64;
        for i in (1..pts.len()).rev() {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            pts.swap(i, (s >> 33) as usize % (i + 1));
        }
        let ord = order(&pts);
        let mut seen = vec![false; pts.len()];
        for &i in &ord {
            assert!(!seen[i]);
            seen[i] = true;
        }
        let first: Vec<Vec3> = ord[..64].iter().map(|&i| pts[i]).collect();
        assert!(first.iter().all(|p| p.x < 4.0 && p.y < 4.0 && p.z < 4.0), "the first 64 ranks are the corner cube");
        // The path through the points in that order: a Z-curve steps to a lattice neighbour or
        // across a diagonal mostly (~1.5 spacings a step on this lattice), the shuffled input
        // across the block (~10).
        let walk = |o: &[usize]| o.windows(2).map(|w| (pts[w[0]] - pts[w[1]]).norm()).sum::<f64>() / (o.len() - 1) as f64;
        let shuffled: Vec<usize> = (0..pts.len()).collect();
        let (z, s) = (walk(&ord), walk(&shuffled));
        assert!(z < 2.0 && s > 5.0, "mean step {z} in Morton order, {s} shuffled");
    }
}
