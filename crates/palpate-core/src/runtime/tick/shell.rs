//! Stage 3 of the tick: the particle sub-steps, with the forces on the active particles before
//! each (the coupling springs to the core faces, the tool on the skin over them, the confinement
//! wall), and the shell's shedding when its step fails.

use super::TickReport;
use crate::error::StepError;
use crate::math::{is_finite3, Vec3};
use crate::meshfree;
use crate::parallel::Fork;
use crate::runtime::sim::Sim;
use crate::runtime::skin::{self, NearLists};
use crate::runtime::stability::stretch_bound;
use crate::runtime::state::{SimState, SimWorkspace};

/// Stage 3, the particle sub-steps (Verlet, as many as the shell's stability needs: [`substeps`]):
/// before each, the coupling springs to the core faces ([`crate::runtime::coupling`]), the tool's
/// penalty contact on the skin over the active particles ([`crate::runtime::tool`]) and the
/// confinement wall ([`crate::runtime::confinement`]). The tool's centre moves linearly from
/// `prev` to `tool` over the sub-steps. What the particles send to the core is spread into
/// `ws.f_core` (the sub-step average); returns the tool's force (the sub-step average) \[N\].
///
/// If the shell's step fails (diverging or non-finite: a press it cannot follow, see
/// [`crate::runtime::stability`]), it is taken again with twice the sub-steps ([`RETRIES`]); if
/// that fails too, the shell is shed: every particle back at its tie, no region
/// active, the shell off for a pause ([`crate::runtime::SimOptions::shell_fallback`]; without
/// it, the error), and the skin the particles carried fades back to its ties
/// (`skin::SkinLift`).
#[allow(clippy::too_many_arguments)]
pub(super) fn step(
    sim: &Sim,
    state: &mut SimState,
    ws: &mut SimWorkspace,
    prev: Vec3,
    tool: Vec3,
    tool_v: Vec3,
    dt: f64,
    fork: &dyn Fork,
    report: &mut TickReport,
) -> Result<Vec3, StepError> {
    ws.f_core.iter_mut().for_each(|f| *f = Vec3::zeros());
    if state.particles.active.is_empty() {
        return Ok(Vec3::zeros());
    }
    let k = substeps(sim, &state.particles, ws, dt);
    let tri_count = state.activation.triangle_counts();
    let rest = &sim.hybrid.particles;
    sim.confinement
        .slacks(&sim.hybrid.grid, &sim.hybrid.voxel_owner, tri_count, rest, &state.particles.active, &mut ws.slacks);
    // Most particles are well inside their regions: the sub-steps look only at those that
    // moved farther than their free radius since the tick's start (the same forces, cheaper).
    for &p in &state.particles.active {
        ws.x0[p] = state.particles.x[p] - ws.anchors[p];
        ws.free[p] = sim.confinement.free_radius(&sim.hybrid.grid, &sim.hybrid.voxel_owner, tri_count, &ws.x0[p], ws.slacks[p]);
    }
    let held = sim.particles.fixed();
    ws.held_active.clear();
    ws.held_active.extend(state.particles.active.iter().copied().filter(|&p| held[p]));
    // What the sub-steps send to the core is gathered per particle (`to_core`, through its
    // tie) and per skin vertex (`skin_to_core`) and spread once after them: the core does not
    // move within a tick, so the spread of the sum is the sum of the spreads (`sub_steps`).
    // A step that fails is taken again with twice the sub-steps (RETRIES times, within the cap)
    // before the shell is shed: the count is set from the stretch at the tick's start, and under
    // a press far through the wall the shell can stiffen within the tick past what it allowed.
    let mut k = k;
    let mut retries = RETRIES;
    let (stepped, tool_force) = loop {
        let (stepped, tool_force) = sub_steps(sim, state, ws, prev, tool, tool_v, k, dt, fork, report);
        if stepped.is_ok() || retries == 0 || 2 * k > sim.options.max_substeps {
            break (stepped, tool_force);
        }
        // Nothing of a failed step reaches the core (the buffers start the next try empty).
        clear_sent(state, ws);
        (retries, k) = (retries - 1, 2 * k);
    };
    match stepped {
        Err(e) => {
            clear_sent(state, ws);
            let Some(pause) = sim.options.shell_fallback else { return Err(e) };
            let off_ticks = crate::runtime::sim::ticks_in(pause, dt);
            shed(sim, state, ws, off_ticks, dt, report);
            Ok(Vec3::zeros())
        }
        Ok(_) => {
            report.substeps = k;
            Ok(spread_reactions(sim, state, ws, k, tool_force))
        }
    }
}

/// How many times a failed shell step is taken again with twice the sub-steps before the shell
/// is shed. Measured (2026-12-08): the 2 N press driven 20 mm through the paper's ellipsoids
/// (`tests/runtime_hand.rs`, the tool past the 7 mm wall, 1,000-1,400 particles active) diverged
/// at 20 mm with the core under the shell at the build's active factor, and held with one retry.
pub const RETRIES: usize = 1;

