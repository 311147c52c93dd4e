//! Newton backward Euler: the minimisation of the incremental potential (`potential.rs`) by
//! Newton's method, the accurate reference of the benchmark.
//!
//! Each iteration assembles the tangent Hessian `H(x) = M / h^2 - K(x) + d^2 D / dx^2` on the
//! free pattern (the elastic law's exact Jacobian, `fem/tet4.rs`, and the dissipation's,
//! `fem/viscous.rs`) and solves `H d = -grad Phi` by conjugate gradients preconditioned by the
//! factorised rest matrix `H0` (the one the linearised and quasi-Newton steps use): no
//! refactorisation per iteration (the preconditioner is refreshed at the deformed state by the
//! quasi-Newton integrator's rule, `quasi_newton.rs`, when the CG iterations it saves pay for the
//! factorisation). Inexact Newton: the CG stops at a relative residual
//! `eta = min(0.5, sqrt(|g| / scale))` (Eisenstat and Walker 1996), which tightens as the
//! iterations converge. Where St. Venant-Kirchhoff's tangent is indefinite (compression), the CG
//! is truncated at the first direction of non-positive curvature (Steihaug 1983): its iterate so
//! far, or the preconditioned gradient, is a descent direction. The same Armijo line search as
//! the quasi-Newton step then guarantees the potential decreases.

use super::factor;
use super::potential::{self, dot, Progress, StepProblem};
use crate::fem::model::NONE;
use crate::fem::{tet10, tet4, viscous, Model, Workspace};
use crate::linalg::cg::{self, CgStop, CgWork};
use crate::math::{Mat3, Vec3};

/// Conjugate-gradient iterations per Newton iteration, at most.
const MAX_CG: usize = 200;

/// Free-node vectors of the preconditioned conjugate gradients, the right-hand side and the
/// Newton direction.
#[derive(Debug, Clone)]
pub(crate) struct CgWorkspace {
    work: CgWork<Vec3>,
    rhs: Vec<Vec3>,
    /// The Newton direction.
    d: Vec<Vec3>,
}

impl CgWorkspace {
    pub fn new(nf: usize) -> CgWorkspace {
        CgWorkspace { work: CgWork::new(nf), rhs: vec![Vec3::zeros(); nf], d: vec![Vec3::zeros(); nf] }
    }
}

/// Hessian blocks of `W + D` at `x` on the free pattern (the mass term is added in `hess_mul`).
fn assemble_hessian(p: &StepProblem, x: &[Vec3], blocks: &mut [Mat3]) {
    let model = p.model;
    blocks.iter_mut().for_each(|b| *b = Mat3::zeros());
    let damped = !model.material.is_undamped();
    if let Some(q) = &model.quadratic {
        for ((e, r), tb) in q.elements.iter().zip(&q.rest).zip(&q.blocks) {
            let xe = e.map(|i| x[i]);
            let (k, _) = tet10::jacobians(&xe, r, &model.material);
            let dh = damped.then(|| tet10::step_dissipation_hessian(&xe, &e.map(|i| p.x_n[i]), r, &model.material, p.h));
            for (j, &bi) in tb.iter().enumerate() {
                if bi != NONE {
                    blocks[bi] -= k[j / 10][j % 10];
                    if let Some(dh) = &dh {
                        blocks[bi] += dh[j / 10][j % 10];
                    }
                }
            }
        }
    }
    for ((t, r), tb) in model.mesh.tets().iter().zip(&model.rest).zip(&model.tet_blocks) {
        let xe = t.map(|i| x[i]);
        let (k, _) = tet4::jacobians(&xe, r, &model.material);
        let dh = damped.then(|| viscous::step_dissipation_hessian(&xe, &t.map(|i| p.x_n[i]), r, &model.material, p.h));
        for e in 0..16 {
            let bi = tb[e];
            if bi != NONE {
                blocks[bi] -= k[e / 4][e % 4];
                if let Some(dh) = &dh {
                    blocks[bi] += dh[e / 4][e % 4];
                }
            }
        }
    }
}

