//! Backward Euler as the minimisation of the incremental potential (the minimising integrators'
//! common part: the potential, its gradient, the force scale and the line search).
//!
//! A backward Euler step from `(x_n, v_n)` over `h` finds the end positions `x` that make
//!
//! ```text
//! Phi(x) = sum_i m_i / (2 h^2) |x_i - x_n,i - h v_n,i|^2      inertia, in the mass metric
//!        + W(x)                                             strain energy (elastic law)
//!        + D(x; x_n)                                        viscous dissipation potential (fem/viscous.rs)
//!        - sum_i (f_ext,i + m_i g) . (x_i - x_n,i)          work of the applied forces
//! ```
//!
//! stationary: `grad Phi = M (x - x_n - h v_n) / h^2 - f_int(x) - f_applied = 0` is backward
//! Euler's `M (v - v_n) = h f(x)` with `v = (x - x_n) / h`, the viscous force taken with the
//! step's strain rate `(E(x) - E(x_n)) / h`. The minimising integrators (quasi-Newton, Newton)
//! only accept steps that lower `Phi` (Armijo's condition), so a step can be cut short by its
//! iteration cap and still be stable: it never returns to a higher potential than the start of
//! the step, where `x = x_n`. Liu, Bouaziz and Kavan 2017, "Quasi-Newton methods for real-time
//! simulation of hyperelastic materials" (ACM TOG 36(3)), describe this formulation.
//!
//! The work term is taken relative to `x_n`, so that `Phi` holds no large constant whose
//! round-off would hide the small decreases of late iterations.

use super::factor;
use crate::error::StepError;
use crate::fem::lanes::ElementLoop;
use crate::fem::{tet10, tet4, viscous, Model, State, Workspace};
use crate::material::linear::Svk;
use crate::material::Law;
use crate::math::Vec3;

/// Multiple of `eps` times the magnitude of the gradient's terms taken as its round-off level.
const ROUND_OFF_FACTOR: f64 = 64.0;
/// Armijo's sufficient-decrease constant.
const ARMIJO_C1: f64 = 1e-4;
/// Shortened trials before the line search gives up (the step is then below `1e-10`).
const MAX_TRIALS: usize = 10;

/// One step's problem: the start state, the applied forces and the step size.
pub(crate) struct StepProblem<'a> {
    pub model: &'a Model,
    pub x_n: &'a [Vec3],
    pub v_n: &'a [Vec3],
    pub f_ext: &'a [Vec3],
    pub h: f64,
    /// A potential of the caller's (a tool's contact) added to `Phi`, if any.
    pub external: Option<&'a dyn super::CorePotential>,
}

/// The potential at one point, with what the integrators report of it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Eval {
    /// `Phi(x)` \[J\].
    pub phi: f64,
    /// Its strain energy term `W(x)` \[J\].
    pub w: f64,
    /// Sum of the magnitudes of `Phi`'s terms \[J\]: the scale of its round-off.
    pub magnitude: f64,
    /// Elements with `det F <= 0`.
    pub inverted: usize,
    /// `|grad Phi|^2` over the free nodes \[N^2\].
    pub gnorm2: f64,
    /// The squared force scale of the step (`force_scale`), computed in the same pass \[N^2\].
    pub scale2: f64,
    /// Sum over elements of the estimated squared magnitude of their nodal forces \[N^2\]
    /// (`2 W_e k_e`, `k_e` the element's stiffness scale `Model::tet_stiffness`).
    pub elastic_f2: f64,
    /// The round-off level of `|grad Phi|` \[N\]: a gradient below it cannot be resolved, and the
    /// iterations stop there whatever the tolerance (a body at rest without load, or a dent held
    /// by balanced internal stresses, has a force scale near zero).
    pub floor: f64,
}

