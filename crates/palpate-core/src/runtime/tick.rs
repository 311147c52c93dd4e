//! The one ordered tick of the hybrid model (paper §5-§7): tool in, force out.
//!
//! 1. **Activation** (§6): the outer vertices within the tool's radius plus a margin touch their
//!    regions; the active set is the union of RV(p_s) over the touched regions, each lingering
//!    a while after its last contact ([`super::activation`]). A particle that enters starts at
//!    its tie's position and velocity (where the core and skin carried it); one that leaves
//!    returns to its tie. The margin makes regions enter before the tool reaches them, so the
//!    particles under the tool are already simulated when it arrives (no force jump).
//! 2. **The ring follows the core**: the inactive neighbours of the active particles are put at
//!    their ties; they bound the active region (their positions shape its deformation
//!    gradients) and take its reactions.
//! 3. **Particle sub-steps** (Verlet, as many as the shell's stability needs): before each,
//!    the tool's penalty contact ([`super::tool`]), the coupling springs to the core faces
//!    ([`super::coupling`]) and the confinement wall ([`super::confinement`]) on the active
//!    particles. The tool's centre moves linearly over the tick's sub-steps. If the shell's step
//!    fails (diverging or non-finite: a press it cannot follow, see [`super::stability`]), the
//!    tick sheds the shell, every particle back at its tie and no region active, and goes on
//!    with the core and the skin; the shell stays off for a pause
//!    ([`super::SimOptions::shell_fallback`]). The hand keeps feeling the organ: the skin the
//!    particles carried stays where they left it and fades back to its ties over 50 ticks
//!    (`SkinLift` in `state.rs`). Measured on the synthetic ventricle's 18 shed presses
//!    (`examples/press_sweep.rs`): the force changes by 0.03-0.15 N in a tick at the switch
//!    (before: 0.65-3.2 N, the skin back at its ties at once and the core's contact explicit).
//! 4. **Skin and core contact** where no particle carries the skin: the tool presses the skin
//!    vertices, and their ties carry the force to the core; the core's surface meets the tool as
//!    a surface (its point nearest the tool's centre, stiff and signed, so that a hard press
//!    cannot pass the tool through the coarse core). Both are taken inside the core's implicit
//!    step ([`super::core_contact`]: held explicitly over the step on the coarse core, they
//!    chattered under a deep press).
//! 5. **The core step** (the default integrator, stable at any press) under the sub-step average
//!    of every reaction: the coupling springs', the ring's (the active particles' stresses on
//!    their frozen neighbours, spread by the ties' weights), the skin's.
//! 6. **The skin** follows its core faces, and over active triangles also the particles under it.
//!
//! The force does not depend on step 6, nor on step 5 when the tool has nothing of the core
//! within reach (the force is then the particles' alone, the common case of a palpation with the
//! shell on): [`tick_force_with`] leaves that work owed and [`finish_tick`] does it, so that a
//! haptic servo sends the force first (on the Rodero ventricle, 5 mm tool pressed 4 mm and slid,
//! the force comes 23-28% sooner: 0.37 against 0.49-0.52 ms mean, `examples/tick_profile.rs`
//! with `SPLIT=1`). [`tick`] does both, and a tick pays what an earlier one owes first: the
//! trajectory is the same bit for bit however the work is split.
//!
//! Every force between two bodies is one of an equal and opposite pair and every tie spreads
//! a force into shares that sum to it, so with the tool away (and no confinement push) the total
//! linear momentum of the core and the active particles is conserved to round-off, and with the
//! tool its change is the tool's impulse (tests/runtime.rs); while the shell is off, to the core
//! step's tolerance (the contact is then part of the step's minimisation). A failed tick leaves the core and the
//! particles' motion as they were (see [`tick`]).

