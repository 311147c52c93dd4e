//! The one ordered tick of the hybrid model (paper §5-§7): tool in, force out. This file
//! orchestrates; each stage is a function in its own file:
//!
//! 1. **Activation** (`activate::activate`, §6): the regions the tool touches, their particles
//!    in and out of the active set, the core under them at the build's active factor.
//! 2. **The ring follows the core** (`activate::follow_core`): the inactive neighbours of the
//!    active particles at their ties; they bound the active region and take its reactions.
//! 3. **Particle sub-steps** (`shell::step`): Verlet, as many as the shell's stability needs,
//!    with the coupling springs, the tool on the skin over the particles and the confinement wall
//!    before each; the skin within the tool's reach as lists of particles
//!    (`super::skin::near_tool`). A step that fails sheds the shell and the tick goes on with
//!    the core and the skin ([`super::SimOptions::shell_fallback`]): the hand keeps feeling the
//!    organ, the skin the particles carried fading back to its ties over 50 ticks (measured on
//!    the synthetic ventricle's 18 shed presses, `examples/press_sweep.rs`: the force changes by
//!    0.03-0.15 N in a tick at the switch).
//! 4. **Skin and core contact** where no particle carries the skin, and 5. **the core's step**
//!    (`core_step::step_core`): the contact inside the core's implicit step (held explicitly on
//!    the coarse core it chattered under a deep press), the core under the sub-step average of
//!    every reaction.
//! 6. **The skin** (`super::skin::update`) follows its core faces, and over active triangles
//!    the particles under it.
//!
//! The force does not depend on stage 6, nor on stage 5 when the tool has nothing of the core
//! within reach (the force is then the particles' alone, the common case of a palpation with the
//! shell on): [`tick_force_with`] leaves that work owed and [`finish_tick`] does it, so that a
//! haptic servo sends the force first. [`tick`] does both, and a tick pays what an earlier one
//! owes first: the trajectory is the same bit for bit however the work is split.
//!
//! Every force between two bodies is one of an equal and opposite pair and every tie spreads
//! a force into shares that sum to it, so with the tool away (and no confinement push) the total
//! linear momentum of the core and the active particles is conserved to round-off, and with the
//! tool its change is the tool's impulse (tests/runtime.rs); while the shell is off, to the core
//! step's tolerance (the contact is then part of the step's minimisation). A failed tick leaves
//! the core and the particles' motion as they were (see [`tick`]).

mod activate;
mod core_step;
mod shell;

pub use super::skin::{SKIN_LIVE_MARGIN, SKIN_SWEEP_TICKS};
pub use core_step::IMPLICIT_CONTACT_MARGIN;

use super::embed;
use super::sim::Sim;
use super::skin;
use super::state::{SimState, SimWorkspace};
use crate::error::StepError;
use crate::integrate::StepReport;
use crate::math::{is_finite3, Vec3};
use crate::meshfree;
use crate::parallel::{Fork, Serial};

/// What a tick did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickReport {
    /// Force on the tool \[N\], world frame: the reaction it must render (the tissue received the
    /// opposite), averaged over the tick.
    pub force: Vec3,
    /// Skin vertices refreshed away from the tool this tick (a slice of a sweep of the whole
    /// skin, or all of it at once: see `LiveSkin`); the ones near the tool are not counted.
    pub skin_refreshed: usize,
    /// Skin vertices in contact over active particles (most over the sub-steps; the particles
    /// under them carry the force), and those no particle carries (at their ties: the core
    /// takes the force, inside its step).
    pub particle_contacts: usize,
    pub skin_contacts: usize,
    /// 1 when the tool touches the core's surface (a press deeper than the shell), else 0: it
    /// meets the surface's point nearest its centre ([`super::core_contact`]).
    pub core_contacts: usize,
    /// Deepest penetration of the tool \[m\].
    pub max_depth: f64,
    /// Active particles, and how many entered and left this tick.
    pub active: usize,
    pub entered: usize,
    pub left: usize,
    /// Particle sub-steps taken.
    pub substeps: usize,
    /// Particles the confinement wall pushed (most over the sub-steps).
    pub confined: usize,
    /// The shell's step failed this tick (diverging or non-finite): the shell was shed and the
    /// tick went on with the core and the skin ([`super::SimOptions::shell_fallback`]).
    pub shell_failed: bool,
    /// The shell was off this tick (within its fallback's pause after a failure): the tool met
    /// the skin and the core only.
    pub shell_off: bool,
    /// The core's step.
    pub core: StepReport,
}

