//! The mutable state of a hybrid simulation ([`SimState`]) and the scratch space of its tick
//! ([`SimWorkspace`]), sized once so that a tick allocates nothing (as [`crate::State`] and
//! [`crate::Workspace`] for the FEM body).

use super::activation::Activation;
use super::sim::{ticks_in, Sim, TICK};
use super::skin::{shed_fade_ticks, LiveSkin, SkinLift};
use crate::error::StepError;
use crate::fem::{State, StepMemory, Workspace};
use crate::math::Vec3;
use crate::meshfree::{ParticleState, ParticleWorkspace};

/// What changes in a hybrid simulation. Positions \[m\], velocities \[m/s\], world frame.
/// `clone_from` onto a state of the same simulation allocates nothing once the destination's
/// arrays are large enough (the haptic loop's checkpoints and restores: a derived `Clone` made
/// a checkpoint of the Rodero ventricle's state 2.5 ms of fresh allocations).
#[derive(Debug)]
pub struct SimState {
    /// The FEM core.
    pub core: State,
    /// Every shell particle; `particles.active` is the active set. Inactive particles' positions
    /// are current only where the tick reads them (the ring around the active set); use
    /// [`Sim::particle_positions`] for all of them.
    pub particles: ParticleState,
    /// The outer surface's vertices (the skin) \[m\]: after the last tick near the tool (within
    /// [`super::skin::SKIN_LIVE_MARGIN`] of its reach) and over active particles, elsewhere
    /// within that margin of their place (see `LiveSkin`); [`super::Sim::skin_positions`]
    /// gives the whole skin fresh.
    pub skin: Vec<Vec3>,
    /// The simulated tool's centre after the last tick \[m\] (`None` before the first): the
    /// device's position, followed at a bounded speed ([`super::SimOptions::max_tool_speed`]).
    pub tool: Option<Vec3>,
    /// The active regions, with their hysteresis.
    pub activation: Activation,
    /// Ticks taken.
    pub ticks: u64,
    /// Per particle: in the active set?
    pub(crate) is_active: Vec<bool>,
    /// The shell is off (no region activates) until `ticks` reaches this, after a failed shell
    /// step ([`super::SimOptions::shell_fallback`]); 0: on.
    pub(crate) shell_off_until: u64,
    /// The skin's lift off its ties after a shed shell, fading (see [`SkinLift`]).
    pub(crate) lift: SkinLift,
    /// The skin vertices the tick looks at between whole updates (see [`LiveSkin`]).
    pub(crate) live: LiveSkin,
    /// The last tick's skin update is still to do ([`super::tick_force_with`] leaves it owed,
    /// [`super::finish_tick`] or the next tick pays it).
    pub(crate) skin_owed: bool,
    /// The last tick's core step is still to do, with this `dt` \[s\] and the reactions already
    /// in `core.f_ext` (owed when the tool had no contact with the core or its skin: the force
    /// did not depend on the step).
    pub(crate) core_owed: Option<f64>,
    /// The last tick's length \[s\] ([`super::sim::TICK`] before the first): the tool's step bound
    /// for the skin's lists, and the ticks of a shed shell's fade.
    pub(crate) dt: f64,
}

impl Clone for SimState {
    fn clone(&self) -> Self {
        SimState {
            core: self.core.clone(),
            particles: self.particles.clone(),
            skin: self.skin.clone(),
            tool: self.tool,
            activation: self.activation.clone(),
            ticks: self.ticks,
            is_active: self.is_active.clone(),
            live: self.live.clone(),
            shell_off_until: self.shell_off_until,
            lift: self.lift.clone(),
            skin_owed: self.skin_owed,
            core_owed: self.core_owed,
            dt: self.dt,
        }
    }
    fn clone_from(&mut self, s: &Self) {
        // Exhaustive: a new field is a compile error here until it is copied.
        let SimState { core, particles, skin, tool, activation, ticks, is_active, live, shell_off_until, lift, skin_owed, core_owed, dt } = self;
        core.clone_from(&s.core);
        particles.clone_from(&s.particles);
        skin.clone_from(&s.skin);
        *tool = s.tool;
        activation.clone_from(&s.activation);
        *ticks = s.ticks;
        is_active.clone_from(&s.is_active);
        live.clone_from(&s.live);
        *shell_off_until = s.shell_off_until;
        *skin_owed = s.skin_owed;
        *core_owed = s.core_owed;
        *dt = s.dt;
        lift.offset.clone_from(&s.lift.offset);
        lift.list.clone_from(&s.lift.list);
        (lift.start, lift.ticks) = (s.lift.start, s.lift.ticks);
    }
}

