//! The mutable state of a hybrid simulation ([`SimState`]) and the scratch space of its tick
//! ([`SimWorkspace`]), sized once so that a tick allocates nothing (as [`crate::State`] and
//! [`crate::Workspace`] for the FEM body).

use super::activation::Activation;
use super::sim::Sim;
use crate::fem::{State, Workspace};
use crate::math::Vec3;
use crate::meshfree::{ParticleState, ParticleWorkspace};

/// What changes in a hybrid simulation. Positions \[m\], velocities \[m/s\], world frame.
#[derive(Debug, Clone)]
pub struct SimState {
    /// The FEM core.
    pub core: State,
    /// Every shell particle; `particles.active` is the active set. Inactive particles' positions
    /// are current only where the tick reads them (the ring around the active set); use
    /// [`Sim::particle_positions`] for all of them.
    pub particles: ParticleState,
    /// The outer surface's vertices (the skin) \[m\]: after the last tick near the tool (within
    /// [`super::tick::SKIN_LIVE_MARGIN`] of its reach), elsewhere as of the last whole update
    /// (every [`super::tick::SKIN_REFRESH_TICKS`] ticks); [`super::Sim::skin_positions`] gives the
    /// whole skin fresh.
    pub skin: Vec<Vec3>,
    /// The simulated tool's centre after the last tick \[m\] (`None` before the first): the
    /// device's position, followed at a bounded speed ([`super::SimOptions::max_tool_step`]).
    pub tool: Option<Vec3>,
    /// The active regions, with their hysteresis.
    pub activation: Activation,
    /// Ticks taken.
    pub ticks: u64,
    /// Per particle: in the active set?
    pub(crate) is_active: Vec<bool>,
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
            activation: Activation::new(&sim.hybrid, sim.options.linger_ticks),
            ticks: 0,
            is_active: vec![false; sim.n_particles()],
        }
    }

    /// Simulated time \[s\].
    pub fn time(&self) -> f64 {
        self.core.t
    }
}

/// Scratch space of [`super::tick`].
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
    /// Skin vertices over active triangles within the tool's reach this tick.
    pub(crate) near: Vec<usize>,
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
    /// Per outer vertex, the last tick (plus one) it was over an active triangle.
    pub(crate) over: Vec<u64>,
    pub(crate) skin_to_core: Vec<Vec3>,
}

impl SimWorkspace {
    /// Scratch space for `sim`.
    pub fn new(sim: &Sim) -> SimWorkspace {
        let n = sim.n_particles();
        let mut particles = ParticleWorkspace::new(&sim.particles);
        particles.set_ring_forces(true); // the ring's reactions go to the core (momentum)
        SimWorkspace {
            core: Workspace::new(&sim.core),
            particles,
            f_core: vec![Vec3::zeros(); sim.core.n_nodes()],
            anchors: vec![Vec3::zeros(); n],
            x_rest: vec![Vec3::zeros(); n],
            f_wall: vec![Vec3::zeros(); n],
            slacks: vec![0.0; n],
            save: Vec::with_capacity(n),
            near: Vec::with_capacity(sim.hybrid.outer_points.len()),
            contact_share: vec![0.0; n],
            tie_x: vec![Vec3::zeros(); n],
            tie_v: vec![Vec3::zeros(); n],
            // Each particle lies under one outer triangle, whose three vertices may be near.
            near_ptr: Vec::with_capacity(sim.hybrid.outer_points.len() + 1),
            near_items: Vec::with_capacity(3 * n),
            near_base: Vec::with_capacity(sim.hybrid.outer_points.len()),
            to_core: vec![Vec3::zeros(); n],
            frames: vec![None; sim.hybrid.core_faces.len()],
            rates: vec![crate::math::Mat3::zeros(); sim.hybrid.core_faces.len()],
            over: vec![0; sim.hybrid.outer_points.len()],
            skin_to_core: vec![Vec3::zeros(); sim.hybrid.outer_points.len()],
        }
    }
}