use super::activation::Activation;
use super::embed;
use super::sim::Sim;
use super::state::{LiveSkin, SimState, SimWorkspace};
use crate::error::StepError;
use crate::integrate::{step, step_with_potential, CorePotential, StepReport};
use super::homogenised_core::{self, Softening, Sum};
use super::core_contact::CoreContact;
use crate::math::{is_finite3, Mat3, Vec3};
use crate::meshfree;
use crate::parallel::{Fork, Serial};
use crate::spatial::closest_on_triangle;
use super::stability::stretch_bound;
use super::exchange::ShellReaction;

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
/// [`super::SimOptions::max_tool_step`], and [`SimState::tool`] says where it is). Allocates nothing. A bad `dt` or tool position changes nothing. A failed,
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
    let SimState { core, particles, skin, tool: last_tool, activation, ticks, is_active, live, shell_off_until, lift, skin_owed, core_owed } = state;
    // The shell's clock is the core's (it advances only while particles are active).
    particles.t = core.t;
    // The core's face frames and their rates, once: every tie on a face shares them.
    embed::face_frames_and_rates(&core.x, &core.v, &sim.hybrid.core_faces, &mut ws.frames, &mut ws.rates);
    let (frames, rates) = (&ws.frames, &ws.rates);
    let (tie, o) = (&sim.particle_tie, &sim.options);
    let prev = last_tool.unwrap_or(tool);
    // The simulated tool follows the device at most `max_tool_step` a tick (SimOptions).
    let tool = prev + (tool - prev).cap_magnitude(o.max_tool_step);
    let tool_v = (tool - prev) / dt;
    // (Activation is skipped while the shell is off after a failed shell step: see
    // SimOptions::shell_fallback.)
    let mut report = TickReport { shell_off: *ticks < *shell_off_until, ..TickReport::default() };
    if !report.shell_off && !lift.list.is_empty() {
        // The shell is back (a pause shorter than the fade): the particles carry the skin again.
        lift.clear();
    }

    // At rest the skin is placed and its references set (LiveSkin::at_rest): the first tick
    // builds the list around its tool here, and looks at that list only, not at every vertex.
    if !live.valid {
        live.rebuild(skin, &tool, list_radius(o));
    }

    // 1. Activation.
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
    // The core under the active shell back to the tissue's stiffness (homogenised_core.rs).
    ws.epoch += 1;
    homogenised_core::softened_tets(sim, &particles.active, &mut ws.node_marks, &mut ws.tet_marks, ws.epoch, &mut ws.soft_tets);

    // 2. The ring follows the core, and so do the held active particles (lone lattice particles,
    // see Sim::new: the step does not move them); the active particles' anchors for confinement.
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

    // The skin vertices over active triangles that the tool may reach this tick.
    ws.near.clear();
    let reach = o.tool.radius + (tool - prev).norm() + o.activation_margin;
    for v in live.iter() {
        if (skin[v] - tool).norm_squared() < reach * reach && over_active(sim, activation, v) {
            ws.near.push(v);
        }
    }
    near_lists(sim, activation, &core.x, &core.v, ws);

    // 3. Particle sub-steps.
    ws.f_core.iter_mut().for_each(|f| *f = Vec3::zeros());
    let mut tool_force = Vec3::zeros();
    if !particles.active.is_empty() {
        let k = substeps(sim, particles, ws, dt);
        let tri_count = activation.triangle_counts();
        let rest = &sim.hybrid.particles;
        sim.confinement.slacks(&sim.hybrid.grid, &sim.hybrid.voxel_owner, tri_count, rest, &particles.active, &mut ws.slacks);
        // Most particles are well inside their regions: the sub-steps look only at those that
        // moved farther than their free radius since the tick's start (the same forces, cheaper).
        for &p in &particles.active {
            ws.x0[p] = particles.x[p] - ws.anchors[p];
            ws.free[p] = sim.confinement.free_radius(&sim.hybrid.grid, &sim.hybrid.voxel_owner, tri_count, &ws.x0[p], ws.slacks[p]);
        }
        // What the sub-steps send to the core is gathered per particle (`to_core`, through its
        // tie) and per skin vertex (`skin_to_core`) and spread once after them: the core does not
        // move within a tick, so the spread of the sum is the sum of the spreads.
        let (shift, slacks, x_rest, f_wall) = (&ws.anchors, &ws.slacks, &mut ws.x_rest, &mut ws.f_wall);
        let (x0, free, wall_check) = (&ws.x0, &ws.free, &mut ws.wall_check);
        ws.held_active.clear();
        ws.held_active.extend(particles.active.iter().copied().filter(|&p| held[p]));
        let held_active = &ws.held_active;
        let (tie_x, tie_v, to_core, skin_to_core) = (&ws.tie_x, &ws.tie_v, &mut ws.to_core, &mut ws.skin_to_core);
        let lists = NearLists { near: &ws.near, ptr: &ws.near_ptr, items: &ws.near_items, base: &ws.near_base };
        let hybrid = &sim.hybrid;
        let external = |sub: &meshfree::SubStep<'_>, f: &mut [Vec3]| {
            let c = prev + ((sub.index + 1) as f64 / k as f64) * (tool - prev);
            // The coupling springs and, in the same pass (one sweep of the active list a
            // sub-step, not two), the particles the wall must look at. The wall belongs to the
            // core's regions: its reaction goes to the core through the particle's tie (momentum
            // stays exact).
            wall_check.clear();
            for &p in sub.active {
                f[p] = if sim.coupled[p] {
                    let fc = sim.coupling.force(&tie_x[p], &tie_v[p], &sub.x[p], &sub.v[p]);
                    to_core[p] -= fc;
                    fc
                } else {
                    Vec3::zeros()
                };
                x_rest[p] = sub.x[p] - shift[p];
                if (x_rest[p] - x0[p]).norm_squared() < free[p] * free[p] {
                    continue;
                }
                f_wall[p] = Vec3::zeros();
                wall_check.push(p);
            }
            // The tool meets the skin over the active particles, and the skin carries the force
            // to the particles under it: a surface, so the tool cannot slip between particles.
            let mut count = 0;
            for (k, &v) in lists.near.iter().enumerate() {
                let items = &lists.items[lists.ptr[k]..lists.ptr[k + 1]];
                let (mut xs, mut vs) = lists.base[k];
                for &(p, w) in items {
                    xs += w * sub.x[p];
                    vs += w * sub.v[p];
                }
                if let Some(contact) = sim.tool.sample(sim.skin_area[v]).contact(&c, &tool_v, &xs, &vs) {
                    // The transpose of the placement: `w_p` of the force to each particle under,
                    // the skin tie's share to the core less the particles' ties' shares.
                    skin_to_core[v] += contact.force;
                    for &(p, w) in items {
                        f[p] += w * contact.force;
                        to_core[p] -= w * contact.force;
                    }
                    tool_force -= contact.force;
                    count += 1;
                    report.max_depth = report.max_depth.max(contact.depth);
                }
            }
            report.particle_contacts = report.particle_contacts.max(count);
            let wall = sim.confinement.apply(&hybrid.grid, &hybrid.voxel_owner, tri_count, x_rest, rest, Some(slacks), wall_check, f_wall);
            report.confined = report.confined.max(wall.pushed);
            if wall.pushed > 0 {
                for &p in wall_check.iter() {
                    f[p] += f_wall[p];
                    to_core[p] -= f_wall[p];
                }
            }
            // Held particles (lone lattice particles, see Sim::new) do not move: what acts on
            // them is carried by the core, through their ties.
            for &p in held_active.iter() {
                to_core[p] += f[p];
            }
        };
        if let Err(e) = meshfree::step_with_fork(&sim.particles, particles, &mut ws.particles, dt, k, fork, external) {
            // Nothing of a failed step reaches the core (the buffers start the next tick empty).
            for &p in &particles.active {
                ws.to_core[p] = Vec3::zeros();
            }
            for &v in &ws.near {
                ws.skin_to_core[v] = Vec3::zeros();
            }
            let Some(off_ticks) = o.shell_fallback else { return Err(e) };
            // The fallback: the shell is shed (every particle back at its tie, no region active)
            // and stays off `off_ticks` ticks; this tick goes on with the core and the skin, so
            // the hand still feels the organ (the skin contact below) rather than nothing.
            for &p in &particles.active {
                is_active[p] = false;
                particles.x[p] = tie.position_framed(p, &core.x, &ws.frames);
                particles.v[p] = tie.velocity_framed(p, &core.v, &ws.rates);
            }
            report.left += particles.active.len();
            // The skin the particles carried stays where they left it, and fades back to its
            // ties (SkinLift): put back at once, the force jumped.
            lift.clear();
            (lift.start, lift.ticks) = (*ticks, super::state::shed_fade_ticks(o));
            for v in live.iter() {
                if live.carried[v] {
                    let d = skin[v] - sim.skin.position_framed(v, &core.x, &ws.frames);
                    if d != Vec3::zeros() && is_finite3(&d) {
                        lift.offset[v] = d;
                        lift.list.push(v as u32);
                    }
                }
            }
            particles.active.clear();
            activation.clear();
            ws.near.clear();
            *shell_off_until = *ticks + 1 + off_ticks;
            (report.shell_failed, report.active, report.particle_contacts, report.confined, tool_force) = (true, 0, 0, 0, Vec3::zeros());
        } else {
            report.substeps = k;
            let inv_k = 1.0 / k as f64;
            for &p in &particles.active {
                let f = std::mem::replace(&mut ws.to_core[p], Vec3::zeros());
                if f != Vec3::zeros() {
                    tie.spread(p, f * inv_k, &core.x, &mut ws.f_core);
                }
            }
            for &v in &ws.near {
                let f = std::mem::replace(&mut ws.skin_to_core[v], Vec3::zeros());
                if f != Vec3::zeros() {
                    sim.skin.spread(v, f * inv_k, &core.x, &mut ws.f_core);
                }
            }
            tool_force *= inv_k;
            // The ring: frozen neighbours (at their ties) and held active particles (lone lattice
            // particles, see Sim::new): both carried by the core.
            for (&j, &f) in ws.particles.ring().iter().zip(ws.particles.ring_forces()) {
                tie.spread(j, f, &core.x, &mut ws.f_core);
            }
        }
    }

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
        ws.reach.extend(live.iter().filter(|&v| (skin[v] - tool).norm_squared() < reach * reach && !over_active(sim, activation, v)));
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
                undo_particles(particles, &ws.save, dt);
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
        tool_force -= match momentum_before {
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

    // A shell off after a failure waits for the tool to let go of the organ as well as for its
    // pause: back under a held press it failed again at once (measured, examples/press_sweep.rs
    // on the synthetic ventricle: 16 of 22 returns failed within 2 ticks), each return a failed
    // tick and two force steps.
    if report.shell_off && report.skin_contacts + report.core_contacts > 0 {
        *shell_off_until = (*shell_off_until).max(*ticks + 2);
    }

    // 6. The skin: owed (see tick_force_with), paid by finish_tick.
    *skin_owed = true;
    report.force = tool_force;
    *last_tool = Some(tool);
    *ticks += 1;
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
        // The softened tets of the active set the tick left (recomputed: a state restored
        // between the tick and this step brings its own).
        ws.epoch += 1;
        homogenised_core::softened_tets(sim, &state.particles.active, &mut ws.node_marks, &mut ws.tet_marks, ws.epoch, &mut ws.soft_tets);
        // The shell's reactions (in `f_ext`) with their implicit share (super::exchange).
        let reaction = ShellReaction::new(sim, &state.particles.active, &state.core.x, &state.core.v, dt, &mut ws.predicted);
        let stepped = match (ws.soft_tets.is_empty(), reaction.is_empty()) {
            (true, true) => step(&sim.core, &mut state.core, &mut ws.core, dt),
            (false, true) => step_with_potential(&sim.core, &mut state.core, &mut ws.core, dt, &Softening { sim, tets: &ws.soft_tets }),
            (true, false) => step_with_potential(&sim.core, &mut state.core, &mut ws.core, dt, &reaction),
            (false, false) => step_with_potential(&sim.core, &mut state.core, &mut ws.core, dt, &Sum(&Softening { sim, tets: &ws.soft_tets }, &reaction)),
        };
        match stepped {
            Ok(r) => done.core = Some(r),
            Err(e) => {
                state.skin_owed = false;
                return Err(e);
            }
        }
    }
    let SimState { core, particles, skin, tool, activation, ticks, live, lift, skin_owed, .. } = state;
    let Some(tool) = *tool else { return Ok(done) };
    if !std::mem::replace(skin_owed, false) {
        return Ok(done);
    }
    // Marks of this update (the workspace's count, as the tick's own).
    ws.epoch += 1;
    let refreshed = update_skin(sim, activation, particles, &core.x, &mut ws.frames, &mut ws.over, ws.epoch, tool, live, skin);
    // A shed shell's skin, lifted off its ties as the next tick's contact will see it (the tick
    // is already counted: its successor's scale).
    if !lift.list.is_empty() {
        let scale = lift.scale(*ticks);
        for &v in &lift.list {
            let v = v as usize;
            skin[v] = sim.skin.position_framed(v, &core.x, &ws.frames) + scale * lift.offset[v];
        }
        if scale == 0.0 {
            lift.clear();
        }
    }
    done.skin_refreshed = refreshed;
    Ok(done)
}

