//! The factorised matrix every implicit integrator shares: `A = M - dt D0 - dt^2 K0` at rest (the
//! linearised step's system; `A / dt^2` the minimising integrators' initial Hessian and
//! preconditioner), or the same with a definite tangent of a deformed state once refreshing it
//! pays (`quasi_newton.rs` module docs). One home for: making it, applying its inverse, and the
//! rule that decides when to redo it.

use crate::error::StepError;
use crate::fem::model::NONE;
use crate::fem::{tangent, tet10};
use crate::fem::{Model, Workspace};
use crate::integrate::{CorePotential, Integrator, StiffnessTerm};
use crate::linalg::Ldl;
use crate::math::{Mat3, Vec3};

/// A factorisation's cost in quasi-Newton iterations per unit of `Ldl::factor_to_solve_ratio`
/// (an iteration is one solve plus about 1.5 force evaluations; measured: BENCHMARKS.md).
pub(crate) const ITERATIONS_PER_FACTOR_RATIO: f64 = 0.7;

/// Rest factors kept besides the one in use, for the `dt` used most recently (issue 16: a haptic
/// loop whose period varies would otherwise refactorise at every change, 40 ms on `lv_10k`). Each
/// costs the memory of one factor (`Ldl::nnz_l` 3x3 blocks); a refreshed (deformed-state) factor
/// is tied to a past state and never kept.
pub const DT_CACHE_SIZE: usize = 3;

/// The rest factors of recently used `dt` other than the one in use, least recent first. Their
/// values depend only on the model and `dt`, so whether a factor comes from here or is made afresh
/// changes the cost of a step, never its result.
#[derive(Debug, Clone)]
pub(crate) struct DtCache {
    entries: Vec<(f64, Ldl)>,
    /// Buffers of dropped (refreshed) factors, reused before a new one is allocated; with
    /// `entries` and the factor in use there are never more than `DT_CACHE_SIZE + 1` factors.
    free: Vec<Ldl>,
}

impl DtCache {
    /// Empty, with room for every entry (so that a cache hit or an eviction allocates nothing).
    pub(crate) fn new() -> DtCache {
        DtCache { entries: Vec::with_capacity(DT_CACHE_SIZE), free: Vec::with_capacity(DT_CACHE_SIZE + 1) }
    }

    fn take(&mut self, dt: f64) -> Option<Ldl> {
        let k = self.entries.iter().position(|(d, _)| *d == dt)?;
        Some(self.entries.remove(k).1)
    }

    fn contains(&self, dt: f64) -> bool {
        self.entries.iter().any(|(d, _)| *d == dt)
    }

    /// A factor buffer for a new entry: the least recent entry's if the cache is full, else a
    /// free one, else a fresh one (the one allocation, once per newly kept `dt`). Afterwards the
    /// cache has room for one entry.
    fn spare(&mut self, model: &Model) -> Ldl {
        if self.entries.len() >= DT_CACHE_SIZE {
            self.entries.remove(0).1
        } else if let Some(l) = self.free.pop() {
            l
        } else {
            model.ldl.clone()
        }
    }
}

/// Make `ws.ldl` hold a factor for `dt`: unchanged if it already does (the rest one, or one
/// refreshed at this `dt`), else the cached rest factor for `dt`, else a new factorisation. The
/// rest factor being left is cached for a later return to its `dt`.
pub(crate) fn ensure(model: &Model, ws: &mut Workspace, dt: f64) -> Result<(), StepError> {
    if ws.factored_dt == dt {
        return Ok(());
    }
    // A rest factor that holds terms is not the rest factor: not kept.
    let leaving = (ws.factored_dt.is_finite() && pristine(ws)).then_some(ws.factored_dt);
    ws.factored_dt = f64::NAN;
    ws.refreshed = false;
    ws.excess_iterations = 0;
    clear_terms(ws);
    let hit = ws.dt_cache.take(dt);
    let cached = hit.is_some();
    let next = match (hit, leaving) {
        (Some(l), _) => Some(l),
        (None, Some(_)) => Some(ws.dt_cache.spare(model)),
        (None, None) => None,
    };
    if let Some(next) = next {
        let old = std::mem::replace(&mut ws.ldl, next);
        match leaving {
            Some(d) => ws.dt_cache.entries.push((d, old)),
            None => ws.dt_cache.free.push(old),
        }
    }
    if !cached {
        model.system_values(1.0, -dt, -dt * dt, &model.k0, &model.d0, &mut ws.a_values);
        model.factor(&mut ws.ldl, &ws.a_values)?;
        ws.factor_count += 1;
    }
    ws.factored_dt = dt;
    Ok(())
}

