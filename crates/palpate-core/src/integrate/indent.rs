//! Static sphere indentation of a FEM body: the reference the hybrid model's force and dent are
//! measured against (issue 33), and the textbook check of that reference against Hertz.
//!
//! A rigid frictionless sphere of radius `R` moves along a unit `direction` into the body; at
//! each travel the body is brought to static equilibrium (Newton on the full Green-strain forces
//! of [`Model`], the model's law and fixed nodes) under the contact potential
//!
//! `U_c = sum_s k_a A_s d_s^2 / 2`,  `d_s = max(0, R - |x_s - c|)`,  `x_s = sum_i b_si x_i`,
//!
//! over sample points `s` fixed on the body's boundary triangles (barycentric `b_si`, rest area
//! share `A_s`): a quadrature of `k_a / 2 int d^2 dA`, so the contact meets the sphere over its
//! whole footprint whatever the mesh (a nodal contact on a coarse mesh is a point load). `k_a`
//! \[N/m^3\] defaults to `1000 E / R`, which leaves a penetration of about a thousandth of the
//! contact radius (Hertz's peak pressure `p0 ~ E* a / R`); the penetration is reported, and the
//! **indentation** (travel beyond first contact minus the deepest penetration: how far the
//! surface was pushed in) is the abscissa every comparison uses, so the penalty drops out.
//!
//! Each travel is reached from the previous equilibrium in increments of at most
//! [`IndentOptions::max_increment`]. Newton's system is the tangent `-K(x)` plus the contact's
//! Gauss-Newton Hessian `sum_s k_a A_s (b_s b_s^T) (x) (n_s n_s^T)` (its curvature term
//! `-k_a A_s d_s / r_s (I - n n^T)` is left out: it is `d/R` of the normal one and would make the
//! system indefinite). The step is accepted by an Armijo line search on the total potential
//! `W(x) + U_c(x)`, which both terms decrease toward equilibrium; where the tangent is indefinite
//! (St. Venant-Kirchhoff under strong compression) a diagonal shift is added until it factors
//! (a Levenberg-Marquardt step), so the solve follows the minimum rather than stopping.
//!
//! Samples and their triangles' nodes are all in the model's pattern (a boundary triangle is a
//! face of a tet), so the contact adds no fill: one symbolic factorisation serves every iteration.
//!
//! On a body of quadratic tets ([`crate::fem::ModelBuilder::order`], the references' element:
//! they do not lock in the wall's bending) a sample lies on the curved face: `b_si` are the six
//! quadratic shape functions of its vertices and edge nodes at the sample's barycentric point,
//! which sum to one as the linear weights do, so the spread is still the transpose of the
//! interpolation and the nodal forces still sum to minus the sphere's.

use crate::error::SolveError;
use crate::fem::model::NONE;
use crate::fem::Model;
use crate::linalg::cg;
use crate::math::{is_finite3, Mat3, Vec3};

/// The rigid sphere and its path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Indenter {
    /// A point on the path of the sphere's centre \[m\], outside the body (travel is measured
    /// from the first contact, found by the solve, so any start outside will do).
    pub start: Vec3,
    /// Unit direction of the press, into the body.
    pub direction: Vec3,
    /// Sphere radius \[m\].
    pub radius: f64,
}

/// Options of [`indent`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndentOptions {
    /// Contact stiffness per unit area `k_a` \[N/m^3\]; 0: `1000 E / R`.
    pub stiffness: f64,
    /// Largest travel between two equilibria \[m\]; 0: `R / 20`.
    pub max_increment: f64,
    /// Sample spacing on the boundary triangles \[m\]; 0: `R / 12`.
    pub sample_spacing: f64,
    /// Convergence: `max_i |r_i| <= tolerance * max_i |f_c,i|` over the free nodes (`f_c` the
    /// nodal contact forces), or the forces' round-off level.
    pub tolerance: f64,
    /// Newton iterations per increment.
    pub max_iterations: usize,
}

impl Default for IndentOptions {
    fn default() -> Self {
        IndentOptions { stiffness: 0.0, max_increment: 0.0, sample_spacing: 0.0, tolerance: 1e-5, max_iterations: 150 }
    }
}

