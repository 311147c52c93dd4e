//! The paper's semi-implicit scheme, eq. (34), after Debunne et al. 2001:
//!
//! ```text
//! v~      = v_t + dt F / m
//! v_t+dt  = (I - alpha dt^2/m J_F)^-1 v~    (per node: J_F = d f_i / d x_i at rest, 3x3; alpha = 1, the paper's)
//! x_t+dt  = x_t + dt v_t+dt
//! ```
//!
//! `J_F` is the node's own diagonal block of the force Jacobian at rest "assuming its neighbours
//! are fixed", precomputed once ([`crate::Model::node_jacobians`]). It is negative semi-definite,
//! so `I - dt^2/m J_F` is positive definite (the paper's README notes the sign). palpate adds the
//! viscous block in the same way, `(I - dt/m D_ii - dt^2/m J_ii)^-1`, so that damping is treated
//! as implicitly as stiffness.
//!
//! Properties, measured (tests/dynamics.rs, BENCHMARKS.md):
//! * **Not unconditionally stable.** The filter stabilises each node against its own stiffness
//!   with its neighbours held fixed; the coupling to the neighbours stays explicit. The step is
//!   stable while `dt^2 lambda_max(M^-1 K)` stays within about `2 dt^2 k_ii/m + 4`: true at 1 ms on
//!   the benchmark's lv_190 .. lv_10k meshes (spectral radius 0.993 on lv_190, 0.998 on lv_1350)
//!   but not on the 48k-tet mesh nor on the default truncated wall generator (radius 1.32), and
//!   damping makes it worse.
//! * **Over-damped on fine meshes.** Every mode is damped by about `1/(1 + dt^2 k_ii/m)` per step
//!   and `k_ii/m ~ 1/h^2`, so on finer meshes the motion creeps toward equilibrium and lags behind it.
//! * **Does not conserve linear momentum**: each node's velocity is scaled by its own matrix, so
//!   even a rigid translation is slowed.
//!
//! **The stable filter** ([`crate::integrate::Filter::Stable`]). Scaling the filter blocks by
//! `alpha >= lambda_max(blockdiag(K)^-1 K) / 2` makes the linearised scheme stable at any `dt`:
//! for `v+ = (M + alpha h^2 K_d)^-1 (M v - h K x)`, `x+ = x + h v+` (one mode: `m`, `k`, `k_d`) the
//! amplification matrix has determinant `m / (m + alpha h^2 k_d) < 1` and trace above `-(1 + det)`
//! exactly when `h^2 k <= 4 m + 2 alpha h^2 k_d`, which `2 alpha K_d >= K` guarantees for every `h`
//! (and likewise `alpha >= lambda_max(D_d^-1 D)/2` for the viscous blocks; the bound is sufficient,
//! not necessary: at a given `h` the `4 M` term allows a smaller `alpha`). `alpha` is computed once, when the model is compiled, by power
//! iteration ([`stable_filter_factor`]); the price is more numerical damping.
//!
//! Backward Euler has none of these defects; the semi-implicit scheme is kept as the paper's reference.

use crate::fem::{Model, State, Workspace};
use crate::linalg::BlockPattern;
use crate::math::{Mat3, Vec3};

/// Safety margin on the power iteration's estimate of `lambda_max` (it approaches from below).
const LAMBDA_MARGIN: f64 = 1.02;

/// `lambda_max(blockdiag(A)^-1 A)` of a symmetric positive semi-definite block matrix `A` (`-K0`
/// or `-D0` on the free pattern) by power iteration on the block-Jacobi-scaled matrix.
fn block_jacobi_lambda_max(pattern: &BlockPattern, a: &[Mat3]) -> f64 {
    let n = pattern.n();
    let d_inv: Vec<Mat3> = (0..n).map(|i| a[pattern.diag[i]].try_inverse().unwrap_or_else(Mat3::zeros)).collect();
    // A deterministic start vector with components in every direction.
    let mut v: Vec<Vec3> = (0..n).map(|i| Vec3::new(1.0, 0.5 + 0.3 * ((i * 7) % 5) as f64, 0.25 + 0.1 * ((i * 3) % 7) as f64)).collect();
    let mut av = vec![Vec3::zeros(); n];
    let mut lambda = 0.0;
    for _ in 0..300 {
        pattern.mul(a, &v, &mut av);
        // Rayleigh quotient of the generalised problem A v = lambda D v.
        let vav: f64 = v.iter().zip(&av).map(|(v, a)| v.dot(a)).sum();
        let vdv: f64 = (0..n).map(|i| v[i].dot(&(a[pattern.diag[i]] * v[i]))).sum();
        if !(vdv > 0.0) {
            return 0.0;
        }
        lambda = vav / vdv;
        let mut norm = 0.0;
        for i in 0..n {
            v[i] = d_inv[i] * av[i];
            norm += v[i].norm_squared();
        }
        let norm = norm.sqrt();
        if !(norm > 0.0) {
            return 0.0;
        }
        v.iter_mut().for_each(|x| *x /= norm);
    }
    lambda
}

/// The stable filter factor `alpha = max(lambda_max(K_d^-1 K), lambda_max(D_d^-1 D)) / 2` (with a
/// 2% margin) of the rest Jacobians `k0`, `d0` (df/dx, df/dv) on the free pattern.
pub(crate) fn stable_filter_factor(pattern: &BlockPattern, k0: &[Mat3], d0: &[Mat3], damped: bool) -> f64 {
    let neg = |a: &[Mat3]| a.iter().map(|b| -b).collect::<Vec<Mat3>>();
    let mut l = block_jacobi_lambda_max(pattern, &neg(k0));
    if damped {
        l = l.max(block_jacobi_lambda_max(pattern, &neg(d0)));
    }
    0.5 * LAMBDA_MARGIN * l
}

pub(super) fn step(model: &Model, state: &mut State, ws: &mut Workspace, dt: f64) -> crate::StepReport {
    if ws.factored_dt != dt {
        for i in 0..model.n_nodes() {
            let m = model.mass[i];
            let alpha = model.filter_alpha;
            let a = Mat3::identity() - (alpha * dt / m) * model.node_d0[i] - (alpha * dt * dt / m) * model.node_k0[i];
            ws.node_inv[i] = a.try_inverse().unwrap_or_else(Mat3::identity);
        }
        ws.factored_dt = dt;
    }
    model.internal_forces(&state.x, Some(&state.v), &mut ws.force);
    model.add_applied(&state.f_ext, &mut ws.force);
    for i in 0..model.n_nodes() {
        if model.fixed[i] {
            state.v[i].fill(0.0);
            continue;
        }
        let v_tilde = state.v[i] + ws.force[i] * (dt / model.mass[i]);
        state.v[i] = ws.node_inv[i] * v_tilde;
        state.x[i] += dt * state.v[i];
    }
    crate::StepReport { iterations: 1, evaluations: 1, converged: true, ..crate::StepReport::default() }
}
