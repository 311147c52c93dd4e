//! Structured tetrahedral meshes of the paper's benchmark geometries.
//!
//! Every generator builds node and tet arrays, writes every tet positively oriented (the
//! orientation follows from the construction, not from a volume test), and passes the arrays
//! through [`TetMesh::from_arrays`]. A reoriented or refused tet would be a bug here, so the
//! generators panic on one instead of handing it on.
//!
//! # Box: [`box_mesh`]
//!
//! The box `[0,sx] x [0,sy] x [0,sz]` is cut into `nx * ny * nz` cells. Node `(i, j, k)` sits at
//! `(i sx/nx, j sy/ny, k sz/nz)` and has index `i + (nx+1) (j + (ny+1) k)`. Each cell is cut
//! into 6 tets by the Kuhn (Freudenthal) split: one tet for each order in which the three axes
//! are walked from the cell's low corner to its high corner, so all 6 share that main diagonal.
//! The split cuts each cell face by its diagonal from the low corner to the high corner, which is
//! the same diagonal when seen from the neighbouring cell, so the mesh is conforming. The tet of
//! the axis order `(p, q, r)` has volume `sign(p, q, r) hx hy hz / 6`; odd orders have their last
//! two nodes swapped. `6 nx ny nz` tets, `(nx+1)(ny+1)(nz+1)` nodes.
//!
//! # Shells: prisms split into three tets
//!
//! The two ellipsoid walls below share one construction. A triangulated surface of `V` vertices
//! and `T` triangles is given twice, on the inner and on the outer ellipsoid, with the same
//! connectivity. `layers + 1` copies of it are interpolated between them (layer `l` node of
//! surface vertex `v` has index `l V + v`); each surface triangle between layers `l` and `l+1`
//! spans a prism, which is cut into 3 tets.
//!
//! Each prism is cut by the conforming rule of [`super::prism`] (the diagonal of each side through
//! its smallest-index vertex), with the tets' vertex order [`TetOrder::SmallestFirst`].
//! Triangles are kept outward-oriented (counter-clockwise seen from outside), which makes the
//! three tets positive. `3 layers T` tets, `(layers + 1) V` nodes.
//!
//! # Closed ellipsoid wall: [`ellipsoid_wall`]
//!
//! The surface is a geodesic sphere: the octahedron (6 vertices, 8 outward triangles) with each
//! triangle cut into 4 at its edge midpoints `subdivisions` times, new vertices pushed back onto
//! the unit sphere, so `T = 8 * 4^s` and `V = 4 * 4^s + 2`. A unit direction `d` is mapped onto
//! the ellipsoid of semi-axes `a` along the ray from the centre, `d / sqrt(sum (d_i / a_i)^2)`.
//! Because that map only scales each vertex, the sign of `det(p, q, r)` of a triangle (its
//! orientation seen from the centre) is the sphere's. Layers interpolate linearly along the same
//! ray. The paper's "Ellipsoids Model" (Table 1, about 188 tets) is the default: one subdivision
//! and two layers, 192 tets on 54 nodes.
//!
//! # Truncated ellipsoid wall (left-ventricle-like): [`truncated_ellipsoid_wall`]
//!
//! Both ellipsoids are parametrised by the same angles, `(a sin th cos ph, b sin th sin ph,
//! c cos th)`, so the inner and outer points of a vertex face each other across the wall. The
//! `longitudinal` rings sit at `th = th_max (1 - k / longitudinal)`, `k = 0 .. longitudinal - 1`,
//! from the base ring (`k = 0`, on the plane `z = z_cut`) towards the apex, with
//! `circumferential` points each at `ph = 2 pi j / circumferential`; the apex (`th = 0`) is one
//! vertex on the axis. `th_max = acos(z_cut / c)` is chosen per surface so that both base rings
//! lie on the cut plane, and their `z` is then set to `z_cut` exactly (for `z_cut = 0` the cosine
//! would leave `1e-18` behind), so that fixing the base by `z <= z_cut + tol` is reliable. Each
//! band between two rings is cut into `2 circumferential` triangles (always the same quad
//! diagonal), the last ring is closed by a fan of `circumferential` triangles around the apex:
//! `T = circumferential (2 longitudinal - 1)`, `V = circumferential longitudinal + 1`. The angular
//! grid crowds points near the apex, where the fan's triangles have an angle of
//! `360 / circumferential` degrees; that bounds the mesh's smallest dihedral angle.

use std::collections::HashMap;
use std::f64::consts::PI;

use super::prism::{split_prism, TetOrder};
use super::TetMesh;
use crate::error::MeshError;
use crate::limits;
use crate::math::Vec3;

/// Validate generated arrays: a generator bug (an inverted or degenerate tet, an unused node) is a
/// panic, not something to hand on with a warning.
fn finish(points: &[Vec3], tets: &[[usize; 4]]) -> TetMesh {
    let (p, t) = to_arrays(points, tets);
    let (mesh, warnings) = TetMesh::from_arrays(&p, &t).expect("mesh generator produced an invalid mesh");
    assert!(warnings.is_empty(), "mesh generator produced inverted tets: {warnings:?}");
    mesh
}