/// Advance the hybrid model by one tick of `dt` \[s\] with the device's tool centre at `tool`
/// \[m\] (world frame; the simulated tool moves toward it by at most
/// [`super::SimOptions::max_tool_speed`], and [`SimState::tool`] says where it is). Allocates nothing. A bad `dt` or tool position changes nothing. A failed,
/// non-finite or diverging (past the speed bound of [`crate::divergence`]) particle step sheds
/// the shell and the tick goes on ([`TickReport::shell_failed`]; with
/// [`super::SimOptions::shell_fallback`] `None` it fails instead). A failed core step (or a
/// failed particle step without the fallback) leaves the core and the particles' motion as they were at
/// the start of the tick, but the activation keeps this tick's update (the regions the tool
/// touched stay active, their particles at their ties).
pub fn tick(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace, tool: Vec3, dt: f64) -> Result<TickReport, StepError> {
    tick_with(sim, state, ws, tool, dt, &Serial)
}

/// [`tick`] with the particle passes split over the caller's threads (`fork`, see
/// [`crate::parallel`]): bitwise the same tick, sooner when the caller has a core to spare (the
/// haptic servo's pool). Everything else runs on the calling thread.
pub fn tick_with(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace, tool: Vec3, dt: f64, fork: &dyn Fork) -> Result<TickReport, StepError> {
    // A debt of an earlier split tick first, so that a failure below is this tick's own.
    finish_tick(sim, state, ws)?;
    let (tool0, ticks0) = (state.tool, state.ticks);
    let mut report = tick_force_with(sim, state, ws, tool, dt, fork)?;
    match finish_tick(sim, state, ws) {
        Ok(done) => {
            report.skin_refreshed = done.skin_refreshed;
            if let Some(core) = done.core {
                report.core = core;
            }
            Ok(report)
        }
        Err(e) => {
            // The owed core step failed: as a failed tick, the particles' motion back to the
            // tick's start (the workspace's save of this tick) and the tick not counted.
            undo_particles(&mut state.particles, &ws.save, dt);
            (state.tool, state.ticks) = (tool0, ticks0);
            Err(e)
        }
    }
}

/// The active particles' positions and velocities back to the tick's start (`save`, in the active
/// set's order) and the shell's clock back by `dt`: what a tick whose core step failed leaves.
fn undo_particles(particles: &mut meshfree::ParticleState, save: &[(Vec3, Vec3)], dt: f64) {
    for (&p, &(x, v)) in particles.active.iter().zip(save) {
        (particles.x[p], particles.v[p]) = (x, v);
    }
    particles.t -= dt;
}

/// What [`finish_tick`] did: the skin vertices refreshed away from the tool
/// ([`TickReport::skin_refreshed`]), and the core's step when it was owed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Finished {
    pub skin_refreshed: usize,
    pub core: Option<StepReport>,
}