impl SimState {
    /// At rest: the core and the shell at their rest positions, no particle active.
    pub fn rest(sim: &Sim) -> SimState {
        let mut particles = ParticleState::rest(&sim.particles);
        particles.active.clear();
        SimState {
            core: State::rest(&sim.core),
            particles,
            skin: sim.hybrid.outer_points.clone(),
            tool: None,
            activation: Activation::new(&sim.hybrid, ticks_in(sim.options.linger, TICK)),
            ticks: 0,
            is_active: vec![false; sim.n_particles()],
            shell_off_until: 0,
            lift: SkinLift::new(sim.hybrid.outer_points.len()),
            live: LiveSkin::at_rest(sim),
            skin_owed: false,
            core_owed: None,
            dt: TICK,
        }
    }

    /// Simulated time \[s\].
    pub fn time(&self) -> f64 {
        self.core.t
    }

    /// What this state and the workspace `ws` that ticked it carry to the next tick, as plain
    /// values ([`SimSnapshot`]): [`SimState::restore`] makes a state and workspace whose ticks
    /// repeat those that followed it bit for bit.
    pub fn snapshot(&self, ws: &SimWorkspace) -> SimSnapshot {
        SimSnapshot {
            time: self.core.t,
            ticks: self.ticks,
            core_x: self.core.x.clone(),
            core_v: self.core.v.clone(),
            core_memory: ws.core.memory(),
            particle_x: self.particles.x.clone(),
            particle_v: self.particles.v.clone(),
            skin: self.skin.clone(),
            tool: self.tool,
            last_touched: self.activation.last_touched().to_vec(),
            regions: self.activation.active_regions().to_vec(),
            live: self.live.valid.then(|| self.live.list.clone()),
            carried: self.live.carried.clone(),
            live_ref_x: self.live.ref_x.clone(),
            live_ref_tool: self.live.ref_tool,
            live_slack: self.live.slack,
            sweep: self.live.sweep_next.map(|next| SkinSweep { next, ref_x: self.live.sweep_ref_x.clone(), slack: self.live.sweep_slack }),
            shell_off_until: self.shell_off_until,
            skin_lift: self.lift.list.iter().map(|&v| (v, self.lift.offset[v as usize])).collect(),
            skin_lift_start: self.lift.start,
            skin_owed: self.skin_owed,
            core_owed: self.core_owed.map(|dt| (dt, self.core.f_ext.clone())),
            dt: self.dt,
        }
    }

