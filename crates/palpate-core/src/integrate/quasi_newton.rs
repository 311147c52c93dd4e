//! The default integrator: backward Euler as the minimisation of the incremental potential
//! (`potential.rs`) by L-BFGS, after Liu, Bouaziz and Kavan 2017.
//!
//! * **Initial Hessian**: the rest matrix `H0 = (M - h D0 - h^2 K0) / h^2`, the matrix the
//!   linearised step factorises once per `dt` (`backward_euler.rs`). Its factor is reused as is:
//!   an iteration costs one evaluation of the forces and energy, one pair of sparse triangular
//!   solves and a few vector operations over the free nodes.
//! * **First iteration = the linearised step**: from `x = x_n` the direction `-H0^-1 grad Phi(x_n)`
//!   is exactly the rest-linearised backward Euler step, so at small deformation one iteration
//!   suffices and costs what that step costs (the forces at `x_n` are those computed at the end
//!   of the previous step, kept in a cache). At least one iteration is always taken: a loose
//!   tolerance never turns the step into an explicit drift.
//! * **Curvature pairs** `(s, y)` with `s . y <= 0` (non-convex regions of St. Venant-Kirchhoff
//!   under compression) are skipped, so the L-BFGS matrix stays positive definite and its
//!   direction is a descent direction; if round-off makes it not one, the history is dropped and
//!   the `H0` direction used.
//! * **Momentum.** The first iteration conserves linear momentum as the linearised step does
//!   (`1^T K0 = 0`), which leaves a gradient summing to zero over the nodes of a free body; the
//!   L-BFGS corrections of later iterations do not preserve that sum, so on a body with no fixed
//!   node every direction gets backward Euler's exact rigid translation
//!   (`potential::exact_translation`; after the first iteration that removes the correction's
//!   translation, which is orthogonal to the gradient). Momentum then changes by exactly `dt`
//!   times the applied forces, at any tolerance.
//! * **Refreshed initial Hessian.** Under a held press the rest matrix misses the stiffness of the
//!   deformed state and every step needs several iterations. The iterations beyond the first are
//!   counted since the last factorisation; once they add up to the cost of a factorisation (in
//!   iterations, estimated from the factor's pattern when the model is compiled: about 8 on
//!   lv_190, 13 on lv_1350, 38 on lv_10k), and the step just taken needed at least
//!   [`REFRESH_MIN_ITERATIONS`], the initial Hessian is refactorised at the end state with a
//!   positive definite approximation of the tangent (`fem/tangent.rs`): the next steps then
//!   converge in one or two iterations. A refresh thus never costs more than the iterations it
//!   replaces (ski-rental amortisation), on small meshes and large. If it fails, the rest matrix
//!   is restored.
//! * **Stop** when `|grad Phi| <= tolerance * force scale` (`potential::force_scale`), at the
//!   iteration cap, or when the line search finds no decrease (the iterate is then at the
//!   round-off level of the potential). Every accepted iterate has a lower potential than the
//!   last, so every step, capped or not, ends below the potential of its start: a press cannot
//!   make the integrator blow up, whatever the load.

use super::factor;
use super::potential::{self, dot, Progress, StepProblem};
use crate::fem::{Model, Workspace};
use crate::math::Vec3;

/// Iterations a step must take for the initial Hessian to be refreshed at its end state.
pub const REFRESH_MIN_ITERATIONS: usize = 3;
/// L-BFGS memory: `history` pairs `(s, y)` of free-node vectors in a ring, and scratch vectors.
#[derive(Debug, Clone)]
pub(crate) struct Lbfgs {
    nf: usize,
    history: usize,
    s: Vec<Vec3>,
    y: Vec<Vec3>,
    rho: Vec<f64>,
    alpha: Vec<f64>,
    /// Pairs stored (<= history) and the ring slot of the newest.
    len: usize,
    newest: usize,
    /// Search direction and the two-loop's work vector, `(n_free)`.
    pub d: Vec<Vec3>,
    q: Vec<Vec3>,
}

impl Lbfgs {
    pub fn new(nf: usize, history: usize) -> Lbfgs {
        Lbfgs {
            nf,
            history,
            s: vec![Vec3::zeros(); nf * history],
            y: vec![Vec3::zeros(); nf * history],
            rho: vec![0.0; history],
            alpha: vec![0.0; history],
            len: 0,
            newest: 0,
            d: vec![Vec3::zeros(); nf],
            q: vec![Vec3::zeros(); nf],
        }
    }

    fn clear(&mut self) {
        self.len = 0;
    }

