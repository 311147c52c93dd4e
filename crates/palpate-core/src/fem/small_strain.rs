//! Small-strain linear elastostatics on linear (P1, 4-node) or quadratic (P2, 10-node)
//! tetrahedra: `K u = f` at rest, factorised once and solved for many loads.
//!
//! Not a simulation body: the build's yardstick. The hybrid's coarse core is made of P1 tets one
//! or two layers across a wall, which lock in bending (VALIDATION.md, "Why a coarse core cannot
//! carry the wall": a 900-tet P1 wall is about twice too stiff) while P2 elements on the same
//! kind of mesh are within a few percent of a converged solution. `hybrid/homogenise.rs` compares
//! the two to give the core the stiffness of the wall it stands for.
//!
//! P2 nodes: the tet's vertices, then its edge midpoints (straight-sided elements). Shape functions
//! in barycentric coordinates `L`: a vertex `L_i (2 L_i - 1)`, an edge `4 L_i L_j`. The stiffness
//! integrand of P2 is quadratic in `L`: the 4-point rule of degree 2 integrates it exactly.
//! The element block of nodes `a`, `b` is `lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I`
//! with `g` the shape-function gradients (linear isotropic elasticity, `sigma = lambda tr(e) I +
//! 2 mu e`).

use crate::error::SolveError;
use crate::linalg::{ordering, BlockPattern, Ldl};
use crate::math::{Mat3, Vec3};
use std::collections::HashMap;

/// The element order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// Linear tets (constant strain): the nodes are the mesh's vertices.
    Linear,
    /// Quadratic tets: the vertices, then one node per edge at its midpoint.
    Quadratic,
}

pub use super::tet10::TET10_EDGES;

/// A factorised small-strain stiffness over the free nodes of a tet mesh.
#[derive(Debug, Clone)]
pub struct SmallStrain {
    order: Order,
    /// Every node \[m\] `(n_nodes)`: the vertices, then (P2) the edge midpoints.
    nodes: Vec<Vec3>,
    /// P2: the vertices of each edge node `(n_nodes - n_vertices)`.
    edges: Vec<[usize; 2]>,
    /// P2: the node of each edge (its vertices in increasing order).
    edge_map: HashMap<(usize, usize), usize>,
    /// Per tet its nodes (4 or 10).
    elements: Vec<Vec<usize>>,
    /// Free node -> position in the permuted system, or `usize::MAX` when held.
    slot: Vec<usize>,
    ldl: Ldl,
}

const NONE: usize = usize::MAX;

/// Barycentric gradients of a tet and its volume (`None` if degenerate or inverted).
fn barycentric_gradients(x: [Vec3; 4]) -> Option<([Vec3; 4], f64)> {
    let d = Mat3::from_columns(&[x[1] - x[0], x[2] - x[0], x[3] - x[0]]);
    let det = d.determinant();
    if !(det > 0.0) {
        return None;
    }
    let inv = d.try_inverse()?;
    // L_1..L_3 = rows of inv applied to (x - x0); L_0 = 1 - the rest.
    let g1 = inv.row(0).transpose();
    let g2 = inv.row(1).transpose();
    let g3 = inv.row(2).transpose();
    Some(([-(g1 + g2 + g3), g1, g2, g3], det / 6.0))
}

/// Shape-function gradients of the element's nodes at barycentric point `l`.
fn gradients(order: Order, g: &[Vec3; 4], l: [f64; 4], out: &mut [Vec3]) {
    match order {
        Order::Linear => out[..4].copy_from_slice(g),
        Order::Quadratic => {
            for i in 0..4 {
                out[i] = g[i] * (4.0 * l[i] - 1.0);
            }
            for (e, [i, j]) in TET10_EDGES.iter().enumerate() {
                out[4 + e] = (g[*i] * l[*j] + g[*j] * l[*i]) * 4.0;
            }
        }
    }
}

