//! What the servo steps: [`Physics`], one tick of a simulation with a position-driven tool, and
//! its implementations: [`HybridPhysics`] (the hybrid runtime, `palpate_core::runtime`),
//! [`FemPhysics`] (a full-FEM body, `palpate_core::fem`), and [`Wall`] and [`Idle`] (a rigid
//! half-space and nothing: the tests' and the idle loop's).

use palpate_core::hybrid::{file, HybridModel};
use palpate_core::math::is_finite3;
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace, Tool};
use palpate_core::{step, Material, Model, ModelError, State, StepError, Vec3, Workspace};

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
    /// Where the simulated tool is \[m\] (`None` before the first tick).
    fn tool(&self) -> Option<Vec3>;
    /// The most the simulated tool moves in a tick \[m\] (the coupling's proxy is held to it, so
    /// proxy and simulated tool stay one point).
    fn max_tool_step(&self) -> f64 {
        f64::INFINITY
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
}

impl HybridPhysics {
    /// Compiles `model` with `material` and `options` ([`Sim::new`]); the state at rest.
    pub fn new(model: HybridModel, material: Material, options: SimOptions) -> Result<HybridPhysics, ModelError> {
        // The model file's bytes without the build's timings (the same geometry built twice
        // must have one identity).
        let mut digest = {
            let mut m = model.clone();
            m.stats = Default::default();
            file::checksum(&file::to_bytes(&m))
        };
        let extra = format!("{material:?} {options:?}");
        digest ^= file::checksum(extra.as_bytes()).rotate_left(1);
        let sim = Sim::new(model, material, options)?;
        let description = format!(
            "hybrid: {} core nodes, {} core tets, {} particles, {} outer vertices; E = {} Pa, nu = {}, rho = {} kg/m^3; tool radius {} m",
            sim.core.n_nodes(), sim.core.n_tets(), sim.n_particles(), sim.hybrid.outer_points.len(), material.young(), material.poisson(), material.density(), options.tool.radius
        );
        Ok(HybridPhysics::from_sim(sim, Identity { digest, description }))
    }

    /// From a compiled simulation (its identity given by the caller).
    pub fn from_sim(sim: Sim, identity: Identity) -> HybridPhysics {
        let state = SimState::rest(&sim);
        let ws = SimWorkspace::new(&sim);
        let good = state.clone();
        HybridPhysics { sim, state, ws, good, identity }
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
        tick(&self.sim, &mut self.state, &mut self.ws, *tool, dt).map(|r| r.force)
    }
    fn tool(&self) -> Option<Vec3> {
        self.state.tool
    }
    fn max_tool_step(&self) -> f64 {
        self.sim.options.max_tool_step
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

/// Options of [`FemPhysics`]: the tool and how far it moves in a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FemOptions {
    /// The rigid sphere: radius \[m\], and the most penalty stiffness \[N/m\] and approach damping
    /// \[N s/m\] per boundary node; each tick takes the least of these and what keeps the
    /// explicit contact stable on the lightest free boundary node ([`FemPhysics::contact_tool`];
    /// the default: that bound alone).
    pub tool: Tool,
    /// The most the simulated tool moves in a tick \[m\] (the hybrid runtime's default).
    pub max_tool_step: f64,
}

impl Default for FemOptions {
    fn default() -> Self {
        FemOptions {
            tool: Tool { radius: palpate_core::runtime::tool::DEFAULT_RADIUS, stiffness: f64::INFINITY, damping: f64::INFINITY },
            max_tool_step: SimOptions::default().max_tool_step,
        }
    }
}

/// `omega^2 h^2` of the contact spring on the lightest free boundary node at the tick's `dt`
/// (see [`FemPhysics::contact_tool`]): half-way to the explicit limit of 4.
pub const FEM_CONTACT_STABILITY: f64 = 1.0;
/// Damping ratio of the contact (of critical, on the lightest free boundary node).
pub const FEM_CONTACT_DAMPING_RATIO: f64 = 0.5;

/// A full-FEM body (`palpate_core::fem`, stepped by [`palpate_core::step`] with the model's
/// integrator) as the servo's physics, touched by a rigid sphere on its boundary nodes.
///
/// # The contact
/// The tool is the hybrid runtime's [`Tool`]: the penalty of [`Tool::apply`] on the mesh's
/// boundary nodes, at the tool's end-of-tick centre, held as the nodes' external force over the
/// step (as the hybrid tick does on its core's surface); the tool receives exactly the opposite
/// of their sum. A force held over an implicit step is explicit, so it is stable while the
/// spring's `omega h = sqrt(k / m) dt` stays below 2 on every node it acts on: the backward-Euler
/// system's compliance at a node is at most `dt^2 / m` (its matrix is `M` plus positive
/// semi-definite terms), so `k <= 4 m_min / dt^2` bounds the loop on every contacted node at
/// once. Each tick takes `k = min(tool.stiffness, FEM_CONTACT_STABILITY m_min / dt^2)` with
/// `m_min` the lightest free boundary node, and damping of ratio [`FEM_CONTACT_DAMPING_RATIO`]
/// (`(omega h)^2 + 2 (2 zeta omega h) = 3 < 4`: symplectic Euler's limit with damping), so
/// any servo rate (250 Hz to 4 kHz) is stable. The price: the contact softens with finer
/// meshes and faster rates (lighter nodes, shorter ticks), and a node pushed by more than
/// `k R` passes through the sphere (the tool then sinks through a coarse mesh; no blow-up).
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
    /// The boundary nodes, ascending: the contact set and the surface's points.
    boundary: Vec<usize>,
    /// The lightest free boundary node's mass \[kg\] (infinite if none is free).
    min_mass: f64,
    /// The contact forces of the tick being computed, swapped with `state.f_ext` for the step.
    forces: Vec<Vec3>,
    tool: Option<Vec3>,
    good_tool: Option<Vec3>,
    identity: Identity,
}