/// The sub-steps this tick needs ([`super::stability`]): the active particles' largest stretch at
/// the start of the tick, and the tool's largest share of a particle over the skin vertices
/// within its reach (`ws.near`, their lists from [`near_lists`]).
fn substeps(sim: &Sim, particles: &meshfree::ParticleState, ws: &mut SimWorkspace, dt: f64) -> usize {
    let held = sim.particles.fixed();
    let stretch2 = particles.active.iter().filter(|&&p| !held[p]).map(|&p| stretch_bound(&sim.particles.deformation_gradient(p, &particles.x))).fold(1.0, f64::max);
    let mass = sim.particles.masses();
    // Each skin vertex's penalty is the tool's per unit area times the vertex's area: the share
    // of a particle is that area times its weight over its mass.
    let mut top = 0.0f64;
    for (k, &v) in ws.near.iter().enumerate() {
        let area = sim.skin_area[v];
        for &(p, w) in &ws.near_items[ws.near_ptr[k]..ws.near_ptr[k + 1]] {
            ws.contact_share[p] += area * w / mass[p];
            top = top.max(ws.contact_share[p]);
        }
    }
    for &(p, _) in &ws.near_items {
        ws.contact_share[p] = 0.0;
    }
    let tool = &sim.tool;
    sim.shell.substeps(dt, stretch2, tool.stiffness * top, tool.damping * top, sim.options.max_substeps)
}