impl SmallStrain {
    /// Assemble and factorise the stiffness of `tets` over `points` \[m\] with Lame constants
    /// `lambda`, `mu` \[Pa\], the vertices with `held[v]` fixed (a P2 edge node is held when both
    /// its vertices are). Errors: an element with non-positive volume (named), a stiffness that is
    /// not positive definite (too few held nodes: a rigid motion left free).
    pub fn new(points: &[Vec3], tets: &[[usize; 4]], order: Order, lambda: f64, mu: f64, held: &[bool]) -> Result<SmallStrain, SolveError> {
        let nv = points.len();
        let mut nodes: Vec<Vec3> = points.to_vec();
        let mut edges: Vec<[usize; 2]> = Vec::new();
        let mut edge_node: HashMap<(usize, usize), usize> = HashMap::new();
        let mut elements = Vec::with_capacity(tets.len());
        for t in tets {
            let mut e: Vec<usize> = t.to_vec();
            if order == Order::Quadratic {
                for [i, j] in TET10_EDGES {
                    let (a, b) = (t[i].min(t[j]), t[i].max(t[j]));
                    let k = *edge_node.entry((a, b)).or_insert_with(|| {
                        nodes.push((points[a] + points[b]) * 0.5);
                        edges.push([a, b]);
                        nodes.len() - 1
                    });
                    e.push(k);
                }
            }
            elements.push(e);
        }
        let n = nodes.len();
        let is_held = |k: usize| if k < nv { held[k] } else { held[edges[k - nv][0]] && held[edges[k - nv][1]] };
        let free: Vec<usize> = (0..n).filter(|&k| !is_held(k)).collect();
        let mut free_index = vec![NONE; n];
        for (f, &k) in free.iter().enumerate() {
            free_index[k] = f;
        }
        let nf = free.len();
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); nf];
        for e in &elements {
            for &a in e {
                if free_index[a] == NONE {
                    continue;
                }
                for &b in e {
                    if free_index[b] != NONE {
                        adj[free_index[a]].push(free_index[b]);
                    }
                }
            }
        }
        for a in adj.iter_mut() {
            a.sort_unstable();
            a.dedup();
        }
        let pattern = BlockPattern::from_adjacency(&adj);
        let mut k = vec![Mat3::zeros(); pattern.nnz()];
        // Degree-2 rule on the tet: the permutations of (a, b, b, b), each a quarter of the volume.
        let (qa, qb) = (0.585_410_196_624_968_5, 0.138_196_601_125_010_5);
        let points_q: Vec<[f64; 4]> = (0..4)
            .map(|i| {
                let mut l = [qb; 4];
                l[i] = qa;
                l
            })
            .collect();
        let mut g = [Vec3::zeros(); 10];
        for (ti, (t, e)) in tets.iter().zip(&elements).enumerate() {
            let Some((gl, vol)) = barycentric_gradients(t.map(|i| points[i])) else {
                return Err(SolveError::Invalid(format!("tet {ti} has non-positive volume")));
            };
            let rule: &[[f64; 4]] = if order == Order::Linear { &points_q[..1] } else { &points_q };
            let w = vol / rule.len() as f64;
            for l in rule {
                gradients(order, &gl, *l, &mut g);
                for (a, &na) in e.iter().enumerate() {
                    let fa = free_index[na];
                    if fa == NONE {
                        continue;
                    }
                    for (b, &nb) in e.iter().enumerate() {
                        let fb = free_index[nb];
                        if fb == NONE {
                            continue;
                        }
                        let (ga, gb) = (g[a], g[b]);
                        let blk = ga * gb.transpose() * lambda + gb * ga.transpose() * mu + Mat3::from_diagonal_element(mu * ga.dot(&gb));
                        let bi = pattern.find(fa, fb).expect("assembled pattern holds every element pair");
                        k[bi] += blk * w;
                    }
                }
            }
        }
        // Fill-reducing order and the permuted upper triangle, as `fem::Model` builds its own.
        let coords: Vec<Vec3> = free.iter().map(|&i| nodes[i]).collect();
        let perm = ordering::fill_reducing_order(&adj, &coords);
        let mut pos = vec![0usize; nf];
        for (p, &i) in perm.iter().enumerate() {
            pos[i] = p;
        }
        let mut columns: Vec<Vec<(usize, usize)>> = vec![Vec::new(); nf];
        for i in 0..nf {
            for bi in pattern.row_ptr[i]..pattern.row_ptr[i + 1] {
                let (p, q) = (pos[i], pos[pattern.col[bi]]);
                if p <= q {
                    columns[q].push((p, bi));
                }
            }
        }
        let mut ap = Vec::with_capacity(nf + 1);
        let mut ai = Vec::new();
        let mut ax = Vec::new();
        ap.push(0);
        for col in columns.iter_mut() {
            col.sort_unstable();
            for &(p, bi) in col.iter() {
                ai.push(p);
                ax.push(k[bi]);
            }
            ap.push(ai.len());
        }
        let mut ldl = Ldl::symbolic(nf, ap, ai);
        ldl.factor(&ax)
            .map_err(|e| SolveError::NotPositiveDefinite { dof: 3 * e.column, node: free[perm[e.column]], pivot: e.pivot })?;
        let mut slot = vec![NONE; n];
        for (f, &node) in free.iter().enumerate() {
            slot[node] = pos[f];
        }
        Ok(SmallStrain { order, nodes, edges, edge_map: edge_node, elements, slot, ldl })
    }

    /// The element order.
    pub fn order(&self) -> Order {
        self.order
    }
    /// Every node \[m\] `(n_nodes)`: the vertices, then (P2) the edge midpoints.
    pub fn nodes(&self) -> &[Vec3] {
        &self.nodes
    }
    /// P2: the vertex pair of each edge node (node `n_vertices + k` is `edges()[k]`'s midpoint).
    pub fn edges(&self) -> &[[usize; 2]] {
        &self.edges
    }
    /// The node of the edge `(a, b)` of vertices (P1: none; P2: none if no tet has that edge).
    pub fn edge_node(&self, a: usize, b: usize) -> Option<usize> {
        self.edge_map.get(&(a.min(b), a.max(b))).copied()
    }
    /// Number of tets.
    pub fn n_tets(&self) -> usize {
        self.elements.len()
    }
    /// Number of free nodes (the system has three times as many unknowns).
    pub fn n_free(&self) -> usize {
        self.ldl.n()
    }

    /// The displacement \[m\] `(n_nodes)` under nodal forces `f` \[N\] `(n_nodes)` (held nodes: zero,
    /// their forces ignored).
    pub fn solve(&self, f: &[Vec3]) -> Vec<Vec3> {
        let mut b = vec![Vec3::zeros(); self.ldl.n()];
        for (node, &s) in self.slot.iter().enumerate() {
            if s != NONE {
                b[s] = f[node];
            }
        }
        self.ldl.solve_in_place(&mut b);
        self.slot.iter().map(|&s| if s == NONE { Vec3::zeros() } else { b[s] }).collect()
    }
}

