//! The two passes of a sub-step and the Verlet update, written once for both copies of the loop
//! (see [`super`]); the portable copy's per-particle gathers, which the AVX2 copy replaces.

use super::{Cols, Disjoint, ExtForce, LoopCopy, P4};
use crate::material::linear::{det3, green_strain_of, mm, strain_rate_of, sym, Scalar, Svk, M3};
use crate::math::Vec3;
use crate::meshfree::{ParticleModel, ParticleState, ParticleWorkspace};
use crate::parallel::{part, Fork, MAX_WAYS};

/// `acc += s * x` on 4 lanes.
#[inline(always)]
fn axpy(acc: &mut P4, s: f64, x: &P4) {
    for l in 0..4 {
        acc[l] += s * x[l];
    }
}

#[inline(always)]
fn add(a: &P4, b: &P4) -> P4 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]]
}

#[inline(always)]
fn sub(a: &P4, b: &P4) -> P4 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3]]
}

/// `a * b + c`, fused in a copy that has FMA.
#[inline(always)]
fn madd<C: LoopCopy>(a: f64, b: f64, c: f64) -> f64 {
    if C::FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// `B = (F S - gamma K) R` from `K = sum_j u_ij q_ij^T` (and `K_v`, the same of the velocities)
/// and `R = A^-1`: `H = K R`, `F = I + H`, `E = (F^T F - I)/2` and the stress `S` of the law
/// ([`Svk::stress`], eq. 9, plus with `L = K_v R` the viscous stress of `nu = (F^T L + L^T F)/2`,
/// eq. 10-11). `B` is `P A^-1 - gamma H`. `linear`: the small-strain stress with `F = I`
/// (`E = sym H`, no viscous part). For one particle (`f64`) or several in SIMD lanes.
#[inline(always)]
///
/// Also returns `det F` (1 for `linear`): below [`crate::meshfree::COMPRESSION_FLOOR`] the caller
/// adds the compression barrier ([`barrier_b`]).
pub(super) fn b_matrix<T: Scalar>(k: &M3<T>, kv: Option<&M3<T>>, r: &M3<T>, gamma: T, law: Svk, linear: bool) -> (M3<T>, T) {
    let h = mm(k, r);
    let mut det = T::splat(1.0);
    let p = if linear {
        law.stress(&sym(&h), None)
    } else {
        let mut f = h;
        for a in 0..3 {
            f[a][a] = f[a][a].add(T::splat(1.0));
        }
        det = det3(&f);
        let nu = match kv {
            Some(kv) if law.is_damped() => Some(strain_rate_of(&f, &mm(kv, r))),
            _ => None,
        };
        mm(&f, &law.stress(&green_strain_of(&f), nu.as_ref()))
    };
    let mut pk = p;
    let ng = T::splat(0.0).sub(gamma);
    for a in 0..3 {
        for b in 0..3 {
            pk[a][b] = ng.madd(k[a][b], p[a][b]);
        }
    }
    (mm(&pk, r), det)
}

/// The compression barrier's part of `B` for a particle with `K` and `R = A^-1` whose
/// `J = det F` is below the floor `J_c` ([`crate::meshfree::COMPRESSION_FLOOR`]): the first
/// Piola-Kirchhoff stress `kappa (J - J_c) cof F` of the energy density `kappa/2 (J_c - J)^2`
/// (`kappa = lambda + 2 mu`), times `R`. See [`crate::meshfree::COMPRESSION_FLOOR`] for why.
pub(super) fn barrier_b(k: &M3<f64>, r: &M3<f64>, law: Svk) -> M3<f64> {
    let mut f = mm(k, r);
    for a in 0..3 {
        f[a][a] += 1.0;
    }
    let j = det3(&f);
    let (lambda, mu) = law.lame();
    let s = (lambda + 2.0 * mu) * (j - crate::meshfree::COMPRESSION_FLOOR).min(0.0);
    // cof F: the derivative of det F, row a column b.
    let mut cof = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            let (a1, a2, b1, b2) = ((a + 1) % 3, (a + 2) % 3, (b + 1) % 3, (b + 2) % 3);
            cof[a][b] = s * (f[a1][b1] * f[a2][b2] - f[a1][b2] * f[a2][b1]);
        }
    }
    mm(&cof, r)
}