/// Buffers of the potential's evaluations (allocated once per workspace), with a cache of the
/// elastic force at the end of the previous step, which is the start of the next: at small
/// deformation a step then costs one force evaluation and one solve, as the linearised step.
#[derive(Debug, Clone)]
pub(crate) struct PotentialWorkspace {
    /// Elastic forces at the current iterate and at the trial point, `(n_nodes)`.
    pub f_el: Vec<Vec3>,
    pub f_el_trial: Vec<Vec3>,
    /// Viscous forces (damped materials only), `(n_nodes)`.
    pub f_visc: Vec<Vec3>,
    pub f_visc_trial: Vec<Vec3>,
    /// Gradient of `Phi` at the current iterate and at the trial point, `(n_free)`, free-node order.
    pub g: Vec<Vec3>,
    pub g_trial: Vec<Vec3>,
    /// The external potential's forces at the point evaluated, `(n_nodes)` (scratch).
    pub f_pot: Vec<Vec3>,
    /// Positions at which `f_el` was last evaluated at the end of a step, its strain energy and
    /// inverted count, and whether they are valid.
    cache_x: Vec<Vec3>,
    cache_w: f64,
    cache_f2: f64,
    cache_inverted: usize,
    cache_valid: bool,
}

impl PotentialWorkspace {
    pub fn new(n: usize, nf: usize) -> PotentialWorkspace {
        let z = |k| vec![Vec3::zeros(); k];
        PotentialWorkspace {
            f_el: z(n),
            f_el_trial: z(n),
            f_visc: z(n),
            f_visc_trial: z(n),
            g: z(nf),
            g_trial: z(nf),
            f_pot: z(n),
            cache_x: z(n),
            cache_w: 0.0,
            cache_f2: 0.0,
            cache_inverted: 0,
            cache_valid: false,
        }
    }

    /// Forget the cached end-of-step forces (after a failed step restored the state).
    pub fn invalidate(&mut self) {
        self.cache_valid = false;
    }

    /// Accept the trial point as the current iterate.
    pub fn accept_trial(&mut self) {
        std::mem::swap(&mut self.f_el, &mut self.f_el_trial);
        std::mem::swap(&mut self.f_visc, &mut self.f_visc_trial);
        std::mem::swap(&mut self.g, &mut self.g_trial);
    }
}

/// Evaluate `Phi` at `x` `(n_nodes)`: forces into `f_el` (and `f_visc` if damped), the gradient
/// into `g` `(n_free)`.
fn evaluate(p: &StepProblem, x: &[Vec3], f_el: &mut [Vec3], f_visc: &mut [Vec3], g: &mut [Vec3], f_pot: &mut [Vec3]) -> Eval {
    let model = p.model;
    f_el.iter_mut().for_each(|f| *f = Vec3::zeros());
    let damped = !model.material.is_undamped();
    if damped {
        f_visc.iter_mut().for_each(|f| *f = Vec3::zeros());
    }
    // Squared magnitude of the element's nodal forces, estimated from its energy as for a linear
    // spring (|f|^2 ~ 2 W k): one multiply-add instead of four norms.
    let (w, d, f2, inverted) = if let Some(q) = &model.quadratic {
        // Quadratic tets (fem/tet10.rs), one at a time.
        let (mut w, mut d, mut f2, mut inverted) = (0.0, 0.0, 0.0, 0);
        for ((e, r), &k) in q.elements.iter().zip(&q.rest).zip(&model.tet_stiffness) {
            let xe = e.map(|i| x[i]);
            let (en, f, det) = tet10::elastic_energy_forces(&xe, r, &model.material);
            w += en;
            f2 += en * k;
            inverted += (det <= 0.0) as usize;
            for a in 0..10 {
                f_el[e[a]] += f[a];
            }
            if damped {
                let (dis, fv) = tet10::step_dissipation(&xe, &e.map(|i| p.x_n[i]), r, &model.material, p.h);
                d += dis;
                for a in 0..10 {
                    f_visc[e[a]] += fv[a];
                }
            }
        }
        (w, d, f2, inverted)
    } else if model.material.law() == Law::StVenantKirchhoff {
        // Four elements at a time in SIMD lanes (fem/lanes.rs).
        let dm = model.material.damping();
        let lp = ElementLoop {
            tets: model.mesh.tets(),
            rest: &model.rest,
            stiffness: &model.tet_stiffness,
            law: Svk::of(&model.material),
            viscous: damped.then_some(((dm.phi, dm.psi), p.x_n, p.h)),
        };
        let s = lp.run(x, f_el, f_visc);
        (s.w, s.d, s.f2, s.inverted)
    } else {
        let (mut w, mut d, mut f2, mut inverted) = (0.0, 0.0, 0.0, 0);
        for ((t, r), &k) in model.mesh.tets().iter().zip(&model.rest).zip(&model.tet_stiffness) {
            let xe = t.map(|i| x[i]);
            let (e, f, det) = tet4::elastic_energy_forces(&xe, r, &model.material);
            w += e;
            f2 += e * k;
            inverted += (det <= 0.0) as usize;
            for a in 0..4 {
                f_el[t[a]] += f[a];
            }
            if damped {
                let (dis, fv) = viscous::step_dissipation(&xe, &t.map(|i| p.x_n[i]), r, &model.material, p.h);
                d += dis;
                for a in 0..4 {
                    f_visc[t[a]] += fv[a];
                }
            }
        }
        (w, d, f2, inverted)
    };
    finish(p, x, w, d, inverted, f2, f_el, damped.then_some(&*f_visc), g, f_pot)
}

