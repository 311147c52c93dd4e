//! Closed triangle surfaces: validation, volume, inside tests, and an ellipsoid generator.
//!
//! A [`TriSurface`] is the boundary of a solid, used to fill that solid with particles
//! ([`super::sample`]). It is validated once, in [`TriSurface::from_arrays`]: finite vertices,
//! indices in range, no repeated vertex in a triangle, no degenerate (zero-area) triangle, no
//! duplicate triangle, every edge shared by exactly two triangles that traverse it in opposite
//! directions (closed, manifold, consistently oriented), and a non-zero enclosed volume. An
//! inward-oriented surface (negative volume) is reversed with a [`SurfaceWarning`].
//!
//! ## Inside tests
//! * [`TriSurface::contains`]: the generalised winding number of Jacobson, Kavan and
//!   Sorkine-Hornung 2013 (*Robust inside-outside segmentation using generalized winding
//!   numbers*), the sum of the solid angles of the triangles seen from the point (Van Oosterom and
//!   Strackee 1983) over `4 pi`; inside when it exceeds 1/2. It is exact (1 or 0) for a closed
//!   surface and degrades gracefully for a slightly open one. `O(triangles)` per query.
//! * [`TriSurface::contains_parity`]: the parity of the crossings of the vertical ray from the
//!   point towards `+z`, with the triangles bucketed by their xy bounding box into a uniform grid
//!   (built once, in validation), so a query costs `O(triangles per grid cell)`. This is the test
//!   the lattice sampler uses, one whole column of lattice points per ray.
//!
//! **Degenerate hits.** A vertical line through an edge or a vertex of the xy projection is
//! decided by *simulation of simplicity* (Edelsbrunner and Muecke 1990): the line is moved by the
//! infinitesimal `(eps, eps^2)` in xy, which never passes through an edge or vertex. Each edge's
//! side test is evaluated in a canonical vertex order (lowest index first), so the two triangles
//! sharing an edge get exactly opposite answers and a line through the edge crosses exactly one of
//! them. Triangles that are vertical (zero xy area) are never crossed.

use std::collections::HashMap;

use thiserror::Error;

use crate::math::Vec3;
use crate::spatial::Buckets;

/// A triangle whose `area / (longest edge)^2` is below this is refused as degenerate.
/// (An equilateral triangle has 0.433; a 1:10^4 sliver about 5e-5.)
pub const DEGENERATE_RELATIVE_AREA: f64 = 1e-10;