/// `K = sum_j (w_j - w_i) q_ij^T` (rows) over one particle's pairs, for a padded field `w`.
#[inline(always)]
fn gather_rows(nbr: &[u32], q: &[P4], w: &[P4], wi: &P4) -> M3<f64> {
    let mut r0 = [[0.0f64; 4]; 3];
    let mut r1 = [[0.0f64; 4]; 3];
    let pairs = nbr.len() / 2;
    for k in 0..pairs {
        let (ja, jb) = (nbr[2 * k] as usize, nbr[2 * k + 1] as usize);
        let (qa, qb) = (&q[2 * k], &q[2 * k + 1]);
        let da = sub(&w[ja], wi);
        let db = sub(&w[jb], wi);
        for a in 0..3 {
            axpy(&mut r0[a], da[a], qa);
            axpy(&mut r1[a], db[a], qb);
        }
    }
    if nbr.len() % 2 == 1 {
        let last = nbr.len() - 1;
        let d = sub(&w[nbr[last] as usize], wi);
        for a in 0..3 {
            axpy(&mut r0[a], d[a], &q[last]);
        }
    }
    let r = [add(&r0[0], &r1[0]), add(&r0[1], &r1[1]), add(&r0[2], &r1[2])];
    [[r[0][0], r[0][1], r[0][2]], [r[1][0], r[1][1], r[1][2]], [r[2][0], r[2][1], r[2][2]]]
}

/// Pass 1 for particle `i` (portable copy, one at a time): its `B_i` as padded columns, from
/// displacements `u` (and velocities `v` for the viscous stress); see [`b_matrix`].
#[inline(always)]
pub(super) fn particle_stress(m: &ParticleModel, i: usize, u: &[P4], v: Option<&[P4]>, linear: bool) -> Cols {
    let (s, e) = (m.ptr[i], m.ptr[i + 1]);
    let nbr = &m.nbr32[s..e];
    let q = &m.q4[s..e];
    let k = gather_rows(nbr, q, u, &u[i]);
    let law = Svk::of(&m.material);
    let kv = match v {
        Some(v) if law.is_damped() && !linear => Some(gather_rows(nbr, q, v, &v[i])),
        _ => None,
    };
    // A^-1 is stored once, as padded columns (for the SIMD copy): row a is (c0[a], c1[a], c2[a]).
    let rc = &m.r4[i];
    let r = [[rc[0][0], rc[1][0], rc[2][0]], [rc[0][1], rc[1][1], rc[2][1]], [rc[0][2], rc[1][2], rc[2][2]]];
    let (mut b, det) = b_matrix(&k, kv.as_ref(), &r, m.gamma[i], law, linear);
    if det < crate::meshfree::COMPRESSION_FLOOR {
        let extra = barrier_b(&k, &r, law);
        for a in 0..3 {
            for c in 0..3 {
                b[a][c] += extra[a][c];
            }
        }
    }
    [[b[0][0], b[1][0], b[2][0], 0.0], [b[0][1], b[1][1], b[2][1], 0.0], [b[0][2], b[1][2], b[2][2], 0.0]]
}

/// Pass 2 for particle `i` (portable copy): the internal force it receives,
/// `V_i [B_i Q_i + sum_j B_j q_ij + sum_j (gamma_i + gamma_j) w_ij (u_j - u_i)]`, from the `B`
/// of pass 1 and `gamma` (`gamma_j`, zero for frozen particles).
#[inline(always)]
pub(super) fn particle_force(m: &ParticleModel, i: usize, u: &[P4], b: &[Cols], gamma: &[f64]) -> P4 {
    let (s, e) = (m.ptr[i], m.ptr[i + 1]);
    let (ui, gi, bi, qs) = (&u[i], gamma[i], &b[i], &m.qsum4[i]);
    let mut acc = [0.0f64; 4];
    let mut hg = [0.0f64; 4];
    for c in 0..3 {
        axpy(&mut acc, qs[c], &bi[c]);
    }
    for ((&j, qp), &wp) in m.nbr32[s..e].iter().zip(&m.q4[s..e]).zip(&m.w[s..e]) {
        let j = j as usize;
        for c in 0..3 {
            axpy(&mut acc, qp[c], &b[j][c]);
        }
        axpy(&mut hg, (gi + gamma[j]) * wp, &sub(&u[j], ui));
    }
    let sum = add(&acc, &hg);
    let vi = m.volume[i];
    [vi * sum[0], vi * sum[1], vi * sum[2], 0.0]
}