/// The nodal terms of `Phi` and its gradient, given the element terms `W` and `D`.
#[allow(clippy::too_many_arguments)]
fn finish(
    p: &StepProblem,
    x: &[Vec3],
    w: f64,
    d: f64,
    inverted: usize,
    f2: f64,
    f_el: &[Vec3],
    f_visc: Option<&[Vec3]>,
    g: &mut [Vec3],
    f_pot: &mut [Vec3],
) -> Eval {
    let model = p.model;
    // The caller's potential (a tool's contact): its energy and forces at `x`.
    let u = match p.external {
        Some(ext) => {
            f_pot.iter_mut().for_each(|f| *f = Vec3::zeros());
            ext.energy_forces(x, f_pot)
        }
        None => 0.0,
    };
    let inv_h2 = 1.0 / (p.h * p.h);
    let inv_h = 1.0 / p.h;
    let (mut inertia, mut work, mut work_abs, mut gnorm2, mut scale2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (fi, &i) in model.free_nodes.iter().enumerate() {
        let m = model.mass[i];
        let du = x[i] - p.x_n[i];
        let a = du - p.h * p.v_n[i];
        let fa = p.f_ext[i] + m * model.gravity;
        inertia += 0.5 * m * inv_h2 * a.norm_squared();
        let wk = fa.dot(&du);
        work += wk;
        work_abs += wk.abs();
        let mut gi = (m * inv_h2) * a - f_el[i] - fa;
        if let Some(fv) = f_visc {
            gi -= fv[i];
        }
        if p.external.is_some() {
            gi -= f_pot[i];
        }
        gnorm2 += gi.norm_squared();
        scale2 += fa.norm_squared() + (m * inv_h * p.v_n[i]).norm_squared();
        g[fi] = gi;
    }
    // Round-off of the gradient: eps times the element forces summed into it (which cancel at an
    // equilibrium, however large they are), the strain error of positions far from the origin,
    // and the inertial term's positions (`sum m^2 |x|^2 / h^4`, at rest: a scale, not a value).
    let noise2 = model.mass_position2 * inv_h2 * inv_h2;
    let floor = ROUND_OFF_FACTOR * f64::EPSILON * (f2 + noise2 + model.position_noise2).sqrt();
    Eval {
        phi: inertia + w + d + u - work,
        w,
        magnitude: inertia + w + d + u.abs() + work_abs,
        inverted,
        gnorm2,
        scale2,
        elastic_f2: f2,
        floor,
    }
}

/// `Phi` at the start of the step (`x = x_n`, where the dissipation and its force vanish), into
/// the current buffers; reuses the previous step's end-of-step elastic forces when `x_n` is the
/// point they were computed at.
/// Returns the evaluation and whether it was computed afresh (no cache).
pub(crate) fn evaluate_start(p: &StepProblem, pw: &mut PotentialWorkspace) -> (Eval, bool) {
    let PotentialWorkspace { f_el, f_visc, g, f_pot, cache_x, cache_w, cache_f2, cache_inverted, cache_valid, .. } = pw;
    if *cache_valid && cache_x.as_slice() == p.x_n {
        if !p.model.material.is_undamped() {
            f_visc.iter_mut().for_each(|f| *f = Vec3::zeros());
        }
        return (finish(p, p.x_n, *cache_w, 0.0, *cache_inverted, *cache_f2, f_el, None, g, f_pot), false);
    }
    (evaluate(p, p.x_n, f_el, f_visc, g, f_pot), true)
}

/// Remember the end-of-step elastic forces (in the current buffer) for the next step's start.
fn store_end(pw: &mut PotentialWorkspace, x: &[Vec3], e: &Eval) {
    pw.cache_x.copy_from_slice(x);
    pw.cache_w = e.w;
    pw.cache_f2 = e.elastic_f2;
    pw.cache_inverted = e.inverted;
    pw.cache_valid = true;
}

/// The force scale of the convergence test \[N\], [`Eval::scale2`]'s root: the L2 norm over the
/// free nodes of the applied forces and of the momenta over `h`, so that the relative gradient
/// measures the error against the forces that drive the step, whether a load is held, ramped or
/// released. (The elastic forces are left out: under a strong press a node's internal forces can
/// far exceed the load they balance, which would loosen the test exactly where the law is most
/// nonlinear.) It depends only on the step's data, not on the point evaluated.
fn force_scale(e: &Eval) -> f64 {
    e.scale2.sqrt()
}

/// On a body with no fixed node, give the direction `d` `(n_free)` the exact rigid translation of
/// backward Euler, `-h^2 sum(g) / sum(m)` (mass-weighted): for a translation the Hessian is exactly
/// `M / h^2` (internal forces are translation invariant), so after the step the gradient sums to
/// zero and linear momentum changes by exactly `h` times the applied forces, however inexactly
/// the rest of the direction was solved (CG, L-BFGS).
pub(crate) fn exact_translation(model: &Model, g: &[Vec3], d: &mut [Vec3], h: f64) {
    let (mut md, mut sg, mut m) = (Vec3::zeros(), Vec3::zeros(), 0.0);
    for (fi, &i) in model.free_nodes.iter().enumerate() {
        md += model.mass[i] * d[fi];
        sg += g[fi];
        m += model.mass[i];
    }
    let shift = -(h * h) * sg / m - md / m;
    d.iter_mut().for_each(|v| *v += shift);
}

/// The bookkeeping both minimising integrators keep over a step: the current evaluation, the
/// convergence target (`tolerance` times the force scale, or the gradient's round-off floor),
/// the counts a `StepReport` gives, and the potential at the start.
pub(crate) struct Progress {
    pub cur: Eval,
    pub iterations: usize,
    pub evaluations: usize,
    pub solves: usize,
    phi0: f64,
    scale: f64,
    tolerance: f64,
}

impl Progress {
    /// From the start of the step (`fresh`: its evaluation was computed, not cached).
    pub fn start(cur: Eval, fresh: bool, tolerance: f64) -> Progress {
        Progress { cur, iterations: 0, evaluations: fresh as usize, solves: 0, phi0: cur.phi, scale: force_scale(&cur), tolerance }
    }
    /// Accept a line search's new iterate.
    pub fn accept(&mut self, e: Eval) {
        self.cur = e;
        self.iterations += 1;
    }
    pub fn gnorm(&self) -> f64 {
        self.cur.gnorm2.sqrt()
    }
    pub fn converged(&self) -> bool {
        self.gnorm() <= (self.tolerance * self.scale).max(self.cur.floor)
    }
    /// The forcing term of an inexact solve: `min(cap, |g| / scale)`.
    pub fn relative_gradient(&self, cap: f64) -> f64 {
        if self.scale > 0.0 {
            (self.gnorm() / self.scale).min(cap)
        } else {
            cap
        }
    }
    pub fn report(&self) -> crate::StepReport {
        crate::StepReport {
            iterations: self.iterations,
            evaluations: self.evaluations,
            solves: self.solves,
            converged: self.converged(),
            residual: if self.scale > 0.0 { self.gnorm() / self.scale } else { 0.0 },
            inverted: self.cur.inverted,
            potential_change: self.cur.phi - self.phi0,
            factorizations: 0, // set by `step`
        }
    }
}

/// End of a minimising step: velocities `(x - x_n) / h` of the free nodes, and the end-of-step
/// forces kept for the next step's start.
pub(crate) fn end_step(p: &StepProblem, pw: &mut PotentialWorkspace, x: &[Vec3], v: &mut [Vec3], cur: &Eval) {
    let inv_h = 1.0 / p.h;
    for &i in &p.model.free_nodes {
        v[i] = (x[i] - p.x_n[i]) * inv_h;
    }
    store_end(pw, x, cur);
}

/// The frame of a step that minimises the incremental potential (quasi-Newton, Newton), written
/// once: factorise the initial Hessian if needed, borrow the start of the step (`x_n`, `v_n`,
/// saved by [`crate::step`]) and the line search's trial buffer from the workspace, evaluate the
/// start, run the method's `iterate` (which moves `state.x` from the start and advances the
/// [`Progress`]; it returns the factor refresh rule's `(surplus, struggled)`), set the end
/// velocities, return the buffers, then refresh the factor if paid (`factor::refresh_if_paid`).
pub(crate) fn minimise(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    dt: f64,
    tolerance: f64,
    external: Option<&dyn super::CorePotential>,
    iterate: impl FnOnce(&StepProblem, &mut [Vec3], &mut [Vec3], &mut Workspace, &mut Progress) -> (usize, bool),
) -> Result<crate::StepReport, StepError> {
    factor::ensure(model, ws, dt)?;
    factor::sync_terms(model, ws, external, &state.x, dt)?;
    // The iterate lives in state.x.
    let (x_n, v_n) = (std::mem::take(&mut ws.x_save), std::mem::take(&mut ws.v_save));
    let mut x_trial = std::mem::take(&mut ws.x_trial);
    x_trial.copy_from_slice(&state.x);
    let p = StepProblem { model, x_n: &x_n, v_n: &v_n, f_ext: &state.f_ext, h: dt, external };
    let (start, fresh) = evaluate_start(&p, &mut ws.potential);
    let mut pr = Progress::start(start, fresh, tolerance);
    let (surplus, struggled) = iterate(&p, &mut state.x, &mut x_trial, ws, &mut pr);
    end_step(&p, &mut ws.potential, &state.x, &mut state.v, &pr.cur);
    ws.x_save = x_n;
    ws.v_save = v_n;
    ws.x_trial = x_trial;
    factor::refresh_if_paid(model, ws, &state.x, dt, surplus, struggled)?;
    Ok(pr.report())
}

/// Dot product of two free-node vectors.
#[inline]
pub(crate) fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a.dot(b)).sum()
}

