//! What the servo steps: [`Physics`], one tick of a simulation with a position-driven tool, and
//! its implementations: [`HybridPhysics`] (the hybrid runtime, `palpate_core::runtime`),
//! [`FemPhysics`] (a full-FEM body, `palpate_core::fem`), and [`Wall`] and [`Idle`] (a rigid
//! half-space and nothing: the tests' and the idle loop's).

use palpate_core::hybrid::{file, HybridModel};
use palpate_core::math::is_finite3;
use palpate_core::parallel::{Fork, Serial};
use palpate_core::runtime::{finish_tick, tick_force_with, Sim, SimOptions, SimState, SimWorkspace, Tool};
use palpate_core::{step, Material, Model, ModelError, State, StepError, Vec3, Workspace};

use crate::pool::SpinPool;
use crate::surface_contact::{self, AreaTool, SurfaceContact};

/// Who the simulation is, for a recording: replaying against another model (or the same model
/// with another material or options) would not give the recorded forces.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// A 64-bit digest (FNV-1a) of the model file's bytes (less the build's timings), the
    /// material and the options.
    pub digest: u64,
    /// A short human-readable description (kind, sizes).
    pub description: String,
}

/// One tick of a simulation whose tool is driven by position. Implementations allocate nothing
/// in [`Physics::tick`] (the servo thread's rule); [`Physics::checkpoint`] may (see
/// [`HybridPhysics`]).
pub trait Physics: Send {
    /// Moves the simulated tool toward `tool` \[m\] (world frame) and advances `dt` \[s\];
    /// returns the force on the tool \[N\] (the tissue's reaction, what a device renders). On
    /// error the simulation is as it was before the tick.
    fn tick(&mut self, tool: &Vec3, dt: f64) -> Result<Vec3, StepError>;
    /// The part of the last tick that its force does not depend on, done once the force is sent
    /// (the servo calls it after the send, before a checkpoint). A tick that finds it undone does
    /// it first, so calling it or not changes no result, only when the work is done. On error
    /// the caller restores the last good state (the tick's force was already given). Default:
    /// nothing (the whole tick is in [`Physics::tick`]).
    fn finish(&mut self) -> Result<(), StepError> {
        Ok(())
    }
    /// Where the simulated tool is \[m\] (`None` before the first tick).
    fn tool(&self) -> Option<Vec3>;
    /// The simulated tool's top speed \[m/s\] (the coupling's proxy is held to it, so proxy and
    /// simulated tool stay one point, whatever the tick's length).
    fn max_tool_speed(&self) -> f64 {
        f64::INFINITY
    }
    /// Makes now what the first tick of `dt` \[s\] would make (an implicit integrator's
    /// factorisation: 1.3-1.5 s on a 50,000-tet body), so that the loop's first tick is not late
    /// by it. Changes no result; `true` if it did work. The loops call it before their first
    /// tick (`HapticCore::prepare`, `PhysicsLoop::new`). Default: nothing to make.
    fn prepare(&mut self, _dt: f64) -> Result<bool, StepError> {
        Ok(false)
    }
    /// Keeps the current state as the last good one.
    fn checkpoint(&mut self);
    /// Goes back to the last good state (the initial state if no checkpoint was taken).
    fn restore(&mut self);
    /// Points of the organ's surface a viewer draws (\[m\], world frame), copied into `out`
    /// without allocating (its length is [`Physics::surface_len`]); default none.
    fn surface(&self, _out: &mut [Vec3]) {}
    /// How many points [`Physics::surface`] gives (0: none).
    fn surface_len(&self) -> usize {
        0
    }
    /// Points inside the organ a viewer draws (\[m\], world frame): the core's nodes, then the
    /// active particles, copied into the start of `out` without allocating; returns how many
    /// (at most `out.len()`, which is [`Physics::interior_capacity`]). Default none.
    fn interior(&self, _out: &mut [Vec3]) -> usize {
        0
    }
    /// The most points [`Physics::interior`] gives (0: none).
    fn interior_capacity(&self) -> usize {
        0
    }
    /// Is every number of the state finite? (Checked by the servo only after a fault or at a
    /// checkpoint: it reads the whole state.)
    fn is_finite(&self) -> bool;
    fn identity(&self) -> Identity;
}

