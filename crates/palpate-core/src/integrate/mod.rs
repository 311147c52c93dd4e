//! Time integrators (paper §5) and the static equilibrium solve.
//!
//! | integrator | per step | use |
//! |---|---|---|
//! | [`Integrator::BackwardEulerQuasiNewton`] (default) | backward Euler as the minimisation of the incremental potential, by L-BFGS with the factorised rest matrix as initial Hessian and an Armijo line search: one force evaluation and one pair of triangular solves per iteration, one iteration at small deformation | any press: the potential decreases in every step, so it cannot blow up |
//! | [`Integrator::BackwardEulerNewton`] | the same minimisation by Newton's method: tangent solves by conjugate gradients preconditioned by the rest factor, same line search | the accurate reference |
//! | [`Integrator::BackwardEulerLinear`] | one sparse solve with `M - dt D0 - dt^2 K0`, the Jacobians at rest, factorised once per `dt` | small deformation only: blows up under a firm press |
//! | [`Integrator::SemiImplicit`] | explicit forces, then each node's velocity filtered by its own 3x3 block `(I - dt^2/m alpha J_F)^-1` precomputed at rest (eq. 34) | the paper's scheme; with [`Filter::Stable`] unconditionally stable (linear) |
//!
//! All take the state at `t` to `t + dt` with `f_ext` held constant, keep fixed nodes at their
//! position with zero velocity, allocate nothing after the first step, and never leave a
//! non-finite state behind: the state is restored and [`StepError::NonFinite`] names the node.
//! A finite state past the physical speed bound ([`crate::divergence`]: a divergence that has
//! started) is restored the same way and reported as [`StepError::Diverging`].

mod backward_euler;
pub(crate) mod factor;
mod indent;
mod newton;
mod potential;
mod quasi_newton;
mod semi_implicit;
mod statics;

pub use factor::DT_CACHE_SIZE;
pub(crate) use factor::ITERATIONS_PER_FACTOR_RATIO;
pub use indent::{indent, indent_with, IndentOptions, IndentPoint, Indenter};
pub(crate) use newton::CgWorkspace;
pub(crate) use potential::PotentialWorkspace;
pub use potential::{incremental_potential, incremental_potential_gradient};
pub(crate) use quasi_newton::Lbfgs;
pub(crate) use semi_implicit::stable_filter_factor;
pub use statics::{static_solve, static_solve_with, StaticOptions, StaticSolution};

use crate::error::StepError;
use crate::fem::{Model, State, Workspace};
use crate::math::{is_finite3, Vec3};

/// The filter of the paper's semi-implicit scheme (eq. 34).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Filter {
    /// The paper's: each node's block `(I - dt^2/m J_F)^-1`, neighbours held fixed. Stable only
    /// while the node blocks dominate the coupling (VALIDATION.md, known issue 2).
    Paper,
    /// The node blocks scaled by `alpha = lambda_max(blockdiag(K)^-1 K) / 2` (and the same for the
    /// viscous blocks), computed when the model is compiled: the linearised scheme is then stable
    /// at any `dt`, at the price of more numerical damping.
    Stable,
}

/// Choice of time integrator (see the module table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Integrator {
    /// The paper's semi-implicit scheme (eq. 34) with the per-node Jacobian block at rest.
    SemiImplicit {
        /// The paper's filter, or the stable one.
        filter: Filter,
    },
    /// Backward Euler, linearised at rest: one factorisation per time step size.
    BackwardEulerLinear,
    /// Backward Euler as the minimisation of the incremental potential by L-BFGS (the default).
    BackwardEulerQuasiNewton {
        /// Iteration cap per step (a capped step still lowers the potential).
        max_iterations: usize,
        /// The iterations stop when `|grad| <= tolerance * force scale` (`potential.rs`).
        tolerance: f64,
        /// Number of L-BFGS correction pairs kept (0: the rest matrix alone).
        history: usize,
    },
    /// Backward Euler as the minimisation of the incremental potential by Newton's method, tangent
    /// solves by conjugate gradients preconditioned by the rest factor.
    BackwardEulerNewton {
        /// Iteration cap per step (the step is accepted and reported unconverged after it).
        max_iterations: usize,
        /// The iterations stop when `|grad| <= tolerance * force scale` (`potential.rs`).
        tolerance: f64,
    },
}

impl Default for Integrator {
    fn default() -> Integrator {
        Integrator::quasi_newton()
    }
}

impl Integrator {
    /// Default iteration cap of the quasi-Newton integrator.
    pub const QUASI_NEWTON_MAX_ITERATIONS: usize = 25;
    /// Default relative gradient tolerance of the quasi-Newton integrator.
    pub const QUASI_NEWTON_TOLERANCE: f64 = 2e-2;
    /// Default L-BFGS history of the quasi-Newton integrator.
    pub const QUASI_NEWTON_HISTORY: usize = 5;
    /// Default iteration cap of the Newton integrator.
    pub const NEWTON_MAX_ITERATIONS: usize = 30;
    /// Default relative gradient tolerance of the Newton integrator.
    pub const NEWTON_TOLERANCE: f64 = 1e-8;