    /// The state and workspace of `snap` (from [`SimState::snapshot`] of a simulation compiled
    /// from the same model, material and options): one factorisation of the core's matrix (see
    /// [`Workspace::restore_memory`]), the rest copies. What a snapshot leaves out is either
    /// scratch a tick rewrites before reading it or follows from what it keeps (the active
    /// particles from the active regions, the skin's reference frames from its reference
    /// positions: the same function of the same values). Errors: a size that does not fit `sim`,
    /// an index out of range, a non-finite position, a failed factorisation.
    pub fn restore(sim: &Sim, snap: &SimSnapshot) -> Result<(SimState, SimWorkspace), StepError> {
        let bad = |what: String| StepError::Snapshot(what);
        let (n_core, n_p, n_skin) = (sim.core.n_nodes(), sim.n_particles(), sim.hybrid.outer_points.len());
        let sizes = [
            ("core positions", snap.core_x.len(), n_core),
            ("core velocities", snap.core_v.len(), n_core),
            ("particle positions", snap.particle_x.len(), n_p),
            ("particle velocities", snap.particle_v.len(), n_p),
            ("skin", snap.skin.len(), n_skin),
            ("skin flags", snap.carried.len(), n_skin),
            ("skin reference", snap.live_ref_x.len(), n_core),
        ];
        for (what, got, want) in sizes {
            if got != want {
                return Err(bad(format!("{what}: {got} rows, the simulation has {want}")));
            }
        }
        for (what, v) in [
            ("core positions", &snap.core_x),
            ("core velocities", &snap.core_v),
            ("particle positions", &snap.particle_x),
            ("particle velocities", &snap.particle_v),
            ("skin", &snap.skin),
            ("skin reference", &snap.live_ref_x),
        ] {
            if let Some(i) = v.iter().position(|x| !x.iter().all(|c| c.is_finite())) {
                return Err(bad(format!("{what}: row {i} is not finite")));
            }
        }
        if !snap.time.is_finite() || !snap.tool.is_none_or(|c| c.iter().all(|x| x.is_finite())) || !snap.live_ref_tool.iter().all(|x| x.is_finite()) {
            return Err(bad("time or tool position not finite".into()));
        }
        if !(snap.live_slack >= 0.0 && snap.live_slack.is_finite()) {
            return Err(bad(format!("skin slack {} m: must be finite and not negative", snap.live_slack)));
        }
        if let Some(sw) = &snap.sweep {
            if sw.next >= n_skin || sw.ref_x.len() != n_core || !(sw.slack >= 0.0 && sw.slack.is_finite()) {
                return Err(bad(format!(
                    "skin sweep: next vertex {} of {n_skin}, reference of {} rows of {n_core}, slack {}",
                    sw.next,
                    sw.ref_x.len(),
                    sw.slack
                )));
            }
            if let Some(i) = sw.ref_x.iter().position(|x| !x.iter().all(|c| c.is_finite())) {
                return Err(bad(format!("skin sweep reference: row {i} is not finite")));
            }
        }
        if let Some(&(v, d)) = snap.skin_lift.iter().find(|&&(v, d)| v as usize >= n_skin || !d.iter().all(|c| c.is_finite())) {
            return Err(bad(format!("skin lift: vertex {v} ({n_skin} vertices), offset {d:?} m: out of range or not finite")));
        }
        if let Some(list) = &snap.live {
            if let Some(&v) = list.iter().find(|&&v| v as usize >= n_skin) {
                return Err(bad(format!("live skin vertex {v} out of range ({n_skin} vertices)")));
            }
        }
        let mut state = SimState::rest(sim);
        state.activation.restore(&snap.last_touched, &snap.regions).map_err(bad)?;
        let mut ws = SimWorkspace::new(sim);
        ws.core.restore_memory(&sim.core, &snap.core_memory)?;
        state.core.x.clone_from(&snap.core_x);
        state.core.v.clone_from(&snap.core_v);
        state.core.t = snap.time;
        state.particles.x.clone_from(&snap.particle_x);
        state.particles.v.clone_from(&snap.particle_v);
        state.particles.t = snap.time;
        state.particles.active.extend_from_slice(state.activation.active());
        for &p in &state.particles.active {
            state.is_active[p] = true;
        }
        state.skin.clone_from(&snap.skin);
        state.tool = snap.tool;
        state.ticks = snap.ticks;
        state.shell_off_until = snap.shell_off_until;
        state.skin_owed = snap.skin_owed && snap.tool.is_some();
        if let Some((dt, f)) = &snap.core_owed {
            if !(*dt > 0.0 && dt.is_finite() && f.len() == n_core && f.iter().all(|x| x.iter().all(|c| c.is_finite())) && state.skin_owed) {
                return Err(bad(format!("owed core step: dt {dt} s, {} forces of {n_core} (finite, with the skin owed too)", f.len())));
            }
            state.core.f_ext.clone_from(f);
            state.core_owed = Some(*dt);
        }
        state.lift.start = snap.skin_lift_start;
        if !(snap.dt > 0.0 && snap.dt.is_finite()) {
            return Err(bad(format!("tick length {} s (must be positive and finite)", snap.dt)));
        }
        state.dt = snap.dt;
        state.lift.ticks = shed_fade_ticks(&sim.options, snap.dt);
        for &(v, d) in &snap.skin_lift {
            if state.lift.offset[v as usize] == Vec3::zeros() && d != Vec3::zeros() {
                state.lift.list.push(v);
            }
            state.lift.offset[v as usize] = d;
        }
        let live = &mut state.live;
        live.carried.clone_from(&snap.carried);
        live.ref_x.clone_from(&snap.live_ref_x);
        live.ref_tool = snap.live_ref_tool;
        if let Some(list) = &snap.live {
            for &v in list {
                if !live.member[v as usize] {
                    live.member[v as usize] = true;
                    live.list.push(v);
                }
            }
            live.list.sort_unstable();
            live.valid = true;
            super::embed::face_frames(&live.ref_x, &sim.hybrid.core_faces, &mut live.ref_frames);
        }
        live.slack = snap.live_slack;
        if let Some(sw) = &snap.sweep {
            live.sweep_next = Some(sw.next);
            live.sweep_ref_x.clone_from(&sw.ref_x);
            live.sweep_slack = sw.slack;
            super::embed::face_frames(&live.sweep_ref_x, &sim.hybrid.core_faces, &mut live.sweep_ref_frames);
        }
        Ok((state, ws))
    }
}