/// Forces of every particle (all active) into `out`: `linear` selects the rest-linearised
/// operator. `b`, `gamma` are scratch of length `n`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
#[allow(unsafe_code)]
pub(super) fn all_forces_impl<C: LoopCopy>(
    c: C,
    m: &ParticleModel,
    u: &[P4],
    v: Option<&[P4]>,
    linear: bool,
    b: &mut [Cols],
    gamma: &mut [f64],
    out: &mut [P4],
) {
    let n = m.n_particles();
    let all: Vec<usize> = (0..n).collect();
    // SAFETY: one call, which `b` is borrowed by alone.
    unsafe { c.stress_pass(m, &all, u, v, linear, &Disjoint::new(b)) };
    gamma.copy_from_slice(&m.gamma);
    c.force_pass(m, &all, u, b, gamma, |i, f| out[i] = f);
}

/// `substeps` Verlet sub-steps of length `h` over the active particles (see
/// [`crate::meshfree::step_with_substeps`], which validated the state and filled `ws.u`, `ws.v`,
/// `ws.touched`, `ws.ring` and `ws.rim`), then the ring's averaged forces into `ws.ring_force`.
/// `ext`: the caller's per-sub-step external forces ([`crate::meshfree::step_with`]).
///
/// Stops after the sub-step in which a free particle's speed relative to the free particles'
/// mass-weighted mean velocity at the step's start passed the material's speed bound (a
/// divergence starting: [`crate::divergence::speed_bound`]), and returns that particle and its
/// speed; the state then holds that sub-step's positions and velocities (finite), for the caller
/// to restore. Checked every sub-step, fused into the force sweep, because an under-stepped shell
/// goes from a few wave speeds to overflow within one tick's sub-steps.
///
/// `fork`: the passes run in its parts (bitwise the same result as in one).
#[inline(always)]
#[allow(unsafe_code, clippy::too_many_arguments)]
pub(super) fn substeps_impl<C: LoopCopy>(
    c: C,
    m: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    h: f64,
    substeps: usize,
    mut ext: Option<ExtForce<'_>>,
    fork: &dyn Fork,
) -> Option<(usize, f64)> {
    for &i in &ws.touched {
        ws.b[i] = [[0.0; 4]; 3];
        ws.gamma[i] = 0.0;
        ws.u_next[i] = ws.u[i];
    }
    for &i in &state.active {
        ws.gamma[i] = m.gamma[i];
    }
    // The free active particles, their constant acceleration (external force and gravity), and
    // fixed particles at rest.
    ws.free.clear();
    for &i in &state.active {
        if m.fixed[i] {
            ws.v[i] = [0.0; 4];
            state.v[i] = Vec3::zeros();
        } else {
            ws.free.push(i);
            ws.acc_ext[i] = super::p4(&(state.f_ext[i] * m.inv_mass[i] + m.gravity));
        }
    }
    // Sums over the sub-steps of the rim's B and displacement (for the ring's gather).
    ws.rim_sum.clear();
    ws.rim_sum.resize(ws.rim.len(), [[0.0; 4]; 4]);
    let damped = !m.material.is_undamped();
    let (mut momentum, mut mass) = (Vec3::zeros(), 0.0);
    for &i in &ws.free {
        momentum += m.mass[i] * state.v[i];
        mass += m.mass[i];
    }
    let mean = if mass > 0.0 { super::p4(&(momentum / mass)) } else { [0.0; 4] };
    let bound = crate::divergence::speed_bound(&m.material);
    let bound2 = bound * bound;
    let mut over: Option<(usize, f64)> = None;
    // Split over the caller's threads only when every particle is in the lists once (`touch`
    // checks): each part then writes its own particles.
    let ways = if ws.unique { fork.ways().clamp(1, MAX_WAYS) } else { 1 };
    for s in 0..substeps {
        if let Some(ext) = ext.as_mut() {
            external_forces(m, state, ws, *ext, s, h);
        }
        let (active, free) = (&state.active[..], &ws.free[..]);
        {
            let (u, v) = (&ws.u[..], if damped { Some(&ws.v[..]) } else { None });
            let b = Disjoint::new(&mut ws.b);
            if ways == 1 {
                // SAFETY: one call, which `b` is borrowed by alone.
                unsafe { c.stress_pass(m, active, u, v, false, &b) };
            } else {
                // SAFETY: part `k` runs once (`Fork`'s contract) on its own piece of the active
                // list, which holds each particle once (`ws.unique`).
                fork.fork(&|k| unsafe { c.stress_pass(m, &active[part(active.len(), ways, k)], u, v, false, &b) });
            }
        }
        if !ws.rim.is_empty() {
            accumulate_rim(&ws.rim, &ws.b, &ws.u, &mut ws.rim_sum);
        }
        // Forces and, in the same sweep, Verlet in velocity form (v += h a, u += h v) into the
        // other displacement buffer: this sweep still reads the current displacements of the
        // neighbours. (Velocities are read again only by the next sub-step's pass 1.)
        let (vel, u_next) = (Disjoint::new(&mut ws.v), Disjoint::new(&mut ws.u_next));
        let args = Verlet { u: &ws.u, b: &ws.b, gamma: &ws.gamma, acc_ext: &ws.acc_ext, h, mean, vel: &vel, u_next: &u_next };
        let (fastest, top) = if ways == 1 {
            // SAFETY: one call, which `vel` and `u_next` are borrowed by alone.
            unsafe { c.verlet_pass(m, free, &args) }
        } else {
            let mut tops = [(usize::MAX, 0.0f64); MAX_WAYS];
            let out = Disjoint::new(&mut tops);
            // SAFETY: as for pass 1, with the free list (part of the active list); `tops[k]` is
            // part `k`'s.
            fork.fork(&|k| unsafe { *out.at(k) = c.verlet_pass(m, &free[part(free.len(), ways, k)], &args) });
            // The first of the fastest, as one sweep in list order finds it.
            tops[..ways].iter().fold((usize::MAX, 0.0f64), |best, &t| if t.1 > best.1 { t } else { best })
        };
        std::mem::swap(&mut ws.u, &mut ws.u_next);
        // Frozen and fixed particles keep their displacement in both buffers.
        if top > bound2 {
            over = Some((fastest, top.sqrt()));
            break;
        }
    }
    for &i in &ws.free {
        state.v[i] = super::v3(&ws.v[i]);
        state.x[i] = m.rest[i] + super::v3(&ws.u[i]);
    }
    if over.is_some() || ws.ring.is_empty() {
        return over;
    }
    // The ring's gather on the sub-step averages (module docs), in the scratch buffers `b` and
    // `u_next`, which the sub-steps no longer need: the rim gets its averages; the ring and its
    // other neighbours are frozen or fixed, with B = 0 (frozen) and a constant displacement in
    // both buffers. (A fixed particle's displacement is constant too: it is averaged like the
    // rest, equal to round-off.)
    let inv = 1.0 / substeps as f64;
    for (&i, sum) in ws.rim.iter().zip(&ws.rim_sum) {
        let scaled = |c: &P4| [inv * c[0], inv * c[1], inv * c[2], 0.0];
        ws.b[i] = [scaled(&sum[0]), scaled(&sum[1]), scaled(&sum[2])];
        ws.u_next[i] = scaled(&sum[3]);
    }
    let out = &mut ws.ring_force;
    out.clear();
    c.force_pass(m, &ws.ring, &ws.u_next, &ws.b, &ws.gamma, |_, f| out.push(super::v3(&f)));
    None
}

