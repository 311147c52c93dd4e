//! The factorised matrix every implicit integrator shares: `A = M - dt D0 - dt^2 K0` at rest (the
//! linearised step's system; `A / dt^2` the minimising integrators' initial Hessian and
//! preconditioner), or the same with a definite tangent of a deformed state once refreshing it
//! pays (`quasi_newton.rs` module docs). One home for: making it, applying its inverse, and the
//! rule that decides when to redo it.

use crate::error::StepError;
use crate::fem::model::NONE;
use crate::fem::tangent;
use crate::fem::{Model, Workspace};
use crate::math::{Mat3, Vec3};

/// A factorisation's cost in quasi-Newton iterations per unit of `Ldl::factor_to_solve_ratio`
/// (an iteration is one solve plus about 1.5 force evaluations; measured: BENCHMARKS.md).
pub(crate) const ITERATIONS_PER_FACTOR_RATIO: f64 = 0.7;

/// Factorise the rest matrix `M - dt D0 - dt^2 K0` into `ws.ldl` unless it already holds a matrix
/// for `dt` (the rest one, or one refreshed at this `dt`).
pub(super) fn ensure(model: &Model, ws: &mut Workspace, dt: f64) -> Result<(), StepError> {
    if ws.factored_dt != dt {
        ws.factored_dt = f64::NAN;
        ws.excess_iterations = 0;
        model.system_values(1.0, -dt, -dt * dt, &model.k0, &model.d0, &mut ws.a_values);
        model.factor(&mut ws.ldl, &ws.a_values)?;
        ws.factored_dt = dt;
        ws.factor_count += 1;
    }
    Ok(())
}

/// `out = dt^2 A^-1 v` over the free nodes (`H0^-1 v`, `H0 = A / dt^2`), through `ws.rhs`.
pub(super) fn apply_inverse(model: &Model, ws: &mut Workspace, v: &[Vec3], out: &mut [Vec3], dt: f64) {
    for (fi, &pos) in model.node_pos.iter().enumerate() {
        ws.rhs[pos] = v[fi];
    }
    ws.ldl.solve_in_place(&mut ws.rhs);
    let h2 = dt * dt;
    for (fi, &pos) in model.node_pos.iter().enumerate() {
        out[fi] = h2 * ws.rhs[pos];
    }
}

/// Count `surplus` work units (iterations beyond what the step needed with an exact Hessian) and,
/// once they have cost a factorisation and this step `struggled`, refactorise at `x` with the
/// definite tangent (ski rental: a refresh never costs more than the work it replaces).
pub(super) fn refresh_if_paid(model: &Model, ws: &mut Workspace, x: &[Vec3], dt: f64, surplus: usize, struggled: bool) -> Result<(), StepError> {
    ws.excess_iterations = ws.excess_iterations.saturating_add(surplus);
    if struggled && ws.excess_iterations as f64 >= model.refresh_cost {
        refresh(model, ws, x, dt)?;
    }
    Ok(())
}

/// Refactorise `ws.ldl` with `M - dt D0 - dt^2 K~(x)`, `K~` the definite tangent approximation at
/// `x` (`fem/tangent.rs`); on failure, the rest matrix again.
fn refresh(model: &Model, ws: &mut Workspace, x: &[Vec3], dt: f64) -> Result<(), StepError> {
    let mut k = std::mem::take(&mut ws.k);
    k.iter_mut().for_each(|b| *b = Mat3::zeros());
    for ((t, r), tb) in model.mesh.tets().iter().zip(&model.rest).zip(&model.tet_blocks) {
        let ke = tangent::definite_jacobian(&t.map(|i| x[i]), r, &model.material);
        for e in 0..16 {
            if tb[e] != NONE {
                k[tb[e]] += ke[e / 4][e % 4];
            }
        }
    }
    model.system_values(1.0, -dt, -dt * dt, &k, &model.d0, &mut ws.a_values);
    ws.k = k;
    ws.excess_iterations = 0;
    ws.factored_dt = f64::NAN;
    ws.factor_count += 1;
    if model.factor(&mut ws.ldl, &ws.a_values).is_ok() {
        ws.factored_dt = dt;
        return Ok(());
    }
    ensure(model, ws, dt)
}