/// The hybrid runtime (FEM core, particle shell, skin) as the servo's physics.
///
/// The last good state is a copy of [`SimState`] made by `clone_from`, which reuses the copy's
/// arrays (allocation-free once warm) and shares the immutable region tables: 77 us on the Rodero
/// ventricle, where a fresh clone took 2.5 ms (measured 2026-11-26; `tests/checkpoint.rs` in the
/// core). The servo takes one every [`crate::ServoConfig::checkpoint_every`] ticks (default 250),
/// with a scan of the state for non-finite numbers (60 us there).
pub struct HybridPhysics {
    sim: Sim,
    state: SimState,
    ws: SimWorkspace,
    good: SimState,
    identity: Identity,
    /// Helpers for the particle passes ([`HybridPhysics::with_threads`]); `None`: one thread.
    pool: Option<SpinPool>,
}

impl HybridPhysics {
    /// Compiles `model` with `material` and `options` ([`Sim::new`]); the state at rest.
    pub fn new(model: HybridModel, material: Material, options: SimOptions) -> Result<HybridPhysics, ModelError> {
        // The model file's bytes without the build's timings (the same geometry built twice
        // must have one identity).
        let mut digest = {
            let mut m = model.clone();
            m.stats = Default::default();
            m.homogenisation.seconds = 0.0;
            file::checksum(&file::to_bytes(&m))
        };
        let extra = format!("{material:?} {options:?}");
        digest ^= file::checksum(extra.as_bytes()).rotate_left(1);
        let sim = Sim::new(model, material, options)?;
        let description = format!(
            "hybrid: {} core nodes, {} core tets, {} particles, {} outer vertices; E = {} Pa, nu = {}, rho = {} kg/m^3; tool radius {} m",
            sim.core.n_nodes(),
            sim.core.n_tets(),
            sim.n_particles(),
            sim.hybrid.outer_points.len(),
            material.young(),
            material.poisson(),
            material.density(),
            options.tool.radius
        );
        Ok(HybridPhysics::from_sim(sim, Identity { digest, description }))
    }

    /// From a compiled simulation (its identity given by the caller).
    pub fn from_sim(sim: Sim, identity: Identity) -> HybridPhysics {
        let state = SimState::rest(&sim);
        let ws = SimWorkspace::new(&sim);
        let good = state.clone();
        HybridPhysics { sim, state, ws, good, identity, pool: None }
    }

    /// Split the particle passes of each tick over `threads` threads (the servo's and
    /// `threads - 1` helpers of a [`SpinPool`], under `SCHED_FIFO` when `realtime`, as the servo
    /// should be). The ticks are bitwise those of one thread ([`palpate_core::parallel`]), so
    /// recordings replay alike either way; only their time changes. 1 (the default) starts no
    /// thread.
    pub fn with_threads(mut self, threads: usize, realtime: bool) -> std::io::Result<HybridPhysics> {
        self.pool = if threads > 1 { Some(SpinPool::new(threads, realtime)?) } else { None };
        Ok(self)
    }

    /// Threads a tick's particle passes run on (1 without helpers).
    pub fn threads(&self) -> usize {
        self.pool.as_ref().map_or(1, |p| p.ways())
    }

    pub fn sim(&self) -> &Sim {
        &self.sim
    }
    pub fn state(&self) -> &SimState {
        &self.state
    }
    /// The state, to change between ticks (fault injection in tests, a reset).
    pub fn state_mut(&mut self) -> &mut SimState {
        &mut self.state
    }
}