    /// The default: quasi-Newton backward Euler with the default options.
    pub const fn quasi_newton() -> Integrator {
        Integrator::BackwardEulerQuasiNewton {
            max_iterations: Self::QUASI_NEWTON_MAX_ITERATIONS,
            tolerance: Self::QUASI_NEWTON_TOLERANCE,
            history: Self::QUASI_NEWTON_HISTORY,
        }
    }

    /// Newton backward Euler with the default options.
    pub const fn newton() -> Integrator {
        Integrator::BackwardEulerNewton { max_iterations: Self::NEWTON_MAX_ITERATIONS, tolerance: Self::NEWTON_TOLERANCE }
    }

    /// The paper's semi-implicit scheme with the paper's filter.
    pub const fn semi_implicit() -> Integrator {
        Integrator::SemiImplicit { filter: Filter::Paper }
    }

    /// Check the options (iteration caps, tolerances, history): the reason if they are invalid.
    pub fn check(&self) -> Result<(), String> {
        let check = |name: &str, max_iterations: usize, tolerance: f64| {
            if max_iterations == 0 {
                return Err(format!("{name} max_iterations must be at least 1"));
            }
            if !(tolerance > 0.0 && tolerance < 1.0) {
                return Err(format!("{name} tolerance {tolerance} must lie in (0, 1)"));
            }
            Ok(())
        };
        match *self {
            Integrator::BackwardEulerNewton { max_iterations, tolerance } => check("Newton", max_iterations, tolerance),
            Integrator::BackwardEulerQuasiNewton { max_iterations, tolerance, history } => {
                check("quasi-Newton", max_iterations, tolerance)?;
                if history > 64 {
                    return Err(format!("quasi-Newton history {history} must be at most 64"));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// L-BFGS pairs the workspace must hold.
    pub(crate) fn history(&self) -> usize {
        match *self {
            Integrator::BackwardEulerQuasiNewton { history, .. } => history,
            _ => 0,
        }
    }
}

/// What a step did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepReport {
    /// Nonlinear iterations (accepted line-search steps); 1 for the one-shot schemes.
    pub iterations: usize,
    /// Evaluations of the forces (and, for the minimising schemes, the potential), line-search
    /// trials included.
    pub evaluations: usize,
    /// Sparse factorisations done in the step (the first step at a new `dt`, and the quasi-Newton
    /// integrator's refreshes of its initial Hessian; the step's cost then includes one).
    pub factorizations: usize,
    /// Linear solves with the factorised matrix (0 for the semi-implicit scheme; for Newton, the
    /// preconditioner applications of its conjugate gradients).
    pub solves: usize,
    /// Whether the iterations met their tolerance (always true for one-shot schemes).
    pub converged: bool,
    /// Final gradient norm of the incremental potential relative to the force scale (0 for
    /// one-shot schemes).
    pub residual: f64,
    /// Elements with `det F <= 0` at the end of the step (inverted or flat).
    pub inverted: usize,
    /// Change of the incremental potential over the step \[J\] (`<= 0` for the minimising
    /// schemes; 0 for the others).
    pub potential_change: f64,
}

/// A rank-one term of a potential's stiffness: `stiffness (w (x) I)(w (x) I)^T` \[N/m\], `w` the
/// node vector with `weights[j]` at `nodes[j]` (a spring from the point `sum_j w_j x_j` to a
/// target). The nodes must share a tet (the factor's pattern holds their pairs); terms on fixed
/// nodes drop those nodes. `id` tells the term from step to step ([`CorePotential::stiffness_terms`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffnessTerm {
    pub id: u32,
    pub nodes: [usize; 3],
    pub weights: [f64; 3],
    /// \[N/m\], positive.
    pub stiffness: f64,
}

/// A conservative force field of the caller's on the nodes (a tool's penalty contact), to be
/// taken implicitly: [`step_with_potential`] adds its energy to the incremental potential that
/// the minimising integrators minimise, so its stiffness needs no time-step bound (an explicit
/// force held over the step does: `omega h < 2` on the nodes it acts on).
pub trait CorePotential {
    /// The energy \[J\] at node positions `x` `(n_nodes)`; adds the forces `-dU/dx` \[N\] to `f`.
    fn energy_forces(&self, x: &[Vec3], f: &mut [Vec3]) -> f64;
    /// True when the energy does not change under a rigid translation of every node (its forces
    /// sum to zero): the step then keeps a free body's linear momentum exact, as without it.
    /// Default false (a tool's contact pushes the body).
    fn translation_invariant(&self) -> bool {
        false
    }
    /// The part of its stiffness made of rank-one terms ([`StiffnessTerm`]), each under an id
    /// stable from step to step, given to `emit` (any order, each id once). The minimising
    /// integrators hold them in the matrix they factorise, and keep it current as terms come and
    /// go with a rank update of the factor per term (`linalg/ldl.rs`, `integrate/factor.rs`): a
    /// potential stiff against the nodes' inertia (the hybrid shell's coupling springs, 8x a core
    /// node's on Rodero) then costs the step no extra iterations. Default: none.
    fn stiffness_terms(&self, _emit: &mut dyn FnMut(StiffnessTerm)) {}
}

/// Advance `state` by `dt` \[s\] with the model's integrator.
///
/// Errors leave `state` as it was: a non-positive or non-finite `dt`, a non-finite external
/// force, position or velocity given, a failed factorisation, or a non-finite result (reported
/// with the first bad node).
pub fn step(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64) -> Result<StepReport, StepError> {
    step_inner(model, state, ws, dt, None)
}

/// [`step`] with the potential `external` as part of the step: implicit (in the incremental
/// potential) for the minimising integrators; the one-shot schemes (semi-implicit, linearised
/// backward Euler) take its forces at the start of the step, explicitly. On a body without fixed
/// nodes the step's linear momentum then changes by `dt` times the forces at the end of the step
/// only to the iterations' tolerance (the exact rigid translation of the free-body step assumes
/// internal forces alone, translation invariant).
pub fn step_with_potential(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64, external: &dyn CorePotential) -> Result<StepReport, StepError> {
    match model.integrator {
        Integrator::SemiImplicit { .. } | Integrator::BackwardEulerLinear => {
            let mut f = std::mem::take(&mut ws.potential.f_pot);
            f.iter_mut().for_each(|v| *v = Vec3::zeros());
            external.energy_forces(&state.x, &mut f);
            state.f_ext.iter_mut().zip(&f).for_each(|(a, b)| *a += b);
            let r = step_inner(model, state, ws, dt, None);
            state.f_ext.iter_mut().zip(&f).for_each(|(a, b)| *a -= b);
            ws.potential.f_pot = f;
            r
        }
        _ => step_inner(model, state, ws, dt, Some(external)),
    }
}

fn step_inner(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64, external: Option<&dyn CorePotential>) -> Result<StepReport, StepError> {
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(StepError::BadTimeStep(dt));
    }
    let n = model.n_nodes();
    if state.x.len() != n || state.v.len() != n || state.f_ext.len() != n {
        return Err(StepError::StateShape { nodes: n, x: state.x.len(), v: state.v.len(), f_ext: state.f_ext.len() });
    }
    if let Some(node) = state.f_ext.iter().position(|f| !is_finite3(f)) {
        return Err(StepError::NonFiniteForce { node });
    }
    // A non-finite state on entry (set by a caller between steps) is refused, not stepped: the
    // minimising schemes would drop a NaN velocity without a word (its line search rejects the
    // NaN trial points and the step's velocity is recomputed from positions), a silent reset.
    let bad_in = state.x.iter().position(|x| !is_finite3(x)).map(|n| ("position given to the step", n));
    if let Some((what, node)) = bad_in.or_else(|| state.v.iter().position(|v| !is_finite3(v)).map(|n| ("velocity given to the step", n))) {
        return Err(StepError::NonFinite { what, node, time: state.t });
    }
    ws.x_save.copy_from_slice(&state.x);
    ws.v_save.copy_from_slice(&state.v);
    let factor_count = ws.factor_count;
    let result = match model.integrator {
        Integrator::SemiImplicit { .. } => Ok(semi_implicit::step(model, state, ws, dt)),
        Integrator::BackwardEulerLinear => backward_euler::step_linear(model, state, ws, dt),
        // The minimising schemes share the frame (potential::minimise) and differ in their iterations.
        Integrator::BackwardEulerQuasiNewton { max_iterations, tolerance, .. } => {
            potential::minimise(model, state, ws, dt, tolerance, external, |p, x, xt, ws, pr| quasi_newton::iterate(p, x, xt, ws, pr, max_iterations))
        }
        Integrator::BackwardEulerNewton { max_iterations, tolerance } => {
            potential::minimise(model, state, ws, dt, tolerance, external, |p, x, xt, ws, pr| newton::iterate(p, x, xt, ws, pr, max_iterations))
        }
    };
    let bad = match &result {
        Ok(_) => state
            .x
            .iter()
            .position(|x| !is_finite3(x))
            .map(|n| ("position", n))
            .or_else(|| state.v.iter().position(|v| !is_finite3(v)).map(|n| ("velocity", n))),
        Err(_) => None,
    };
    // Finite but past the physical speed bound: a divergence starting (crate::divergence),
    // restored and reported as a non-finite step is.
    let diverging = match (&result, bad) {
        (Ok(_), None) => crate::divergence::over_bound(&state.v, model.masses(), 0..n, crate::divergence::speed_bound(&model.material)),
        _ => None,
    };
    if result.is_err() || bad.is_some() || diverging.is_some() {
        state.x.copy_from_slice(&ws.x_save);
        state.v.copy_from_slice(&ws.v_save);
        ws.potential.invalidate();
    }
    let mut report = result?;
    report.factorizations = (ws.factor_count - factor_count) as usize;
    if let Some((what, node)) = bad {
        return Err(StepError::NonFinite { what, node, time: state.t });
    }
    if let Some((node, speed)) = diverging {
        return Err(StepError::Diverging { what: "velocity", node, speed, bound: crate::divergence::speed_bound(&model.material), time: state.t });
    }
    state.t += dt;
    Ok(report)
}