/// Line search from the current iterate `x` along the free-node direction `d` (`gd = g . d < 0`):
/// the first trial is the full step `alpha = 1`; a trial that fails Armijo's sufficient decrease
/// `Phi(x + alpha d) <= Phi(x) + c1 alpha gd` is replaced by the minimiser of the cubic that
/// interpolates `Phi` and its slope at 0 and at the trial (Nocedal and Wright 2006, eq. 3.59),
/// kept within `[0.1, 0.5]` of the trial (a decrease below the round-off of `Phi`'s terms counts
/// as none). One interpolation usually lands on the curvature the initial Hessian missed, where
/// halving would take two or three trials. On success `x` holds the new iterate, the workspace's
/// current buffers its forces and gradient, and the new evaluation and `alpha` are returned; on
/// failure `x` is left as it was.
#[allow(clippy::too_many_arguments)]
pub(crate) fn line_search(
    p: &StepProblem,
    pw: &mut PotentialWorkspace,
    x: &mut [Vec3],
    x_trial: &mut [Vec3],
    d: &[Vec3],
    cur: &Eval,
    gd: f64,
    evaluations: &mut usize,
) -> Option<(Eval, f64)> {
    let model = p.model;
    let round_off = 64.0 * f64::EPSILON * cur.magnitude;
    // At a point whose gradient is below its round-off level the potential's changes along `d`
    // are noise of about `floor |d|` per unit step: such a step (the one iteration a step always
    // takes, at rest) is accepted within that noise rather than shortened until it vanishes.
    let noise_per_alpha = if cur.gnorm2 <= cur.floor * cur.floor { cur.floor * dot(d, d).sqrt() } else { 0.0 };
    let mut alpha = 1.0;
    for _ in 0..=MAX_TRIALS {
        for (fi, &i) in model.free_nodes.iter().enumerate() {
            x_trial[i] = x[i] + alpha * d[fi];
        }
        let e = evaluate(p, x_trial, &mut pw.f_el_trial, &mut pw.f_visc_trial, &mut pw.g_trial, &mut pw.f_pot);
        *evaluations += 1;
        if e.phi.is_finite() && e.phi <= cur.phi + ARMIJO_C1 * alpha * gd + round_off + noise_per_alpha * alpha {
            for &i in &model.free_nodes {
                x[i] = x_trial[i];
            }
            pw.accept_trial();
            return Some((e, alpha));
        }
        alpha = if e.phi.is_finite() {
            let slope = dot(&pw.g_trial, d);
            alpha * cubic_step(cur.phi, gd * alpha, e.phi, slope * alpha)
        } else {
            0.1 * alpha
        };
    }
    None
}

