//! Backward (implicit) Euler: find `v+` with
//!
//! ```text
//! M (v+ - v) = dt f(x + dt v+, v+),     x+ = x + dt v+,
//! ```
//!
//! `f` the internal (elastic + viscous) plus applied forces. With `K = df/dx`, `D = df/dv`:
//!
//! * **linearised at rest** (`BackwardEulerLinear`, Baraff & Witkin 1998 with `K0`, `D0` at rest):
//!   `(M - dt D0 - dt^2 K0) v+ = M v + dt (f(x, v) - D0 v)`. The matrix depends only on `dt`, so
//!   it is factorised once and each step costs one force evaluation and one pair of sparse
//!   triangular solves. At a fixed point `v+ = v = 0` the equation reduces to `f(x) = 0` with the
//!   full nonlinear force, so steady states are exact equilibria whatever the linearisation.
//! * **Newton** (`BackwardEulerNewton`): iterate `(M - dt D(x~) - dt^2 K(x~)) dv = -r(v+)` on the
//!   residual `r(v+) = M (v+ - v) - dt f(x + dt v+, v+)`, with the tangent at `x~ = x + dt v+`,
//!   refactorised every iteration (the pattern and ordering are reused). The iterations stop when
//!   `|r| <= tolerance (|r_0| + |(M v, dt f_applied)|)`: relative to the momenta that make up the
//!   residual, so that a step near equilibrium does not chase round-off.

use crate::error::{SolveError, StepError};
use crate::math::Vec3;
use crate::scene::{Model, State, Workspace};
use crate::StepReport;

pub(super) fn step_linear(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64) -> Result<StepReport, StepError> {
    if ws.factored_dt != dt {
        model.system_values(1.0, -dt, -dt * dt, &model.k0, &model.d0, &mut ws.a_values);
        model.factor(&mut ws.ldl, &ws.a_values)?;
        ws.factored_dt = dt;
    }
    model.internal_forces(&state.x, Some(&state.v), &mut ws.force);
    model.add_applied(&state.f_ext, &mut ws.force);
    let damped = !model.material.is_undamped();
    let p = &model.pattern;
    for (fi, &node) in model.free_nodes.iter().enumerate() {
        let mut b = model.mass[node] * state.v[node] + dt * ws.force[node];
        if damped {
            // - dt D0 v, over the free neighbours (fixed nodes have zero velocity).
            let mut dv = Vec3::zeros();
            for k in p.row_ptr[fi]..p.row_ptr[fi + 1] {
                dv += model.d0[k] * state.v[model.free_nodes[p.col[k]]];
            }
            b -= dt * dv;
        }
        ws.rhs[model.node_pos[fi]] = b;
    }
    ws.ldl.solve_in_place(&mut ws.rhs);
    for (fi, &node) in model.free_nodes.iter().enumerate() {
        let v = ws.rhs[model.node_pos[fi]];
        state.v[node] = v;
        state.x[node] += dt * v;
    }
    Ok(StepReport { solves: 1, converged: true, residual: 0.0 })
}

/// Residual `r = M (v~ - v) - dt f(x + dt v~, v~)` of the free nodes, written negated into `ws.rhs`
/// (the right-hand side of the Newton update); returns `|r|`.
fn residual(model: &Model, state: &State, ws: &mut Workspace, dt: f64) -> f64 {
    for &node in &model.free_nodes {
        ws.x_trial[node] = state.x[node] + dt * ws.v_trial[node];
    }
    model.internal_forces(&ws.x_trial, Some(&ws.v_trial), &mut ws.force);
    model.add_applied(&state.f_ext, &mut ws.force);
    let mut norm2 = 0.0;
    for (fi, &node) in model.free_nodes.iter().enumerate() {
        let r = model.mass[node] * (ws.v_trial[node] - state.v[node]) - dt * ws.force[node];
        norm2 += r.norm_squared();
        ws.rhs[model.node_pos[fi]] = -r;
    }
    norm2.sqrt()
}

pub(super) fn step_newton(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    dt: f64,
    max_iterations: usize,
    tolerance: f64,
) -> Result<StepReport, StepError> {
    ws.v_trial.copy_from_slice(&state.v);
    ws.x_trial.copy_from_slice(&state.x);
    let r0 = residual(model, state, ws, dt);
    // The residual is a difference of momenta; measure it against the momenta that make it up
    // (not r0 alone, which is ~0 near equilibrium and would ask for accuracy below round-off).
    let mut scale2 = 0.0;
    for &node in &model.free_nodes {
        let m = model.mass[node];
        scale2 += (m * state.v[node]).norm_squared() + (dt * (state.f_ext[node] + m * model.gravity)).norm_squared();
    }
    let scale = r0 + scale2.sqrt();
    let mut r = r0;
    let mut solves = 0;
    while r > tolerance * scale && solves < max_iterations {
        if !r.is_finite() {
            let node = model.free_nodes.iter().copied().find(|&i| !crate::math::is_finite3(&ws.force[i])).unwrap_or(0);
            return Err(StepError::Solve(SolveError::NonFinite { what: "Newton residual", node }));
        }
        // Tangent at the current iterate (x_trial was set by `residual`).
        model.assemble_jacobians(&ws.x_trial, &mut ws.k, &mut ws.d);
        model.system_values(1.0, -dt, -dt * dt, &ws.k, &ws.d, &mut ws.a_values);
        model.factor(&mut ws.ldl, &ws.a_values)?;
        ws.ldl.solve_in_place(&mut ws.rhs);
        for (fi, &node) in model.free_nodes.iter().enumerate() {
            ws.v_trial[node] += ws.rhs[model.node_pos[fi]];
        }
        solves += 1;
        r = residual(model, state, ws, dt);
    }
    ws.factored_dt = f64::NAN; // the factors now hold a tangent, not a rest matrix
    for &node in &model.free_nodes {
        state.v[node] = ws.v_trial[node];
        state.x[node] += dt * ws.v_trial[node];
    }
    let rel = if scale > 0.0 { r / scale } else { 0.0 };
    Ok(StepReport { solves, converged: r <= tolerance * scale, residual: rel })
}