/// Validate generated arrays without panicking: for parameters at the edge of their ranges (a
/// box of cells a million times thinner than wide, a ventricle of 4096 rings) the construction is
/// right but its tets are too thin for [`TetMesh::from_arrays`]; that is the caller's input, so
/// it is an error naming the generator, not a panic.
fn try_finish(generator: &'static str, points: &[Vec3], tets: &[[usize; 4]]) -> Result<TetMesh, MeshError> {
    let (p, t) = to_arrays(points, tets);
    match TetMesh::from_arrays(&p, &t) {
        Ok((mesh, warnings)) if warnings.is_empty() => Ok(mesh),
        Ok((_, warnings)) => Err(MeshError::Generator { generator, reason: format!("the parameters give inverted tets ({} of them)", warnings.len()) }),
        Err(e) => Err(MeshError::Generator {
            generator,
            reason: format!("these parameters give a mesh that fails validation ({e}): its cells are too thin or too small; use fewer cells along the short direction or less extreme sizes"),
        }),
    }
}

/// Bytes a generated mesh of `nodes` nodes and `tets` tets takes while it is built and validated
/// (arrays built, converted and checked: ~3 copies), for the memory budget.
fn check_size(generator: &'static str, nodes: f64, tets: f64) -> Result<(), MeshError> {
    limits::check(&format!("{generator}: {nodes:.3e} nodes and {tets:.3e} tets"), 1.0, nodes * 3.0 * 24.0 + tets * 3.0 * 64.0)?;
    Ok(())
}

fn param(generator: &'static str, ok: bool, reason: impl FnOnce() -> String) -> Result<(), MeshError> {
    if ok {
        Ok(())
    } else {
        Err(MeshError::Generator { generator, reason: reason() })
    }
}

fn to_arrays(points: &[Vec3], tets: &[[usize; 4]]) -> (Vec<[f64; 3]>, Vec<[i64; 4]>) {
    let p = points.iter().map(|v| [v.x, v.y, v.z]).collect();
    let t = tets.iter().map(|t| t.map(|i| i as i64)).collect();
    (p, t)
}

fn check_axes(name: &str, axes: [f64; 3]) {
    assert!(axes.iter().all(|a| a.is_finite() && *a > 0.0), "{name} semi-axes must be finite and positive, got {axes:?}");
}

// ---------------------------------------------------------------------------------------------
// Box
// ---------------------------------------------------------------------------------------------

/// The box `[0,sx] x [0,sy] x [0,sz]` \[m\] cut into `nx * ny * nz` cells of 6 tets each (Kuhn
/// split, see the module docs): `6 nx ny nz` tets, `(nx+1)(ny+1)(nz+1)` nodes, node `(i, j, k)`
/// at index `i + (nx+1) (j + (ny+1) k)`.
///
/// # Panics
/// If a size is not finite and positive or a cell count is zero.
pub fn box_mesh(size: [f64; 3], cells: [usize; 3]) -> TetMesh {
    let (points, tets) = box_arrays(size, cells);
    finish(&points, &tets)
}

/// [`box_mesh`] for input from outside: parameters are checked before anything is built (the
/// sizes against the memory budget, the cells' shape against the validator's degeneracy bound:
/// a Kuhn tet of cell `hx, hy, hz` has volume `hx hy hz / 6` and longest edge the cell
/// diagonal), and refused with a [`MeshError::Generator`] instead of a panic.
pub fn try_box_mesh(size: [f64; 3], cells: [usize; 3]) -> Result<TetMesh, MeshError> {
    const G: &str = "box_mesh";
    param(G, size.iter().all(|s| s.is_finite() && *s > 0.0), || format!("size must be finite and positive, got {size:?}"))?;
    param(G, cells.iter().all(|&n| n > 0), || format!("cells must be at least 1 per axis, got {cells:?}"))?;
    let c = cells.map(|n| n as f64);
    check_size(G, (c[0] + 1.0) * (c[1] + 1.0) * (c[2] + 1.0), 6.0 * c[0] * c[1] * c[2])?;
    let h: [f64; 3] = std::array::from_fn(|a| size[a] / c[a]);
    let diag = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    let relative = h[0] * h[1] * h[2] / 6.0 / (diag * diag * diag);
    // A margin of 2 over the bound: the validator measures each tet's own longest edge after
    // rounding.
    param(G, relative >= 2.0 * super::tet_mesh::DEGENERATE_RELATIVE_VOLUME && h.iter().all(|x| x.is_normal()), || {
        format!(
            "cells of {:.3e} x {:.3e} x {:.3e} m are too thin (tet volume {relative:.1e} of its longest edge cubed, the validator needs {:.0e}): make size / cells closer on the three axes",
            h[0], h[1], h[2], super::tet_mesh::DEGENERATE_RELATIVE_VOLUME
        )
    })?;
    let (points, tets) = box_arrays(size, cells);
    try_finish(G, &points, &tets)
}