/// A triangle surface that cannot be used. Every variant names the offending triangle, vertex or
/// edge and the reason; `InFile` adds the file it came from.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SurfaceError {
    #[error("empty surface: {what}")]
    Empty { what: &'static str },
    #[error("vertex {vertex}: non-finite coordinate ({x}, {y}, {z})")]
    NonFiniteVertex { vertex: usize, x: f64, y: f64, z: f64 },
    #[error("triangle {triangle}: vertex index {index} out of range (surface has {n_vertices} vertices)")]
    IndexOutOfRange { triangle: usize, index: i64, n_vertices: usize },
    #[error("triangle {triangle}: vertex {vertex} appears twice")]
    RepeatedVertex { triangle: usize, vertex: usize },
    #[error("triangle {triangle}: degenerate (area {area:e} m^2, relative {relative:e} of its longest edge squared)")]
    Degenerate { triangle: usize, area: f64, relative: f64 },
    #[error("triangle {triangle}: duplicate of triangle {other} (same three vertices)")]
    DuplicateTriangle { triangle: usize, other: usize },
    #[error("open surface: edge ({a}, {b}) of triangle {triangle} belongs to no other triangle (a hole or a boundary)")]
    OpenEdge { a: usize, b: usize, triangle: usize },
    #[error("non-manifold: edge ({a}, {b}) is shared by {count} triangles ({}), not two", list(triangles))]
    NonManifoldEdge { a: usize, b: usize, count: usize, triangles: Vec<usize> },
    #[error("non-manifold (inconsistent orientation): edge ({a}, {b}) is traversed from vertex {a} to vertex {b} by both triangle {first} and triangle {second}; one of them is flipped")]
    InconsistentOrientation { a: usize, b: usize, first: usize, second: usize },
    #[error("the surface encloses no volume ({volume:e} m^3)")]
    NoVolume { volume: f64 },
    #[error("{name} = {value}: {reason}")]
    Parameter { name: &'static str, value: f64, reason: &'static str },
    #[error("inner surface vertex {vertex} at ({x}, {y}, {z}) lies outside the outer surface: the inner surface must lie inside the outer one")]
    NotNested { vertex: usize, x: f64, y: f64, z: f64 },
    #[error("the sampling lattice would have {points:e} points (spacing too small for the surface's bounding box; the limit is {limit:e})")]
    TooLarge { points: f64, limit: f64 },
    #[error("{file}: {source}")]
    InFile { file: String, source: Box<SurfaceError> },
    #[error(transparent)]
    Limit(#[from] crate::error::LimitError),
}

fn list(v: &[usize]) -> String {
    v.iter().map(|t| t.to_string()).collect::<Vec<_>>().join(", ")
}

impl SurfaceError {
    /// Attach the file name the surface came from.
    pub fn in_file(self, file: impl Into<String>) -> SurfaceError {
        SurfaceError::InFile { file: file.into(), source: Box::new(self) }
    }
}

/// Something fixed or noticed during validation that the user should hear about.
#[derive(Debug, Clone, PartialEq)]
pub enum SurfaceWarning {
    /// The surface was oriented inward (negative volume): every triangle was reversed.
    Reoriented { triangles: usize, volume: f64 },
    /// These vertices belong to no triangle (ignored).
    UnusedVertices { vertices: Vec<usize> },
}

impl std::fmt::Display for SurfaceWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SurfaceWarning::Reoriented { triangles, volume } => {
                write!(f, "the surface is oriented inward (signed volume {volume:e} m^3): reversed all {triangles} triangles")
            }
            SurfaceWarning::UnusedVertices { vertices } => {
                let shown: Vec<String> = vertices.iter().take(8).map(|v| v.to_string()).collect();
                let more = if vertices.len() > 8 { format!(", ... ({} in all)", vertices.len()) } else { String::new() };
                write!(f, "{} vertex(es) used by no triangle (ignored): {}{}", vertices.len(), shown.join(", "), more)
            }
        }
    }
}

/// A closed, manifold, outward-oriented triangle surface \[m\] (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct TriSurface {
    points: Vec<Vec3>,
    triangles: Vec<[usize; 3]>,
    lo: Vec3,
    hi: Vec3,
    grid: ColumnGrid,
}

impl TriSurface {
    /// Validate a surface given as points `(n, 3)` \[m\] and triangles `(m, 3)` of vertex indices
    /// (signed, so that negative indices from a file are reported rather than wrapped).
    pub fn from_arrays(points: &[[f64; 3]], triangles: &[[i64; 3]]) -> Result<(TriSurface, Vec<SurfaceWarning>), SurfaceError> {
        if points.is_empty() {
            return Err(SurfaceError::Empty { what: "no vertices" });
        }
        if triangles.is_empty() {
            return Err(SurfaceError::Empty { what: "no triangles" });
        }
        let n = points.len();
        let pts = super::finite_points(points).map_err(|i| {
            let p = points[i];
            SurfaceError::NonFiniteVertex { vertex: i, x: p[0], y: p[1], z: p[2] }
        })?;
        let mut tris = Vec::with_capacity(triangles.len());
        let mut seen: HashMap<[usize; 3], usize> = HashMap::with_capacity(triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            let mut idx = [0usize; 3];
            for k in 0..3 {
                let i = tri[k];
                if i < 0 || i as u64 >= n as u64 {
                    return Err(SurfaceError::IndexOutOfRange { triangle: t, index: i, n_vertices: n });
                }
                idx[k] = i as usize;
            }
            for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                if idx[a] == idx[b] {
                    return Err(SurfaceError::RepeatedVertex { triangle: t, vertex: idx[a] });
                }
            }
            let [a, b, c] = idx.map(|i| pts[i]);
            let area = 0.5 * (b - a).cross(&(c - a)).norm();
            let lmax = [(b - a).norm(), (c - b).norm(), (a - c).norm()].into_iter().fold(0.0, f64::max);
            let relative = if lmax > 0.0 { area / (lmax * lmax) } else { 0.0 };
            if !(relative >= DEGENERATE_RELATIVE_AREA) {
                return Err(SurfaceError::Degenerate { triangle: t, area, relative });
            }
            let mut key = idx;
            key.sort_unstable();
            if let Some(&other) = seen.get(&key) {
                return Err(SurfaceError::DuplicateTriangle { triangle: t, other });
            }
            seen.insert(key, t);
            tris.push(idx);
        }
        check_edges(&tris)?;