/// Put the rest factor for `dt` into the cache (or keep the one in use) without changing what the
/// next step at the current `dt` does; returns whether it factorised.
pub(crate) fn prepare(model: &Model, ws: &mut Workspace, dt: f64) -> Result<bool, StepError> {
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(StepError::BadTimeStep(dt));
    }
    if (ws.factored_dt == dt && pristine(ws)) || ws.dt_cache.contains(dt) {
        return Ok(false);
    }
    let mut ldl = ws.dt_cache.spare(model);
    model.system_values(1.0, -dt, -dt * dt, &model.k0, &model.d0, &mut ws.a_values);
    model.factor(&mut ldl, &ws.a_values)?;
    ws.factor_count += 1;
    ws.dt_cache.entries.push((dt, ldl));
    Ok(true)
}

/// Bring the factor and the refresh rule's count to what `mem` records (see
/// [`crate::fem::StepMemory`]): the rest factor for its `dt`, or the definite tangent refreshed at
/// its positions, both made the same way as in the step that made them, hence bit-identical.
pub(crate) fn restore(model: &Model, ws: &mut Workspace, mem: &crate::fem::StepMemory) -> Result<(), StepError> {
    let dt = mem.factored_dt;
    if matches!(model.integrator, Integrator::SemiImplicit { .. }) || dt.is_nan() {
        // The semi-implicit scheme's per-node inverses are redone at the next step's dt.
        ws.factored_dt = f64::NAN;
        ws.refreshed = false;
    } else if !(dt > 0.0 && dt.is_finite()) {
        return Err(StepError::BadTimeStep(dt));
    } else if let Some(x) = &mem.refreshed_at {
        ws.base_terms.clone_from(&mem.base_terms);
        refresh(model, ws, x, dt)?;
        replay(model, ws, &mem.term_updates, dt)?;
    } else {
        if !pristine(ws) {
            ws.factored_dt = f64::NAN;
            ws.refreshed = false;
        }
        ensure(model, ws, dt)?;
        if !mem.base_terms.is_empty() {
            ws.base_terms.clone_from(&mem.base_terms);
            remake_rest(model, ws, dt)?;
        }
        replay(model, ws, &mem.term_updates, dt)?;
    }
    ws.excess_iterations = mem.excess_iterations;
    ws.potential.invalidate();
    Ok(())
}