fn box_arrays(size: [f64; 3], cells: [usize; 3]) -> (Vec<Vec3>, Vec<[usize; 4]>) {
    assert!(size.iter().all(|s| s.is_finite() && *s > 0.0), "box size must be finite and positive, got {size:?}");
    assert!(cells.iter().all(|&n| n > 0), "box needs at least one cell per axis, got {cells:?}");
    let [nx, ny, nz] = cells;
    let node = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);

    let mut points = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                // Divide rather than accumulate a step, so the far faces land exactly on `size`.
                points.push(Vec3::new(size[0] * i as f64 / nx as f64, size[1] * j as f64 / ny as f64, size[2] * k as f64 / nz as f64));
            }
        }
    }

    // The 6 orders of walking the axes from the low corner to the high one, with their parity:
    // the tet of an order has the sign of the permutation's determinant.
    const ORDERS: [([usize; 3], bool); 6] =
        [([0, 1, 2], true), ([1, 2, 0], true), ([2, 0, 1], true), ([0, 2, 1], false), ([2, 1, 0], false), ([1, 0, 2], false)];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for (order, even) in ORDERS {
                    let mut corner = [i, j, k];
                    let mut tet = [node(i, j, k); 4];
                    for (step, &axis) in order.iter().enumerate() {
                        corner[axis] += 1;
                        tet[step + 1] = node(corner[0], corner[1], corner[2]);
                    }
                    if !even {
                        tet.swap(2, 3);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    (points, tets)
}

// ---------------------------------------------------------------------------------------------
// Shells (shared by both ellipsoid walls)
// ---------------------------------------------------------------------------------------------

/// Stack `layers` layers of prisms between two copies of one outward-oriented triangulation,
/// `inner[v]` and `outer[v]`, each prism cut into 3 tets by the conforming rule of the module
/// docs. Layer `l` node of vertex `v` is `l V + v`.
fn extrude_shell(inner: &[Vec3], outer: &[Vec3], triangles: &[[usize; 3]], layers: usize) -> (Vec<Vec3>, Vec<[usize; 4]>) {
    assert!(layers > 0, "a wall needs at least one layer");
    let nv = inner.len();
    debug_assert_eq!(nv, outer.len());

    let mut points = Vec::with_capacity(nv * (layers + 1));
    for l in 0..=layers {
        points.extend(inner.iter().zip(outer).map(|(p, q)| layer_point(p, q, l, layers)));
    }

    let mut tets = Vec::with_capacity(3 * layers * triangles.len());
    for l in 0..layers {
        let (lo, hi) = (l * nv, (l + 1) * nv);
        for tri in triangles {
            tets.extend(split_prism(tri.map(|i| lo + i), hi - lo, TetOrder::SmallestFirst));
        }
    }
    (points, tets)
}

/// Layer `l` of `layers` between the inner point `p` and the outer point `q`: `p + t (q - p)`,
/// not `(1-t) p + t q`, so that where `p == q` in a component (the base ring's z) it stays
/// exactly `p`. One function for [`extrude_shell`] and [`check_shell`], so that the check sees
/// the very points the mesh will have.
fn layer_point(p: &Vec3, q: &Vec3, l: usize, layers: usize) -> Vec3 {
    p + (q - p) * (l as f64 / layers as f64)
}

/// Refuse, before the shell is built, parameters whose mesh would fail validation: every tet that
/// [`extrude_shell`] would make, in its order, is measured as [`TetMesh::from_arrays`] measures it
/// (same points, same arithmetic) and the first one that is inverted or thinner than the
/// validator's bound is an error naming it. It streams over the prisms without allocating: a
/// small fraction of the build's time (no arrays, no duplicate-tet map), and it stops at the
/// first bad tet. (An over-fine ventricle, e.g. 96 x 600 points, has its thin tets at the apex,
/// where the rings crowd together; they cannot be found from the parameters in closed form.)
fn check_shell(generator: &'static str, inner: &[Vec3], outer: &[Vec3], triangles: &[[usize; 3]], layers: usize) -> Result<(), MeshError> {
    let nv = inner.len();
    let point = |g: usize| layer_point(&inner[g % nv], &outer[g % nv], g / nv, layers);
    let mut t = 0usize;
    for l in 0..layers {
        for tri in triangles {
            for tet in split_prism(tri.map(|i| l * nv + i), nv, TetOrder::SmallestFirst) {
                let [a, b, c, d] = tet.map(point);
                let (volume, relative) = super::tet_mesh::volume_and_relative(&a, &b, &c, &d);
                if !(volume > 0.0 && relative >= super::tet_mesh::DEGENERATE_RELATIVE_VOLUME) {
                    return Err(MeshError::Generator {
                        generator,
                        reason: format!(
                            "refused before building: these parameters give tet {t} (layer {l}) {} (volume {volume:.3e} m^3, {relative:.1e} of its longest edge cubed; the validator needs {:.0e}): its cells are too thin or too small; use fewer points along the crowded direction, fewer layers or a thicker wall",
                            if volume > 0.0 { "too thin" } else { "inverted or flat" },
                            super::tet_mesh::DEGENERATE_RELATIVE_VOLUME
                        ),
                    });
                }
                t += 1;
            }
        }
    }
    Ok(())
}

/// The point where the ray from the centre along `d` meets the ellipsoid of semi-axes `axes`.
fn onto_ellipsoid(d: &Vec3, axes: [f64; 3]) -> Vec3 {
    let s = ((d.x / axes[0]).powi(2) + (d.y / axes[1]).powi(2) + (d.z / axes[2]).powi(2)).sqrt();
    d / s
}

// ---------------------------------------------------------------------------------------------
// Closed ellipsoid wall
// ---------------------------------------------------------------------------------------------

/// The region between two concentric, axis-aligned ellipsoids, meshed as a geodesic sphere
/// extruded in layers (see the module docs).
///
/// With `s = subdivisions`: `8 * 4^s` triangles per surface, `3 * layers * 8 * 4^s` tets and
/// `(layers + 1) (4 * 4^s + 2)` nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct EllipsoidWall {
    /// Semi-axes of the inner ellipsoid along x, y, z \[m\].
    pub inner: [f64; 3],
    /// Semi-axes of the outer ellipsoid along x, y, z \[m\]; each larger than the inner one.
    pub outer: [f64; 3],
    /// Times the octahedron's triangles are cut into 4.
    pub subdivisions: usize,
    /// Tet layers across the wall.
    pub layers: usize,
}