/// Zero what the particles were to send to the core (`to_core`, `skin_to_core`).
fn clear_sent(state: &SimState, ws: &mut SimWorkspace) {
    for &p in &state.particles.active {
        ws.to_core[p] = Vec3::zeros();
    }
    for &v in &ws.near {
        ws.skin_to_core[v] = Vec3::zeros();
    }
}

/// `k` sub-steps of the active particles with their forces ([`SubStepForces`]); returns the
/// step's result and the tool's force summed over the sub-steps \[N\].
#[allow(clippy::too_many_arguments)]
fn sub_steps(
    sim: &Sim,
    state: &mut SimState,
    ws: &mut SimWorkspace,
    prev: Vec3,
    tool: Vec3,
    tool_v: Vec3,
    k: usize,
    dt: f64,
    fork: &dyn Fork,
    report: &mut TickReport,
) -> (Result<meshfree::ParticleStepReport, StepError>, Vec3) {
    let tri_count = state.activation.triangle_counts();
    let mut forces = SubStepForces {
        sim,
        tri_count,
        prev,
        tool,
        tool_v,
        substeps: k,
        shift: &ws.anchors,
        slacks: &ws.slacks,
        x0: &ws.x0,
        free: &ws.free,
        x_rest: &mut ws.x_rest,
        f_wall: &mut ws.f_wall,
        wall_check: &mut ws.wall_check,
        held_active: &ws.held_active,
        tie_x: &ws.tie_x,
        tie_v: &ws.tie_v,
        to_core: &mut ws.to_core,
        skin_to_core: &mut ws.skin_to_core,
        lists: NearLists { near: &ws.near, ptr: &ws.near_ptr, items: &ws.near_items, base: &ws.near_base },
        tool_force: Vec3::zeros(),
        report,
    };
    let stepped = meshfree::step_with_fork(&sim.particles, &mut state.particles, &mut ws.particles, dt, k, fork, |sub, f| forces.apply(sub, f));
    (stepped, forces.tool_force)
}

/// The forces on the active particles before a sub-step (the callback of
/// [`meshfree::step_with_fork`]), and what they send to the core and the tool.
struct SubStepForces<'a, 'r> {
    sim: &'a Sim,
    tri_count: &'a [u32],
    /// The tool's centre at the tick's start and end \[m\], its velocity \[m/s\], and the tick's
    /// sub-steps (the centre moves linearly over them).
    prev: Vec3,
    tool: Vec3,
    tool_v: Vec3,
    substeps: usize,
    /// Per particle: the anchor (its tie's displacement), the confinement's slack, the rest-frame
    /// position at the tick's start and the radius it may move from it before the wall looks.
    shift: &'a [Vec3],
    slacks: &'a [f64],
    x0: &'a [Vec3],
    free: &'a [f64],
    x_rest: &'a mut [Vec3],
    f_wall: &'a mut [Vec3],
    wall_check: &'a mut Vec<usize>,
    held_active: &'a [usize],
    tie_x: &'a [Vec3],
    tie_v: &'a [Vec3],
    to_core: &'a mut [Vec3],
    skin_to_core: &'a mut [Vec3],
    lists: NearLists<'a>,
    /// The tool's force summed over the sub-steps \[N\].
    tool_force: Vec3,
    report: &'r mut TickReport,
}

impl SubStepForces<'_, '_> {
    fn apply(&mut self, sub: &meshfree::SubStep<'_>, f: &mut [Vec3]) {
        let c = self.prev + ((sub.index + 1) as f64 / self.substeps as f64) * (self.tool - self.prev);
        self.springs(sub, f);
        self.tool_on_skin(sub, f, &c);
        self.wall(f);
        // Held particles (lone lattice particles, see Sim::new) do not move: what acts on
        // them is carried by the core, through their ties.
        for &p in self.held_active {
            self.to_core[p] += f[p];
        }
    }

    /// The coupling springs ([`crate::runtime::coupling`]) and, in the same pass (one sweep of
    /// the active list a sub-step, not two), the particles the wall must look at.
    fn springs(&mut self, sub: &meshfree::SubStep<'_>, f: &mut [Vec3]) {
        let sim = self.sim;
        self.wall_check.clear();
        for &p in sub.active {
            f[p] = if sim.coupled[p] {
                let fc = sim.coupling.force(&self.tie_x[p], &self.tie_v[p], &sub.x[p], &sub.v[p]);
                self.to_core[p] -= fc;
                fc
            } else {
                Vec3::zeros()
            };
            self.x_rest[p] = sub.x[p] - self.shift[p];
            if (self.x_rest[p] - self.x0[p]).norm_squared() < self.free[p] * self.free[p] {
                continue;
            }
            self.f_wall[p] = Vec3::zeros();
            self.wall_check.push(p);
        }
    }