/// The equilibrium at one travel.
#[derive(Debug, Clone, PartialEq)]
pub struct IndentPoint {
    /// Travel of the sphere beyond its first contact with the rest surface \[m\].
    pub travel: f64,
    /// Force on the sphere \[N\], world frame (the body pushes it back: along `-direction`).
    pub force: Vec3,
    /// Deepest penetration of a sample into the sphere \[m\].
    pub penetration: f64,
    /// `travel - penetration` \[m\]: how far the surface was pushed in.
    pub indentation: f64,
    /// Samples in contact, and their rest area \[m^2\].
    pub contact_samples: usize,
    pub contact_area: f64,
    /// Newton iterations over the increments that led here from the previous point, and the
    /// factorisations among them.
    pub iterations: usize,
    pub factorisations: usize,
    /// Equilibrium positions \[m\] `(n_nodes)`.
    pub x: Vec<Vec3>,
    /// The contact's nodal forces on the body \[N\] `(n_nodes)` (they sum to `-force`).
    pub contact_forces: Vec<Vec3>,
}

/// A sample point of a boundary triangle.
struct Sample {
    /// The triangle's nodes: its three vertices, and on quadratic elements its three edge
    /// nodes (of edges `(0, 1)`, `(1, 2)`, `(0, 2)`), with the shape functions' values at the
    /// sample; `n` of them (3 or 6).
    nodes: [usize; 6],
    bary: [f64; 6],
    n: usize,
    area: f64,
}

impl Sample {
    /// The sample's position at node positions `x`.
    #[inline]
    fn point(&self, x: &[Vec3]) -> Vec3 {
        let mut p = self.bary[0] * x[self.nodes[0]] + self.bary[1] * x[self.nodes[1]] + self.bary[2] * x[self.nodes[2]];
        for a in 3..self.n {
            p += self.bary[a] * x[self.nodes[a]];
        }
        p
    }
}

/// The sample at barycentric `l` of boundary triangle `f`: its vertices' weights, or on
/// quadratic elements the six quadratic shape functions' (the edge nodes from `edge_node`).
fn sample_at(f: [usize; 3], l: [f64; 3], area: f64, edge_node: &std::collections::HashMap<(usize, usize), usize>) -> Sample {
    if edge_node.is_empty() {
        return Sample { nodes: [f[0], f[1], f[2], 0, 0, 0], bary: [l[0], l[1], l[2], 0.0, 0.0, 0.0], n: 3, area };
    }
    let e = |i: usize, j: usize| edge_node[&(f[i].min(f[j]), f[i].max(f[j]))];
    let v = |i: usize| l[i] * (2.0 * l[i] - 1.0);
    Sample {
        nodes: [f[0], f[1], f[2], e(0, 1), e(1, 2), e(0, 2)],
        bary: [v(0), v(1), v(2), 4.0 * l[0] * l[1], 4.0 * l[1] * l[2], 4.0 * l[0] * l[2]],
        n: 6,
        area,
    }
}

/// Samples of the boundary triangles within `reach` of the sphere's path: each triangle cut into
/// `n^2` equal sub-triangles (`n` its longest edge over `spacing`, rounded up), sampled at their
/// centroids with a sub-triangle's area each.
fn samples(model: &Model, ind: &Indenter, spacing: f64, reach: f64, travel_max: f64) -> Vec<Sample> {
    let x = model.rest_positions();
    let nv = model.mesh.n_nodes();
    let edge_node: std::collections::HashMap<(usize, usize), usize> = model.edges().iter().enumerate().map(|(k, &[a, b])| ((a, b), nv + k)).collect();
    let mut out = Vec::new();
    let seg = |p: &Vec3| {
        // distance from the centre's path, the segment start .. start + travel_max d
        let t = (p - ind.start).dot(&ind.direction).clamp(0.0, travel_max);
        (p - (ind.start + t * ind.direction)).norm()
    };
    for f in model.mesh.boundary_faces() {
        let [a, b, c] = f.map(|i| x[i]);
        let centre = (a + b + c) / 3.0;
        let size = (a - b).norm().max((b - c).norm()).max((c - a).norm());
        if seg(&centre) > reach + size {
            continue;
        }
        let area = 0.5 * (b - a).cross(&(c - a)).norm();
        let n = ((size / spacing).ceil() as usize).max(1);
        let share = area / (n * n) as f64;
        // Sub-triangle centroids of the n x n split, in barycentric coordinates (i, j steps).
        for i in 0..n {
            for j in 0..n - i {
                let mut push = |u: f64, v: f64| {
                    let bary = [1.0 - u - v, u, v];
                    let s = sample_at(f, bary, share, &edge_node);
                    if seg(&s.point(x)) <= reach {
                        out.push(s);
                    }
                };
                let (fi, fj, nf) = (i as f64, j as f64, n as f64);
                push((fi + 1.0 / 3.0) / nf, (fj + 1.0 / 3.0) / nf);
                if i + j + 1 < n {
                    push((fi + 2.0 / 3.0) / nf, (fj + 2.0 / 3.0) / nf);
                }
            }
        }
    }
    out
}