/// What pass 2 and the Verlet update of a sub-step read (`u`: the displacements at its start;
/// `b`, `gamma`: pass 1's; `acc_ext`: the external accelerations; `mean`: the free particles'
/// mean velocity at the step's start, for the speed check) and write (`vel`, `u_next`: the
/// velocities, updated in place, and the displacements at its end).
pub(crate) struct Verlet<'a, 'b> {
    pub u: &'a [P4],
    pub b: &'a [Cols],
    pub gamma: &'a [f64],
    pub acc_ext: &'a [P4],
    pub h: f64,
    pub mean: P4,
    pub vel: &'a Disjoint<'b, P4>,
    pub u_next: &'a Disjoint<'b, P4>,
}

/// Pass 2 over the free particles `idx` and, as each force arrives, the Verlet update in velocity
/// form (`v += h a`, `u_next = u + h v`): returns the fastest particle and its squared speed
/// relative to `s.mean` (`(usize::MAX, 0)` for none faster than 0).
///
/// # Safety
/// While it runs, nothing else reaches the entries of `s.vel` and `s.u_next` at `idx`.
#[inline(always)]
#[allow(unsafe_code)]
pub(super) unsafe fn verlet_impl<C: LoopCopy>(c: C, m: &ParticleModel, idx: &[usize], s: &Verlet<'_, '_>) -> (usize, f64) {
    let (h, mean) = (s.h, s.mean);
    let (mut fastest, mut top) = (usize::MAX, 0.0f64);
    c.force_pass(m, idx, s.u, s.b, s.gamma, |i, f| {
        let (ae, im, u) = (&s.acc_ext[i], m.inv_mass[i], &s.u[i]);
        // SAFETY: the caller's contract gives this call the entries at `i` (in `idx`).
        let (v, un) = unsafe { (s.vel.at(i), s.u_next.at(i)) };
        let mut s2 = 0.0;
        for l in 0..3 {
            v[l] = madd::<C>(h, madd::<C>(f[l], im, ae[l]), v[l]);
            un[l] = madd::<C>(h, v[l], u[l]);
            s2 += (v[l] - mean[l]) * (v[l] - mean[l]);
        }
        if s2 > top {
            (fastest, top) = (i, s2);
        }
    });
    (fastest, top)
}