    /// The tool, centred at `c`, meets the skin over the active particles, and the skin carries
    /// the force to the particles under it: a surface, so the tool cannot slip between particles.
    fn tool_on_skin(&mut self, sub: &meshfree::SubStep<'_>, f: &mut [Vec3], c: &Vec3) {
        let (sim, lists) = (self.sim, &self.lists);
        let mut count = 0;
        for (k, &v) in lists.near.iter().enumerate() {
            let items = &lists.items[lists.ptr[k]..lists.ptr[k + 1]];
            let (mut xs, mut vs) = lists.base[k];
            for &(p, w) in items {
                xs += w * sub.x[p];
                vs += w * sub.v[p];
            }
            if let Some(contact) = sim.tool.sample(sim.skin_area[v]).contact(c, &self.tool_v, &xs, &vs) {
                // The transpose of the placement: `w_p` of the force to each particle under,
                // the skin tie's share to the core less the particles' ties' shares.
                self.skin_to_core[v] += contact.force;
                for &(p, w) in items {
                    f[p] += w * contact.force;
                    self.to_core[p] -= w * contact.force;
                }
                self.tool_force -= contact.force;
                count += 1;
                self.report.max_depth = self.report.max_depth.max(contact.depth);
            }
        }
        self.report.particle_contacts = self.report.particle_contacts.max(count);
    }

    /// The confinement wall ([`crate::runtime::confinement`]) on the particles [`Self::springs`]
    /// listed. The wall belongs to the core's regions: its reaction goes to the core through the
    /// particle's tie (momentum stays exact).
    fn wall(&mut self, f: &mut [Vec3]) {
        let (sim, hybrid) = (self.sim, &self.sim.hybrid);
        let wall = sim.confinement.apply(
            &hybrid.grid,
            &hybrid.voxel_owner,
            self.tri_count,
            self.x_rest,
            &hybrid.particles,
            Some(self.slacks),
            self.wall_check,
            self.f_wall,
        );
        self.report.confined = self.report.confined.max(wall.pushed);
        if wall.pushed > 0 {
            for &p in self.wall_check.iter() {
                f[p] += self.f_wall[p];
                self.to_core[p] -= self.f_wall[p];
            }
        }
    }
}

/// The shell shed after a failed step: every particle back at its tie, no region active, the
/// shell off `off_ticks` ticks (of `dt` \[s\], which also counts the skin's fade); the tick goes on with the core and the skin, so the hand still
/// feels the organ (the skin contact of stage 4) rather than nothing. The skin the particles
/// carried stays where they left it and fades back to its ties (`skin::SkinLift`): put back
/// at once, the force jumped.
fn shed(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace, off_ticks: u64, dt: f64, report: &mut TickReport) {
    let SimState { core, particles, skin, activation, ticks, is_active, live, shell_off_until, lift, .. } = state;
    let tie = &sim.particle_tie;
    for &p in &particles.active {
        is_active[p] = false;
        particles.x[p] = tie.position_framed(p, &core.x, &ws.frames);
        particles.v[p] = tie.velocity_framed(p, &core.v, &ws.rates);
    }
    report.left += particles.active.len();
    lift.clear();
    (lift.start, lift.ticks) = (*ticks, skin::shed_fade_ticks(&sim.options, dt));
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
    // Saturating: a pause of any finite length (SimOptions::check) is a count of ticks.
    *shell_off_until = ticks.saturating_add(1).saturating_add(off_ticks);
    (report.shell_failed, report.active, report.particle_contacts, report.confined) = (true, 0, 0, 0);
}

/// After a good step: what the sub-steps sent to the core (their average over the `k` sub-steps)
/// and the ring's reactions spread into `ws.f_core`; returns the tool's force, the sub-step
/// average of `tool_force` \[N\].
fn spread_reactions(sim: &Sim, state: &SimState, ws: &mut SimWorkspace, k: usize, tool_force: Vec3) -> Vec3 {
    let (tie, core) = (&sim.particle_tie, &state.core);
    let inv_k = 1.0 / k as f64;
    for &p in &state.particles.active {
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
    // The ring: frozen neighbours (at their ties) and held active particles (lone lattice
    // particles, see Sim::new): both carried by the core.
    for (&j, &f) in ws.particles.ring().iter().zip(ws.particles.ring_forces()) {
        tie.spread(j, f, &core.x, &mut ws.f_core);
    }
    tool_force * inv_k
}

/// The sub-steps this tick needs ([`crate::runtime::stability`]): the active particles' largest stretch at
/// the start of the tick, and the tool's largest share of a particle over the skin vertices
/// within its reach (`ws.near`, their lists from `skin::near_tool`).
fn substeps(sim: &Sim, particles: &meshfree::ParticleState, ws: &mut SimWorkspace, dt: f64) -> usize {
    let held = sim.particles.fixed();
    let stretch2 = particles
        .active
        .iter()
        .filter(|&&p| !held[p])
        .map(|&p| stretch_bound(&sim.particles.deformation_gradient(p, &particles.x)))
        .fold(1.0, f64::max);
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