/// Is outer vertex `v` on a triangle with active particles?
pub(crate) fn over_active(sim: &Sim, activation: &Activation, v: usize) -> bool {
    sim.hybrid.outer_adjacency.vertex_tris.get(v).iter().any(|&t| activation.is_triangle_active(t))
}

/// The skin vertices within the tool's reach this tick, each placed over the particles under its
/// active triangles (see [`skin_over_particles`]) by a list of `(particle, w_p / W)` and a base:
/// the vertex is at `base.0 + sum w_p / W x_p`, moving at `base.1 + sum w_p / W v_p`.
struct NearLists<'a> {
    near: &'a [usize],
    ptr: &'a [usize],
    items: &'a [(usize, f64)],
    base: &'a [(Vec3, Vec3)],
}

/// Fills `ws.near_ptr`, `ws.near_items` and `ws.near_base` for `ws.near` (allocation-free: their
/// capacities are the model's bounds). The core does not move within a tick, so the ties' part of
/// each vertex's place is computed once here (`ws.tie_x`, `ws.tie_v` hold the active particles').
fn near_lists(sim: &Sim, activation: &Activation, core_x: &[Vec3], core_v: &[Vec3], ws: &mut SimWorkspace) {
    ws.near_ptr.clear();
    ws.near_items.clear();
    ws.near_base.clear();
    ws.near_ptr.push(0);
    ws.uncarried.clear();
    let mut kept = 0;
    for i in 0..ws.near.len() {
        let v = ws.near[i];
        let start = ws.near_items.len();
        ws.near_items.extend(skin_weights(sim, activation, v));
        let wsum: f64 = ws.near_items[start..].iter().map(|&(_, w)| w).sum();
        if !(wsum > 0.0) {
            // No particle carries it: it stays at its tie, and meets the tool in the core's
            // step (step 4).
            ws.near_items.truncate(start);
            ws.uncarried.push(v);
            continue;
        }
        ws.near[kept] = v;
        kept += 1;
        let (mut bx, mut bv) = (sim.skin.position(v, core_x), sim.skin.velocity(v, core_x, core_v));
        for item in &mut ws.near_items[start..] {
            item.1 /= wsum;
            bx -= item.1 * ws.tie_x[item.0];
            bv -= item.1 * ws.tie_v[item.0];
        }
        ws.near_base.push((bx, bv));
        ws.near_ptr.push(ws.near_items.len());
    }
    ws.near.truncate(kept);
}

