//! The meshfree (particle) solid of paper §3.2: particles carrying the same continuum law as the
//! tetrahedra, usable alone (a particle body) and, in the hybrid issues, as the shell of the
//! paper's model.
//!
//! The particle body has the FEM body's shape: [`ParticleModelBuilder`] (`builder.rs`) compiles
//! an immutable [`ParticleModel`] (`model.rs`; its stable time step in `stability.rs`),
//! [`ParticleState`] and [`ParticleWorkspace`] (`state.rs`) hold what changes, and
//! [`step`]`(&model, &mut state, &mut workspace, dt)` (`step.rs`) advances it with the hot loop
//! of `pair_loop/`. `mass_scaling.rs`: optional selective mass scaling of the stiffest particles
//! (a longer stable step for the same statics; the hybrid shell uses it).
//!
//! ## Formulation (total Lagrangian, moving least squares)
//! Particle `i` has rest position `X_i`, mass `m_i`, density `rho_i` and volume `V_i = m_i / rho_i`
//! (eq. 25; the kernel sum is Shepard-normalised, `rho_i = sum_j m_j W_ij / sum_j (m_j/rho_0) W_ij`,
//! so that a uniform body has `rho_i = rho_0` up to its boundary, where a plain kernel sum is
//! deficient). Its neighbours `j` lie within the support radius `h` at rest, found once.
//!
//! The deformation gradient is the moving-least-squares fit of Mueller et al. 2004, which the
//! paper follows: with weights `w_ij = V_j W(|X_ij|, h)`, `X_ij = X_j - X_i`, the moment matrix
//! `A_i = sum_j w_ij X_ij X_ij^T` and the corrected gradients `g_ij = w_ij A_i^-1 X_ij`
//! (precomputed at rest),
//!
//! ```text
//! F_i = sum_j x_ij g_ij^T = I + sum_j u_ij g_ij^T,      Fdot_i = sum_j v_ij g_ij^T,
//! ```
//!
//! which is exact for every affine motion (`sum_j X_ij g_ij^T = I`). Green strain, elastic and
//! viscous stress are those of the FEM ([`crate::material`]), St. Venant-Kirchhoff law only: the
//! builder refuses a Neo-Hookean material with `MaterialError::UnsupportedLaw`.
//!
//! **Forces.** The elastic energy `U = sum_i V_i psi(F_i)` gives, exactly, `f = -dU/dx`:
//! each particle `i` exerts on each neighbour `j` the force `-V_i P_i g_ij` and on itself the
//! opposite, `P_i = F_i (S_i + S_v,i)`. This is eq. (29) (`sum_j sigma_j grad W_ij V_i V_j`) in a
//! total-Lagrangian, pairwise antisymmetric form: every interaction is an equal and opposite pair,
//! so linear momentum is conserved exactly (to round-off) and the forces of a rigid motion vanish.
//!
//! **Zero-energy modes.** Nodal integration of a particle gradient has modes with `F_i = I` at
//! every particle but non-affine neighbourhoods (hourglass / checkerboard modes). palpate's
//! safeguard is the hourglass control of Ganzenmueller 2015 (Comput. Methods Appl. Mech. Eng.
//! 286), written as an energy: `U_hg = sum_i c_i/2 sum_j w_ij |x_ij - F_i X_ij|^2`, the residual
//! of the very least-squares fit that defines `F_i`, with `c_i = kappa mu V_i / sum_j w_ij |X_ij|^2`.
//! Because `F_i` minimises that residual, its force is simply `-c_i w_ij e_ij` on `j` and the
//! opposite on `i` (`e_ij = x_ij - F_i X_ij`): energy-consistent, momentum-conserving, zero for
//! affine motions, and it penalises exactly the motions the gradient cannot see. `kappa` (default
//! [`DEFAULT_HOURGLASS`]) is dimensionless.
//!
//! **Active set and ring.** A step moves only `state.active` (the paper's active particles, §6);
//! the others are frozen and shape their active neighbours' `F` without carrying stress. The
//! pair forces being equal and opposite, the forces the active particles' stresses and
//! hourglass terms exert on the particles the step does not move (the *ring*: their inactive
//! neighbours and the fixed active particles) are exactly the momentum that leaves the active
//! set. With [`ParticleWorkspace::set_ring_forces`] on, a step reports them, averaged over its
//! sub-steps ([`ParticleWorkspace::ring`], [`ParticleWorkspace::ring_forces`]), for the hybrid
//! runtime to hand to the FEM core that moves the frozen particles; then
//! `sum_free m (v' - v) + dt sum_ring f_r = dt sum_free (f_ext + m g)` holds to round-off.
//!
//! **Sub-steps.** A step runs `k` leapfrog sub-steps (eq. 33 in velocity form). Forces that
//! depend on the state at each sub-step (tool contact, coupling springs, confinement) go through
//! [`step_with`]'s callback, which equals running the sub-steps one per call except for round-off
//! and the per-call overhead (see [`step_with_substeps`]).

mod builder;
pub mod kernel;
mod mass_scaling;
mod model;
pub mod neighbors;
mod pair_loop;
mod stability;
mod state;
mod step;

pub use builder::{ParticleModelBuilder, DEFAULT_HOURGLASS, DEFAULT_MIN_WEIGHT};
pub use kernel::Kernel;
pub use mass_scaling::{MassScaling, WORTH_IT};
pub use model::{barrier_energy_density, ParticleModel};

/// `det F` below which a particle's St. Venant-Kirchhoff stress gets a compression barrier, the
/// energy density `kappa/2 (J_c - J)^2` (`kappa = lambda + 2 mu`, `J = det F`).
///
/// Why: St. Venant-Kirchhoff's resistance to compression peaks and then falls (in a hydrostatic
/// compression its stress turns back at `J = 0.19`, in a uniaxial one at a stretch of
/// `1/sqrt(3)`) and an inverted particle (`J < 0`) finds a mirrored equilibrium: the law, written
/// as the paper has it, lets a pressed particle collapse. The particles under a deep press (the
/// tool 7 mm into the paper's ellipsoids, a 6 mm wall) inverted and the shell diverged
/// (`examples/touch.rs`, 15 mm press). The barrier leaves the paper's law untouched above
/// `J_c = 0.5` (a particle compressed to half its volume), and below it resists further
/// compression with the tissue's P-wave modulus, through `J = 0` and beyond, so an inverted
/// particle is pushed back out. The particle force stays minus the gradient of
/// [`ParticleModel::strain_energy`] (which includes it: tests/meshfree.rs).
pub const COMPRESSION_FLOOR: f64 = 0.5;
pub(crate) use pair_loop::simd_allowed;
pub use pair_loop::{set_simd_enabled, simd_path};
pub use stability::STABILITY_SAFETY;
pub use state::{ParticleState, ParticleStepReport, ParticleWorkspace, SubStep};
pub use step::{step, step_with, step_with_fork, step_with_substeps};