/// Steps 1-5 of [`tick_with`] that the tick's force depends on; the rest is left owed, to be
/// paid by [`finish_tick`] once the force is on its way (a haptic servo sends the force first,
/// so that this work comes out of the tick's slack, not before its deadline):
/// - always the skin's update (step 6), which only the next tick's contact and the drawn surface
///   read: 40-90 us on the Rodero ventricle, and a slice of a sweep of the far skin when one runs;
/// - the core's step (step 5) when the tool has nothing of the core within reach (no skin vertex
///   at its tie, no core face: the force is then the particles' alone), the core stepping under
///   the reactions already gathered: the common case of a palpation with the shell on, ~20% of
///   the tick.
///
/// A tick that finds work still owed pays it first, so the trajectory is bitwise [`tick_with`]'s
/// whether or not the caller finishes. [`TickReport::skin_refreshed`] is 0 here, and
/// [`TickReport::core`] is the default when the core's step is owed: [`finish_tick`] returns
/// them. Errors as [`tick_with`]'s, and an owed core step of the previous tick that fails here
/// (see [`finish_tick`]).
pub fn tick_force_with(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace, tool: Vec3, dt: f64, fork: &dyn Fork) -> Result<TickReport, StepError> {
    finish_tick(sim, state, ws)?;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(StepError::BadTimeStep(dt));
    }
    if !is_finite3(&tool) {
        return Err(StepError::NonFiniteTool);
    }
    state.dt = dt;
    // The shell's clock is the core's (it advances only while particles are active).
    state.particles.t = state.core.t;
    // The core's face frames and their rates, once: every tie on a face shares them.
    embed::face_frames_and_rates(&state.core.x, &state.core.v, &sim.hybrid.core_faces, &mut ws.frames, &mut ws.rates);
    let o = &sim.options;
    let prev = state.tool.unwrap_or(tool);
    // The simulated tool follows the device at most at `max_tool_speed` (SimOptions).
    let tool = prev + (tool - prev).cap_magnitude(o.max_tool_speed * dt);
    let tool_v = (tool - prev) / dt;
    let mut report = TickReport { shell_off: state.ticks < state.shell_off_until, ..TickReport::default() };
    if !report.shell_off && !state.lift.list.is_empty() {
        // The shell is back (a pause shorter than the fade): the particles carry the skin again.
        state.lift.clear();
    }
    // At rest the skin is placed and its references set (LiveSkin::at_rest): the first tick
    // builds the list around its tool here, and looks at that list only, not at every vertex.
    if !state.live.valid {
        state.live.rebuild(&state.skin, &tool, skin::list_radius(o, dt));
    }

    activate::activate(sim, state, ws, tool, &mut report);
    activate::follow_core(sim, state, ws);
    skin::near_tool(sim, state, ws, tool, prev);
    let mut tool_force = shell::step(sim, state, ws, prev, tool, tool_v, dt, fork, &mut report)?;
    core_step::step_core(sim, state, ws, tool, dt, &mut tool_force, &mut report)?;

    // A shell off after a failure waits for the tool to let go of the organ as well as for its
    // pause: back under a held press it failed again at once (measured, examples/press_sweep.rs
    // on the synthetic ventricle: 16 of 22 returns failed within 2 ticks), each return a failed
    // tick and two force steps.
    if report.shell_off && report.skin_contacts + report.core_contacts > 0 {
        state.shell_off_until = state.shell_off_until.max(state.ticks + 2);
    }
    // 6. The skin: owed, paid by finish_tick.
    state.skin_owed = true;
    report.force = tool_force;
    state.tool = Some(tool);
    state.ticks += 1;
    Ok(report)
}

/// What [`tick_force_with`] left owed of its tick, if anything: the core's step when owed
/// (step 5, under the reactions in the core's `f_ext`), then the skin (step 6), which follows its
/// core faces near the tool every tick, and over active triangles the particles under it; the
/// far skin a slice of a sweep a tick (see `LiveSkin`); a shed shell's skin as lifted off its
/// ties. Allocates nothing.
///
/// A failed core step leaves the core as it was and skips the skin; the particles stay where
/// the tick left them and the tick stays counted (its force was given): the caller restores a
/// state it trusts (the haptic servo's last good one). [`tick_with`] instead undoes the whole
/// tick, as for a core step that fails within it.
pub fn finish_tick(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace) -> Result<Finished, StepError> {
    let mut done = Finished::default();
    if let Some(dt) = state.core_owed.take() {
        match core_step::owed(sim, state, ws, dt) {
            Ok(r) => done.core = Some(r),
            Err(e) => {
                state.skin_owed = false;
                return Err(e);
            }
        }
    }
    done.skin_refreshed = skin::update(sim, state, ws);
    Ok(done)
}