impl Physics for HybridPhysics {
    fn tick(&mut self, tool: &Vec3, dt: f64) -> Result<Vec3, StepError> {
        let fork: &dyn Fork = match &self.pool {
            Some(pool) => {
                // The helpers wake while the tick's serial start (activation, ties) runs.
                pool.wake();
                pool
            }
            None => &Serial,
        };
        // The skin's update, and the core's step when the tool has nothing of the core within
        // reach, are left owed (runtime::tick_force_with): `finish` pays them after the send, out
        // of the time to the deadline.
        tick_force_with(&self.sim, &mut self.state, &mut self.ws, *tool, dt, fork).map(|r| r.force)
    }
    /// What the last tick owes (`runtime::finish_tick`): the skin's update (40-90 us on the
    /// Rodero ventricle, and a slice of a sweep of the far skin when one runs), and the core's
    /// step when the tool had nothing of the core within reach (~20% of a pressing tick).
    fn finish(&mut self) -> Result<(), StepError> {
        finish_tick(&self.sim, &mut self.state, &mut self.ws).map(|_| ())
    }
    fn prepare(&mut self, dt: f64) -> Result<bool, StepError> {
        self.ws.prepare(&self.sim, dt)
    }
    fn tool(&self) -> Option<Vec3> {
        self.state.tool
    }
    fn max_tool_speed(&self) -> f64 {
        self.sim.options.max_tool_speed
    }
    fn checkpoint(&mut self) {
        self.good.clone_from(&self.state);
    }
    /// The skin as the state holds it: fresh within reach of the tool, elsewhere as of its last
    /// whole update (every 32 ticks, `runtime::tick::SKIN_REFRESH_TICKS`): a copy, not the
    /// whole skin's recomputation (`Sim::skin_positions`, too costly for the servo thread on a
    /// 31,788-vertex skin).
    fn surface(&self, out: &mut [Vec3]) {
        out.copy_from_slice(&self.state.skin);
    }
    fn surface_len(&self) -> usize {
        self.state.skin.len()
    }
    /// The core's nodes (all of them, in the model's order), then the active particles as
    /// simulated (in the order of the active set).
    fn interior(&self, out: &mut [Vec3]) -> usize {
        let core = &self.state.core.x;
        let nc = core.len().min(out.len());
        out[..nc].copy_from_slice(&core[..nc]);
        let mut n = nc;
        for (o, &p) in out[nc..].iter_mut().zip(self.state.particles.active.iter()) {
            *o = self.state.particles.x[p];
            n += 1;
        }
        n
    }
    fn interior_capacity(&self) -> usize {
        self.state.core.x.len() + self.state.particles.x.len()
    }
    fn restore(&mut self) {
        self.state.clone_from(&self.good);
    }
    fn is_finite(&self) -> bool {
        let f = |v: &[Vec3]| v.iter().all(|p| p.iter().all(|c| c.is_finite()));
        f(&self.state.core.x) && f(&self.state.core.v) && f(&self.state.particles.x) && f(&self.state.particles.v) && f(&self.state.skin)
    }
    fn identity(&self) -> Identity {
        self.identity.clone()
    }
}

/// Options of [`FemPhysics`]: the tool, its contact with the surface, and how far it moves in a
/// tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FemOptions {
    /// The rigid sphere's radius \[m\].
    pub radius: f64,
    /// The most penalty stiffness per unit of surface area `k_a` \[N/m^3\]; each tick takes the
    /// least of this and what keeps the explicit contact stable ([`FemPhysics::contact_tool`],
    /// capped further where the surface in reach is more than a flat disc).
    /// `None`: [`default_area_stiffness`] of the model's material and the radius.
    pub area_stiffness: Option<f64>,
    /// The most approach damping per unit area \[N s/m^3\] (infinite: ratio
    /// [`FEM_CONTACT_DAMPING_RATIO`] of critical at the stability bound, the default).
    pub area_damping: f64,
    /// The simulated tool's top speed \[m/s\] (the hybrid runtime's default).
    pub max_tool_speed: f64,
}

