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
//!
//! The linearisation holds only near rest: under a firm press (1 N on the benchmark ventricle) the
//! rest stiffness no longer bounds the true one and the step blows up. The minimising integrators
//! (`quasi_newton.rs`, `newton.rs`) solve the same equation without that limit, and reuse this
//! factorisation as their initial Hessian and preconditioner.

use crate::error::StepError;
use crate::fem::{Model, State, Workspace};
use crate::math::Vec3;
use crate::StepReport;

pub(super) fn step_linear(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64) -> Result<StepReport, StepError> {
    super::factor::ensure(model, ws, dt)?;
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
    Ok(StepReport { iterations: 1, evaluations: 1, solves: 1, converged: true, ..StepReport::default() })
}