        let mut used = vec![false; n];
        for t in &tris {
            for &i in t {
                used[i] = true;
            }
        }
        let mut warnings = Vec::new();
        let unused: Vec<usize> = (0..n).filter(|&i| !used[i]).collect();
        if !unused.is_empty() {
            warnings.push(SurfaceWarning::UnusedVertices { vertices: unused });
        }
        let (mut lo, mut hi) = (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY));
        for (p, _) in pts.iter().zip(&used).filter(|(_, &u)| u) {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let volume = signed_volume(&pts, &tris);
        let d = (hi - lo).norm();
        if !(volume.abs() > 1e-12 * d * d * d) {
            return Err(SurfaceError::NoVolume { volume });
        }
        if volume < 0.0 {
            for t in tris.iter_mut() {
                t.swap(1, 2);
            }
            warnings.push(SurfaceWarning::Reoriented { triangles: tris.len(), volume });
        }
        let grid = ColumnGrid::new(&pts, &tris, lo, hi);
        Ok((TriSurface { points: pts, triangles: tris, lo, hi, grid }, warnings))
    }

    /// Vertex positions \[m\].
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }
    /// Triangles as vertex indices, outward oriented (counter-clockwise seen from outside).
    pub fn triangles(&self) -> &[[usize; 3]] {
        &self.triangles
    }
    /// Number of vertices (including any unused ones).
    pub fn n_vertices(&self) -> usize {
        self.points.len()
    }
    /// Number of triangles.
    pub fn n_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// Enclosed volume \[m^3\] by the divergence theorem, `sum_t a . (b x c) / 6`: positive (the
    /// surface is outward oriented after validation).
    pub fn volume(&self) -> f64 {
        signed_volume(&self.points, &self.triangles)
    }

    /// Surface area \[m^2\].
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.points[i]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    /// Axis-aligned bounding box `(lo, hi)` of the vertices used by triangles \[m\].
    pub fn bounding_box(&self) -> (Vec3, Vec3) {
        (self.lo, self.hi)
    }

    /// Generalised winding number of the surface around `p` (1 inside, 0 outside for a closed
    /// surface; 1/2 on it): `sum_t Omega_t / (4 pi)` with the signed solid angle `Omega_t` of
    /// triangle `t` seen from `p` (Van Oosterom and Strackee 1983).
    pub fn winding_number(&self, p: &Vec3) -> f64 {
        winding_number(&self.points, &self.triangles, p)
    }

    /// Is `p` inside? Generalised winding number above 1/2 (see the module docs).
    pub fn contains(&self, p: &Vec3) -> bool {
        if (0..3).any(|a| p[a] < self.lo[a] || p[a] > self.hi[a]) {
            return false;
        }
        self.winding_number(p) > 0.5
    }

    /// Is `p` inside? Parity of the crossings of the ray from `p` towards `+z` (see the module docs).
    /// A point exactly on the surface may go either way.
    pub fn contains_parity(&self, p: &Vec3) -> bool {
        if (0..3).any(|a| p[a] < self.lo[a] || p[a] > self.hi[a]) {
            return false;
        }
        let mut z = Vec::new();
        self.column_crossings(p.x, p.y, &mut z);
        z.iter().filter(|&&zc| zc > p.z).count() % 2 == 1
    }

    /// Heights `z` \[m\] at which the vertical line through `(x, y)` crosses the surface, unsorted,
    /// appended to `out` (a line through an edge or vertex is decided by simulation of simplicity).
    /// For a closed surface their number is even.
    pub fn column_crossings(&self, x: f64, y: f64, out: &mut Vec<f64>) {
        for &t in self.grid.candidates(x, y) {
            if let Some(z) = crossing(&self.points, &self.triangles[t as usize], x, y) {
                out.push(z);
            }
        }
    }
}