/// Minimiser, as a fraction of the interval, of the cubic with values `f0`, `f1` and slopes `s0`,
/// `s1` (per unit of the interval) at its ends 0 and 1, clamped to `[0.1, 0.5]`.
fn cubic_step(f0: f64, s0: f64, f1: f64, s1: f64) -> f64 {
    let d1 = s0 + s1 - 3.0 * (f1 - f0);
    let disc = d1 * d1 - s0 * s1;
    let t = if disc >= 0.0 {
        let d2 = disc.sqrt();
        1.0 - (s1 + d2 - d1) / (s1 - s0 + 2.0 * d2)
    } else {
        // No real minimiser: the quadratic through f0, s0 and f1.
        -s0 / (2.0 * (f1 - f0 - s0))
    };
    if t.is_finite() {
        t.clamp(0.1, 0.5)
    } else {
        0.5
    }
}

/// The incremental potential `Phi(x)` \[J\] of a backward Euler step of `h` \[s\] from positions
/// `x_n` and velocities `v_n` under external forces `f_ext` \[N\] (all `(n_nodes)`), as the
/// minimising integrators define it (module docs). For tests and diagnostics: it allocates.
pub fn incremental_potential(model: &Model, x: &[Vec3], x_n: &[Vec3], v_n: &[Vec3], f_ext: &[Vec3], h: f64) -> f64 {
    evaluate_alone(model, x, x_n, v_n, f_ext, h).0.phi
}

/// The gradient of [`incremental_potential`] \[N\] at `x`, `(n_nodes)` (zero at fixed nodes).
pub fn incremental_potential_gradient(model: &Model, x: &[Vec3], x_n: &[Vec3], v_n: &[Vec3], f_ext: &[Vec3], h: f64) -> Vec<Vec3> {
    let g = evaluate_alone(model, x, x_n, v_n, f_ext, h).1;
    let mut out = vec![Vec3::zeros(); model.n_nodes()];
    for (fi, &i) in model.free_nodes.iter().enumerate() {
        out[i] = g[fi];
    }
    out
}

/// [`evaluate`] with buffers of its own; returns the evaluation and the gradient `(n_free)`.
fn evaluate_alone(model: &Model, x: &[Vec3], x_n: &[Vec3], v_n: &[Vec3], f_ext: &[Vec3], h: f64) -> (Eval, Vec<Vec3>) {
    let n = model.n_nodes();
    let p = StepProblem { model, x_n, v_n, f_ext, h, external: None };
    let (mut f_el, mut f_visc, mut g) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n], vec![Vec3::zeros(); model.free_nodes.len()]);
    let e = evaluate(&p, x, &mut f_el, &mut f_visc, &mut g, &mut []);
    (e, g)
}