impl Default for FemOptions {
    fn default() -> Self {
        FemOptions {
            radius: palpate_core::runtime::tool::DEFAULT_RADIUS,
            area_stiffness: None,
            area_damping: f64::INFINITY,
            max_tool_speed: SimOptions::default().max_tool_speed,
        }
    }
}

/// `omega^2 h^2` of the contact on the node it loads most at the tick's `dt` (see
/// [`FemPhysics`]): a quarter of the explicit limit of 4.
pub const FEM_CONTACT_STABILITY: f64 = 1.0;
/// Damping ratio of the contact (of critical, at the stability bound).
pub const FEM_CONTACT_DAMPING_RATIO: f64 = 0.5;
pub use palpate_core::runtime::tool::AREA_STIFFNESS_PER_E_OVER_R;

/// The default penalty stiffness per unit area \[N/m^3\] for a tissue of `material` under a
/// sphere of `radius` \[m\]: `12 E* / R` ([`AreaTool::default_stiffness`], the hybrid's too; the
/// mesh's resolution is not counted: on the protocol meshes the stability bound sets the
/// stiffness far below it).
/// At 1 kHz on the protocol meshes the stability bound is lower (see [`FemPhysics`]), and sets
/// the stiffness.
pub fn default_area_stiffness(material: &Material, radius: f64) -> f64 {
    AreaTool::default_stiffness(material, radius, f64::INFINITY)
}