/// Signed volume `sum_t a . (b x c) / 6` \[m^3\].
fn signed_volume(points: &[Vec3], triangles: &[[usize; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| points[i]);
            a.dot(&b.cross(&c))
        })
        .sum::<f64>()
        / 6.0
}

/// Every edge must be used by exactly two triangles, in opposite directions.
fn check_edges(tris: &[[usize; 3]]) -> Result<(), SurfaceError> {
    // (undirected edge, triangle, forward = traversed from the lower to the higher index)
    let mut uses: Vec<((usize, usize), usize, bool)> = Vec::with_capacity(3 * tris.len());
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            uses.push(((a.min(b), a.max(b)), t, a < b));
        }
    }
    uses.sort_unstable();
    // Report the problem of the lowest-numbered triangle, so the answer does not depend on
    // vertex numbering quirks more than necessary.
    let mut worst: Option<(usize, SurfaceError)> = None;
    let mut keep = |t: usize, e: SurfaceError| {
        if worst.as_ref().is_none_or(|(w, _)| t < *w) {
            worst = Some((t, e));
        }
    };
    let mut s = 0;
    while s < uses.len() {
        let mut e = s + 1;
        while e < uses.len() && uses[e].0 == uses[s].0 {
            e += 1;
        }
        let group = &uses[s..e];
        let (lo, hi) = group[0].0;
        match group.len() {
            1 => {
                let (_, t, fwd) = group[0];
                let (a, b) = if fwd { (lo, hi) } else { (hi, lo) };
                keep(t, SurfaceError::OpenEdge { a, b, triangle: t });
            }
            2 => {
                if group[0].2 == group[1].2 {
                    let (a, b) = if group[0].2 { (lo, hi) } else { (hi, lo) };
                    keep(group[0].1, SurfaceError::InconsistentOrientation { a, b, first: group[0].1, second: group[1].1 });
                }
            }
            k => {
                let triangles: Vec<usize> = group.iter().map(|g| g.1).collect();
                keep(group[0].1, SurfaceError::NonManifoldEdge { a: lo, b: hi, count: k, triangles });
            }
        }
        s = e;
    }
    match worst {
        Some((_, e)) => Err(e),
        None => Ok(()),
    }
}

/// Which side of the directed xy edge `u -> v` the point `(x, y)` lies on: positive to the left.
/// Evaluated with the lower vertex index first, so swapping `u` and `v` negates the result
/// exactly; an exact zero is replaced by the sign the point moved by `(eps, eps^2)` would give.
/// Returns `(raw value, decided sign)`; the sign is 0 only if `u` and `v` coincide in xy.
#[inline]
fn edge_side(points: &[Vec3], u: usize, v: usize, x: f64, y: f64) -> (f64, f64) {
    let (a, b, flip) = if u < v { (u, v, false) } else { (v, u, true) };
    let (pa, pb) = (&points[a], &points[b]);
    let (dx, dy) = (pb.x - pa.x, pb.y - pa.y);
    let e = dx * (y - pa.y) - dy * (x - pa.x);
    // (x + eps, y + eps^2): e + eps^2 dx - eps dy
    let s = if e != 0.0 {
        e
    } else if dy != 0.0 {
        -dy
    } else {
        dx
    };
    if flip {
        (-e, -s.signum())
    } else {
        (e, s.signum())
    }
}