/// Contact at positions `x` for centre `c`: energy, deepest penetration, samples and area in
/// contact; adds the nodal forces `-dU_c/dx` to `f`.
fn contact(samples: &[Sample], k: f64, r: f64, c: &Vec3, x: &[Vec3], f: &mut [Vec3]) -> (f64, f64, usize, f64) {
    let (mut u, mut deepest, mut count, mut area) = (0.0, 0.0f64, 0, 0.0);
    for s in samples {
        let p = s.point(x);
        let e = p - c;
        let dist = e.norm();
        let d = r - dist;
        if d <= 0.0 || dist == 0.0 {
            continue;
        }
        let ka = k * s.area;
        u += 0.5 * ka * d * d;
        deepest = deepest.max(d);
        count += 1;
        area += s.area;
        let push = (ka * d / dist) * e;
        for a in 0..s.n {
            f[s.nodes[a]] += s.bary[a] * push;
        }
    }
    (u, deepest, count, area)
}

/// The travel at which the sphere, moving from `ind.start`, first meets a sample at rest.
fn first_contact(samples: &[Sample], ind: &Indenter, x: &[Vec3]) -> Option<f64> {
    let mut best: Option<f64> = None;
    for s in samples {
        let p = s.point(x);
        // |p - start - t d| = R: t^2 - 2 t (q.d) + |q|^2 - R^2 = 0, q = p - start; first root.
        let q = p - ind.start;
        let b = q.dot(&ind.direction);
        let disc = b * b - (q.norm_squared() - ind.radius * ind.radius);
        if disc < 0.0 {
            continue;
        }
        let t = b - disc.sqrt();
        best = Some(best.map_or(t, |v: f64| v.min(t)));
    }
    best
}

/// Static equilibria of `model` pressed by the sphere `ind` to each travel of `travels` \[m\]
/// (beyond first contact, increasing), from rest. Errors: an invalid indenter or options
/// ([`SolveError::Invalid`]), a sphere whose path meets no boundary triangle, or Newton failing
/// at an increment ([`SolveError::NoConvergence`]).
pub fn indent(model: &Model, ind: &Indenter, travels: &[f64], opts: &IndentOptions) -> Result<Vec<IndentPoint>, SolveError> {
    indent_with(model, ind, travels, opts, &mut || false)
}

