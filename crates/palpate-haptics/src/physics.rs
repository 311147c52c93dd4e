//! What the servo steps: [`Physics`], one tick of a simulation with a position-driven tool, and
//! its implementations: [`HybridPhysics`] (the hybrid runtime, `palpate_core::runtime`), and
//! [`Wall`] and [`Idle`] (a rigid half-space and nothing: the tests' and the idle loop's).

use palpate_core::hybrid::{file, HybridModel};
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::{Material, ModelError, StepError, Vec3};

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