/// Height at which the vertical line through `(x, y)` crosses triangle `t`, if it does.
#[inline]
fn crossing(points: &[Vec3], t: &[usize; 3], x: f64, y: f64) -> Option<f64> {
    let (e_ab, s_ab) = edge_side(points, t[0], t[1], x, y);
    let (e_bc, s_bc) = edge_side(points, t[1], t[2], x, y);
    if s_ab == 0.0 || s_ab != s_bc {
        return None;
    }
    let (e_ca, s_ca) = edge_side(points, t[2], t[0], x, y);
    if s_ca != s_ab {
        return None;
    }
    // Barycentric weights: the weight of a vertex is the side value of the opposite edge.
    let sum = e_ab + e_bc + e_ca;
    let [za, zb, zc] = t.map(|i| points[i].z);
    Some(if sum != 0.0 { (e_bc * za + e_ca * zb + e_ab * zc) / sum } else { (za + zb + zc) / 3.0 })
}

/// Triangles bucketed by their xy bounding box into a uniform grid over the surface's xy extent.
#[derive(Debug, Clone, PartialEq)]
struct ColumnGrid {
    x0: f64,
    y0: f64,
    inv_cell: f64,
    nx: usize,
    ny: usize,
    /// Triangles of cell `i + nx j`.
    cells: Buckets,
}

impl ColumnGrid {
    fn new(points: &[Vec3], triangles: &[[usize; 3]], lo: Vec3, hi: Vec3) -> ColumnGrid {
        // About one cell per triangle edge length: cell side = sqrt(xy area / triangles) * 2,
        // capped so the grid has at most ~4 cells per triangle.
        let (wx, wy) = ((hi.x - lo.x).max(0.0), (hi.y - lo.y).max(0.0));
        let extent = wx.max(wy).max(f64::MIN_POSITIVE);
        let target = (triangles.len() as f64).sqrt().ceil().clamp(1.0, 4096.0);
        let cell = extent / target;
        let nx = ((wx / cell).floor() as usize + 1).max(1);
        let ny = ((wy / cell).floor() as usize + 1).max(1);
        let inv_cell = 1.0 / cell;
        let range = |t: &[usize; 3]| {
            let (mut xmin, mut xmax, mut ymin, mut ymax) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
            for &i in t {
                xmin = xmin.min(points[i].x);
                xmax = xmax.max(points[i].x);
                ymin = ymin.min(points[i].y);
                ymax = ymax.max(points[i].y);
            }
            // One cell of slack each way: a line exactly on a cell border finds the triangle.
            let cl = |v: f64, o: f64, n: usize| (((v - o) * inv_cell).floor() as i64).clamp(0, n as i64 - 1) as usize;
            (
                cl(xmin, lo.x, nx).saturating_sub(1),
                (cl(xmax, lo.x, nx) + 1).min(nx - 1),
                cl(ymin, lo.y, ny).saturating_sub(1),
                (cl(ymax, lo.y, ny) + 1).min(ny - 1),
            )
        };
        let cells = Buckets::build(nx * ny, triangles.len(), |t| {
            let (i0, i1, j0, j1) = range(&triangles[t]);
            (j0..=j1).flat_map(move |j| (i0..=i1).map(move |i| i + nx * j))
        });
        ColumnGrid { x0: lo.x, y0: lo.y, inv_cell, nx, ny, cells }
    }

    /// Triangles whose xy bounding box may contain `(x, y)`.
    #[inline]
    fn candidates(&self, x: f64, y: f64) -> &[u32] {
        let fi = ((x - self.x0) * self.inv_cell).floor();
        let fj = ((y - self.y0) * self.inv_cell).floor();
        // Outside the box (beyond the one slack cell on each side), or NaN: no triangle.
        if !(fi >= -1.0 && fj >= -1.0 && fi <= self.nx as f64 && fj <= self.ny as f64) {
            return &[];
        }
        let i = (fi.max(0.0) as usize).min(self.nx - 1);
        let j = (fj.max(0.0) as usize).min(self.ny - 1);
        self.cell(i, j)
    }

    #[inline]
    fn cell(&self, i: usize, j: usize) -> &[u32] {
        self.cells.get(i + self.nx * j)
    }
}

