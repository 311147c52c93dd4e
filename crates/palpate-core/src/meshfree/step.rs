//! The particle step: validation, the Verlet sub-steps of the hot loop ([`super::pair_loop`]) and
//! the rollback of a failed step; the same shape as the FEM's [`crate::step`].

use super::model::ParticleModel;
use super::pair_loop::{self, p4, ExtForce};
use super::state::{ParticleState, ParticleStepReport, ParticleWorkspace, SubStep};
use crate::error::StepError;
use crate::math::{is_finite3, Vec3};
use crate::parallel::{Fork, Serial};

/// Advance by `dt` \[s\] with the position-Verlet scheme of eq. (33), in as many equal
/// sub-steps as stability needs ([`ParticleModel::substeps`]), only over the active particles.
///
/// Eq. (33), `x+ = 2x - x- + dt^2 F/m`, is run in its velocity form (`v+1/2 = v-1/2 + dt F/m`,
/// `x+ = x + dt v+1/2`: algebraically the same sequence of positions), which lets the sub-step
/// size change between calls and gives the viscous stress a velocity. Inactive particles are
/// frozen: they shape their active neighbours' deformation gradients but do not move; the
/// forces the active particles exert on them (and on fixed active particles) are reported in
/// [`ParticleWorkspace::ring_forces`] when the workspace asks for them. Errors leave the state
/// unchanged.
pub fn step(model: &ParticleModel, state: &mut ParticleState, ws: &mut ParticleWorkspace, dt: f64) -> Result<ParticleStepReport, StepError> {
    if !(dt > 0.0 && dt.is_finite()) {
        ws.ring.clear();
        ws.ring_force.clear();
        return Err(StepError::BadTimeStep(dt));
    }
    step_with_substeps(model, state, ws, dt, model.substeps(dt))
}

/// [`step`] with a caller-chosen number of sub-steps (for stability studies
/// and benchmarks; fewer than [`ParticleModel::substeps`] may be unstable).
///
/// After a successful step with the ring turned on ([`ParticleWorkspace::set_ring_forces`]),
/// [`ParticleWorkspace::ring`] and [`ParticleWorkspace::ring_forces`] give the forces the active
/// particles exerted on the particles the step does not move.
///
/// **Sub-stepping from outside.** `k` calls with `(h, 1)` run the same leapfrog sequence as one
/// call with `(k h, k)`, but are equal only to round-off, not bitwise: each call re-derives the
/// displacements `u = x - X` from positions stored as `X + u` (one rounding per particle per call),
/// and adds `h` to `t` `k` times. They also repeat the per-call work (validation, the neighbour
/// scan of the active set, the ring set-up) `k` times. A caller whose forces depend on the state
/// at every sub-step should use [`step_with`], which is exactly this function's loop.
pub fn step_with_substeps(
    model: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    dt: f64,
    substeps: usize,
) -> Result<ParticleStepReport, StepError> {
    advance(model, state, ws, dt, substeps, None, &Serial)
}

