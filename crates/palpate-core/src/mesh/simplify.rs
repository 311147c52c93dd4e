//! Triangle-mesh simplification by quadric-error edge collapse (Garland and Heckbert 1997).
//!
//! Used to make the coarse inner surface of the hybrid model's FEM core from the (fine) inner
//! surface of an organ wall. Each vertex carries the quadric of its triangles' planes (area
//! weighted); an edge collapses to the point that minimises the summed quadric (or, when that
//! 3x3 system is singular, the best of its end points and midpoint). A collapse is refused when
//! it would change the topology (the link condition), fold a triangle over (its normal turning
//! by more than [`MAX_NORMAL_TURN_DEG`]) or pinch a boundary (an interior edge joining two
//! boundary vertices). Boundary edges get heavy perpendicular-plane quadrics, so boundary loops
//! (the base of a truncated ventricle, valve rings) are kept in place and in shape.

use crate::math::Vec3;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

/// Largest turn of a triangle's normal that a collapse may cause \[deg\].
pub const MAX_NORMAL_TURN_DEG: f64 = 60.0;
/// Smallest shape quality (1 = equilateral) a collapse may create (relaxed step by step, down
/// to 0.1, if the simplification stalls above its target).
pub const MIN_SHAPE: f64 = 0.35;
/// Longest edge a collapse may create, relative to the edge of a uniform mesh of the target size.
pub const MAX_EDGE_FACTOR: f64 = 1.6;
/// Weight of the squared-squared edge length in the collapse order (see `best`).
const LENGTH_WEIGHT: f64 = 0.05;
/// Weight of the boundary-preserving quadrics relative to the surface ones.
const BOUNDARY_WEIGHT: f64 = 100.0;

/// A symmetric 4x4 quadric `[a b c d]^T [a b c d]`, stored as its 10 upper entries.
#[derive(Debug, Clone, Copy, Default)]
struct Quadric([f64; 10]);

impl Quadric {
    fn plane(n: Vec3, d: f64, w: f64) -> Quadric {
        let (a, b, c) = (n.x, n.y, n.z);
        Quadric([a * a * w, a * b * w, a * c * w, a * d * w, b * b * w, b * c * w, b * d * w, c * c * w, c * d * w, d * d * w])
    }
    fn add(&self, o: &Quadric) -> Quadric {
        let mut q = [0.0; 10];
        for (k, v) in q.iter_mut().enumerate() {
            *v = self.0[k] + o.0[k];
        }
        Quadric(q)
    }
    fn eval(&self, p: &Vec3) -> f64 {
        let q = &self.0;
        let (x, y, z) = (p.x, p.y, p.z);
        q[0] * x * x
            + 2.0 * q[1] * x * y
            + 2.0 * q[2] * x * z
            + 2.0 * q[3] * x
            + q[4] * y * y
            + 2.0 * q[5] * y * z
            + 2.0 * q[6] * y
            + q[7] * z * z
            + 2.0 * q[8] * z
            + q[9]
    }
    /// The minimiser, if the 3x3 block is well conditioned.
    fn optimum(&self) -> Option<Vec3> {
        let q = &self.0;
        let a = crate::math::Mat3::new(q[0], q[1], q[2], q[1], q[4], q[5], q[2], q[5], q[7]);
        let scale = a.abs().max();
        if !(scale > 0.0) || a.determinant().abs() < 1e-9 * scale * scale * scale {
            return None;
        }
        a.try_inverse().map(|inv| -(inv * Vec3::new(q[3], q[6], q[8])))
    }
}

fn old_longest(pos: &[Vec3], tri: &[usize; 3]) -> f64 {
    [
        (pos[tri[1]] - pos[tri[0]]).norm_squared(),
        (pos[tri[2]] - pos[tri[1]]).norm_squared(),
        (pos[tri[0]] - pos[tri[2]]).norm_squared(),
    ]
    .into_iter()
    .fold(0.0, f64::max)
}

