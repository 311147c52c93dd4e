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
//! as implicitly as stiffness.
//!
//! Properties, measured (tests/dynamics.rs, BENCHMARKS.md):
//! * **Not unconditionally stable.** The filter stabilises each node against its own stiffness
//!   with its neighbours held fixed; the coupling to the neighbours stays explicit. The step is
//!   stable while `dt^2 lambda_max(M^-1 K)` stays within about `2 dt^2 k_ii/m + 4`: true at 1 ms on
//!   the benchmark's lv_190 .. lv_10k meshes (spectral radius 0.993 on lv_190, 0.998 on lv_1350)
//!   but not on the 48k-tet mesh nor on the default truncated wall generator (radius 1.32), and
//!   damping makes it worse.
//! * **Over-damped on fine meshes.** Every mode is damped by about `1/(1 + dt^2 k_ii/m)` per step
//!   and `k_ii/m ~ 1/h^2`, so on finer meshes the motion creeps toward equilibrium and lags behind it.
//! * **Does not conserve linear momentum**: each node's velocity is scaled by its own matrix, so
//!   even a rigid translation is slowed.
//!
//! Backward Euler (`BackwardEulerLinear`) has none of these defects at a similar cost on small
//! meshes; the semi-implicit scheme is kept as the paper's reference.

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
