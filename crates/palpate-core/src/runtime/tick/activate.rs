//! Stages 1 and 2 of the tick: which particles are simulated, and the frozen ring around them.

use super::TickReport;
use crate::math::Vec3;
use crate::runtime::homogenised_core;
use crate::runtime::sim::Sim;
use crate::runtime::state::{SimState, SimWorkspace};

/// Stage 1, activation (§6): the outer vertices within the tool's radius plus a margin touch
/// their regions; the active set is the union of RV(p_s) over the touched regions, each lingering
/// a while after its last contact ([`crate::runtime::activation`]). A particle that enters starts
/// at its tie's position and velocity (where the core and skin carried it); one that leaves
/// returns to its tie. The margin makes regions enter before the tool reaches them, so the
/// particles under the tool are already simulated when it arrives (no force jump). Skipped while
/// the shell is off after a failed shell step ([`crate::runtime::SimOptions::shell_fallback`]).
/// Then the core under the active shell is brought to the build's active factor
/// ([`homogenised_core`]).
pub(super) fn activate(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace, tool: Vec3, report: &mut TickReport) {
    let SimState { core, particles, skin, activation, ticks, is_active, live, dt, lift, .. } = state;
    let (frames, rates) = (&ws.frames, &ws.rates);
    let (tie, o) = (&sim.particle_tie, &sim.options);
    activation.set_linger(crate::runtime::sim::ticks_in(o.linger, *dt));
    if !report.shell_off {
        activation.touch_sphere_among(&tool, o.tool.radius, o.activation_margin, skin, live.iter());
    }
    let sets = activation.update(*ticks);
    for &p in sets.entered {
        is_active[p] = true;
    }
    for &p in sets.left {
        is_active[p] = false;
    }
    for &p in sets.entered.iter().chain(sets.left) {
        particles.x[p] = tie.position_framed(p, &core.x, frames);
        particles.v[p] = tie.velocity_framed(p, &core.v, rates);
    }
    (report.active, report.entered, report.left) = (sets.active.len(), sets.entered.len(), sets.left.len());
    particles.active.clear();
    particles.active.extend_from_slice(sets.active);
    // The core under the active shell (and a shed shell's fading skin) at the build's active
    // factor (homogenised_core.rs).
    ws.epoch += 1;
    homogenised_core::softened_tets(sim, &particles.active, lift, *ticks, &mut ws.node_marks, &mut ws.tet_marks, ws.epoch, &mut ws.soft_tets);
}

/// Stage 2, the ring follows the core: the inactive neighbours of the active particles are put at
/// their ties (they bound the active region, their positions shape its deformation gradients,
/// and they take its reactions), and so are the held active particles (lone lattice particles,
/// see [`Sim::new`]: the step does not move them). Also the active particles' ties (fixed over the
/// sub-steps) and anchors for confinement, and the tick's save of their motion.
pub(super) fn follow_core(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace) {
    let SimState { core, particles, is_active, .. } = state;
    let (frames, rates) = (&ws.frames, &ws.rates);
    let tie = &sim.particle_tie;
    let held = sim.particles.fixed();
    // Marks of this tick (the workspace's own count, so that marks left by another state's
    // ticks, e.g. one restored from a snapshot, are never mistaken for this tick's).
    ws.epoch += 1;
    let stamp = ws.epoch;
    for &p in &particles.active {
        if held[p] {
            particles.x[p] = tie.position_framed(p, &core.x, frames);
            particles.v[p] = tie.velocity_framed(p, &core.v, rates);
        }
        for &j in sim.particles.neighbours(p) {
            // A ring particle borders several active ones: placed once a tick.
            if !is_active[j] && ws.placed[j] != stamp {
                ws.placed[j] = stamp;
                particles.x[j] = tie.position_framed(j, &core.x, frames);
                particles.v[j] = tie.velocity_framed(j, &core.v, rates);
            }
        }
        // The tie's place and velocity, fixed over the tick's sub-steps (the core moves once a
        // tick); its displacement: confinement measures a particle in the rest frame of the core
        // around it (the voxels are the rest configuration's).
        ws.tie_x[p] = tie.position_framed(p, &core.x, frames);
        ws.tie_v[p] = tie.velocity_framed(p, &core.v, rates);
        ws.anchors[p] = ws.tie_x[p] - sim.hybrid.particles[p];
    }
    ws.save.clear();
    ws.save.extend(particles.active.iter().map(|&p| (particles.x[p], particles.v[p])));
}