/// The ellipsoid of semi-axes `semi_axes` \[m\] (along x, y, z, centred at the origin) as a
/// closed, outward-oriented surface: the octahedron cut `subdivisions` times into 4 (new vertices
/// pushed onto the unit sphere), then scaled by the semi-axes. `8 * 4^s` triangles,
/// `4 * 4^s + 2` vertices; the enclosed volume converges to `4/3 pi a b c` (from below).
///
/// # Panics
/// If a semi-axis is not finite and positive, or `subdivisions > 10` (8 million triangles).
/// [`ellipsoid_surface`] for input from outside: the semi-axes checked (finite, positive, and
/// within 1e6 of each other: a flatter ellipsoid's triangles are degenerate) and the surface
/// validated without panicking.
pub fn try_ellipsoid_surface(semi_axes: [f64; 3], subdivisions: usize) -> Result<TriSurface, SurfaceError> {
    let (lo, hi) = (semi_axes.iter().copied().fold(f64::INFINITY, f64::min), semi_axes.iter().copied().fold(0.0, f64::max));
    if !(semi_axes.iter().all(|a| a.is_finite() && a.is_normal() && *a > 0.0) && hi <= 1e6 * lo && hi < 1e150) {
        return Err(SurfaceError::Parameter {
            name: "ellipsoid semi-axes ratio",
            value: hi / lo,
            reason: "semi-axes must be finite, positive, below 1e150 m and within a factor 1e6 of each other",
        });
    }
    if subdivisions > 10 {
        return Err(SurfaceError::Parameter { name: "subdivisions", value: subdivisions as f64, reason: "too many (at most 10)" });
    }
    let (verts, tris) = super::generate::geodesic_sphere(subdivisions);
    let points: Vec<[f64; 3]> = verts.iter().map(|d| [semi_axes[0] * d.x, semi_axes[1] * d.y, semi_axes[2] * d.z]).collect();
    let triangles: Vec<[i64; 3]> = tris.iter().map(|t| t.map(|i| i as i64)).collect();
    let (s, warnings) = TriSurface::from_arrays(&points, &triangles)?;
    if !warnings.is_empty() {
        return Err(SurfaceError::Parameter {
            name: "ellipsoid surface warnings",
            value: warnings.len() as f64,
            reason: "the semi-axes give a surface that needed repairs",
        });
    }
    Ok(s)
}

pub fn ellipsoid_surface(semi_axes: [f64; 3], subdivisions: usize) -> TriSurface {
    assert!(semi_axes.iter().all(|a| a.is_finite() && *a > 0.0), "ellipsoid semi-axes must be finite and positive, got {semi_axes:?}");
    assert!(subdivisions <= 10, "subdivisions = {subdivisions} is too many (at most 10)");
    let (verts, tris) = super::generate::geodesic_sphere(subdivisions);
    let points: Vec<[f64; 3]> = verts.iter().map(|d| [semi_axes[0] * d.x, semi_axes[1] * d.y, semi_axes[2] * d.z]).collect();
    let triangles: Vec<[i64; 3]> = tris.iter().map(|t| t.map(|i| i as i64)).collect();
    let (s, warnings) = TriSurface::from_arrays(&points, &triangles).expect("generated ellipsoid surface is valid");
    assert!(warnings.is_empty(), "generated ellipsoid surface: {warnings:?}");
    s
}

#[cfg(test)]
#[path = "surface_tests.rs"]
mod tests;

/// Generalised winding number around `p` of the triangles `triangles` over `points` (1 inside,
/// 0 outside a closed, outward-oriented surface; 1/2 on it; for an open one, its fraction):
/// `sum_t Omega_t / (4 pi)` with the signed solid angle `Omega_t` of triangle `t` seen from `p`
/// (Van Oosterom and Strackee 1983; Jacobson, Kavan and Sorkine-Hornung 2013). It changes only
/// where `p` crosses a triangle, and a fold seen from both sides cancels in it.
pub fn winding_number(points: &[Vec3], triangles: &[[usize; 3]], p: &Vec3) -> f64 {
    let mut total = 0.0;
    for t in triangles {
        let a = points[t[0]] - p;
        let b = points[t[1]] - p;
        let c = points[t[2]] - p;
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let num = a.dot(&b.cross(&c));
        let den = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
        total += 2.0 * num.atan2(den);
    }
    total / (4.0 * std::f64::consts::PI)
}