    /// Store the pair `s = alpha d`, `y = g_new - g_old` if its curvature `s . y` is positive.
    fn push(&mut self, alpha: f64, g_new: &[Vec3], g_old: &[Vec3]) {
        if self.history == 0 {
            return;
        }
        let slot = if self.len == 0 { 0 } else { (self.newest + 1) % self.history };
        let r = slot * self.nf..(slot + 1) * self.nf;
        let mut sy = 0.0;
        let (mut ss, mut yy) = (0.0, 0.0);
        for ((s, y), k) in self.s[r.clone()].iter_mut().zip(&mut self.y[r]).zip(0..self.nf) {
            *s = alpha * self.d[k];
            *y = g_new[k] - g_old[k];
            sy += s.dot(y);
            ss += s.norm_squared();
            yy += y.norm_squared();
        }
        // Skip pairs of non-positive (or round-off) curvature: they would make the matrix
        // indefinite. The slot written was free, or held the oldest pair, now dropped.
        if !(sy > 1e-12 * (ss * yy).sqrt()) {
            if self.len == self.history {
                self.len -= 1;
            }
            return;
        }
        self.rho[slot] = 1.0 / sy;
        self.newest = slot;
        self.len = (self.len + 1).min(self.history);
    }
}

/// The L-BFGS direction `d = -H g` (two-loop recursion, Nocedal and Wright, Alg. 7.4) into `lb.d`.
fn direction(model: &Model, ws: &mut Workspace, lb: &mut Lbfgs, g: &[Vec3], h: f64) {
    if lb.len == 0 {
        // No pairs: d = -H0^-1 g directly.
        factor::apply_inverse(model, ws, g, &mut lb.d, h);
        lb.d.iter_mut().for_each(|d| *d = -*d);
        return;
    }
    lb.q.copy_from_slice(g);
    let hist = lb.history.max(1);
    for j in 0..lb.len {
        let k = (lb.newest + hist - j) % hist;
        let r = k * lb.nf..(k + 1) * lb.nf;
        let a = lb.rho[k] * dot(&lb.s[r.clone()], &lb.q);
        lb.alpha[k] = a;
        for (q, y) in lb.q.iter_mut().zip(&lb.y[r]) {
            *q -= a * y;
        }
    }
    let (q, mut d) = (std::mem::take(&mut lb.q), std::mem::take(&mut lb.d));
    factor::apply_inverse(model, ws, &q, &mut d, h);
    lb.q = q;
    lb.d = d;
    for j in (0..lb.len).rev() {
        let k = (lb.newest + hist - j) % hist;
        let r = k * lb.nf..(k + 1) * lb.nf;
        let c = lb.alpha[k] - lb.rho[k] * dot(&lb.y[r.clone()], &lb.d);
        for (d, s) in lb.d.iter_mut().zip(&lb.s[r]) {
            *d += c * s;
        }
    }
    lb.d.iter_mut().for_each(|d| *d = -*d);
}

/// One step's L-BFGS iterations (run inside [`potential::minimise`]); returns the surplus
/// iterations and whether the step struggled, for the refresh rule (`factor.rs`).
pub(super) fn iterate(p: &StepProblem, x: &mut [Vec3], x_trial: &mut [Vec3], ws: &mut Workspace, pr: &mut Progress, max_iterations: usize) -> (usize, bool) {
    let model = p.model;
    let h = p.h;
    let mut lb = std::mem::replace(&mut ws.lbfgs, Lbfgs::new(0, 0));
    lb.clear();
    let free_body = model.is_free_body();
    loop {
        let g = std::mem::take(&mut ws.potential.g);
        direction(model, ws, &mut lb, &g, h);
        pr.solves += 1;
        let mut gd = dot(&g, &lb.d);
        if !(gd < 0.0) && lb.len > 0 {
            lb.clear();
            direction(model, ws, &mut lb, &g, h);
            pr.solves += 1;
            gd = dot(&g, &lb.d);
        }
        if free_body && p.external.is_none_or(|e| e.translation_invariant()) {
            // Keep the momentum exact (see the module docs).
            potential::exact_translation(model, &g, &mut lb.d, h);
        }
        ws.potential.g = g;
        if !(gd < 0.0) {
            break; // a zero gradient: nothing to do
        }
        let Some((e, alpha)) = potential::line_search(p, &mut ws.potential, x, x_trial, &lb.d, &pr.cur, gd, &mut pr.evaluations) else {
            break;
        };
        pr.accept(e);
        if pr.converged() || pr.iterations >= max_iterations {
            break;
        }
        // After the line search the current gradient is the new one and g_trial the old.
        lb.push(alpha, &ws.potential.g, &ws.potential.g_trial);
    }
    ws.lbfgs = lb;
    let it = pr.iterations;
    (it.saturating_sub(1), it >= REFRESH_MIN_ITERATIONS)
}
