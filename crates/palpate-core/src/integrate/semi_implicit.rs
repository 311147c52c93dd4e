//! The paper's semi-implicit scheme, eq. (34), after Debunne et al. 2001:
//!
//! ```text
//! v~      = v_t + dt F / m
//! v_t+dt  = (I - dt^2/m J_F)^-1 v~          (per node: J_F = d f_i / d x_i at rest, 3x3)
//! x_t+dt  = x_t + dt v_t+dt
//! ```
//!
//! `J_F` is the node's own diagonal block of the force Jacobian at rest "assuming its neighbours
//! are fixed", precomputed once ([`crate::Model::node_jacobians`]). It is negative semi-definite,
//! so `I - dt^2/m J_F` is positive definite (the paper's README notes the sign). palpate adds the
//! viscous block in the same way, `(I - dt/m D_ii - dt^2/m J_ii)^-1`, so that damping is treated
//! as implicitly as stiffness. The per-node filter is unconditionally stable for the local
//! oscillation but damps every mode by `1/(1 + dt^2 k_ii/m)` per step, a factor that grows as the
//! mesh is refined (`k_ii/m ~ 1/h^2`): on fine meshes the scheme is over-damped and lags behind the
//! equilibrium (measured in BENCHMARKS.md).

use crate::math::Mat3;
use crate::scene::{Model, State, Workspace};

pub(super) fn step(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64) -> crate::StepReport {
    if ws.factored_dt != dt {
        for i in 0..model.n_nodes() {
            let m = model.mass[i];
            let a = Mat3::identity() - (dt / m) * model.node_d0[i] - (dt * dt / m) * model.node_k0[i];
            ws.node_inv[i] = a.try_inverse().unwrap_or_else(Mat3::identity);
        }
        ws.factored_dt = dt;
    }
    model.internal_forces(&state.x, Some(&state.v), &mut ws.force);
    model.add_applied(&state.f_ext, &mut ws.force);
    for i in 0..model.n_nodes() {
        if model.fixed[i] {
            state.v[i].fill(0.0);
            continue;
        }
        let v_tilde = state.v[i] + ws.force[i] * (dt / model.mass[i]);
        state.v[i] = ws.node_inv[i] * v_tilde;
        state.x[i] += dt * state.v[i];
    }
    crate::StepReport { solves: 0, converged: true, residual: 0.0 }
}