/// A full-FEM body (`palpate_core::fem`, stepped by [`palpate_core::step`] with the model's
/// integrator) as the servo's physics, touched by a rigid sphere on its boundary surface.
///
/// # The contact
/// One contact model: the sphere against the mesh's boundary **triangles**
/// ([`crate::surface_contact`]), a penalty per unit of surface area `k_a` integrated by sample
/// points spaced at most a third of the radius on every boundary triangle, each sample's force
/// spread to its triangle's nodes by its barycentric weights (the transpose of its
/// interpolation: the nodal forces are minus the penalty energy's gradient). The force depends
/// on how deep the sphere is in the surface, not on where the nodes are: a press between two
/// nodes 15 mm apart feels as a press on a node, deeper presses push harder, and a slide is
/// smooth. (It replaces a penalty on the boundary nodes alone, under which the sphere slipped
/// between nodes on meshes as coarse as the tool: no force between nodes, a node sliding off the
/// sphere near 0.7 N on `ellipsoid_192`, ~0.06 N at most under a 6 mm press on lv_1350 before the
/// sphere sank through.) Rejected: nearest-point contact against the triangles (one point per
/// triangle): its force jumps where the nearest triangle changes and it has no area, so its
/// stiffness would not scale with the patch pressed.
///
/// The forces are computed at the tool's end-of-tick centre and the start-of-tick positions and
/// held as the nodes' external force over the step (as the hybrid tick does on its core's
/// surface); the tool receives exactly minus their sum (summed over the nodes, in node order).
///
/// # Stability
/// A force held over an implicit step is explicit, so it is stable while its `omega h` stays
/// below 2 on every node it acts on: the backward-Euler system's compliance at a node is at most
/// `dt^2 / m` (its matrix is `M` plus positive semi-definite terms). The contact's `omega^2` on
/// node `a` is at most `k_a G_a / m_a` (Gershgorin; `G_a` the area of its samples in contact,
/// weighted by their barycentric weight at it), so each tick takes
/// `k_a = min(area_stiffness, FEM_CONTACT_STABILITY min_a (m_a / G_a) / dt^2)` over the free
/// boundary nodes, `G_a` bounded two ways ([`crate::surface_contact`]): once for the whole
/// surface by a flat disc a little wider than the tool ([`FemPhysics::contact_tool`], which
/// sets the stiffness everywhere but where a deep press wraps the surface around the sphere),
/// and each tick by the samples within reach of the tool. Damping of ratio
/// [`FEM_CONTACT_DAMPING_RATIO`] (`(omega h)^2 + 2 (2 zeta omega h) <= 3 < 4`: symplectic
/// Euler's limit with damping): any servo rate (250 Hz to 4 kHz) is stable.
///
/// # The price, measured (1 kHz, myocardium, the 5 mm tool)
/// The stability bound, not the tissue, sets the stiffness, 35-60x below
/// [`default_area_stiffness`]'s 8.6e7 N/m^3: `k_a` = 1.4e6 N/m^3 on lv_1350, 2.3e6 on
/// `ellipsoid_192`, 1.5e6 on a slab with 15 mm cells (`tests/fem_physics.rs` prints them).
/// At that stiffness the surface hardly moves under the tool, and the sphere sinks into it by
/// about the whole press; a sphere sunk `D` into a flat surface pushes
/// `pi k_a (R - D) D^2` (the samples' radial forces turn sideways as the centre nears the
/// surface), most at `D = 2 R / 3`: ~0.085 N on lv_1350 (a 6 mm press peaks there, then the
/// sphere sinks through the wall; the nodes-only contact peaked at ~0.06 N), ~0.15 N under a
/// 15 mm press on `ellipsoid_192` (the nodes-only contact reached ~0.7 N on its probe node
/// before the node slid off, and nothing between nodes). The node-only contact spent the same
/// per-node budget `m / dt^2` on one point at full depth; spread over a patch whose mean depth
/// is a fraction of the press it pushes less, but the same everywhere. The contact softens with
/// finer meshes and faster rates (lighter nodes, shorter ticks), and is 16x stiffer at 250 Hz.
/// Lifting the bound needs the contact inside the implicit step (its penalty in the step's
/// incremental potential, `palpate_core::integrate::potential`), where `k_a` could be the
/// tissue-matched default: not a better explicit bound.
///
/// # State
/// The last good state is a copy made by `clone_from` (allocation-free once warm); a failed step
/// leaves the state as before the tick (`step` restores positions and velocities, the tick puts
/// the external forces back).
pub struct FemPhysics {
    model: Model,
    state: State,
    ws: Workspace,
    good: State,
    options: FemOptions,
    /// The requested stiffness per unit area (the options' or the default) \[N/m^3\].
    area_stiffness: f64,
    /// The boundary nodes, ascending: the surface's points.
    boundary: Vec<usize>,
    /// The boundary triangles and their contact samples.
    contact: SurfaceContact,
    /// The lightest free boundary node's mass per contact area \[kg/m^2\].
    mass_per_area: f64,
    /// The contact forces of the tick being computed, swapped with `state.f_ext` for the step.
    forces: Vec<Vec3>,
    tool: Option<Vec3>,
    good_tool: Option<Vec3>,
    identity: Identity,
}

