//! Time integrators (paper §5) and the static equilibrium solve.
//!
//! | integrator | per step | use |
//! |---|---|---|
//! | [`Integrator::SemiImplicit`] | explicit forces, then each node's velocity filtered by its own 3x3 block `(I - dt^2/m J_F)^-1` precomputed at rest (eq. 34) | the paper's scheme: cheapest, stable, but over-damped on fine meshes |
//! | [`Integrator::BackwardEulerLinear`] | one sparse solve with `M - dt D0 - dt^2 K0`, the Jacobians at rest, factorised once per `dt` | accurate and fast for small and moderate deformation |
//! | [`Integrator::BackwardEulerNewton`] | Newton iterations of backward Euler with the tangent at the current state, refactorised each iteration | large deformation |
//!
//! All take the state at `t` to `t + dt` with `f_ext` held constant, keep fixed nodes at their
//! position with zero velocity, allocate nothing after the first step, and never leave a
//! non-finite state behind: the state is restored and [`StepError::NonFinite`] names the node.

mod backward_euler;
mod semi_implicit;
mod statics;

pub use statics::{static_solve, StaticOptions, StaticSolution};

use crate::error::StepError;
use crate::math::is_finite3;
use crate::scene::{Model, State, Workspace};

/// Choice of time integrator (see the module table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Integrator {
    /// The paper's semi-implicit scheme (eq. 34) with the per-node Jacobian block at rest.
    SemiImplicit,
    /// Backward Euler, linearised at rest: one factorisation per time step size.
    BackwardEulerLinear,
    /// Backward Euler solved by Newton's method with the current tangent.
    BackwardEulerNewton {
        /// Iteration cap per step (the step is accepted and reported unconverged after it).
        max_iterations: usize,
        /// Relative reduction of the residual norm that ends the iterations.
        tolerance: f64,
    },
}

impl Integrator {
    /// Newton backward Euler with defaults suited to haptic rates (8 iterations, 1e-8).
    pub fn newton() -> Integrator {
        Integrator::BackwardEulerNewton { max_iterations: 8, tolerance: 1e-8 }
    }

    pub(crate) fn validate(&self) -> Result<(), String> {
        if let Integrator::BackwardEulerNewton { max_iterations, tolerance } = *self {
            if max_iterations == 0 {
                return Err("Newton max_iterations must be at least 1".into());
            }
            if !(tolerance > 0.0 && tolerance < 1.0) {
                return Err(format!("Newton tolerance {tolerance} must lie in (0, 1)"));
            }
        }
        Ok(())
    }
}

/// What a step did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepReport {
    /// Linear solves performed (0 for the semi-implicit scheme).
    pub solves: usize,
    /// Whether the nonlinear iterations met their tolerance (always true for one-shot schemes).
    pub converged: bool,
    /// Final relative residual of the Newton iterations (0 for one-shot schemes).
    pub residual: f64,
}

/// Advance `state` by `dt` \[s\] with the model's integrator.
///
/// Errors leave `state` as it was: a non-positive or non-finite `dt`, a non-finite external
/// force, a failed factorisation, or a non-finite result (reported with the first bad node).
pub fn step(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64) -> Result<StepReport, StepError> {
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(StepError::BadTimeStep(dt));
    }
    let n = model.n_nodes();
    if state.x.len() != n || state.v.len() != n || state.f_ext.len() != n {
        return Err(StepError::StateShape { nodes: n, x: state.x.len(), v: state.v.len(), f_ext: state.f_ext.len() });
    }
    if let Some(node) = state.f_ext.iter().position(|f| !is_finite3(f)) {
        return Err(StepError::NonFiniteForce { node });
    }
    ws.x_save.copy_from_slice(&state.x);
    ws.v_save.copy_from_slice(&state.v);
    let result = match model.integrator {
        Integrator::SemiImplicit => Ok(semi_implicit::step(model, state, ws, dt)),
        Integrator::BackwardEulerLinear => backward_euler::step_linear(model, state, ws, dt),
        Integrator::BackwardEulerNewton { max_iterations, tolerance } => {
            backward_euler::step_newton(model, state, ws, dt, max_iterations, tolerance)
        }
    };
    let bad = match &result {
        Ok(_) => state
            .x
            .iter()
            .position(|x| !is_finite3(x))
            .map(|n| ("position", n))
            .or_else(|| state.v.iter().position(|v| !is_finite3(v)).map(|n| ("velocity", n))),
        Err(_) => None,
    };
    if result.is_err() || bad.is_some() {
        state.x.copy_from_slice(&ws.x_save);
        state.v.copy_from_slice(&ws.v_save);
    }
    let report = result?;
    if let Some((what, node)) = bad {
        return Err(StepError::NonFinite { what, node, time: state.t });
    }
    state.t += dt;
    Ok(report)
}