/// The consistent nodal forces \[N\] of a traction `t(x)` \[Pa\] on the triangles `tris` (vertex
/// indices) of a [`SmallStrain`] mesh, added into `out` `(n_nodes)`: see [`linear_surface_forces`];
/// P2 weights a point by the face's quadratic shape functions (`L_i (2 L_i - 1)` at its vertices,
/// `4 L_i L_j` at its edge nodes).
pub fn surface_forces(s: &SmallStrain, tris: &[[usize; 3]], max_sub: f64, t: impl Fn(Vec3) -> Vec3, out: &mut [Vec3]) {
    for tri in tris {
        let edge_nodes = match s.order {
            Order::Linear => None,
            Order::Quadratic => match (s.edge_node(tri[0], tri[1]), s.edge_node(tri[1], tri[2]), s.edge_node(tri[0], tri[2])) {
                (Some(a), Some(b), Some(c)) => Some([a, b, c]),
                _ => None,
            },
        };
        triangle_points(tri.map(|i| s.nodes[i]), max_sub, |l, w, p| {
            let f = t(p) * w;
            match edge_nodes {
                None => {
                    for k in 0..3 {
                        out[tri[k]] += f * l[k];
                    }
                }
                Some(en) => {
                    for k in 0..3 {
                        out[tri[k]] += f * (l[k] * (2.0 * l[k] - 1.0));
                    }
                    out[en[0]] += f * (4.0 * l[0] * l[1]);
                    out[en[1]] += f * (4.0 * l[1] * l[2]);
                    out[en[2]] += f * (4.0 * l[0] * l[2]);
                }
            }
        });
    }
}