/// A hybrid simulation's state as plain values ([`SimState::snapshot`], [`SimState::restore`]):
/// what a tick carries to the next. Positions \[m\], velocities \[m/s\], world frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSnapshot {
    /// Simulated time \[s\] and ticks taken.
    pub time: f64,
    pub ticks: u64,
    /// The core's nodes, and its integrator's memory.
    pub core_x: Vec<Vec3>,
    pub core_v: Vec<Vec3>,
    pub core_memory: StepMemory,
    /// Every particle (the inactive ones where the last tick left them).
    pub particle_x: Vec<Vec3>,
    pub particle_v: Vec<Vec3>,
    /// The stored skin ([`SimState::skin`]: stale within a margin away from the tool).
    pub skin: Vec<Vec3>,
    /// The simulated tool's centre (`None` before the first tick).
    pub tool: Option<Vec3>,
    /// The activation's hysteresis: each region's last contact tick (`u64::MAX`: never) and the
    /// active regions in their order ([`Activation::last_touched`], [`Activation::active_regions`]).
    pub last_touched: Vec<u64>,
    pub regions: Vec<u32>,
    /// The skin's bookkeeping (`LiveSkin`): the vertices a tick looks at (`None` before the
    /// first tick: the list is then built around that tick's tool), per vertex whether particles carry it, the core's positions at
    /// the last whole update and the tool's centre at the last rebuild of the list. What it
    /// skips is proven not to change a force; it is kept so that a restored tick does the same
    /// work as the original (without it, a restored state's first tick would update the whole
    /// skin).
    pub live: Option<Vec<u32>>,
    pub carried: Vec<bool>,
    pub live_ref_x: Vec<Vec3>,
    pub live_ref_tool: Vec3,
    /// The skin's slack \[m\] and the sweep in progress, if any (see `LiveSkin`).
    pub live_slack: f64,
    pub sweep: Option<SkinSweep>,
    /// The tick the shell may return at after a failed shell step (0: on; see
    /// [`super::SimOptions::shell_fallback`]).
    pub shell_off_until: u64,
    /// The skin's lift off its ties after a shed shell: `(vertex, offset [m])` pairs and the shed
    /// tick (see `SkinLift`; empty: none).
    pub skin_lift: Vec<(u32, Vec3)>,
    pub skin_lift_start: u64,
    /// The last tick's skin update is still owed (a state taken between
    /// [`super::tick_force_with`] and [`super::finish_tick`]; false after a whole tick).
    pub skin_owed: bool,
    /// The last tick's core step too, when owed: its `dt` \[s\] and the core's external forces
    /// \[N\] (`(n_core)`, world frame: the shell's reactions it steps under).
    pub core_owed: Option<(f64, Vec<Vec3>)>,
    /// The last tick's length \[s\] ([`super::sim::TICK`] before the first; a state of a loop
    /// ticking at 250 Hz has 4 ms): the time-valued options ([`super::SimOptions::linger`], the
    /// shed shell's fade) count ticks of it.
    pub dt: f64,
}