/// `out = dt^2 A^-1 v` over the free nodes (`H0^-1 v`, `H0 = A / dt^2`), through `ws.rhs`.
pub(crate) fn apply_inverse(model: &Model, ws: &mut Workspace, v: &[Vec3], out: &mut [Vec3], dt: f64) {
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
/// The new factor holds the stiffness terms the step held (`sync_terms`).
pub(crate) fn refresh_if_paid(model: &Model, ws: &mut Workspace, x: &[Vec3], dt: f64, surplus: usize, struggled: bool) -> Result<(), StepError> {
    ws.excess_iterations = ws.excess_iterations.saturating_add(surplus);
    if struggled && ws.excess_iterations as f64 >= model.refresh_cost {
        let Workspace { base_terms, held_terms, .. } = ws;
        base_terms.clone_from(held_terms);
        refresh(model, ws, x, dt)?;
    }
    Ok(())
}

/// Rank updates a factor takes before it is remade instead (a refresh at the step's start): the
/// bound of [`crate::fem::StepMemory::term_updates`], whose replay a restore pays.
pub(crate) const MAX_TERM_UPDATES: usize = 256;

/// Make the factor hold the stiffness terms of the step's potential `external`
/// ([`CorePotential::stiffness_terms`]; none without one): a rank update per term added or
/// removed since the last step (`Ldl::update`), logged for the memory. If the updates would pass
/// [`MAX_TERM_UPDATES`] or cost more than a factorisation, or one fails (a downdate that lost
/// definiteness to round-off), the factor is remade holding them, refreshed at `x` (the step's
/// start). (Remaking a rest factor as the rest matrix with the terms, without the tangent's
/// eigen decompositions, was tried: under the 2 N press driven through the ventricle's wall,
/// `tests/runtime_hand.rs`, the shell then failed at 19.8 mm.)
pub(crate) fn sync_terms(model: &Model, ws: &mut Workspace, external: Option<&dyn CorePotential>, x: &[Vec3], dt: f64) -> Result<(), StepError> {
    let mut now = std::mem::take(&mut ws.step_terms);
    now.clear();
    if let Some(p) = external {
        p.stiffness_terms(&mut |t| now.push(t));
    }
    now.sort_unstable_by_key(|t| t.id);
    if now == ws.held_terms {
        ws.step_terms = now;
        return Ok(());
    }
    let mut count = 0;
    changes(&ws.held_terms, &now, |_, _| {
        count += 1;
        true
    });
    let affordable = ws.term_updates.len() + count <= MAX_TERM_UPDATES && (count as f64) * model.update_cost <= 1.0;
    let held = std::mem::take(&mut ws.held_terms);
    let ok = affordable
        && changes(&held, &now, |t, added| {
            let ok = apply_term(model, ws, &t, added, dt).is_ok();
            if ok {
                ws.term_updates.push((t, added));
            }
            ok
        });
    ws.held_terms = held;
    if ok {
        // The factor holds `now`.
        ws.held_terms.clone_from(&now);
        ws.step_terms = now;
        return Ok(());
    }
    ws.base_terms.clone_from(&now);
    ws.step_terms = now;
    refresh(model, ws, x, dt)
}

/// Walk two term lists sorted by id: `each(term, added)` for every term only in `held` (removed)
/// or only in `now` (added), a changed term removed then added, in id order, until `each`
/// returns false; returns whether it went through.
fn changes(held: &[StiffnessTerm], now: &[StiffnessTerm], mut each: impl FnMut(StiffnessTerm, bool) -> bool) -> bool {
    let (mut i, mut j) = (0, 0);
    loop {
        let (remove, add) = match (held.get(i), now.get(j)) {
            (None, None) => return true,
            (Some(h), Some(n)) if h.id == n.id => {
                i += 1;
                j += 1;
                if h == n {
                    continue;
                }
                (Some(*h), Some(*n))
            }
            (Some(h), n) if n.is_none_or(|n| h.id < n.id) => {
                i += 1;
                (Some(*h), None)
            }
            (_, n) => {
                j += 1;
                (None, n.copied())
            }
        };
        for (t, added) in remove.map(|t| (t, false)).into_iter().chain(add.map(|t| (t, true))) {
            if !each(t, added) {
                return false;
            }
        }
    }
}

/// Whether `ws.ldl` is a rest factor as made (or none): no refresh, no terms held.
fn pristine(ws: &Workspace) -> bool {
    !ws.refreshed && ws.term_updates.is_empty() && ws.base_terms.is_empty()
}

/// Refactorise `ws.ldl` with the rest matrix and the stiffness terms `ws.base_terms`,
/// `M - dt D0 - dt^2 (K0 - S)`, which it then holds: what a memory with base terms and no
/// `refreshed_at` describes (the steps themselves remake a factor as a refresh); on failure,
/// the rest matrix.
fn remake_rest(model: &Model, ws: &mut Workspace, dt: f64) -> Result<(), StepError> {
    let mut k = std::mem::take(&mut ws.k);
    k.copy_from_slice(&model.k0);
    subtract_terms(model, &ws.base_terms, &mut k);
    model.system_values(1.0, -dt, -dt * dt, &k, &model.d0, &mut ws.a_values);
    ws.k = k;
    ws.factored_dt = f64::NAN;
    ws.refreshed = false;
    ws.factor_count += 1;
    if model.factor(&mut ws.ldl, &ws.a_values).is_ok() {
        ws.factored_dt = dt;
        let Workspace { base_terms, held_terms, term_updates, .. } = ws;
        held_terms.clone_from(base_terms);
        term_updates.clear();
        return Ok(());
    }
    clear_terms(ws);
    ensure(model, ws, dt)
}

/// `k -= S`, `S` the stiffness of `terms` on the free pattern (`k` is the forces' Jacobian).
fn subtract_terms(model: &Model, terms: &[StiffnessTerm], k: &mut [Mat3]) {
    for t in terms {
        for (&a, &wa) in t.nodes.iter().zip(&t.weights) {
            for (&b, &wb) in t.nodes.iter().zip(&t.weights) {
                let (fa, fb) = (model.node_to_free[a], model.node_to_free[b]);
                if let Some(bi) = (fa != NONE && fb != NONE).then(|| model.pattern.find(fa, fb)).flatten() {
                    k[bi] -= Mat3::from_diagonal_element(t.stiffness * wa * wb);
                }
            }
        }
    }
}

/// Apply the logged rank updates `updates` to the factor in use (a restore), as `sync_terms`
/// did, keeping the held terms in step.
fn replay(model: &Model, ws: &mut Workspace, updates: &[(StiffnessTerm, bool)], dt: f64) -> Result<(), StepError> {
    for (t, added) in updates {
        if apply_term(model, ws, t, *added, dt).is_err() {
            return Err(StepError::Snapshot(format!("the factor's rank update for stiffness term {} failed on replay", t.id)));
        }
        ws.term_updates.push((*t, *added));
        match (ws.held_terms.binary_search_by_key(&t.id, |h| h.id), added) {
            (Ok(k), false) => {
                ws.held_terms.remove(k);
            }
            (Err(k), true) => ws.held_terms.insert(k, *t),
            _ => return Err(StepError::Snapshot(format!("stiffness term {} {} twice in a row", t.id, if *added { "added" } else { "removed" }))),
        }
    }
    Ok(())
}

/// Add (`added`) or remove the term `t` from the factor: `A += -+ dt^2 k (w (x) I)(w (x) I)^T`
/// over its free nodes (`H0 = A / dt^2` gains or loses the term's stiffness).
fn apply_term(model: &Model, ws: &mut Workspace, t: &StiffnessTerm, added: bool, dt: f64) -> Result<(), crate::linalg::LdlError> {
    let (mut rows, mut w, mut m) = ([0usize; 3], [0.0; 3], 0);
    for (&a, &wa) in t.nodes.iter().zip(&t.weights) {
        let f = model.node_to_free[a];
        if f != NONE && wa != 0.0 {
            rows[m] = model.node_pos[f];
            w[m] = wa;
            m += 1;
        }
    }
    if m == 0 {
        return Ok(());
    }
    let sign = if added { 1.0 } else { -1.0 };
    ws.ldl.update(&rows[..m], &w[..m], sign * t.stiffness * dt * dt)
}

/// The factor holds no terms (a rest factor, made or taken from the cache).
fn clear_terms(ws: &mut Workspace) {
    ws.held_terms.clear();
    ws.base_terms.clear();
    ws.term_updates.clear();
}

/// Refactorise `ws.ldl` with `M - dt D0 - dt^2 (K~(x) - S)`, `K~` the definite tangent
/// approximation at `x` (`fem/tangent.rs`) and `S` the stiffness terms `ws.base_terms`, which it
/// then holds; on failure, the rest matrix again.
fn refresh(model: &Model, ws: &mut Workspace, x: &[Vec3], dt: f64) -> Result<(), StepError> {
    let mut k = std::mem::take(&mut ws.k);
    k.iter_mut().for_each(|b| *b = Mat3::zeros());
    if let Some(q) = &model.quadratic {
        for ((e, r), tb) in q.elements.iter().zip(&q.rest).zip(&q.blocks) {
            let ke = tet10::definite_jacobian(&e.map(|i| x[i]), r, &model.material);
            for (j, &bi) in tb.iter().enumerate() {
                if bi != NONE {
                    k[bi] += ke[j / 10][j % 10];
                }
            }
        }
    }
    for ((t, r), tb) in model.mesh.tets().iter().zip(&model.rest).zip(&model.tet_blocks) {
        let ke = tangent::definite_jacobian(&t.map(|i| x[i]), r, &model.material);
        for e in 0..16 {
            if tb[e] != NONE {
                k[tb[e]] += ke[e / 4][e % 4];
            }
        }
    }
    // `k` is the forces' Jacobian: a potential's stiffness enters with a minus sign.
    subtract_terms(model, &ws.base_terms, &mut k);
    model.system_values(1.0, -dt, -dt * dt, &k, &model.d0, &mut ws.a_values);
    ws.k = k;
    ws.excess_iterations = 0;
    ws.factored_dt = f64::NAN;
    ws.refreshed = false;
    ws.factor_count += 1;
    if model.factor(&mut ws.ldl, &ws.a_values).is_ok() {
        ws.factored_dt = dt;
        // Remembered so that a saved state can remake this factor (`restore`).
        ws.refresh_x.copy_from_slice(x);
        ws.refreshed = true;
        let Workspace { base_terms, held_terms, term_updates, .. } = ws;
        held_terms.clone_from(base_terms);
        term_updates.clear();
        return Ok(());
    }
    ensure(model, ws, dt)
}
