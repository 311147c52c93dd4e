//! Static equilibrium: find positions `x` with `f_int(x) + f_ext + m g = 0` at every free node,
//! by Newton's method on the full nonlinear (Green strain) forces with the exact tangent
//! `K(x) = df_int/dx`, a backtracking line search on the residual norm, and optional load
//! increments for large loads. Used to validate the dynamic schemes and as a reference.

use crate::error::SolveError;
use crate::fem::{tet10, tet4};
use crate::fem::{Model, Workspace};
use crate::math::{is_finite3, Vec3};

/// Options of [`static_solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticOptions {
    /// Newton iteration cap per load increment.
    pub max_iterations: usize,
    /// Convergence: `max_i |r_i| <= tolerance * max_i |f_ext,i + m_i g|` over free nodes, or the
    /// round-off level of the internal forces (see `round_off_floor`), whichever is larger.
    pub tolerance: f64,
    /// The load is applied in this many equal increments (1 for small loads); if Newton fails
    /// (indefinite tangent or no convergence), the solve restarts with 4x as many, up to 256.
    pub load_steps: usize,
}

impl Default for StaticOptions {
    fn default() -> Self {
        StaticOptions { max_iterations: 100, tolerance: 1e-10, load_steps: 1 }
    }
}

/// The equilibrium found by [`static_solve`].
#[derive(Debug, Clone, PartialEq)]
pub struct StaticSolution {
    /// Equilibrium positions \[m\], `(n_nodes)`.
    pub x: Vec<Vec3>,
    /// Newton iterations used.
    pub iterations: usize,
    /// Final residual `max_i |r_i|` \[N\].
    pub residual: f64,
}

/// Round-off level of the assembled internal force at `x` \[N\], below which a residual cannot
/// be resolved. Two sources, summed per node over its tets: the force sum itself
/// (`eps |f_e|`), and the deformation gradient, whose differences of positions lose
/// `eps |x| |Dm^-1|` of strain, i.e. a force of `V (lambda + 2 mu) |Dm^-1|^2 eps |x|`.
fn round_off_floor(model: &Model, x: &[Vec3], per_node: &mut [f64]) -> f64 {
    per_node.iter_mut().for_each(|v| *v = 0.0);
    let modulus = model.material.lambda() + 2.0 * model.material.mu();
    if let Some(q) = &model.quadratic {
        for (e, r) in q.elements.iter().zip(&q.rest) {
            let xe = e.map(|i| x[i]);
            let f = tet10::forces(&xe, None, r, &model.material);
            let xmax = xe.iter().map(|p| p.norm()).fold(0.0, f64::max);
            let strain_noise = modulus * r.gradient_scale() * xmax;
            for a in 0..10 {
                per_node[e[a]] += f[a].norm() + strain_noise;
            }
        }
    }
    for (t, r) in model.mesh.tets().iter().zip(&model.rest) {
        let xe = t.map(|i| x[i]);
        let f = tet4::forces(&xe, None, r, &model.material);
        let xmax = xe.iter().map(|p| p.norm()).fold(0.0, f64::max);
        let strain_noise = r.volume * modulus * r.dm_inv.norm_squared() * xmax;
        for a in 0..4 {
            per_node[t[a]] += f[a].norm() + strain_noise;
        }
    }
    let worst = model.free_nodes.iter().map(|&i| per_node[i]).fold(0.0, f64::max);
    ROUND_OFF_FACTOR * f64::EPSILON * worst
}

/// Multiple of the estimated round-off taken as converged.
const ROUND_OFF_FACTOR: f64 = 16.0;

fn residual(model: &Model, x: &[Vec3], applied: &[Vec3], lam: f64, ws: &mut Workspace) -> f64 {
    model.internal_forces(x, None, &mut ws.force);
    let mut worst: f64 = 0.0;
    for &node in &model.free_nodes {
        ws.force[node] += lam * applied[node];
        worst = worst.max(ws.force[node].norm());
    }
    if worst.is_nan() {
        f64::INFINITY
    } else {
        worst
    }
}

/// Static equilibrium of `model` under per-node external forces `f_ext` \[N\] `(n_nodes)` and gravity.
pub fn static_solve(model: &Model, f_ext: &[Vec3], opts: &StaticOptions) -> Result<StaticSolution, SolveError> {
    static_solve_with(model, f_ext, opts, &mut || false)
}