/// A sweep of the whole skin in progress ([`SimSnapshot::sweep`]): the next vertex it places,
/// the core's positions \[m\] when it began, and the skin's travel from them so far \[m\].
#[derive(Debug, Clone, PartialEq)]
pub struct SkinSweep {
    pub next: usize,
    pub ref_x: Vec<Vec3>,
    pub slack: f64,
}

/// Scratch space of [`super::tick()`].
#[derive(Debug, Clone)]
pub struct SimWorkspace {
    pub(crate) core: Workspace,
    pub(crate) particles: ParticleWorkspace,
    /// Forces on the core nodes summed over the sub-steps \[N\] (divided by their count).
    pub(crate) f_core: Vec<Vec3>,
    /// Each active particle's tie displacement this tick \[m\] (confinement's frame).
    pub(crate) anchors: Vec<Vec3>,
    /// Active particles' positions less their tie displacement \[m\] (per sub-step).
    pub(crate) x_rest: Vec<Vec3>,
    /// The confinement wall's force on each active particle (per sub-step) \[N\].
    pub(crate) f_wall: Vec<Vec3>,
    /// Confinement slack of each active particle this tick \[m\] (see [`super::confinement`]).
    pub(crate) slacks: Vec<f64>,
    /// Each active particle's rest-frame position at the tick's start \[m\] and how far from it
    /// the wall surely leaves it alone \[m\] ([`super::Confinement::free_radius`]); the particles
    /// of a sub-step that moved farther (the only ones the wall looks at).
    pub(crate) x0: Vec<Vec3>,
    pub(crate) free: Vec<f64>,
    pub(crate) wall_check: Vec<usize>,
    /// The held (lone) particles among the active ones this tick.
    pub(crate) held_active: Vec<usize>,
    /// Ticks run with this workspace: the stamp of this tick's marks (`placed`, `over`).
    pub(crate) epoch: u64,
    /// Per particle, the stamp of the last tick it was put at its tie as part of the ring.
    pub(crate) placed: Vec<u64>,
    /// Skin vertices over active triangles within the tool's reach this tick.
    pub(crate) near: Vec<usize>,
    /// Skin vertices and core faces within reach of the tool for the core's implicit contact;
    /// the near skin vertices no particle carries (weightless: at their ties).
    pub(crate) reach: Vec<usize>,
    pub(crate) core_reach: Vec<usize>,
    pub(crate) uncarried: Vec<usize>,
    /// Start-of-tick positions and velocities of the active particles (rollback).
    pub(crate) save: Vec<(Vec3, Vec3)>,
    /// Per particle, the tool contact's Gershgorin row sum `sum_v w_p / (W_v m_p)` \[1/kg\]
    /// (zero outside a tick).
    pub(crate) contact_share: Vec<f64>,
    /// Each active particle's tie position \[m\] and velocity \[m/s\] this tick, and each near skin
    /// vertex's; what the sub-steps send to the core per particle and per skin vertex \[N\]
    /// (summed over the sub-steps, spread once; zero outside a tick).
    pub(crate) tie_x: Vec<Vec3>,
    pub(crate) tie_v: Vec<Vec3>,
    /// The near skin vertices' placement over the particles this tick (see `tick.rs`'s
    /// `NearLists`): per vertex a range of `(particle, weight)` and a base position and velocity.
    pub(crate) near_ptr: Vec<usize>,
    pub(crate) near_items: Vec<(usize, f64)>,
    pub(crate) near_base: Vec<(Vec3, Vec3)>,
    pub(crate) to_core: Vec<Vec3>,
    /// The core faces' frames and their rates (at the tick's start; the frames again at its end,
    /// for the skin's update).
    pub(crate) frames: Vec<Option<crate::math::Mat3>>,
    pub(crate) rates: Vec<crate::math::Mat3>,
    /// Per outer vertex, the stamp of the last tick it was over an active triangle.
    pub(crate) over: Vec<u64>,
    pub(crate) skin_to_core: Vec<Vec3>,
    /// The core tets brought to the build's active factor this tick (`homogenised_core.rs`),
    /// and the tick's marks on core nodes and tets.
    pub(crate) soft_tets: Vec<(usize, f64)>,
    /// The core's predicted positions `x0 + dt v0` of the shell's implicit reactions
    /// (`exchange.rs`), `(n_core_nodes)`.
    pub(crate) predicted: Vec<Vec3>,
    pub(crate) node_marks: Vec<u64>,
    pub(crate) tet_marks: Vec<u64>,
}