/// The particles that carry outer vertex `v` (one of whose own triangles is active: every
/// caller asks only for such vertices) over an active zone: those under its active carrier
/// triangles ([`super::sim::SkinCarriers`]: its own triangles, or, where none has a particle under
/// it, the next rings'), with their weights in its placement: each tie's squared depth over its
/// core face, so that the outermost particles, just under the skin, count most.
fn skin_weights<'a>(sim: &'a Sim, activation: &'a Activation, v: usize) -> impl Iterator<Item = (usize, f64)> + 'a {
    let h = &sim.hybrid;
    sim.skin_carriers.get(v).iter().filter(|&&t| activation.is_triangle_active(t)).flat_map(move |&t| {
        (h.tri_particle_ptr[t as usize] as usize..h.tri_particle_ptr[t as usize + 1] as usize).map(move |p| (p, sim.particle_tie.offsets()[p].norm_squared()))
    })
}

/// Where outer vertex `v` is, over active triangles (the caller checks that it is: [`over_active`]):
/// its tie to the core moved by the weighted mean displacement of the particles that carry it
/// from their own ties ([`skin_weights`]); `None` when no active particle carries it. (The sub-steps place the near vertices the same way through
/// [`NearLists`], with the ties computed once a tick.) With the core's face `frames` at `core_x`
/// ([`embed::face_frames`]), the ties take them instead of computing a frame per particle.
pub(crate) fn skin_over_particles(sim: &Sim, activation: &Activation, v: usize, x: &[Vec3], core_x: &[Vec3], frames: Option<&[Option<Mat3>]>) -> Option<Vec3> {
    let tie = &sim.particle_tie;
    let at = |e: &embed::Embedding, i: usize| match frames {
        Some(f) => e.position_framed(i, core_x, f),
        None => e.position(i, core_x),
    };
    let (mut d, mut wsum) = (Vec3::zeros(), 0.0);
    for (p, w) in skin_weights(sim, activation, v) {
        d += w * (x[p] - at(tie, p));
        wsum += w;
    }
    (wsum > 0.0).then(|| at(&sim.skin, v) + d / wsum)
}