impl Default for EllipsoidWall {
    /// The paper's "Ellipsoids Model" (Mero & Susin, Table 1: about 188 tets): 192 tets, 54 nodes,
    /// with a left-ventricle-sized wall of inner semi-axes (20, 20, 35) mm and outer (26, 26, 42) mm.
    fn default() -> Self {
        Self { inner: [0.020, 0.020, 0.035], outer: [0.026, 0.026, 0.042], subdivisions: 1, layers: 2 }
    }
}

impl EllipsoidWall {
    /// Triangles on each of the two surfaces, `8 * 4^subdivisions`.
    pub fn n_surface_triangles(&self) -> usize {
        8 * 4usize.pow(self.subdivisions as u32)
    }
    /// Tets of the generated mesh, `3 * layers * 8 * 4^subdivisions`.
    pub fn n_tets(&self) -> usize {
        3 * self.layers * self.n_surface_triangles()
    }
    /// Nodes of the generated mesh, `(layers + 1) (4 * 4^subdivisions + 2)`.
    pub fn n_nodes(&self) -> usize {
        (self.layers + 1) * (4 * 4usize.pow(self.subdivisions as u32) + 2)
    }
}

/// Mesh the wall between two concentric ellipsoids (a closed shell) as described in the module docs.
///
/// # Panics
/// If a semi-axis is not finite and positive, an outer semi-axis is not larger than the inner
/// one, or `layers` is zero.
pub fn ellipsoid_wall(p: &EllipsoidWall) -> TetMesh {
    let (points, tets) = ellipsoid_wall_arrays(p);
    finish(&points, &tets)
}

fn axes_ok(g: &'static str, name: &str, axes: [f64; 3]) -> Result<(), MeshError> {
    param(g, axes.iter().all(|a| a.is_finite() && *a > 0.0), || format!("{name} semi-axes must be finite and positive, got {axes:?}"))
}

/// [`ellipsoid_wall`] for input from outside: parameters and size checked first, a mesh that
/// fails validation an error (not a panic).
pub fn try_ellipsoid_wall(p: &EllipsoidWall) -> Result<TetMesh, MeshError> {
    const G: &str = "ellipsoid_wall";
    axes_ok(G, "inner", p.inner)?;
    axes_ok(G, "outer", p.outer)?;
    param(G, (0..3).all(|i| p.outer[i] > p.inner[i]), || format!("outer semi-axes {:?} must exceed inner {:?}", p.outer, p.inner))?;
    param(G, p.layers > 0 && p.subdivisions <= 12, || {
        format!("layers must be at least 1 and subdivisions at most 12, got {} and {}", p.layers, p.subdivisions)
    })?;
    let t = 8.0 * 4f64.powi(p.subdivisions as i32);
    check_size(G, (p.layers as f64 + 1.0) * (t / 2.0 + 2.0), 3.0 * p.layers as f64 * t)?;
    let (inner, outer, triangles) = ellipsoid_wall_surfaces(p);
    check_shell(G, &inner, &outer, &triangles, p.layers)?;
    let (points, tets) = extrude_shell(&inner, &outer, &triangles, p.layers);
    try_finish(G, &points, &tets)
}

fn ellipsoid_wall_arrays(p: &EllipsoidWall) -> (Vec<Vec3>, Vec<[usize; 4]>) {
    let (inner, outer, triangles) = ellipsoid_wall_surfaces(p);
    extrude_shell(&inner, &outer, &triangles, p.layers)
}

/// The inner and outer surfaces of an [`EllipsoidWall`] (one geodesic sphere, mapped onto each
/// ellipsoid) and their shared triangles.
fn ellipsoid_wall_surfaces(p: &EllipsoidWall) -> (Vec<Vec3>, Vec<Vec3>, Vec<[usize; 3]>) {
    check_axes("inner", p.inner);
    check_axes("outer", p.outer);
    // Larger on every axis means the outer ellipsoid is further out along every ray.
    assert!((0..3).all(|i| p.outer[i] > p.inner[i]), "outer semi-axes {:?} must exceed inner {:?}", p.outer, p.inner);
    let (dirs, triangles) = geodesic_sphere(p.subdivisions);
    let inner: Vec<Vec3> = dirs.iter().map(|d| onto_ellipsoid(d, p.inner)).collect();
    let outer: Vec<Vec3> = dirs.iter().map(|d| onto_ellipsoid(d, p.outer)).collect();
    (inner, outer, triangles)
}