/// Add the rim's `B` and displacement of this sub-step to their sums (kept out of line: inlined,
/// it slowed the whole sub-step by more than its own work, by crowding the hot passes).
#[inline(never)]
fn accumulate_rim(rim: &[usize], b: &[Cols], u: &[P4], sums: &mut [[P4; 4]]) {
    for (&i, sum) in rim.iter().zip(sums) {
        let (b, u) = (&b[i], &u[i]);
        for l in 0..4 {
            sum[0][l] += b[0][l];
            sum[1][l] += b[1][l];
            sum[2][l] += b[2][l];
            sum[3][l] += u[l];
        }
    }
}

/// Before sub-step `s`: write the free active particles' positions and velocities back to the
/// state (the callback reads them there; the first sub-step's are the state's own), ask the
/// caller for this sub-step's external forces, and turn them into accelerations.
#[inline(never)]
fn external_forces(
    m: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    ext: &mut dyn FnMut(&crate::meshfree::SubStep<'_>, &mut [Vec3]),
    s: usize,
    h: f64,
) {
    if s > 0 {
        for &i in &ws.free {
            state.v[i] = super::v3(&ws.v[i]);
            state.x[i] = m.rest[i] + super::v3(&ws.u[i]);
        }
    }
    for &i in &state.active {
        ws.f_sub[i] = state.f_ext[i];
    }
    let sub = crate::meshfree::SubStep { index: s, t: state.t + s as f64 * h, h, x: &state.x, v: &state.v, active: &state.active };
    ext(&sub, &mut ws.f_sub);
    for &i in &ws.free {
        ws.acc_ext[i] = super::p4(&(ws.f_sub[i] * m.inv_mass[i] + m.gravity));
    }
}