impl FemPhysics {
    /// The body `model` at rest, touched by `options`' tool.
    pub fn new(model: Model, options: FemOptions) -> Result<FemPhysics, ModelError> {
        let o = &options;
        let k = o.area_stiffness.unwrap_or_else(|| default_area_stiffness(model.material(), o.radius));
        for (name, value, ok, reason) in [
            ("tool radius", o.radius, o.radius > 0.0 && o.radius.is_finite(), "must be positive and finite [m]"),
            ("tool area stiffness", k, k > 0.0 && !k.is_nan(), "must be positive [N/m^3] (infinite: the stability bound)"),
            ("tool area damping", o.area_damping, o.area_damping >= 0.0, "must be >= 0 [N s/m^3] (infinite: the stability bound's)"),
            ("max tool speed", o.max_tool_speed, o.max_tool_speed > 0.0, "must be positive [m/s]"),
        ] {
            if !ok {
                return Err(ModelError::Parameter { name, value, reason });
            }
        }
        let faces = model.mesh().boundary_faces();
        let mut boundary: Vec<usize> = faces.iter().flatten().copied().collect();
        boundary.sort_unstable();
        boundary.dedup();
        let contact = SurfaceContact::new(model.mesh().points(), faces, o.radius)?;
        let identity = fem_identity(&model, &options);
        let state = State::rest(&model);
        let ws = Workspace::new(&model);
        let good = state.clone();
        let forces = vec![Vec3::zeros(); model.n_nodes()];
        let (m, share) = (model.masses(), contact.area_shares());
        let disc = std::f64::consts::PI * (o.radius * (1.0 + surface_contact::REACH_MARGIN)).powi(2);
        let mass_per_area = boundary
            .iter()
            .filter(|&&i| !model.fixed()[i] && share[i] > 0.0)
            .map(|&i| m[i] / share[i].min(disc))
            .fold(f64::INFINITY, f64::min);
        Ok(FemPhysics {
            model,
            state,
            ws,
            good,
            options,
            area_stiffness: k,
            boundary,
            contact,
            mass_per_area,
            forces,
            tool: None,
            good_tool: None,
            identity,
        })
    }

    pub fn model(&self) -> &Model {
        &self.model
    }
    pub fn state(&self) -> &State {
        &self.state
    }
    /// The state, to change between ticks (fault injection in tests).
    pub fn state_mut(&mut self) -> &mut State {
        &mut self.state
    }
    /// The boundary nodes in ascending order: the order of [`Physics::surface`]'s points
    /// (`numpy.unique` of the mesh's boundary faces).
    pub fn boundary_nodes(&self) -> &[usize] {
        &self.boundary
    }
    /// The boundary triangles and their contact samples.
    pub fn surface_contact(&self) -> &SurfaceContact {
        &self.contact
    }
    /// The requested stiffness per unit area \[N/m^3\] (the options' or the default), before the
    /// stability cap.
    pub fn area_stiffness(&self) -> f64 {
        self.area_stiffness
    }
    /// The lightest free boundary node's mass per contact area \[kg/m^2\], `min_a m_a / G_a` with
    /// `G_a` the smaller of the area its samples carry and a flat disc of radius
    /// `R (1 + REACH_MARGIN)` (infinite if no boundary node is free): the surface's one
    /// stiffness bound ([`crate::surface_contact`]).
    pub fn mass_per_area(&self) -> f64 {
        self.mass_per_area
    }

    /// The contact in a tick of `dt` \[s\] with the tool nowhere in particular: the options'
    /// radius, the stiffness and damping per unit area capped by the surface's one stability
    /// bound (the tick may cap it further where the surface within reach is more than a flat
    /// disc; type docs).
    pub fn contact_tool(&self, dt: f64) -> AreaTool {
        self.capped(self.mass_per_area, dt)
    }

    fn capped(&self, rho: f64, dt: f64) -> AreaTool {
        let k = self.area_stiffness.min(FEM_CONTACT_STABILITY * rho / (dt * dt));
        let k = if k.is_finite() { k } else { 0.0 };
        let c = self.options.area_damping.min(Tool::damping_for(k, rho, FEM_CONTACT_DAMPING_RATIO));
        AreaTool { radius: self.options.radius, stiffness: k, damping: c }
    }

    /// The contact for a tick of `dt` with the tool at `centre`: [`FemPhysics::contact_tool`],
    /// capped further by the samples in reach; leaves the faces in reach in `self.contact`.
    fn tick_contact(&mut self, centre: &Vec3, dt: f64) -> AreaTool {
        let r = self.options.radius;
        self.contact.find_near(centre, &self.state.x, r * (1.0 + surface_contact::REACH_MARGIN));
        let rho = self.contact.reach_mass_per_area(r, centre, &self.state.x, self.model.masses(), self.model.fixed());
        self.capped(rho.min(self.mass_per_area), dt)
    }
}