/// The nodal forces \[N\] of a traction `t(x)` \[Pa\] on the linear triangles `tris` over
/// `points` \[m\], added into `out` `(n_points)`: each triangle split into `m x m` sub-triangles
/// with edges of at most `max_sub` \[m\], one point at each sub-triangle's centroid, weighted by
/// the barycentric coordinates.
pub fn linear_surface_forces(points: &[Vec3], tris: &[[usize; 3]], max_sub: f64, t: impl Fn(Vec3) -> Vec3, out: &mut [Vec3]) {
    for tri in tris {
        triangle_points(tri.map(|i| points[i]), max_sub, |l, w, p| {
            let f = t(p) * w;
            for k in 0..3 {
                out[tri[k]] += f * l[k];
            }
        });
    }
}

/// The centroids of the `m x m` sub-triangles of `x` (edges of at most `max_sub`): calls
/// `visit(barycentric, weight, point)` with the weight its area.
fn triangle_points(x: [Vec3; 3], max_sub: f64, mut visit: impl FnMut([f64; 3], f64, Vec3)) {
    let area = 0.5 * (x[1] - x[0]).cross(&(x[2] - x[0])).norm();
    let longest = (x[1] - x[0]).norm().max((x[2] - x[1]).norm()).max((x[0] - x[2]).norm());
    let m = ((longest / max_sub).ceil() as usize).clamp(1, 64);
    let w = area / (m * m) as f64;
    let mf = m as f64;
    let mut add = |l: [f64; 3]| visit(l, w, x[0] * l[0] + x[1] * l[1] + x[2] * l[2]);
    // Up-pointing sub-triangles (i, j), and the down-pointing one beside each but the last.
    for i in 0..m {
        for j in 0..m - i {
            let (a, b) = (i as f64, j as f64);
            add([(a + 1.0 / 3.0) / mf, (b + 1.0 / 3.0) / mf, 1.0 - (a + b + 2.0 / 3.0) / mf]);
            if i + j + 1 < m {
                add([(a + 2.0 / 3.0) / mf, (b + 2.0 / 3.0) / mf, 1.0 - (a + b + 4.0 / 3.0) / mf]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box `[0, lx] x [0, ly] x [0, lz]` of `nx x ny x nz` cubes, each split into 6 tets.
    fn beam(l: [f64; 3], n: [usize; 3]) -> (Vec<Vec3>, Vec<[usize; 4]>) {
        let id = |i: usize, j: usize, k: usize| (k * (n[1] + 1) + j) * (n[0] + 1) + i;
        let mut pts = Vec::new();
        for k in 0..=n[2] {
            for j in 0..=n[1] {
                for i in 0..=n[0] {
                    pts.push(Vec3::new(l[0] * i as f64 / n[0] as f64, l[1] * j as f64 / n[1] as f64, l[2] * k as f64 / n[2] as f64));
                }
            }
        }
        let mut tets = Vec::new();
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let c = [
                        id(i, j, k),
                        id(i + 1, j, k),
                        id(i + 1, j + 1, k),
                        id(i, j + 1, k),
                        id(i, j, k + 1),
                        id(i + 1, j, k + 1),
                        id(i + 1, j + 1, k + 1),
                        id(i, j + 1, k + 1),
                    ];
                    // Kuhn's split of the cube along its diagonal 0-6.
                    for t in [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]] {
                        let mut tet = t.map(|q| c[q]);
                        let d = Mat3::from_columns(&[pts[tet[1]] - pts[tet[0]], pts[tet[2]] - pts[tet[0]], pts[tet[3]] - pts[tet[0]]]).determinant();
                        if d < 0.0 {
                            tet.swap(1, 2);
                        }
                        tets.push(tet);
                    }
                }
            }
        }
        (pts, tets)
    }

    /// A cantilever (length 100 mm, 10 x 10 mm section) clamped at x = 0, loaded at its free end
    /// by a shear traction: Euler-Bernoulli tip deflection `F L^3 / (3 E I)` plus Timoshenko's
    /// shear term. P2 on two elements across the section is within 3%; P1 locks (measured: 2.8x
    /// too stiff). The test fails if the P2 element, its quadrature or the loads are wrong.
    #[test]
    fn p2_bends_like_a_beam_and_p1_locks() {
        let (l, h) = (0.1, 0.01);
        let (pts, tets) = beam([l, h, h], [10, 2, 2]);
        let held: Vec<bool> = pts.iter().map(|p| p.x < 1e-12).collect();
        let (e, nu) = (3.0e4, 0.3);
        let mu = e / (2.0 * (1.0 + nu));
        let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
        let force = 1e-4;
        let i_area = h * h * h * h / 12.0;
        let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
        let expected = force * l * l * l / (3.0 * e * i_area) + force * l / (kappa * mu * h * h);
        let tip = |order: Order| {
            let s = SmallStrain::new(&pts, &tets, order, lambda, mu, &held).unwrap();
            let end: Vec<[usize; 3]> = tip_faces(&pts, &tets, l);
            let mut f = vec![Vec3::zeros(); s.nodes().len()];
            surface_forces(&s, &end, 1e-3, |_| Vec3::new(0.0, 0.0, -force / (h * h)), &mut f);
            let total: Vec3 = f.iter().sum();
            assert!((total.z + force).abs() < 1e-9 * force, "consistent forces sum to the load: {total:?}");
            let u = s.solve(&f);
            // Mean deflection of the end face's vertices.
            let ends: Vec<usize> = (0..pts.len()).filter(|&i| (pts[i].x - l).abs() < 1e-12).collect();
            -ends.iter().map(|&i| u[i].z).sum::<f64>() / ends.len() as f64
        };
        let p2 = tip(Order::Quadratic) / expected;
        let p1 = tip(Order::Linear) / expected;
        assert!((p2 - 1.0).abs() < 0.03, "P2 tip deflection / beam theory = {p2}");
        assert!(p1 < 0.5, "P1 should lock: deflection ratio {p1}");
    }

    fn tip_faces(pts: &[Vec3], tets: &[[usize; 4]], l: f64) -> Vec<[usize; 3]> {
        let mut out = Vec::new();
        for t in tets {
            let on: Vec<usize> = t.iter().copied().filter(|&i| (pts[i].x - l).abs() < 1e-12).collect();
            if on.len() == 3 {
                out.push([on[0], on[1], on[2]]);
            }
        }
        out
    }

    /// A single held vertex leaves the body free to rotate: refused, not solved.
    #[test]
    fn a_free_rotation_is_refused() {
        let (pts, tets) = beam([0.02, 0.01, 0.01], [2, 1, 1]);
        for order in [Order::Linear, Order::Quadratic] {
            let held: Vec<bool> = (0..pts.len()).map(|i| i == 0).collect();
            let s = SmallStrain::new(&pts, &tets, order, 2.0e4, 1.0e4, &held);
            assert!(matches!(s, Err(SolveError::NotPositiveDefinite { .. })), "{order:?}");
        }
    }
}