/// Unit sphere triangulated from the octahedron by `subdivisions` 1-to-4 splits: unit vertices and
/// outward-oriented triangles.
pub(crate) fn geodesic_sphere(subdivisions: usize) -> (Vec<Vec3>, Vec<[usize; 3]>) {
    let mut verts = vec![Vec3::x(), -Vec3::x(), Vec3::y(), -Vec3::y(), Vec3::z(), -Vec3::z()];
    // Face (±x, ±y, ±z) is outward when det of its vertices is positive, i.e. an even number of
    // minus signs; otherwise swap two vertices.
    let mut tris = Vec::with_capacity(8);
    for (sx, sy, sz) in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 1, 1)] {
        let (x, y, z) = (sx, 2 + sy, 4 + sz);
        tris.push(if (sx + sy + sz) % 2 == 0 { [x, y, z] } else { [y, x, z] });
    }
    for _ in 0..subdivisions {
        // One vertex per edge, shared by the two triangles on it.
        let mut midpoint: HashMap<(usize, usize), usize> = HashMap::new();
        let mut mid = |a: usize, b: usize, verts: &mut Vec<Vec3>| {
            *midpoint.entry((a.min(b), a.max(b))).or_insert_with(|| {
                verts.push((verts[a] + verts[b]).normalize());
                verts.len() - 1
            })
        };
        let mut next = Vec::with_capacity(4 * tris.len());
        for [a, b, c] in tris {
            let (ab, bc, ca) = (mid(a, b, &mut verts), mid(b, c, &mut verts), mid(c, a, &mut verts));
            // The corner triangles and the middle one all keep the orientation of (a, b, c).
            next.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        tris = next;
    }
    (verts, tris)
}

// ---------------------------------------------------------------------------------------------
// Truncated ellipsoid wall
// ---------------------------------------------------------------------------------------------

/// The left-ventricle-like wall: the region between two concentric ellipsoids above the plane
/// `z = z_cut` (see the module docs).
///
/// With `C = circumferential`, `L = longitudinal`: `C (2L - 1)` triangles per surface,
/// `3 * layers * C (2L - 1)` tets, `(layers + 1)(C L + 1)` nodes, of which `C (layers + 1)` lie
/// on the base plane.
#[derive(Debug, Clone, PartialEq)]
pub struct TruncatedEllipsoidWall {
    /// Semi-axes of the inner ellipsoid along x, y, z \[m\].
    pub inner: [f64; 3],
    /// Semi-axes of the outer ellipsoid along x, y, z \[m\]; each larger than the inner one.
    pub outer: [f64; 3],
    /// Height of the base plane \[m\]; only `z >= z_cut` is kept. Must lie strictly between
    /// `-inner[2]` and `inner[2]`.
    pub z_cut: f64,
    /// Points per ring (at least 3).
    pub circumferential: usize,
    /// Rings from the base to the apex, base included, apex excluded (at least 1).
    pub longitudinal: usize,
    /// Tet layers across the wall.
    pub layers: usize,
}

impl Default for TruncatedEllipsoidWall {
    /// The benchmark-sized ventricle, cut at the equator: 20 x 6 points per surface plus the apex,
    /// 2 layers: 1320 tets, 363 nodes.
    fn default() -> Self {
        Self { inner: [0.020, 0.020, 0.035], outer: [0.026, 0.026, 0.042], z_cut: 0.0, circumferential: 20, longitudinal: 6, layers: 2 }
    }
}

impl TruncatedEllipsoidWall {
    /// The default wall at resolution `n` (at least 1): `circumferential = 4n`, `longitudinal = n`,
    /// `layers = max(1, n / 4)`, so `3 max(1, n/4) 4n (2n - 1)` tets: 180 for `n = 3`, 2880 for
    /// `n = 8`, 9936 for `n = 12`.
    pub fn with_resolution(n: usize) -> Self {
        assert!(n > 0, "resolution must be at least 1");
        Self { circumferential: 4 * n, longitudinal: n, layers: (n / 4).max(1), ..Self::default() }
    }
    /// Triangles on each of the inner and outer surfaces, `C (2L - 1)`.
    pub fn n_surface_triangles(&self) -> usize {
        self.circumferential * (2 * self.longitudinal - 1)
    }
    /// Tets of the generated mesh, `3 * layers * C (2L - 1)`.
    pub fn n_tets(&self) -> usize {
        3 * self.layers * self.n_surface_triangles()
    }
    /// Nodes of the generated mesh, `(layers + 1)(C L + 1)`.
    pub fn n_nodes(&self) -> usize {
        (self.layers + 1) * (self.circumferential * self.longitudinal + 1)
    }
}

/// Mesh the wall between two concentric ellipsoids above `z = z_cut`, as described in the module
/// docs. The base nodes lie exactly on `z = z_cut`; [`base_nodes`] finds them.
///
/// # Panics
/// If a semi-axis is not finite and positive, an outer semi-axis is not larger than the inner
/// one, `z_cut` is not strictly inside `(-inner[2], inner[2])`, `circumferential < 3`, or
/// `longitudinal` or `layers` is zero.
pub fn truncated_ellipsoid_wall(p: &TruncatedEllipsoidWall) -> TetMesh {
    let (points, tets) = truncated_ellipsoid_wall_arrays(p);
    finish(&points, &tets)
}