/// The model's digest (FNV-1a, as the hybrid file's checksum) over its rest mesh, fixed nodes,
/// masses, gravity, material, integrator and the options.
fn fem_identity(model: &Model, options: &FemOptions) -> Identity {
    let mut bytes: Vec<u8> = Vec::with_capacity(8 * (3 * model.n_nodes() + 4 * model.n_tets() + 2 * model.n_nodes()));
    for p in model.mesh().points() {
        p.iter().for_each(|c| bytes.extend_from_slice(&c.to_le_bytes()));
    }
    for t in model.mesh().tets() {
        t.iter().for_each(|&i| bytes.extend_from_slice(&(i as u64).to_le_bytes()));
    }
    bytes.extend(model.fixed().iter().map(|&f| f as u8));
    model.masses().iter().for_each(|m| bytes.extend_from_slice(&m.to_le_bytes()));
    let material = model.material();
    bytes.extend_from_slice(format!("{:?} {:?} {material:?} {:?} {options:?}", model.gravity(), model.integrator(), model.fixed().len()).as_bytes());
    let description = format!(
        "full FEM: {} nodes ({} fixed), {} tets; E = {} Pa, nu = {}, rho = {} kg/m^3; tool radius {} m",
        model.n_nodes(),
        model.fixed().iter().filter(|&&f| f).count(),
        model.n_tets(),
        material.young(),
        material.poisson(),
        material.density(),
        options.radius
    );
    Identity { digest: file::checksum(&bytes), description }
}

impl Physics for FemPhysics {
    fn prepare(&mut self, dt: f64) -> Result<bool, StepError> {
        self.ws.prepare(&self.model, dt)
    }
    fn tick(&mut self, tool: &Vec3, dt: f64) -> Result<Vec3, StepError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(StepError::BadTimeStep(dt));
        }
        if !is_finite3(tool) {
            return Err(StepError::NonFiniteTool);
        }
        let prev = self.tool.unwrap_or(*tool);
        // The simulated tool follows the device at most at `max_tool_speed` (as the hybrid's).
        let at = prev + (tool - prev).cap_magnitude(self.options.max_tool_speed * dt);
        let tool_v = (at - prev) / dt;
        self.forces.iter_mut().for_each(|f| *f = Vec3::zeros());
        let contact = self.tick_contact(&at, dt);
        self.contact.apply(&contact, &at, &tool_v, &self.state.x, &self.state.v, &mut self.forces);
        // The tool's force: minus the nodes' sum, in node order (exactly the reaction).
        let force_on_tool = -self.forces.iter().fold(Vec3::zeros(), |a, f| a + f);
        // The contact forces become the step's external force; on failure the previous ones
        // come back (the state as before the tick).
        std::mem::swap(&mut self.state.f_ext, &mut self.forces);
        if let Err(e) = step(&self.model, &mut self.state, &mut self.ws, dt) {
            std::mem::swap(&mut self.state.f_ext, &mut self.forces);
            return Err(e);
        }
        self.tool = Some(at);
        Ok(force_on_tool)
    }
    fn tool(&self) -> Option<Vec3> {
        self.tool
    }
    fn max_tool_speed(&self) -> f64 {
        self.options.max_tool_speed
    }
    fn checkpoint(&mut self) {
        self.good.clone_from(&self.state);
        self.good_tool = self.tool;
    }
    fn restore(&mut self) {
        self.state.clone_from(&self.good);
        self.tool = self.good_tool;
    }
    /// The boundary nodes as simulated, in ascending node order ([`FemPhysics::boundary_nodes`]).
    fn surface(&self, out: &mut [Vec3]) {
        for (o, &i) in out.iter_mut().zip(&self.boundary) {
            *o = self.state.x[i];
        }
    }
    fn surface_len(&self) -> usize {
        self.boundary.len()
    }
    /// Every node, in the mesh's order.
    fn interior(&self, out: &mut [Vec3]) -> usize {
        let n = self.state.x.len().min(out.len());
        out[..n].copy_from_slice(&self.state.x[..n]);
        n
    }
    fn interior_capacity(&self) -> usize {
        self.state.x.len()
    }
    fn is_finite(&self) -> bool {
        let f = |v: &[Vec3]| v.iter().all(is_finite3);
        f(&self.state.x) && f(&self.state.v) && self.tool.is_none_or(|t| is_finite3(&t))
    }
    fn identity(&self) -> Identity {
        self.identity.clone()
    }
}