/// Skin vertices at their ties, or, over active triangles, carried by the particles under them.
/// Every stored skin vertex is within this \[m\] of its place (see `LiveSkin` in `state.rs`):
/// the whole skin is updated when the core's faces may have carried it half as far since the
/// last whole update, and the vertices within this of the tool's reach every tick.
pub const SKIN_LIVE_MARGIN: f64 = 0.005;

/// With the shell on, the skin vertices and core faces the core's implicit contact looks
/// at (step 4) are those within the tool's radius plus this \[m\] at the tick's start: more than
/// the core's nodes move in a tick under a hand's press (a node that moves farther into the tool
/// meets it the tick after). With the shell off it is [`SKIN_LIVE_MARGIN`].
pub const IMPLICIT_CONTACT_MARGIN: f64 = 0.001;

/// Ticks a sweep of the whole skin is spread over (see `LiveSkin`): 1/16 of the Rodero
/// ventricle's skin is ~80 us a tick, where the whole took 1.2 ms in one.
pub const SKIN_SWEEP_TICKS: usize = 16;

/// The radius \[m\] within which the skin is updated every tick: the tool's reach, two of its
/// steps (it moves before the next tick's contact) and [`SKIN_LIVE_MARGIN`] (a stale vertex is
/// no farther than that from its place).
fn live_radius(o: &super::SimOptions) -> f64 {
    o.tool.radius + o.activation_margin + 2.0 * o.max_tool_step + SKIN_LIVE_MARGIN
}