/// [`truncated_ellipsoid_wall`] for input from outside: parameters and size checked first, then
/// every tet measured before the mesh is built (`check_shell`: the validation cannot be
/// predicted in closed form here, since the apex fan and the crowded rings near it set the
/// thinnest tet), so a fine resolution inside the documented ranges is refused up front with the
/// reason; a mesh that still failed validation would be an error too (not a panic).
pub fn try_truncated_ellipsoid_wall(p: &TruncatedEllipsoidWall) -> Result<TetMesh, MeshError> {
    const G: &str = "truncated_ellipsoid_wall";
    axes_ok(G, "inner", p.inner)?;
    axes_ok(G, "outer", p.outer)?;
    param(G, (0..3).all(|i| p.outer[i] > p.inner[i]), || format!("outer semi-axes {:?} must exceed inner {:?}", p.outer, p.inner))?;
    param(G, p.z_cut.is_finite() && p.z_cut.abs() < p.inner[2], || {
        format!("z_cut = {} must lie strictly inside the inner ellipsoid's z range", p.z_cut)
    })?;
    param(G, p.circumferential >= 3 && p.longitudinal >= 1 && p.layers >= 1, || {
        format!("need circumferential >= 3, longitudinal >= 1 and layers >= 1, got {}, {}, {}", p.circumferential, p.longitudinal, p.layers)
    })?;
    let (c, l, n) = (p.circumferential as f64, p.longitudinal as f64, p.layers as f64);
    check_size(G, (n + 1.0) * (c * l + 1.0), 3.0 * n * c * (2.0 * l - 1.0))?;
    let (inner, outer, triangles) = truncated_ellipsoid_wall_surfaces(p);
    check_shell(G, &inner, &outer, &triangles, p.layers)?;
    let (points, tets) = extrude_shell(&inner, &outer, &triangles, p.layers);
    try_finish(G, &points, &tets)
}

fn truncated_ellipsoid_wall_arrays(p: &TruncatedEllipsoidWall) -> (Vec<Vec3>, Vec<[usize; 4]>) {
    let (inner, outer, triangles) = truncated_ellipsoid_wall_surfaces(p);
    extrude_shell(&inner, &outer, &triangles, p.layers)
}