/// A rigid half-space `{x : (x - point) . normal < 0}` pushing a point tool out with a spring
/// `stiffness` \[N/m\] and an approach damper `damping` \[N s/m\]: stiff contact whose exact
/// energy is known (the passivity and safety tests), with the runtime's bounded tool step.
#[derive(Debug, Clone)]
pub struct Wall {
    pub point: Vec3,
    /// Unit outward normal.
    pub normal: Vec3,
    pub stiffness: f64,
    pub damping: f64,
    /// The tool's top speed \[m/s\] (as the runtime's `max_tool_speed`).
    pub max_speed: f64,
    tool: Option<Vec3>,
    good: Option<Vec3>,
}

impl Wall {
    pub fn new(point: Vec3, normal: Vec3, stiffness: f64, damping: f64) -> Wall {
        Wall {
            point,
            normal: normal.normalize(),
            stiffness,
            damping,
            max_speed: SimOptions::default().max_tool_speed,
            tool: None,
            good: None,
        }
    }
}

impl Physics for Wall {
    fn tick(&mut self, tool: &Vec3, dt: f64) -> Result<Vec3, StepError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(StepError::BadTimeStep(dt));
        }
        if !tool.iter().all(|c| c.is_finite()) {
            return Err(StepError::NonFiniteTool);
        }
        let prev = self.tool.unwrap_or(*tool);
        let x = prev + (tool - prev).cap_magnitude(self.max_speed * dt);
        let depth = -(x - self.point).dot(&self.normal);
        let approach = -(x - prev).dot(&self.normal) / dt;
        self.tool = Some(x);
        Ok(if depth > 0.0 {
            self.normal * (self.stiffness * depth + self.damping * approach.max(0.0))
        } else {
            Vec3::zeros()
        })
    }
    fn tool(&self) -> Option<Vec3> {
        self.tool
    }
    fn max_tool_speed(&self) -> f64 {
        self.max_speed
    }
    fn checkpoint(&mut self) {
        self.good = self.tool;
    }
    fn restore(&mut self) {
        self.tool = self.good;
    }
    fn is_finite(&self) -> bool {
        self.tool.is_none_or(|t| t.iter().all(|c| c.is_finite()))
    }
    fn identity(&self) -> Identity {
        let d = format!("wall {:?} {:?} k {} c {} speed {}", self.point, self.normal, self.stiffness, self.damping, self.max_speed);
        Identity { digest: file::checksum(d.as_bytes()), description: d }
    }
}

/// No simulation: zero force, the tool where the device is. The idle loop (what the clock and
/// the scheduler alone do to the period) for the benchmark.
#[derive(Debug, Clone, Default)]
pub struct Idle {
    tool: Option<Vec3>,
}

impl Physics for Idle {
    fn tick(&mut self, tool: &Vec3, _dt: f64) -> Result<Vec3, StepError> {
        self.tool = Some(*tool);
        Ok(Vec3::zeros())
    }
    fn tool(&self) -> Option<Vec3> {
        self.tool
    }
    fn checkpoint(&mut self) {}
    fn restore(&mut self) {}
    fn is_finite(&self) -> bool {
        true
    }
    fn identity(&self) -> Identity {
        Identity { digest: 0, description: "idle".into() }
    }
}
