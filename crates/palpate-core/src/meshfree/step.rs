//! The particle step: validation, the Verlet sub-steps of the hot loop ([`super::pair_loop`]) and
//! the rollback of a failed step; the same shape as the FEM's [`crate::step`].

use super::model::ParticleModel;
use super::pair_loop::{self, p4};
use super::state::{ParticleState, ParticleStepReport, ParticleWorkspace};
use crate::error::StepError;
use crate::math::is_finite3;

/// Advance by `dt` \[s\] with the position-Verlet scheme of eq. (33), in as many equal
/// sub-steps as stability needs ([`ParticleModel::substeps`]), only over the active particles.
///
/// Eq. (33), `x+ = 2x - x- + dt^2 F/m`, is run in its velocity form (`v+1/2 = v-1/2 + dt F/m`,
/// `x+ = x + dt v+1/2`: algebraically the same sequence of positions), which lets the sub-step
/// size change between calls and gives the viscous stress a velocity. Inactive particles are
/// frozen: they shape their active neighbours' deformation gradients but do not move.
/// Errors leave the state unchanged.
pub fn step(model: &ParticleModel, state: &mut ParticleState, ws: &mut ParticleWorkspace, dt: f64) -> Result<ParticleStepReport, StepError> {
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(StepError::BadTimeStep(dt));
    }
    step_with_substeps(model, state, ws, dt, model.substeps(dt))
}

/// [`step`] with a caller-chosen number of sub-steps (for stability studies
/// and benchmarks; fewer than [`ParticleModel::substeps`] may be unstable).
pub fn step_with_substeps(model: &ParticleModel, state: &mut ParticleState, ws: &mut ParticleWorkspace, dt: f64, substeps: usize) -> Result<ParticleStepReport, StepError> {
    if !(dt > 0.0 && dt.is_finite()) || substeps == 0 {
        return Err(StepError::BadTimeStep(dt));
    }
    let n = model.n_particles();
    if state.x.len() != n || state.v.len() != n || state.f_ext.len() != n {
        return Err(StepError::StateShape { nodes: n, x: state.x.len(), v: state.v.len(), f_ext: state.f_ext.len() });
    }
    if ws.len() != n {
        return Err(StepError::WorkspaceShape { nodes: n, workspace: ws.len() });
    }
    for &i in &state.active {
        if i >= n {
            return Err(StepError::ActiveOutOfRange { index: i, n });
        }
        if !is_finite3(&state.f_ext[i]) {
            return Err(StepError::NonFiniteForce { node: i });
        }
    }
    ws.save.clear();
    ws.save.extend(state.active.iter().map(|&i| (state.x[i], state.v[i])));
    // Displacements of the active particles and their (possibly frozen) neighbours, and the
    // list of those particles (each once: `mark` holds a per-call stamp).
    ws.stamp = ws.stamp.wrapping_add(1);
    ws.touched.clear();
    for &i in &state.active {
        for &j in std::iter::once(&i).chain(model.neighbours(i)) {
            if ws.mark[j] != ws.stamp {
                ws.mark[j] = ws.stamp;
                ws.touched.push(j);
                ws.u[j] = p4(&(state.x[j] - model.rest[j]));
                ws.v[j] = p4(&state.v[j]);
            }
        }
    }
    let h = dt / substeps as f64;
    pair_loop::run_substeps(model, state, ws, h, substeps);
    let bad = state.active.iter().copied().find(|&i| !is_finite3(&state.x[i]) || !is_finite3(&state.v[i]));
    if let Some(node) = bad {
        for (k, &i) in state.active.iter().enumerate() {
            (state.x[i], state.v[i]) = ws.save[k];
        }
        return Err(StepError::NonFinite { what: "particle position or velocity", node, time: state.t });
    }
    state.t += dt;
    Ok(ParticleStepReport { substeps, substep_dt: h })
}