/// The inner and outer surfaces of a [`TruncatedEllipsoidWall`] (the same angular grid on each
/// ellipsoid) and their shared triangles.
fn truncated_ellipsoid_wall_surfaces(p: &TruncatedEllipsoidWall) -> (Vec<Vec3>, Vec<Vec3>, Vec<[usize; 3]>) {
    check_axes("inner", p.inner);
    check_axes("outer", p.outer);
    assert!((0..3).all(|i| p.outer[i] > p.inner[i]), "outer semi-axes {:?} must exceed inner {:?}", p.outer, p.inner);
    assert!(p.z_cut.is_finite() && p.z_cut.abs() < p.inner[2], "z_cut = {} must lie strictly inside the inner ellipsoid's z range", p.z_cut);
    assert!(p.circumferential >= 3, "need at least 3 points per ring, got {}", p.circumferential);
    assert!(p.longitudinal >= 1, "need at least the base ring");
    let (nc, nl) = (p.circumferential, p.longitudinal);

    // Vertex (k, j) of ring k, angle j, is `k C + j`; the apex comes last.
    let surface = |axes: [f64; 3]| -> Vec<Vec3> {
        let th_max = (p.z_cut / axes[2]).acos();
        let mut pts = Vec::with_capacity(nc * nl + 1);
        for k in 0..nl {
            let th = th_max * (1.0 - k as f64 / nl as f64);
            for j in 0..nc {
                let ph = 2.0 * PI * j as f64 / nc as f64;
                // The base ring is put on the cut plane exactly, not at `c cos(th_max)`.
                let z = if k == 0 { p.z_cut } else { axes[2] * th.cos() };
                pts.push(Vec3::new(axes[0] * th.sin() * ph.cos(), axes[1] * th.sin() * ph.sin(), z));
            }
        }
        pts.push(Vec3::new(0.0, 0.0, axes[2]));
        pts
    };
    let inner = surface(p.inner);
    let outer = surface(p.outer);

    // Outward orientation: with ph increasing counter-clockwise about +z and rings climbing to the
    // apex, (along ph) x (towards the apex) points out of the wall, so (A, B, C) with A = (k, j),
    // B = (k, j+1), C = (k+1, j+1) is outward, and so is (A, C, D) with D = (k+1, j).
    let id = |k: usize, j: usize| k * nc + j % nc;
    let apex = nc * nl;
    let mut triangles = Vec::with_capacity(nc * (2 * nl - 1));
    for k in 0..nl - 1 {
        for j in 0..nc {
            let (a, b, c, d) = (id(k, j), id(k, j + 1), id(k + 1, j + 1), id(k + 1, j));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    for j in 0..nc {
        triangles.push([id(nl - 1, j), id(nl - 1, j + 1), apex]);
    }
    (inner, outer, triangles)
}

/// Nodes with `z <= z_cut + tol`, ascending: the base of a [`truncated_ellipsoid_wall`], to be
/// fixed. Its base nodes lie exactly on the plane, so any small `tol` (e.g. `1e-9` m) works.
pub fn base_nodes(mesh: &TetMesh, z_cut: f64, tol: f64) -> Vec<usize> {
    mesh.points().iter().enumerate().filter(|(_, p)| p.z <= z_cut + tol).map(|(i, _)| i).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::tet_mesh::signed_volume;

    /// The raw arrays must pass validation untouched: no reorientation, every tet positive.
    fn assert_positive_no_warnings(points: &[Vec3], tets: &[[usize; 4]]) {
        for (t, tet) in tets.iter().enumerate() {
            let [a, b, c, d] = tet.map(|i| points[i]);
            assert!(signed_volume(&a, &b, &c, &d) > 0.0, "tet {t} {tet:?} is not positive");
        }
        let (p, t) = to_arrays(points, tets);
        let (_, warnings) = TetMesh::from_arrays(&p, &t).expect("generated mesh refused");
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    /// Every face is shared by one tet (boundary) or two (interior), never more.
    fn assert_faces_manifold(mesh: &TetMesh) {
        let mut count: HashMap<[usize; 3], usize> = HashMap::new();
        for t in mesh.tets() {
            for skip in 0..4 {
                let mut f = [0; 3];
                let mut n = 0;
                for (m, &i) in t.iter().enumerate() {
                    if m != skip {
                        f[n] = i;
                        n += 1;
                    }
                }
                f.sort_unstable();
                *count.entry(f).or_default() += 1;
            }
        }
        assert!(count.values().all(|&c| c == 1 || c == 2), "a face is shared by more than two tets");
    }

    fn shell_volume(inner: [f64; 3], outer: [f64; 3]) -> f64 {
        4.0 / 3.0 * PI * (outer.iter().product::<f64>() - inner.iter().product::<f64>())
    }

    /// Volume of the ellipsoid of semi-axes `a` above `z = h`: `pi a b (c - h - (c^3 - h^3) / (3 c^2))`.
    fn cap_volume(a: [f64; 3], h: f64) -> f64 {
        let c = a[2];
        PI * a[0] * a[1] * (c - h - (c.powi(3) - h.powi(3)) / (3.0 * c * c))
    }

    #[test]
    fn generate_box_volume_counts_and_indexing() {
        let (size, cells) = ([0.3, 0.2, 0.1], [3, 4, 5]);
        let (points, tets) = box_arrays(size, cells);
        assert_positive_no_warnings(&points, &tets);
        let m = box_mesh(size, cells);
        assert_eq!(m.n_tets(), 6 * 3 * 4 * 5);
        assert_eq!(m.n_nodes(), 4 * 5 * 6);
        assert!((m.volume() - 0.3 * 0.2 * 0.1).abs() < 1e-15);
        // Node (i, j, k) = i + (nx+1) (j + (ny+1) k).
        let p = m.points()[2 + 4 * (3 + 5 * 4)];
        assert!((p - Vec3::new(0.2, 0.15, 0.08)).norm() < 1e-15, "{p:?}");
        assert_eq!(m.points().last().unwrap(), &Vec3::new(0.3, 0.2, 0.1));
        // Kuhn tets of a cube have dihedral angles 45, 60 and 90 degrees.
        let cube = box_mesh([1.0; 3], [2, 2, 2]);
        assert!((cube.min_dihedral_deg() - 45.0).abs() < 1e-9);
    }

    #[test]
    fn generate_box_kuhn_split_is_conforming() {
        for [nx, ny, nz] in [[1, 1, 1], [3, 4, 5], [2, 1, 7]] {
            let m = box_mesh([1.0, 2.0, 3.0], [nx, ny, nz]);
            assert_faces_manifold(&m);
            // Each boundary cell face is cut into 2 triangles; a mismatched diagonal inside would
            // leave 4 extra boundary triangles per interior face.
            assert_eq!(m.boundary_faces().len(), 2 * 2 * (nx * ny + ny * nz + nx * nz));
        }
    }

    #[test]
    fn generate_ellipsoid_wall_default_matches_paper_size() {
        let p = EllipsoidWall::default();
        let (points, tets) = ellipsoid_wall_arrays(&p);
        assert_positive_no_warnings(&points, &tets);
        let m = ellipsoid_wall(&p);
        assert!((180..=200).contains(&m.n_tets()), "{} tets", m.n_tets());
        assert_eq!((m.n_tets(), m.n_nodes()), (p.n_tets(), p.n_nodes()));
        assert_eq!((m.n_tets(), m.n_nodes()), (192, 54));
        let q = m.min_dihedral_deg();
        assert!(q > 5.0, "min dihedral {q} deg");
    }

    #[test]
    fn generate_ellipsoid_wall_is_a_closed_conforming_shell() {
        for (subdivisions, layers) in [(0, 1), (1, 2), (2, 3)] {
            let p = EllipsoidWall { subdivisions, layers, ..Default::default() };
            let (points, tets) = ellipsoid_wall_arrays(&p);
            assert_positive_no_warnings(&points, &tets);
            let m = ellipsoid_wall(&p);
            assert_faces_manifold(&m);
            assert_eq!(m.boundary_faces().len(), 2 * p.n_surface_triangles());
            assert_eq!((m.n_tets(), m.n_nodes()), (p.n_tets(), p.n_nodes()));
            // Surface nodes lie on their ellipsoids.
            let nv = m.n_nodes() / (layers + 1);
            for (range, axes) in [(0..nv, p.inner), (layers * nv..(layers + 1) * nv, p.outer)] {
                for x in &m.points()[range] {
                    let r: f64 = (0..3).map(|i| (x[i] / axes[i]).powi(2)).sum();
                    assert!((r - 1.0).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn generate_ellipsoid_wall_volume_converges() {
        let exact = shell_volume(EllipsoidWall::default().inner, EllipsoidWall::default().outer);
        let errors: Vec<f64> = (1..=4)
            .map(|subdivisions| {
                let m = ellipsoid_wall(&EllipsoidWall { subdivisions, ..Default::default() });
                (m.volume() - exact).abs() / exact
            })
            .collect();
        assert!(errors.windows(2).all(|w| w[1] < w[0]), "errors not decreasing: {errors:?}");
        assert!(errors[3] < 0.02, "errors {errors:?}");
    }

    #[test]
    fn generate_truncated_wall_counts_base_and_boundary() {
        for p in [
            TruncatedEllipsoidWall::default(),
            TruncatedEllipsoidWall::with_resolution(1),
            TruncatedEllipsoidWall::with_resolution(3),
            TruncatedEllipsoidWall { z_cut: 0.012, layers: 3, ..Default::default() },
            TruncatedEllipsoidWall { z_cut: -0.02, circumferential: 7, longitudinal: 4, ..Default::default() },
        ] {
            let (points, tets) = truncated_ellipsoid_wall_arrays(&p);
            assert_positive_no_warnings(&points, &tets);
            let m = truncated_ellipsoid_wall(&p);
            assert_eq!((m.n_tets(), m.n_nodes()), (p.n_tets(), p.n_nodes()));
            assert_faces_manifold(&m);
            // Inner and outer surfaces plus the base annulus: `layers` quads per base ring segment.
            assert_eq!(m.boundary_faces().len(), 2 * p.n_surface_triangles() + 2 * p.circumferential * p.layers);
            let base = base_nodes(&m, p.z_cut, 1e-9);
            assert_eq!(base.len(), p.circumferential * (p.layers + 1));
            assert!(base.iter().all(|&i| m.points()[i].z == p.z_cut));
            assert!(m.points().iter().all(|x| x.z >= p.z_cut));
        }
    }

    #[test]
    fn generate_truncated_wall_resolution_sizes() {
        let n3 = TruncatedEllipsoidWall::with_resolution(3).n_tets();
        let n12 = TruncatedEllipsoidWall::with_resolution(12).n_tets();
        assert!((150..=250).contains(&n3), "{n3}");
        assert!((8_000..=12_000).contains(&n12), "{n12}");
        let m = truncated_ellipsoid_wall(&TruncatedEllipsoidWall::default());
        assert_eq!((m.n_tets(), m.n_nodes()), (1320, 363));
        let q = m.min_dihedral_deg();
        assert!(q > 5.0, "min dihedral {q} deg");
    }

    #[test]
    fn generate_truncated_wall_volume_converges() {
        let d = TruncatedEllipsoidWall::default();
        for z_cut in [0.0, 0.012] {
            let exact = cap_volume(d.outer, z_cut) - cap_volume(d.inner, z_cut);
            if z_cut == 0.0 {
                assert!((exact - 0.5 * shell_volume(d.inner, d.outer)).abs() < 1e-15);
            }
            let errors: Vec<f64> = [2, 4, 8, 16]
                .map(|n| {
                    let m = truncated_ellipsoid_wall(&TruncatedEllipsoidWall { z_cut, ..TruncatedEllipsoidWall::with_resolution(n) });
                    (m.volume() - exact).abs() / exact
                })
                .to_vec();
            assert!(errors.windows(2).all(|w| w[1] < w[0]), "z_cut {z_cut}: errors not decreasing: {errors:?}");
            assert!(errors[3] < 0.02, "z_cut {z_cut}: errors {errors:?}");
        }
    }

    /// The check before building agrees with the validator: where it passes, the built mesh
    /// validates without a warning; where it refuses, the arrays built anyway are refused too.
    /// The refusals are the corpus's ventricles inside the documented ranges (issue 15: a
    /// `PanicException`, then a `MeshError` after seconds of building) and a wall 0.1 um thick.
    #[test]
    fn generate_shell_check_before_building_agrees_with_validation() {
        let d = TruncatedEllipsoidWall::default();
        for (c, l, layers, ok) in [(20, 6, 2, true), (96, 24, 1, true), (96, 600, 1, false), (3, 4096, 1, false), (3, 50, 2, true), (400, 3, 1, true)] {
            let p = TruncatedEllipsoidWall { circumferential: c, longitudinal: l, layers, ..d.clone() };
            let (inner, outer, triangles) = truncated_ellipsoid_wall_surfaces(&p);
            let checked = check_shell("t", &inner, &outer, &triangles, layers);
            let (pts, tets) = truncated_ellipsoid_wall_arrays(&p);
            let (a, t) = to_arrays(&pts, &tets);
            let validated = matches!(TetMesh::from_arrays(&a, &t), Ok((_, w)) if w.is_empty());
            assert_eq!((checked.is_ok(), validated), (ok, ok), "({c}, {l}, {layers}): {checked:?}");
            if !ok {
                let e = try_truncated_ellipsoid_wall(&p).unwrap_err().to_string();
                assert!(e.contains("refused before building"), "({c}, {l}): {e}");
            }
        }
        let thin = EllipsoidWall { inner: [0.02, 0.02, 0.035], outer: [0.0200000001, 0.0200000001, 0.0350000001], ..EllipsoidWall::default() };
        let e = try_ellipsoid_wall(&thin).unwrap_err().to_string();
        assert!(e.contains("refused before building"), "{e}");
        assert!(try_ellipsoid_wall(&EllipsoidWall { subdivisions: 3, layers: 3, ..EllipsoidWall::default() }).is_ok());
    }
}
