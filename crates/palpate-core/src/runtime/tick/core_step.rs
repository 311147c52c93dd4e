//! Stages 4 and 5 of the tick: the tool against what moves with the core, and the core's step.

use super::TickReport;
use crate::error::StepError;
use crate::integrate::{step, step_with_potential, CorePotential, StepReport};
use crate::math::Vec3;
use crate::runtime::core_contact::CoreContact;
use crate::runtime::exchange::ShellReaction;
use crate::runtime::homogenised_core::{self, Softening, Sum};
use crate::runtime::sim::Sim;
use crate::runtime::skin::{over_active, SKIN_LIVE_MARGIN};
use crate::runtime::state::{SimState, SimWorkspace};
use crate::spatial::closest_on_triangle;

/// With the shell on, the skin vertices and core faces the core's implicit contact looks
/// at (step 4) are those within the tool's radius plus this \[m\] at the tick's start: more than
/// the core's nodes move in a tick under a hand's press (a node that moves farther into the tool
/// meets it the tick after). With the shell off it is [`SKIN_LIVE_MARGIN`].
pub const IMPLICIT_CONTACT_MARGIN: f64 = 0.001;

/// Stages 4 and 5: the skin no particle carries and the core's surface within the tool's reach
/// meet the tool inside the core's implicit step ([`crate::runtime::core_contact`]), and the core
/// steps under the sub-step average of every reaction (`ws.f_core`: the coupling springs', the
/// ring's, the skin's) with the softening of the homogenised core and the shell's implicit
/// exchange ([`crate::runtime::exchange`]). When nothing of the core is within the tool's reach,
/// the force is the particles' alone and the core's step is left owed (`owed`, after the force
/// is sent). Adds the core's share to `tool_force` \[N\]. A failed core step puts the
/// particles' motion back at the tick's start.
pub(super) fn step_core(
    sim: &Sim,
    state: &mut SimState,
    ws: &mut SimWorkspace,
    tool: Vec3,
    dt: f64,
    tool_force: &mut Vec3,
    report: &mut TickReport,
) -> Result<(), StepError> {
    let SimState { core, particles, skin, activation, ticks, live, lift, core_owed, .. } = state;
    let o = &sim.options;
    // 4. The tool against what moves with the core: the skin where no particle carries it (over
    // no active particle, or with no particle under its carrier triangles: see SkinCarriers) and
    // the core's surface (where the tool has pushed the shell aside).
    // That contact is taken inside the core's implicit step (super::core_contact): held over the
    // 1 ms step as an explicit force it chattered, with the shell off (after a failure) and with
    // it on (measured on the Rodero ventricle, `examples/press_sweep.rs`, the paper's damping, the
    // tool held 11.35 mm in at the 75.8 mm, 3.44 rad probe, 2026-11-27: the force alternated
    // between 2.2 and 4.8 N tick by tick, median change 1.3 N a tick, through skin vertices no
    // particle carried; with their contact in the step, at most 0.014 N a tick).
    let implicit = report.shell_off || report.shell_failed;
    ws.reach.clear();
    ws.core_reach.clear();
    let margin = if implicit { SKIN_LIVE_MARGIN } else { IMPLICIT_CONTACT_MARGIN };
    let reach = o.tool.radius + margin;
    if implicit {
        ws.reach.extend(live.iter().filter(|&v| (skin[v] - tool).norm_squared() < reach * reach));
    } else {
        ws.reach
            .extend(live.iter().filter(|&v| (skin[v] - tool).norm_squared() < reach * reach && !over_active(sim, activation, v)));
        ws.reach.extend(ws.uncarried.iter().copied().filter(|&v| (skin[v] - tool).norm_squared() < reach * reach));
    }
    // The core's faces within reach of their nearest point (a face can reach the tool with its
    // three nodes out of it), and a radius more: a face the tool's centre has been pushed
    // beneath stays in the contact (whose sign then keeps pushing the tool out, see
    // super::core_contact) up to a radius beneath it.
    let core_reach = reach + o.tool.radius;
    let mut nearest2 = f64::INFINITY;
    ws.core_reach.extend(sim.hybrid.core_faces.iter().enumerate().filter_map(|(t, &[a, b, c])| {
        let (pa, pb, pc) = (core.x[a], core.x[b], core.x[c]);
        // Most faces are far: their bounding sphere (about the centroid) tells, cheaper than the
        // nearest point (300 faces on the Rodero ventricle's core, every tick).
        let centroid = (pa + pb + pc) / 3.0;
        let bound = core_reach + (pa - centroid).norm_squared().max((pb - centroid).norm_squared()).max((pc - centroid).norm_squared()).sqrt();
        if !((centroid - tool).norm_squared() < bound * bound) {
            return None;
        }
        let (p, _) = closest_on_triangle(&tool, &pa, &pb, &pc);
        let d2 = (p - tool).norm_squared();
        nearest2 = nearest2.min(d2);
        (d2 < core_reach * core_reach).then_some(t)
    }));

    // 5. The core.
    core.f_ext.copy_from_slice(&ws.f_core);
    // The side of the core's surface the tool's centre is on, where it matters: within a radius
    // of the surface (farther out there is no contact; a centre more than a radius beneath,
    // 2 k R = 20 N at the default stiffness, counts as out).
    let beneath = nearest2 < o.tool.radius * o.tool.radius && CoreContact::centre_is_beneath(sim, &core.x, &tool);
    if !beneath {
        // The extra radius of `core_reach` is for a centre beneath the surface. Outside it, a
        // face farther than the skin's reach cannot meet the tool within the tick (the margin's
        // bound on the core's motion, as for every face beyond `core_reach`): without it the
        // contact set is empty, and the force does not depend on the core's step (see below).
        let (faces, x) = (&sim.hybrid.core_faces, &core.x);
        ws.core_reach.retain(|&t| {
            let [a, b, c] = faces[t];
            (closest_on_triangle(&tool, &x[a], &x[b], &x[c]).0 - tool).norm_squared() < reach * reach
        });
    }
    let contact = CoreContact { sim, centre: tool, skin: &ws.reach, core: &ws.core_reach, lift: &lift.offset, lift_scale: lift.scale(*ticks), beneath };
    let touched = !ws.reach.is_empty() || !ws.core_reach.is_empty();
    if touched {
        let momentum_before = if sim.core.is_free_body() { Some(sim.core.momentum(&core.v)) } else { None };
        let softening = Softening { sim, tets: &ws.soft_tets };
        let reaction = ShellReaction::new(sim, &particles.active, &core.x, &core.v, dt, &mut ws.predicted);
        let inner = Sum(&softening, &reaction);
        let both = Sum(&contact, &inner);
        let potential: &dyn CorePotential = &both;
        report.core = match step_with_potential(&sim.core, core, &mut ws.core, dt, potential) {
            Ok(r) => r,
            Err(e) => {
                super::undo_particles(particles, &ws.save, dt);
                return Err(e);
            }
        };
        let c = contact.sum(&core.x);
        // On a body with no fixed node, what the step gave the core (its momentum's change less
        // the other applied forces' impulse): the contact's forces at the end of the step and
        // the minimisation's residual, which sums to the tolerance, not to zero (the exact
        // rigid translation of a free body's step needs translation-invariant forces). Reported
        // so, linear momentum stays exact with the tool (tests/runtime.rs). Held, the fixed
        // nodes take the residual: the contact's forces.
        *tool_force -= match momentum_before {
            Some(p0) => {
                let applied: Vec3 = core.f_ext.iter().sum::<Vec3>() + sim.core.masses().iter().sum::<f64>() * sim.core.gravity();
                (sim.core.momentum(&core.v) - p0) / dt - applied
            }
            None => c.force,
        };
        (report.skin_contacts, report.core_contacts) = (c.skin_contacts, c.core_contacts);
        report.max_depth = report.max_depth.max(c.max_depth);
    } else {
        // Nothing of the core within the tool's reach: the force is the particles' alone, and
        // the core's step (under the reactions in `f_ext`) is owed to finish_tick, after the
        // force is sent.
        *core_owed = Some(dt);
    }
    Ok(())
}