/// The radius \[m\] of the list of skin vertices a tick looks at (see `LiveSkin`): the live
/// radius, a margin (the list is rebuilt once the tool has travelled that far) and a tool's step.
fn list_radius(o: &super::SimOptions) -> f64 {
    live_radius(o) + SKIN_LIVE_MARGIN + o.max_tool_step
}

/// How far \[m\] the skin's ties may have moved since the core was at `ref_x` with face frames
/// `ref_frames`: over the faces carrying skin, `sum |w| max |dx| + |dR|_F |o|` (infinite where a
/// face's frame turned degenerate or back).
fn skin_travel(sim: &Sim, core_x: &[Vec3], frames: &[Option<Mat3>], ref_x: &[Vec3], ref_frames: &[Option<Mat3>]) -> f64 {
    let mut travel = 0.0f64;
    for (f, (&(w, o), face)) in sim.skin_face_reach.iter().zip(&sim.hybrid.core_faces).enumerate() {
        if w == 0.0 && o == 0.0 {
            continue;
        }
        let dx = face.iter().map(|&a| (core_x[a] - ref_x[a]).norm()).fold(0.0, f64::max);
        let dr = match (frames[f], ref_frames[f]) {
            (Some(a), Some(b)) => (a - b).norm(),
            (None, None) => 0.0,
            _ => f64::INFINITY,
        };
        travel = travel.max(w * dx + dr * o);
    }
    travel
}