/// [`static_solve`], asking `interrupted` before each Newton iteration whether to stop
/// ([`SolveError::Interrupted`]): how a caller bounds it by a wall clock or lets a user cancel
/// it (the core has no clock; the Python binding polls Ctrl-C there). Many load steps with many
/// iterations each can take hours; this is the way out that is not a killed process.
pub fn static_solve_with(model: &Model, f_ext: &[Vec3], opts: &StaticOptions, interrupted: &mut dyn FnMut() -> bool) -> Result<StaticSolution, SolveError> {
    let n = model.n_nodes();
    if f_ext.len() != n {
        return Err(SolveError::Invalid(format!("f_ext has {} rows, the model has {n} nodes", f_ext.len())));
    }
    if let Some(node) = f_ext.iter().position(|f| !is_finite3(f)) {
        return Err(SolveError::NonFinite { what: "external force", node });
    }
    if let Some(node) = f_ext.iter().position(|f| !crate::limits::force_in_bound(f)) {
        return Err(SolveError::Invalid(format!(
            "node {node}: external force of {:e} N over the bound of {:e} N (limits::MAX_FORCE_N)",
            crate::limits::force_magnitude(&f_ext[node]),
            crate::limits::MAX_FORCE_N
        )));
    }
    // Zero increments is no solve at all: refused, not taken as 1 (issue 35 item 6).
    if opts.load_steps == 0 {
        return Err(SolveError::Invalid("load_steps = 0: the load is applied in at least 1 increment".into()));
    }
    let applied: Vec<Vec3> = (0..n).map(|i| f_ext[i] + model.mass[i] * model.gravity).collect();
    let scale = model.free_nodes.iter().map(|&i| applied[i].norm()).fold(0.0, f64::max);
    if scale == 0.0 || model.free_nodes.is_empty() {
        return Ok(StaticSolution { x: model.rest_x.clone(), iterations: 0, residual: 0.0 });
    }
    // A load too large for one Newton solve from rest (the tangent turns indefinite on the way,
    // or Newton stalls) is retried in more increments: 4x more each time, up to 256.
    let mut steps = opts.load_steps;
    loop {
        match solve_in_increments(model, &applied, scale, opts, steps, interrupted) {
            Err(SolveError::NotPositiveDefinite { .. } | SolveError::NoConvergence { .. }) if steps < 256 => steps *= 4,
            other => return other,
        }
    }
}

/// Newton from rest, the load applied in `steps` equal increments.
fn solve_in_increments(
    model: &Model,
    applied: &[Vec3],
    scale: f64,
    opts: &StaticOptions,
    steps: usize,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<StaticSolution, SolveError> {
    let n = model.n_nodes();
    let mut x = model.rest_x.clone();
    let tol = opts.tolerance * scale;
    let mut ws = Workspace::new(model);
    let mut trial = x.clone();
    let mut magnitudes = vec![0.0; n];
    let mut iterations = 0;
    let mut r = 0.0;
    for s in 1..=steps {
        let lam = s as f64 / steps as f64;
        if interrupted() {
            return Err(SolveError::Interrupted { iterations });
        }
        r = residual(model, &x, applied, lam, &mut ws);
        let first = iterations;
        loop {
            // Converged at the requested tolerance, or at the round-off level of the forces
            // (a tolerance below it could never be met).
            let floor = round_off_floor(model, &x, &mut magnitudes);
            if r <= tol.max(floor) {
                break;
            }
            if iterations - first >= opts.max_iterations {
                return Err(SolveError::NoConvergence { iterations, residual: r, tolerance: tol.max(floor) });
            }
            if interrupted() {
                return Err(SolveError::Interrupted { iterations });
            }
            iterations += 1;
            // Newton direction: (-K) dx = f.
            model.gather_free(&ws.force, &mut ws.rhs);
            model.assemble_jacobians(&x, &mut ws.k, &mut ws.d);
            model.system_values(0.0, 0.0, -1.0, &ws.k, &ws.d, &mut ws.a_values);
            model.factor(&mut ws.ldl, &ws.a_values)?;
            ws.ldl.solve_in_place(&mut ws.rhs);
            // Backtracking line search on the residual norm.
            let mut alpha = 1.0;
            loop {
                for (fi, &node) in model.free_nodes.iter().enumerate() {
                    trial[node] = x[node] + alpha * ws.rhs[model.node_pos[fi]];
                }
                let rt = residual(model, &trial, applied, lam, &mut ws);
                if rt < r || alpha < 1e-4 {
                    r = rt;
                    break;
                }
                alpha *= 0.5;
            }
            x.copy_from_slice(&trial);
            // `ws.force` now holds the residual at the accepted point.
        }
    }
    Ok(StaticSolution { x, iterations, residual: r })
}