impl SimWorkspace {
    /// Scratch space for `sim`.
    /// Factorise the core's matrix for ticks of `dt` \[s\] now, ahead of the first tick at that
    /// `dt` (which would otherwise make it: a stall of the factorisation's time in the first
    /// tick). Changes no result, only when the work is done; `true` if it factorised (false: the
    /// factor was held already). See [`crate::Workspace::prepare`].
    pub fn prepare(&mut self, sim: &Sim, dt: f64) -> Result<bool, crate::error::StepError> {
        self.core.prepare(&sim.core, dt)
    }

    pub fn new(sim: &Sim) -> SimWorkspace {
        let n = sim.n_particles();
        let mut particles = ParticleWorkspace::new(&sim.particles);
        particles.set_ring_forces(true); // the ring's reactions go to the core (momentum)
        SimWorkspace {
            core: {
                // The shell's coupling springs, offered to the core's factor as terms
                // (super::exchange): room for all of them, so that the tick allocates nothing.
                let mut w = Workspace::new(&sim.core);
                w.reserve_stiffness_terms(sim.coupled.iter().filter(|&&c| c).count());
                w
            },
            particles,
            f_core: vec![Vec3::zeros(); sim.core.n_nodes()],
            anchors: vec![Vec3::zeros(); n],
            x_rest: vec![Vec3::zeros(); n],
            f_wall: vec![Vec3::zeros(); n],
            slacks: vec![0.0; n],
            x0: vec![Vec3::zeros(); n],
            free: vec![0.0; n],
            wall_check: Vec::with_capacity(n),
            held_active: Vec::with_capacity(n),
            epoch: 0,
            placed: vec![0; n],
            save: Vec::with_capacity(n),
            near: Vec::with_capacity(sim.hybrid.outer_points.len()),
            reach: Vec::with_capacity(2 * sim.hybrid.outer_points.len()),
            core_reach: Vec::with_capacity(sim.hybrid.core_faces.len()),
            uncarried: Vec::with_capacity(sim.hybrid.outer_points.len()),
            contact_share: vec![0.0; n],
            tie_x: vec![Vec3::zeros(); n],
            tie_v: vec![Vec3::zeros(); n],
            // Each particle carries the vertices its triangle is a carrier of (SkinCarriers).
            near_ptr: Vec::with_capacity(sim.hybrid.outer_points.len() + 1),
            near_items: Vec::with_capacity(sim.skin_carriers.max_items.max(3 * n)),
            near_base: Vec::with_capacity(sim.hybrid.outer_points.len()),
            to_core: vec![Vec3::zeros(); n],
            frames: vec![None; sim.hybrid.core_faces.len()],
            rates: vec![crate::math::Mat3::zeros(); sim.hybrid.core_faces.len()],
            over: vec![0; sim.hybrid.outer_points.len()],
            skin_to_core: vec![Vec3::zeros(); sim.hybrid.outer_points.len()],
            soft_tets: Vec::with_capacity(sim.core.n_tets()),
            predicted: vec![Vec3::zeros(); sim.core.n_nodes()],
            node_marks: vec![0; sim.core.n_nodes()],
            tet_marks: vec![0; sim.core.n_tets()],
        }
    }
}