#[derive(Debug, PartialEq)]
struct Candidate {
    cost: f64,
    a: usize,
    b: usize,
    stamp: (u32, u32),
}
impl Eq for Candidate {}
impl Ord for Candidate {
    fn cmp(&self, o: &Self) -> Ordering {
        // Min-heap on the cost.
        o.cost.total_cmp(&self.cost).then_with(|| (o.a, o.b).cmp(&(self.a, self.b)))
    }
}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// A simplified surface.
#[derive(Debug, Clone)]
pub struct Simplified {
    /// Vertex positions \[m\].
    pub points: Vec<Vec3>,
    /// Triangles (same orientation as the input).
    pub triangles: Vec<[usize; 3]>,
    /// For each output vertex, one input vertex it was collapsed from (for tags).
    pub origin: Vec<usize>,
    /// Output vertices on a boundary loop of the surface.
    pub boundary: Vec<bool>,
}

/// Simplify a manifold, consistently oriented triangle surface (open or closed) down to at most
/// `target` triangles, or as far as the safety checks allow.
pub fn simplify(points: &[Vec3], triangles: &[[usize; 3]], target: usize) -> Simplified {
    let mut pos = points.to_vec();
    let mut tris: Vec<[usize; 3]> = triangles.to_vec();
    let mut alive = vec![true; tris.len()];
    let mut vtris: Vec<Vec<usize>> = vec![vec![]; pos.len()];
    for (t, tri) in tris.iter().enumerate() {
        for &v in tri {
            vtris[v].push(t);
        }
    }
    // Edge -> number of triangles (boundary edges have one).
    let mut edge_count: HashMap<(usize, usize), u32> = HashMap::new();
    for tri in &tris {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *edge_count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let mut quad = vec![Quadric::default(); pos.len()];
    let mut on_boundary = vec![false; pos.len()];
    for tri in &tris {
        let (p0, p1, p2) = (pos[tri[0]], pos[tri[1]], pos[tri[2]]);
        let n2 = (p1 - p0).cross(&(p2 - p0));
        let area2 = n2.norm();
        if area2 == 0.0 {
            continue;
        }
        let n = n2 / area2;
        let q = Quadric::plane(n, -n.dot(&p0), 0.5 * area2);
        for &v in tri {
            quad[v] = quad[v].add(&q);
        }
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            if edge_count[&(a.min(b), a.max(b))] == 1 {
                on_boundary[a] = true;
                on_boundary[b] = true;
                let e = pos[b] - pos[a];
                let m = e.cross(&n);
                let len2 = e.norm_squared();
                if m.norm() > 0.0 {
                    let m = m.normalize();
                    let qb = Quadric::plane(m, -m.dot(&pos[a]), BOUNDARY_WEIGHT * len2);
                    quad[a] = quad[a].add(&qb);
                    quad[b] = quad[b].add(&qb);
                }
            }
        }
    }
    let mut stamp = vec![0u32; pos.len()];
    let mut origin: Vec<usize> = (0..pos.len()).collect();
    let mut heap = BinaryHeap::new();
    let best = |quad: &[Quadric], pos: &[Vec3], a: usize, b: usize| -> (f64, Vec3) {
        let q = quad[a].add(&quad[b]);
        let mut cands = vec![pos[a], pos[b], 0.5 * (pos[a] + pos[b])];
        if let Some(o) = q.optimum() {
            // Keep the optimum near the edge (a far optimum is a near-singular system).
            let len = (pos[b] - pos[a]).norm();
            if (o - 0.5 * (pos[a] + pos[b])).norm() <= len {
                cands.push(o);
            }
        }
        let (err, p) = cands.into_iter().map(|p| (q.eval(&p).max(0.0), p)).min_by(|x, y| x.0.total_cmp(&y.0)).unwrap();
        // Short edges first: with the quadric error alone, a coarse target on a smooth surface
        // ends in slivers; the length term keeps the result even, the quadric places the vertex.
        let len2 = (pos[b] - pos[a]).norm_squared();
        (err + LENGTH_WEIGHT * len2 * len2, p)
    };
    for &(a, b) in edge_count.keys() {
        let (cost, _) = best(&quad, &pos, a, b);
        heap.push(Candidate { cost, a, b, stamp: (0, 0) });
    }
    let mut n_alive = tris.len();
    // Edge length of a uniform mesh of `target` triangles over the same area: collapses that
    // would make longer edges are refused, which keeps the coarse mesh even (and boundary loops
    // from collapsing to a few vertices while the interior is still fine).
    let area: f64 = tris.iter().map(|t| 0.5 * (pos[t[1]] - pos[t[0]]).cross(&(pos[t[2]] - pos[t[0]])).norm()).sum();
    let max_edge = MAX_EDGE_FACTOR * (4.0 * area / (3f64.sqrt() * target.max(1) as f64)).sqrt();
    let cos_max = MAX_NORMAL_TURN_DEG.to_radians().cos();
    let neighbours = |vtris: &Vec<Vec<usize>>, tris: &Vec<[usize; 3]>, v: usize| -> Vec<usize> {
        let mut out: Vec<usize> = vtris[v].iter().flat_map(|&t| tris[t]).filter(|&w| w != v).collect();
        out.sort_unstable();
        out.dedup();
        out
    };
    let mut rejected = [0usize; 6];
    let mut min_shape = MIN_SHAPE;
    while n_alive > target {
        let Some(c) = heap.pop() else {
            // Stalled above the target: accept worse shapes, and try every edge again.
            if min_shape <= 0.1 {
                break;
            }
            min_shape *= 0.7;
            let mut edges: Vec<(usize, usize)> = Vec::new();
            for (t, tri) in tris.iter().enumerate() {
                if alive[t] {
                    for k in 0..3 {
                        let (a, b) = (tri[k], tri[(k + 1) % 3]);
                        edges.push((a.min(b), a.max(b)));
                    }
                }
            }
            edges.sort_unstable();
            edges.dedup();
            for (a, b) in edges {
                let (cost, _) = best(&quad, &pos, a, b);
                heap.push(Candidate { cost, a, b, stamp: (stamp[a], stamp[b]) });
            }
            continue;
        };
        let (a, b) = (c.a, c.b);
        if c.stamp != (stamp[a], stamp[b]) {
            continue;
        }
        // The edge must still exist.
        let shared: Vec<usize> = vtris[a].iter().copied().filter(|t| tris[*t].contains(&b)).collect();
        if shared.is_empty() {
            continue;
        }
        let edge_is_boundary = shared.len() == 1;
        if on_boundary[a] && on_boundary[b] && !edge_is_boundary {
            rejected[0] += 1;
            continue;
        }
        // Link condition: common neighbours are exactly the apexes of the shared triangles.
        let (na, nb) = (neighbours(&vtris, &tris, a), neighbours(&vtris, &tris, b));
        let common = na.iter().filter(|w| nb.binary_search(w).is_ok()).count();
        if common != shared.len() {
            rejected[1] += 1;
            continue;
        }
        let (_, p_new) = best(&quad, &pos, a, b);
        // No fold-overs, no slivers.
        let mut ok = true;
        for &v in &[a, b] {
            for &t in &vtris[v] {
                if shared.contains(&t) {
                    continue;
                }
                let tri = tris[t];
                let p = |w: usize| if w == a || w == b { p_new } else { pos[w] };
                let n_old = (pos[tri[1]] - pos[tri[0]]).cross(&(pos[tri[2]] - pos[tri[0]]));
                let n_new = (p(tri[1]) - p(tri[0])).cross(&(p(tri[2]) - p(tri[0])));
                let (lo, ln) = (n_old.norm(), n_new.norm());
                let longest = [(p(tri[1]) - p(tri[0])).norm_squared(), (p(tri[2]) - p(tri[1])).norm_squared(), (p(tri[0]) - p(tri[2])).norm_squared()]
                    .into_iter()
                    .fold(0.0, f64::max);
                // Shape: 2 sqrt(3) |n| / sum of squared edges is 1 for an equilateral triangle.
                let sum_sq = (p(tri[1]) - p(tri[0])).norm_squared() + (p(tri[2]) - p(tri[1])).norm_squared() + (p(tri[0]) - p(tri[2])).norm_squared();
                let shape = 2.0 * 3f64.sqrt() * ln / sum_sq;
                let old_sum_sq =
                    (pos[tri[1]] - pos[tri[0]]).norm_squared() + (pos[tri[2]] - pos[tri[1]]).norm_squared() + (pos[tri[0]] - pos[tri[2]]).norm_squared();
                let old_shape = 2.0 * 3f64.sqrt() * lo / old_sum_sq;
                if longest.sqrt() > max_edge && longest > old_longest(&pos, &tri) {
                    rejected[2] += 1;
                    ok = false;
                    break;
                }
                if lo == 0.0 || ln <= 0.05 * longest || n_old.dot(&n_new) < cos_max * lo * ln || shape < min_shape.min(0.999 * old_shape) {
                    rejected[if lo == 0.0 {
                        3
                    } else if ln <= 0.05 * longest {
                        4
                    } else if shape < min_shape.min(0.999 * old_shape) {
                        5
                    } else {
                        3
                    }] += 1;
                    ok = false;
                    break;
                }
            }
            if !ok {
                break;
            }
        }
        if !ok {
            continue;
        }
        // Collapse b into a.
        for &t in &shared {
            alive[t] = false;
            n_alive -= 1;
            for &w in &tris[t] {
                if w != a && w != b {
                    vtris[w].retain(|&s| s != t);
                }
            }
        }
        let moved: Vec<usize> = vtris[b].iter().copied().filter(|t| alive[*t]).collect();
        for &t in &moved {
            for w in tris[t].iter_mut() {
                if *w == b {
                    *w = a;
                }
            }
        }
        vtris[a].retain(|t| alive[*t]);
        vtris[a].extend(moved);
        vtris[b].clear();
        pos[a] = p_new;
        quad[a] = quad[a].add(&quad[b]);
        on_boundary[a] |= on_boundary[b];
        if origin[a] == a && on_boundary[b] && !on_boundary[a] {
            origin[a] = origin[b];
        }
        // Only the edges at `a` changed cost (their quadric sum and end point); the others
        // keep their heap entries (link and fold checks are redone when they are popped).
        stamp[a] += 1;
        stamp[b] += 1;
        for x in neighbours(&vtris, &tris, a) {
            let (cost, _) = best(&quad, &pos, a, x);
            heap.push(Candidate { cost, a, b: x, stamp: (stamp[a], stamp[x]) });
        }
    }
    if std::env::var_os("PALPATE_DEBUG").is_some() {
        eprintln!(
            "simplify: {} -> {n_alive} triangles (target {target}); rejected: pinch {}, link {}, long edge {}, fold {}, sliver {}, shape {}",
            tris.len(),
            rejected[0],
            rejected[1],
            rejected[2],
            rejected[3],
            rejected[4],
            rejected[5]
        );
    }
    // Compact.
    let mut map = vec![usize::MAX; pos.len()];
    let mut out = Simplified { points: vec![], triangles: vec![], origin: vec![], boundary: vec![] };
    for (t, tri) in tris.iter().enumerate() {
        if !alive[t] {
            continue;
        }
        let mut nt = [0; 3];
        for (k, &v) in tri.iter().enumerate() {
            if map[v] == usize::MAX {
                map[v] = out.points.len();
                out.points.push(pos[v]);
                out.origin.push(origin[v]);
                out.boundary.push(on_boundary[v]);
            }
            nt[k] = map[v];
        }
        out.triangles.push(nt);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::surface::ellipsoid_surface;

    #[test]
    fn simplified_ellipsoid_stays_closed_and_close() {
        let s = ellipsoid_surface([0.02, 0.02, 0.035], 4);
        let out = simplify(s.points(), s.triangles(), 64);
        assert!(out.triangles.len() <= 64 && out.triangles.len() >= 56, "{}", out.triangles.len());
        // Closed: every edge in exactly two triangles, consistently oriented.
        let mut dir = HashMap::new();
        for tri in &out.triangles {
            for k in 0..3 {
                assert!(dir.insert((tri[k], tri[(k + 1) % 3]), ()).is_none());
            }
        }
        for &(a, b) in dir.keys() {
            assert!(dir.contains_key(&(b, a)));
        }
        // Vertices near the ellipsoid: a coarse vertex's quadric optimum sits off a curved
        // surface by about the sagitta of its edges (here edges of ~15 mm on radii of 20-35 mm).
        for p in &out.points {
            let l = ((p.x / 0.02).powi(2) + (p.y / 0.02).powi(2) + (p.z / 0.035).powi(2)).sqrt();
            assert!((l - 1.0).abs() < 0.08, "normalised radius {l}");
        }
    }
}