/// [`indent`], asking `interrupted` before each Newton iteration whether to stop
/// ([`SolveError::Interrupted`]; see [`super::static_solve_with`]): a fine reference curve takes
/// half an hour.
pub fn indent_with(
    model: &Model,
    ind: &Indenter,
    travels: &[f64],
    opts: &IndentOptions,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<Vec<IndentPoint>, SolveError> {
    let bad = |m: String| Err(SolveError::Invalid(m));
    if !(ind.radius > 0.0 && ind.radius.is_finite()) {
        return bad(format!("sphere radius {} m must be positive and finite", ind.radius));
    }
    if !is_finite3(&ind.start) || !is_finite3(&ind.direction) || (ind.direction.norm() - 1.0).abs() > 1e-9 {
        return bad("the start must be finite and the direction a unit vector".into());
    }
    if travels.iter().any(|t| !(t.is_finite() && *t >= 0.0)) || travels.windows(2).any(|w| w[1] < w[0]) {
        return bad("travels must be finite, non-negative and increasing [m]".into());
    }
    if model.free_nodes.is_empty() {
        return bad("the body has no free node".into());
    }
    let material = model.material();
    let r = ind.radius;
    let k = if opts.stiffness > 0.0 { opts.stiffness } else { 1000.0 * material.young() / r };
    let inc = if opts.max_increment > 0.0 { opts.max_increment } else { r / 20.0 };
    let spacing = if opts.sample_spacing > 0.0 { opts.sample_spacing } else { r / 12.0 };
    if !(k.is_finite() && inc.is_finite() && spacing.is_finite() && opts.tolerance > 0.0) {
        return bad("stiffness, increment, sample spacing and tolerance must be positive and finite".into());
    }
    let travel_max = travels.last().copied().unwrap_or(0.0);
    let x0 = model.rest_positions();
    // Reach: a sample farther than R from every centre of the path cannot touch at rest; the
    // body's sideways bulge under the sphere is bounded by the travel.
    let reach = r + travel_max + 2.0 * spacing;
    // First contact: every sample the sphere can meet along a path as long as the body is far.
    let far = x0.iter().map(|p| (p - ind.start).norm()).fold(0.0, f64::max);
    let all = samples(model, ind, spacing, r + spacing, far);
    let t0 = match first_contact(&all, ind, x0) {
        Some(t) => t,
        None => return bad("the sphere's path meets no boundary triangle of the body".into()),
    };
    // Keep the samples within reach of the path from first contact to the deepest travel.
    let start = ind.start + t0 * ind.direction;
    let path = Indenter { start, ..*ind };
    let samples = samples(model, &path, spacing, reach, travel_max);

    let n = model.n_nodes();
    let nf = model.free_nodes.len();
    let mut free_index = vec![NONE; n];
    for (fi, &node) in model.free_nodes.iter().enumerate() {
        free_index[node] = fi;
    }
    // Pattern blocks of each sample's node pairs (NONE where a node is fixed).
    let blocks: Vec<[usize; 36]> = samples
        .iter()
        .map(|s| {
            let mut b = [NONE; 36];
            for a in 0..s.n {
                for c in 0..s.n {
                    let (i, j) = (free_index[s.nodes[a]], free_index[s.nodes[c]]);
                    if i != NONE && j != NONE {
                        b[6 * a + c] = model.pattern.find(i, j).unwrap_or(NONE);
                    }
                }
            }
            b
        })
        .collect();

    let mut ws = crate::fem::Workspace::new(model);
    let mut x = x0.to_vec();
    let mut trial = x.clone();
    let mut f = vec![Vec3::zeros(); n];
    let mut fc = vec![Vec3::zeros(); n];
    let mut step = vec![Vec3::zeros(); nf];
    let mut out = Vec::with_capacity(travels.len());
    let mut travel = 0.0;
    let mut iterations = 0;
    let mut iterations_factored = 0;
    let mut factored = false;
    let mut op = vec![Mat3::zeros(); model.pattern.nnz()];
    let mut b = vec![Vec3::zeros(); nf];
    let mut perm = vec![Vec3::zeros(); nf];
    let mut cg_work = cg::CgWork::new(nf);
    // Total potential and residual (forces) at y for centre c.
    let eval = |y: &[Vec3], c: &Vec3, f: &mut [Vec3], fc: &mut [Vec3], ws: &mut crate::fem::Workspace| -> (f64, (f64, f64, usize, f64)) {
        model.internal_forces(y, None, &mut ws.force);
        fc.iter_mut().for_each(|v| *v = Vec3::zeros());
        let con = contact(&samples, k, r, c, y, fc);
        for i in 0..n {
            f[i] = if model.fixed[i] { Vec3::zeros() } else { ws.force[i] + fc[i] };
        }
        (model.strain_energy(y) + con.0, con)
    };
    // The previous increment's motion, for a secant predictor: each increment starts from the
    // last equilibrium moved on by the last increment's displacement (scaled to this travel), so
    // that its first iterate has nearly the right contact set (from the bare last equilibrium,
    // the surface under the sphere starts a whole increment deep and the set swings for
    // iterations).
    let mut last_dx = vec![Vec3::zeros(); n];
    let mut last_inc = 0.0;
    let mut x_prev = x.clone();
    for &target in travels {
        while travel < target {
            let step_len = (target - travel).min(inc);
            travel += step_len;
            if target - travel < 1e-12 * inc {
                travel = target;
            }
            let c = start + travel * ind.direction;
            x_prev.copy_from_slice(&x);
            if last_inc > 0.0 {
                let s = step_len / last_inc;
                for (xi, d) in x.iter_mut().zip(&last_dx) {
                    *xi += s * d;
                }
            }
            let mut it = 0;
            // Newton-PCG: each iteration solves the exact system at x by conjugate gradients
            // preconditioned by a factorisation of it at an earlier iterate, made anew when CG
            // needs more than PCG_REFACTOR iterations (or meets negative curvature, or fails):
            // a solve costs ~1% of a factorisation on the reference meshes, and the system
            // changes little from one iterate to the next (the contact set at the rim).
            loop {
                let (phi, con) = eval(&x, &c, &mut f, &mut fc, &mut ws);
                let rnorm = model.free_nodes.iter().map(|&i| f[i].norm()).fold(0.0, f64::max);
                let scale = model.free_nodes.iter().map(|&i| fc[i].norm()).fold(0.0, f64::max);
                let floor = round_off(model, &x);
                if !rnorm.is_finite() {
                    let node = (0..n).find(|&i| !is_finite3(&f[i]) || !is_finite3(&x[i])).unwrap_or(0);
                    return Err(SolveError::NonFinite { what: "indentation residual", node });
                }
                if trace() {
                    eprintln!("indent: travel {travel:.4e} m, iteration {it}: potential {phi:.6e} J, residual {rnorm:.3e} N (contact {scale:.3e} N), {} samples in contact, {iterations_factored} factorisations", con.2);
                }
                if rnorm <= (opts.tolerance * scale).max(floor) || (con.2 == 0 && rnorm <= floor) {
                    break;
                }
                if it >= opts.max_iterations {
                    return Err(SolveError::NoConvergence { iterations: iterations + it, residual: rnorm, tolerance: (opts.tolerance * scale).max(floor) });
                }
                if interrupted() {
                    return Err(SolveError::Interrupted { iterations: iterations + it });
                }
                it += 1;
                assemble_system(model, &samples, &blocks, k, r, &c, &x, &mut ws, &mut op);
                for (fi, &node) in model.free_nodes.iter().enumerate() {
                    b[fi] = f[node];
                    step[fi] = Vec3::zeros();
                }
                let mut solved = false;
                if factored {
                    let rep = cg::solve(
                        |v, out| model.pattern.mul(&op, v, out),
                        |rr, z| precondition(model, &ws.ldl, &mut perm, rr, z),
                        &b,
                        &mut step,
                        &mut cg_work,
                        cg::CgStop { tolerance: 1e-3, max_iterations: PCG_REFACTOR },
                    );
                    solved = rep.converged && !rep.breakdown;
                }
                if !solved {
                    factor_system(model, &mut ws)?;
                    factored = true;
                    iterations_factored += 1;
                    model.gather_free(&f, &mut ws.rhs);
                    ws.ldl.solve_in_place(&mut ws.rhs);
                    for (fi, s) in step.iter_mut().enumerate() {
                        *s = ws.rhs[model.node_pos[fi]];
                    }
                }
                // Armijo on the total potential: the step is a descent direction (the system is
                // positive definite), slope -f.dx.
                let slope: f64 = -model.free_nodes.iter().zip(&step).map(|(&i, s)| f[i].dot(s)).sum::<f64>();
                let mut alpha = 1.0;
                loop {
                    trial.copy_from_slice(&x);
                    for (fi, &node) in model.free_nodes.iter().enumerate() {
                        trial[node] = x[node] + alpha * step[fi];
                    }
                    let phit = model.strain_energy(&trial) + {
                        fc.iter_mut().for_each(|v| *v = Vec3::zeros());
                        contact(&samples, k, r, &c, &trial, &mut fc).0
                    };
                    // Accept a decrease, or any step once the decrease is below the potential's
                    // round-off (near the solution the energy no longer resolves the step).
                    let noise = 1e-12 * phi.abs().max(1e-30);
                    if phit <= phi + 1e-4 * alpha * slope + noise || alpha < 1e-6 {
                        break;
                    }
                    alpha *= 0.5;
                }
                x.copy_from_slice(&trial);
            }
            iterations += it;
            for ((d, a), b) in last_dx.iter_mut().zip(&x).zip(&x_prev) {
                *d = a - b;
            }
            last_inc = step_len;
        }
        let c = start + travel * ind.direction;
        let (_, con) = eval(&x, &c, &mut f, &mut fc, &mut ws);
        let force = -fc.iter().sum::<Vec3>();
        out.push(IndentPoint {
            travel,
            force,
            penetration: con.1,
            indentation: travel - con.1,
            contact_samples: con.2,
            contact_area: con.3,
            iterations,
            factorisations: iterations_factored,
            x: x.clone(),
            contact_forces: fc.clone(),
        });
        iterations = 0;
        iterations_factored = 0;
    }
    Ok(out)
}

/// Round-off level of the internal forces at `x` (as `static_solve`'s floor, cheaper: the
/// largest element force scale times `eps |x|`).
fn round_off(model: &Model, x: &[Vec3]) -> f64 {
    let xmax = x.iter().map(|p| p.norm()).fold(0.0, f64::max);
    let modulus = model.material.lambda() + 2.0 * model.material.mu();
    let worst = match &model.quadratic {
        None => model.rest.iter().map(|r| r.volume * modulus * r.dm_inv.norm_squared()).fold(0.0, f64::max),
        Some(q) => q.rest.iter().map(|r| modulus * r.gradient_scale()).fold(0.0, f64::max),
    };
    64.0 * f64::EPSILON * worst * xmax
}

fn trace() -> bool {
    std::env::var_os("PALPATE_INDENT_TRACE").is_some()
}

/// CG iterations after which the preconditioner is factorised anew.
const PCG_REFACTOR: usize = 40;

/// Newton's system at `x` on the free pattern: `op = -K(x) + H_c`, `H_c` the contact's
/// Gauss-Newton Hessian `sum_s k_a A_s (b_s b_s^T) (x) (n_s n_s^T)`; `ws.k` keeps `-op`.
#[allow(clippy::too_many_arguments)]
fn assemble_system(
    model: &Model,
    samples: &[Sample],
    blocks: &[[usize; 36]],
    k: f64,
    r: f64,
    c: &Vec3,
    x: &[Vec3],
    ws: &mut crate::fem::Workspace,
    op: &mut [Mat3],
) {
    model.assemble_jacobians(x, &mut ws.k, &mut ws.d);
    for (s, b) in samples.iter().zip(blocks) {
        let p = s.point(x);
        let e = p - c;
        let dist = e.norm();
        if dist >= r || dist == 0.0 {
            continue;
        }
        let n = e / dist;
        let nn = n * n.transpose() * (k * s.area);
        for a in 0..s.n {
            for cc in 0..s.n {
                let bi = b[6 * a + cc];
                if bi != NONE {
                    ws.k[bi] -= nn * (s.bary[a] * s.bary[cc]);
                }
            }
        }
    }
    for (o, kb) in op.iter_mut().zip(&ws.k) {
        *o = -kb;
    }
}

/// `z = A^-1 r` by the factor (free-node order in and out; `perm` is scratch).
fn precondition(model: &Model, ldl: &crate::linalg::Ldl, perm: &mut [Vec3], r: &[Vec3], z: &mut [Vec3]) {
    for (fi, v) in r.iter().enumerate() {
        perm[model.node_pos[fi]] = *v;
    }
    ldl.solve_in_place(perm);
    for (fi, v) in z.iter_mut().enumerate() {
        *v = perm[model.node_pos[fi]];
    }
}

/// Factor the system assembled last ([`assemble_system`], in `ws.k`), with a diagonal shift
/// where it is indefinite (St. Venant-Kirchhoff under strong compression): a
/// Levenberg-Marquardt step.
fn factor_system(model: &Model, ws: &mut crate::fem::Workspace) -> Result<(), SolveError> {
    let nf = model.free_nodes.len();
    let diag_scale = (0..nf).map(|fi| ws.k[model.pattern.diag[fi]].trace().abs() / 3.0).fold(0.0, f64::max);
    let mut shift = 0.0;
    loop {
        model.system_values(0.0, 0.0, -1.0, &ws.k, &ws.d, &mut ws.a_values);
        if shift > 0.0 {
            for fi in 0..nf {
                let p = model.entry_to_a[model.pattern.diag[fi]];
                ws.a_values[p] += Mat3::from_diagonal_element(shift);
            }
        }
        match model.factor(&mut ws.ldl, &ws.a_values) {
            Ok(()) => return Ok(()),
            Err(_) if shift < diag_scale => shift = if shift == 0.0 { 1e-6 * diag_scale } else { 10.0 * shift },
            Err(e) => return Err(e),
        }
    }
}