/// The core's step a tick left owed (`super::finish_tick`), under the reactions in the core's
/// `f_ext`, with the softened tets of the active set the tick left and the shell's implicit
/// exchange.
pub(super) fn owed(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace, dt: f64) -> Result<StepReport, StepError> {
    // The softened tets of the active set the tick left (recomputed: a state restored
    // between the tick and this step brings its own).
    ws.epoch += 1;
    homogenised_core::softened_tets(sim, &state.particles.active, &state.lift, state.ticks, &mut ws.node_marks, &mut ws.tet_marks, ws.epoch, &mut ws.soft_tets);
    // The shell's reactions (in `f_ext`) with their implicit share (super::exchange).
    let reaction = ShellReaction::new(sim, &state.particles.active, &state.core.x, &state.core.v, dt, &mut ws.predicted);
    let stepped = match (ws.soft_tets.is_empty(), reaction.is_empty()) {
        (true, true) => step(&sim.core, &mut state.core, &mut ws.core, dt),
        (false, true) => step_with_potential(&sim.core, &mut state.core, &mut ws.core, dt, &Softening { sim, tets: &ws.soft_tets }),
        (true, false) => step_with_potential(&sim.core, &mut state.core, &mut ws.core, dt, &reaction),
        (false, false) => step_with_potential(&sim.core, &mut state.core, &mut ws.core, dt, &Sum(&Softening { sim, tets: &ws.soft_tets }, &reaction)),
    };
    stepped
}