/// [`step_with_substeps`] with external forces that the caller recomputes before each sub-step
/// (tool contact, coupling springs, confinement: forces of the current positions and velocities).
///
/// Before sub-step `s`, `external(&sub, f)` is called with the state at its start ([`SubStep`]:
/// positions, leapfrog velocities `v_{s-1/2}`, the active list, `t` and `h`) and `f`
/// `(n_particles)` holding `state.f_ext` on the active particles; the sub-step applies `f` (plus
/// gravity) to the free active particles, as `state.f_ext` in [`step_with_substeps`]. Entries
/// of inactive or fixed particles are ignored; `state.f_ext` itself is not changed. A callback
/// that leaves `f` as it found it gives bitwise the result of [`step_with_substeps`].
///
/// The callback must not allocate for the step to stay allocation-free. Non-finite forces it
/// returns make the step fail (non-finite state) and leave the state unchanged.
pub fn step_with<E>(
    model: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    dt: f64,
    substeps: usize,
    mut external: E,
) -> Result<ParticleStepReport, StepError>
where
    E: FnMut(&SubStep<'_>, &mut [Vec3]),
{
    advance(model, state, ws, dt, substeps, Some(&mut external), &Serial)
}

/// [`step_with`] with the passes of each sub-step split over the caller's threads (`fork`, see
/// [`crate::parallel`]): bitwise the same result. The callback runs on the calling thread,
/// between the passes.
pub fn step_with_fork<E>(
    model: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    dt: f64,
    substeps: usize,
    fork: &dyn Fork,
    mut external: E,
) -> Result<ParticleStepReport, StepError>
where
    E: FnMut(&SubStep<'_>, &mut [Vec3]),
{
    advance(model, state, ws, dt, substeps, Some(&mut external), fork)
}

/// The most particle-sub-steps one step may take (active particles x sub-steps, about a second
/// of work), and the sub-step cap never goes below [`MIN_SUBSTEP_CAP`].
pub const MAX_PARTICLE_SUBSTEPS: usize = 100_000_000;
pub const MIN_SUBSTEP_CAP: usize = 1000;

fn advance(
    model: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    dt: f64,
    substeps: usize,
    external: Option<ExtForce<'_>>,
    fork: &dyn Fork,
) -> Result<ParticleStepReport, StepError> {
    // A ring left from an earlier step must not be mistaken for this one's if this one fails.
    ws.ring.clear();
    ws.ring_force.clear();
    if !(dt > 0.0 && dt.is_finite()) || substeps == 0 {
        return Err(StepError::BadTimeStep(dt));
    }
    // Bounded work per step: a dt of 1e3 s (or a stiffness of 1e150 Pa) asks for 1e8+ sub-steps,
    // minutes with no answer. The cap is on particle-sub-steps (about a second of work); the
    // stable count saturates at usize::MAX when the stable dt underflows, and is refused too.
    let cap = (MAX_PARTICLE_SUBSTEPS / state.active.len().max(1)).max(MIN_SUBSTEP_CAP);
    if substeps > cap {
        let wanted = if substeps == usize::MAX { dt / model.stable_dt() } else { substeps as f64 };
        return Err(StepError::TooManySubsteps { dt, stable_dt: model.stable_dt(), substeps: wanted, cap });
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
    touch(model, state, ws);
    let h = dt / substeps as f64;
    // The physical speed bound (crate::divergence), checked every sub-step inside the loop.
    let diverging = pair_loop::run_substeps(model, state, ws, h, substeps, external, fork);
    let bad = state.active.iter().copied().find(|&i| !is_finite3(&state.x[i]) || !is_finite3(&state.v[i]));
    if let Some(node) = bad {
        for (k, &i) in state.active.iter().enumerate() {
            (state.x[i], state.v[i]) = ws.save[k];
        }
        ws.ring.clear();
        ws.ring_force.clear();
        return Err(StepError::NonFinite { what: "particle position or velocity", node, time: state.t });
    }
    // Finite but past the physical speed bound: a divergence starting (crate::divergence),
    // restored and reported as a non-finite step is.
    if let Some((node, speed)) = diverging {
        for (k, &i) in state.active.iter().enumerate() {
            (state.x[i], state.v[i]) = ws.save[k];
        }
        ws.ring.clear();
        ws.ring_force.clear();
        let bound = crate::divergence::speed_bound(&model.material);
        return Err(StepError::Diverging { what: "particle velocity", node, speed, bound, time: state.t });
    }
    state.t += dt;
    Ok(ParticleStepReport { substeps, substep_dt: h })
}

/// The particles a call reads, each once (`ws.touched`), with their displacements and
/// velocities loaded: the active particles, the ring (`ws.ring`: their inactive neighbours, then
/// the fixed active particles), the ring's other inactive neighbours (which the ring's gather
/// reads: they must carry `B = 0`, `gamma = 0` and a current displacement, not a stale one), and
/// the rim (`ws.rim`: the active particles that gather reads); the last three only when the
/// ring is on. `mark` holds per-call stamps, so nothing is cleared per particle: with the ring
/// off, or empty, the extra cost over the old scan is one or two passes over the active list.
fn touch(model: &ParticleModel, state: &ParticleState, ws: &mut ParticleWorkspace) {
    let base = ws.stamp;
    let (active, rim, ring, outer) = (base.wrapping_add(1), base.wrapping_add(2), base.wrapping_add(3), base.wrapping_add(4));
    ws.stamp = outer;
    ws.touched.clear();
    ws.rim.clear();
    let load = |ws: &mut ParticleWorkspace, j: usize| {
        ws.touched.push(j);
        ws.u[j] = p4(&(state.x[j] - model.rest[j]));
        ws.v[j] = p4(&state.v[j]);
    };
    ws.unique = true;
    for &i in &state.active {
        if ws.mark[i] != active {
            ws.mark[i] = active;
            load(ws, i);
        } else {
            ws.unique = false;
        }
    }
    for &i in &state.active {
        for &j in model.neighbours(i) {
            if ws.mark[j] != active && ws.mark[j] != ring && ws.mark[j] != rim {
                ws.mark[j] = ring;
                load(ws, j);
                if ws.ring_on {
                    ws.ring.push(j);
                }
            }
        }
    }
    if !ws.ring_on {
        return;
    }
    for &i in &state.active {
        if model.fixed[i] && ws.mark[i] == active {
            ws.mark[i] = rim;
            ws.rim.push(i);
            ws.ring.push(i);
        }
    }
    for r in 0..ws.ring.len() {
        let r = ws.ring[r];
        for &j in model.neighbours(r) {
            let mj = ws.mark[j];
            if mj == active {
                ws.mark[j] = rim;
                ws.rim.push(j);
            } else if mj != rim && mj != ring && mj != outer {
                ws.mark[j] = outer;
                load(ws, j);
            }
        }
    }
}