impl FemPhysics {
    /// The body `model` at rest, touched by `options`' tool.
    pub fn new(model: Model, options: FemOptions) -> Result<FemPhysics, ModelError> {
        let t = &options.tool;
        for (name, value, ok, reason) in [
            ("tool radius", t.radius, t.radius > 0.0 && t.radius.is_finite(), "must be positive and finite [m]"),
            ("tool stiffness", t.stiffness, t.stiffness > 0.0, "must be positive [N/m] (infinite: the stability bound)"),
            ("tool damping", t.damping, t.damping >= 0.0, "must be >= 0 [N s/m] (infinite: the stability bound's)"),
            ("max tool step", options.max_tool_step, options.max_tool_step > 0.0, "must be positive [m]"),
        ] {
            if !ok {
                return Err(ModelError::Parameter { name, value, reason });
            }
        }
        let mut boundary: Vec<usize> = model.mesh().boundary_faces().iter().flatten().copied().collect();
        boundary.sort_unstable();
        boundary.dedup();
        let min_mass = boundary.iter().filter(|&&i| !model.fixed()[i]).map(|&i| model.masses()[i]).fold(f64::INFINITY, f64::min);
        let identity = fem_identity(&model, &options);
        let state = State::rest(&model);
        let ws = Workspace::new(&model);
        let good = state.clone();
        let forces = vec![Vec3::zeros(); model.n_nodes()];
        Ok(FemPhysics { model, state, ws, good, options, boundary, min_mass, forces, tool: None, good_tool: None, identity })
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
    /// The boundary nodes in ascending order: the contact set, and the order of
    /// [`Physics::surface`]'s points (`numpy.unique` of the mesh's boundary faces).
    pub fn boundary_nodes(&self) -> &[usize] {
        &self.boundary
    }

    /// The tool as it acts in a tick of `dt` \[s\]: the options' radius, the stiffness and damping
    /// capped by the explicit contact's stability on the lightest free boundary node (type docs).
    pub fn contact_tool(&self, dt: f64) -> Tool {
        let t = &self.options.tool;
        let k = t.stiffness.min(FEM_CONTACT_STABILITY * self.min_mass / (dt * dt));
        let c = t.damping.min(Tool::damping_for(k, self.min_mass, FEM_CONTACT_DAMPING_RATIO));
        Tool { radius: t.radius, stiffness: if k.is_finite() { k } else { 0.0 }, damping: c }
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
        model.n_nodes(), model.fixed().iter().filter(|&&f| f).count(), model.n_tets(), material.young(), material.poisson(), material.density(), options.tool.radius
    );
    Identity { digest: file::checksum(&bytes), description }
}

impl Physics for FemPhysics {
    fn tick(&mut self, tool: &Vec3, dt: f64) -> Result<Vec3, StepError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(StepError::BadTimeStep(dt));
        }
        if !is_finite3(tool) {
            return Err(StepError::NonFiniteTool);
        }
        let prev = self.tool.unwrap_or(*tool);
        // The simulated tool follows the device at most `max_tool_step` a tick (as the hybrid's).
        let at = prev + (tool - prev).cap_magnitude(self.options.max_tool_step);
        let tool_v = (at - prev) / dt;
        self.forces.iter_mut().for_each(|f| *f = Vec3::zeros());
        let sum = self.contact_tool(dt).apply(&at, &tool_v, &self.state.x, &self.state.v, &self.boundary, &mut self.forces);
        // The contact forces become the step's external force; on failure the previous ones
        // come back (the state as before the tick).
        std::mem::swap(&mut self.state.f_ext, &mut self.forces);
        if let Err(e) = step(&self.model, &mut self.state, &mut self.ws, dt) {
            std::mem::swap(&mut self.state.f_ext, &mut self.forces);
            return Err(e);
        }
        self.tool = Some(at);
        Ok(sum.force_on_tool)
    }
    fn tool(&self) -> Option<Vec3> {
        self.tool
    }
    fn max_tool_step(&self) -> f64 {
        self.options.max_tool_step
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
    /// The most the tool moves in a tick \[m\] (as the runtime's `max_tool_step`).
    pub max_step: f64,
    tool: Option<Vec3>,
    good: Option<Vec3>,
}

impl Wall {
    pub fn new(point: Vec3, normal: Vec3, stiffness: f64, damping: f64) -> Wall {
        Wall { point, normal: normal.normalize(), stiffness, damping, max_step: SimOptions::default().max_tool_step, tool: None, good: None }
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
        let x = prev + (tool - prev).cap_magnitude(self.max_step);
        let depth = -(x - self.point).dot(&self.normal);
        let approach = -(x - prev).dot(&self.normal) / dt;
        self.tool = Some(x);
        Ok(if depth > 0.0 { self.normal * (self.stiffness * depth + self.damping * approach.max(0.0)) } else { Vec3::zeros() })
    }
    fn tool(&self) -> Option<Vec3> {
        self.tool
    }
    fn max_tool_step(&self) -> f64 {
        self.max_step
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
        let d = format!("wall {:?} {:?} k {} c {} step {}", self.point, self.normal, self.stiffness, self.damping, self.max_step);
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