/// `y = (M / h^2 + blocks) v` over the free nodes.
fn hess_mul(model: &Model, blocks: &[Mat3], inv_h2: f64, v: &[Vec3], y: &mut [Vec3]) {
    let pat = &model.pattern;
    for (fi, &node) in model.free_nodes.iter().enumerate() {
        let mut s = (model.mass[node] * inv_h2) * v[fi];
        for k in pat.row_ptr[fi]..pat.row_ptr[fi + 1] {
            s += blocks[k] * v[pat.col[k]];
        }
        y[fi] = s;
    }
}

/// Truncated preconditioned CG (`linalg::cg`) for `H d = -g` into `cg.d`, to a relative
/// residual `eta`; returns the preconditioner applications. At a direction of non-positive
/// curvature the iterate so far is kept, or, at the first, the preconditioned gradient.
fn newton_direction(model: &Model, ws: &mut Workspace, cg: &mut CgWorkspace, g: &[Vec3], eta: f64, h: f64) -> usize {
    let inv_h2 = 1.0 / (h * h);
    let CgWorkspace { work, rhs, d } = cg;
    for (bi, gi) in rhs.iter_mut().zip(g) {
        *bi = -gi;
    }
    d.iter_mut().for_each(|v| *v = Vec3::zeros());
    // The Hessian blocks are read by the operator while the preconditioner refreshes nothing
    // but needs the workspace's factor: take the blocks out for the solve (no allocation).
    let blocks = std::mem::take(&mut ws.k);
    let mut solves = 0;
    let rep = cg::solve(
        |v, y| hess_mul(model, &blocks, inv_h2, v, y),
        |r, z| {
            factor::apply_inverse(model, ws, r, z, h);
            solves += 1;
        },
        rhs,
        d,
        work,
        CgStop { tolerance: eta, max_iterations: MAX_CG },
    );
    ws.k = blocks;
    if rep.breakdown && rep.iterations == 0 {
        d.copy_from_slice(&work.z); // preconditioned steepest descent
    }
    solves
}

/// One step's Newton iterations (run inside [`potential::minimise`]); returns the surplus
/// preconditioner applications and whether the step struggled, for the refresh rule (`factor.rs`).
pub(super) fn iterate(p: &StepProblem, x: &mut [Vec3], x_trial: &mut [Vec3], ws: &mut Workspace, pr: &mut Progress, max_iterations: usize) -> (usize, bool) {
    let model = p.model;
    let h = p.h;
    let mut cg = std::mem::replace(&mut ws.cg, CgWorkspace::new(0));
    let free_body = model.is_free_body();
    while pr.iterations < max_iterations && (pr.iterations == 0 || !pr.converged()) {
        let mut blocks = std::mem::take(&mut ws.k);
        assemble_hessian(p, x, &mut blocks);
        ws.k = blocks;
        let eta = pr.relative_gradient(0.25);
        let g = std::mem::take(&mut ws.potential.g);
        pr.solves += newton_direction(model, ws, &mut cg, &g, eta, h);
        if free_body && p.external.is_none_or(|e| e.translation_invariant()) {
            potential::exact_translation(model, &g, &mut cg.d, h);
        }
        let gd = dot(&g, &cg.d);
        ws.potential.g = g;
        if !(gd < 0.0) {
            break;
        }
        let Some((e, _)) = potential::line_search(p, &mut ws.potential, x, x_trial, &cg.d, &pr.cur, gd, &mut pr.evaluations) else {
            break;
        };
        pr.accept(e);
    }
    ws.cg = cg;
    // The preconditioner is refreshed by the quasi-Newton rule: the preconditioner applications
    // beyond one per Newton iteration count as surplus, and once they have cost a factorisation
    // the factor is redone with the definite tangent at the end state.
    let n = pr.iterations.max(1);
    (pr.solves.saturating_sub(n), pr.solves >= 2 * n)
}