/// The core's face frames are computed once (`frames`), not per vertex, and the vertices over
/// active triangles are found from the active triangles' list (`over[v] == stamp`) rather than
/// by asking every vertex's triangles (or every active region's: neighbouring regions share
/// most of their triangles, and that loop was 2% of the Rodero tick). Then, unless the skin's travel bound calls for a whole update: the
/// vertices of `live` within [`live_radius`] of the tool, and those no longer carried by
/// particles, go to their ties (a fine outer surface, the Rodero model's 31,788 vertices, made
/// the whole skin's update a third of its tick); the list is rebuilt when the tool has moved
/// [`SKIN_LIVE_MARGIN`] since it last was. Every vertex moved here joins `live`.
#[allow(clippy::too_many_arguments)]
fn update_skin(sim: &Sim, activation: &Activation, particles: &meshfree::ParticleState, core_x: &[Vec3], frames: &mut [Option<Mat3>], over: &mut [u64], stamp: u64, tool: Vec3, live: &mut LiveSkin, skin: &mut [Vec3]) -> usize {
    embed::face_frames(core_x, &sim.hybrid.core_faces, frames);
    let frames = &*frames;
    let place = |v: usize, over: bool| {
        let carried = if over { skin_over_particles(sim, activation, v, &particles.x, core_x, Some(frames)) } else { None };
        carried.unwrap_or_else(|| sim.skin.position_framed(v, core_x, frames))
    };
    for &t in activation.active_triangles() {
        for &v in &sim.hybrid.outer_tris[t as usize] {
            if over[v] != stamp {
                over[v] = stamp;
                skin[v] = place(v, true);
                live.carried[v] = true;
                live.add(v);
            }
        }
    }
    live.sort();
    let r_live = live_radius(&sim.options);
    let r_list = list_radius(&sim.options);
    live.travel = skin_travel(sim, core_x, frames, &live.ref_x, &live.ref_frames);
    // A sweep's vertices were placed from the core at or after its start: within its reference's
    // travel plus what the skin travelled from it while the sweep went on.
    let sweep_travel = match live.sweep_next {
        Some(_) => {
            let t = skin_travel(sim, core_x, frames, &live.sweep_ref_x, &live.sweep_ref_frames);
            live.sweep_slack = live.sweep_slack.max(t);
            t
        }
        None => 0.0,
    };
    let bound = (live.travel + live.slack).max(if live.sweep_next.is_some() { sweep_travel + live.sweep_slack } else { 0.0 });
    if !(2.0 * bound <= SKIN_LIVE_MARGIN) {
        // The whole skin at once (a sweep could not keep up): every stored vertex back at its
        // place.
        for v in 0..skin.len() {
            if over[v] != stamp {
                skin[v] = place(v, false);
                live.carried[v] = false;
            }
        }
        live.ref_x.copy_from_slice(core_x);
        live.ref_frames.copy_from_slice(frames);
        (live.travel, live.slack, live.sweep_next) = (0.0, 0.0, None);
        live.rebuild(skin, &tool, r_list);
        return skin.len();
    }
    // Past a quarter of the margin, a sweep of the whole skin begins, a slice a tick: it ends
    // before the bound reaches half the margin unless the skin moves faster than ~0.08 m/s, when
    // the whole update above takes over. (At an eighth, sweeps ran twice as often in a slow press
    // for no gain: tests/runtime_hand.rs counts them.)
    if live.sweep_next.is_none() && 4.0 * (live.travel + live.slack) > SKIN_LIVE_MARGIN {
        live.sweep_ref_x.copy_from_slice(core_x);
        live.sweep_ref_frames.copy_from_slice(frames);
        (live.sweep_next, live.sweep_slack) = (Some(0), 0.0);
    }
    let mut refreshed = 0;
    if let Some(start) = live.sweep_next {
        let n = skin.len();
        let end = (start + n.div_ceil(SKIN_SWEEP_TICKS)).min(n);
        refreshed = end - start;
        for v in start..end {
            if over[v] != stamp {
                skin[v] = place(v, false);
                live.carried[v] = false;
            }
        }
        if end < n {
            live.sweep_next = Some(end);
        } else {
            // Done: the sweep's reference is the skin's.
            std::mem::swap(&mut live.ref_x, &mut live.sweep_ref_x);
            std::mem::swap(&mut live.ref_frames, &mut live.sweep_ref_frames);
            (live.travel, live.slack, live.sweep_next) = (sweep_travel, live.sweep_slack, None);
            live.rebuild(skin, &tool, r_list);
        }
    }
    for k in 0..live.list.len() {
        let v = live.list[k] as usize;
        if over[v] != stamp && (live.carried[v] || (skin[v] - tool).norm_squared() <= r_live * r_live) {
            skin[v] = place(v, false);
            live.carried[v] = false;
        }
    }
    if !((tool - live.ref_tool).norm() <= SKIN_LIVE_MARGIN) {
        live.rebuild(skin, &tool, r_list);
    }
    refreshed
}
