//! The AVX2 + FMA copy of the two passes (4 lanes = one `__m256d`), and its entry points: the
//! crate's one module with `unsafe` code (intrinsics, `target_feature` calls after run-time
//! detection, and unchecked neighbour reads).
//!
//! Soundness rests on two facts: an [`Avx2`] value exists only on a CPU with AVX2 and FMA (its
//! one constructor, [`Avx2::detect`], checks), and the neighbour indices of a [`ParticleModel`]
//! are smaller than its particle count (built so, never changed), while the passes check that
//! every per-particle array has that length.

use super::passes::{self, b_matrix, Verlet};
use super::{Cols, Disjoint, ExtForce, LoopCopy, P4};
use crate::material::linear::{Scalar, Svk, M3};
use crate::meshfree::{ParticleModel, ParticleState, ParticleWorkspace};
use crate::parallel::Fork;
use std::arch::x86_64::*;

/// Proof that the CPU has AVX2 and FMA: the AVX2 copy of the loop.
#[derive(Clone, Copy)]
pub(super) struct Avx2(());

impl Avx2 {
    /// `Some` if and only if this CPU has AVX2 and FMA.
    #[inline]
    pub(super) fn detect() -> Option<Avx2> {
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            Some(Avx2(()))
        } else {
            None
        }
    }

    /// `substeps` Verlet sub-steps (see [`passes::substeps_impl`]) in this copy.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn run_substeps(
        self,
        m: &ParticleModel,
        state: &mut ParticleState,
        ws: &mut ParticleWorkspace,
        h: f64,
        substeps: usize,
        ext: Option<ExtForce<'_>>,
        fork: &dyn Fork,
    ) -> Option<(usize, f64)> {
        // SAFETY: a `target_feature` function needs only that the CPU has the features, which
        // an `Avx2` proves.
        unsafe { substeps_avx2(self, m, state, ws, h, substeps, ext, fork) }
    }

    /// Forces of every particle (see [`passes::all_forces_impl`]) in this copy.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn all_forces(self, m: &ParticleModel, u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols], gamma: &mut [f64], out: &mut [P4]) {
        // SAFETY: as in `run_substeps`.
        unsafe { all_forces_avx2(self, m, u, v, linear, b, gamma, out) }
    }
}

#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
fn substeps_avx2(
    c: Avx2,
    m: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    h: f64,
    substeps: usize,
    ext: Option<ExtForce<'_>>,
    fork: &dyn Fork,
) -> Option<(usize, f64)> {
    passes::substeps_impl(c, m, state, ws, h, substeps, ext, fork)
}

/// Pass 2 and the Verlet update in this copy (a part of a split sub-step runs it on any thread).
///
/// # Safety
/// The CPU has AVX2 and FMA, and the contract of [`LoopCopy::verlet_pass`].
#[target_feature(enable = "avx2,fma")]
unsafe fn verlet_avx2(c: Avx2, m: &ParticleModel, idx: &[usize], s: &Verlet<'_, '_>) -> (usize, f64) {
    // SAFETY: the caller's contract.
    unsafe { passes::verlet_impl(c, m, idx, s) }
}

#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
fn all_forces_avx2(c: Avx2, m: &ParticleModel, u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols], gamma: &mut [f64], out: &mut [P4]) {
    passes::all_forces_impl(c, m, u, v, linear, b, gamma, out)
}

impl LoopCopy for Avx2 {
    const FMA: bool = true;

    #[inline(always)]
    unsafe fn stress_pass(self, m: &ParticleModel, idx: &[usize], u: &[P4], v: Option<&[P4]>, linear: bool, b: &Disjoint<'_, Cols>) {
        let n = m.n_particles();
        assert!(u.len() == n && v.is_none_or(|v| v.len() == n) && b.len() == n);
        // SAFETY: `self` proves the CPU features; the lengths are checked above, neighbour
        // indices are `< n` (module docs), `idx` entries are used with checked indexing, and
        // the caller's contract gives this call the entries of `b` at `idx`.
        unsafe { stress_pass(m, idx, u, v, linear, b) }
    }

    #[inline(always)]
    unsafe fn verlet_pass(self, m: &ParticleModel, idx: &[usize], s: &Verlet<'_, '_>) -> (usize, f64) {
        // SAFETY: `self` proves the CPU features; the rest is the caller's contract.
        unsafe { verlet_avx2(self, m, idx, s) }
    }

    #[inline(always)]
    fn force_pass(self, m: &ParticleModel, idx: &[usize], u: &[P4], b: &[Cols], gamma: &[f64], mut sink: impl FnMut(usize, P4)) {
        let n = m.n_particles();
        assert!(u.len() == n && b.len() == n && gamma.len() == n);
        for &i in idx {
            let (s, e) = (m.ptr[i], m.ptr[i + 1]);
            // SAFETY: as in `stress_pass`; `q` and `w` are sliced to the neighbour list's length.
            let sum = unsafe { force(&m.nbr32[s..e], &m.q4[s..e], &m.w[s..e], u, b, gamma, &u[i], gamma[i], &b[i], &m.qsum4[i]) };
            let vi = m.volume[i];
            sink(i, [vi * sum[0], vi * sum[1], vi * sum[2], 0.0]);
        }
    }
}

/// Four particles side by side, one per AVX lane.
///
/// Invariant: values of this type exist only inside functions compiled with
/// `target_feature(enable = "avx2,fma")`, reached only through an [`Avx2`] (so on CPUs that
/// have both), so the intrinsics in its methods, inlined there, always meet their feature
/// requirement.
#[derive(Clone, Copy)]
struct F4(__m256d);

// SAFETY (every `unsafe` below): the invariant of `F4`.
impl Scalar for F4 {
    #[inline(always)]
    fn splat(x: f64) -> Self {
        unsafe { F4(_mm256_set1_pd(x)) }
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        unsafe { F4(_mm256_add_pd(self.0, o.0)) }
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        unsafe { F4(_mm256_sub_pd(self.0, o.0)) }
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        unsafe { F4(_mm256_mul_pd(self.0, o.0)) }
    }
    #[inline(always)]
    fn madd(self, b: Self, c: Self) -> Self {
        unsafe { F4(_mm256_fmadd_pd(self.0, b.0, c.0)) }
    }
}

/// Rows of the 4x4 matrix whose columns are `a`, `b`, `c`, `d`.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn transpose(a: __m256d, b: __m256d, c: __m256d, d: __m256d) -> [__m256d; 4] {
    let t0 = _mm256_unpacklo_pd(a, b);
    let t1 = _mm256_unpackhi_pd(a, b);
    let t2 = _mm256_unpacklo_pd(c, d);
    let t3 = _mm256_unpackhi_pd(c, d);
    [
        _mm256_permute2f128_pd::<0x20>(t0, t2),
        _mm256_permute2f128_pd::<0x20>(t1, t3),
        _mm256_permute2f128_pd::<0x31>(t0, t2),
        _mm256_permute2f128_pd::<0x31>(t1, t3),
    ]
}

/// Three 3x3 matrices given by columns, one per particle (4 particles), as one matrix of lanes.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn to_lanes(cols: &[[__m256d; 3]; 4]) -> M3<F4> {
    let z = F4(_mm256_setzero_pd());
    let mut m = [[z; 3]; 3];
    for c in 0..3 {
        let t = transpose(cols[0][c], cols[1][c], cols[2][c], cols[3][c]);
        for a in 0..3 {
            m[a][c] = F4(t[a]);
        }
    }
    m
}

/// `K = sum_j (w_j - w_i) q_ij^T` as columns.
///
/// # Safety
/// The CPU has AVX2 and FMA; every `nbr` entry is `< w.len()`; `q.len() == nbr.len()`.
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn gather_cols(nbr: &[u32], q: &[P4], w: &[P4], wi: &P4) -> [__m256d; 3] {
    // SAFETY (every `get_unchecked`): the caller's contract.
    let at = |j: u32| -> &P4 { unsafe { w.get_unchecked(j as usize) } };
    let wi = load(wi);
    let z = _mm256_setzero_pd();
    let (mut a0, mut a1, mut a2) = (z, z, z);
    let (mut b0, mut b1, mut b2) = (z, z, z);
    let mut pairs = nbr.chunks_exact(2).zip(q.chunks_exact(2));
    for (j, qq) in &mut pairs {
        let (qa, qb) = (&qq[0], &qq[1]);
        let da = _mm256_sub_pd(load(at(j[0])), wi);
        let db = _mm256_sub_pd(load(at(j[1])), wi);
        a0 = _mm256_fmadd_pd(da, _mm256_broadcast_sd(&qa[0]), a0);
        a1 = _mm256_fmadd_pd(da, _mm256_broadcast_sd(&qa[1]), a1);
        a2 = _mm256_fmadd_pd(da, _mm256_broadcast_sd(&qa[2]), a2);
        b0 = _mm256_fmadd_pd(db, _mm256_broadcast_sd(&qb[0]), b0);
        b1 = _mm256_fmadd_pd(db, _mm256_broadcast_sd(&qb[1]), b1);
        b2 = _mm256_fmadd_pd(db, _mm256_broadcast_sd(&qb[2]), b2);
    }
    if let (Some(&j), Some(qa)) = (nbr.chunks_exact(2).remainder().first(), q.chunks_exact(2).remainder().first()) {
        let da = _mm256_sub_pd(load(at(j)), wi);
        a0 = _mm256_fmadd_pd(da, _mm256_broadcast_sd(&qa[0]), a0);
        a1 = _mm256_fmadd_pd(da, _mm256_broadcast_sd(&qa[1]), a1);
        a2 = _mm256_fmadd_pd(da, _mm256_broadcast_sd(&qa[2]), a2);
    }
    [_mm256_add_pd(a0, b0), _mm256_add_pd(a1, b1), _mm256_add_pd(a2, b2)]
}

/// [`gather_cols`] of two fields `w` and `y` (displacements and velocities) over the same pairs
/// in one sweep: each neighbour's index and `q_ij` are read and broadcast once for both (the two
/// fields' sums are the two independent accumulator chains).
///
/// # Safety
/// As [`gather_cols`], for both `w` and `y`.
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn gather_cols2(nbr: &[u32], q: &[P4], w: &[P4], wi: &P4, y: &[P4], yi: &P4) -> ([__m256d; 3], [__m256d; 3]) {
    // SAFETY (every `get_unchecked`): the caller's contract.
    let at = |f: &[P4], j: u32| -> __m256d { load(unsafe { f.get_unchecked(j as usize) }) };
    let (wi, yi) = (load(wi), load(yi));
    let z = _mm256_setzero_pd();
    let (mut a0, mut a1, mut a2) = (z, z, z);
    let (mut b0, mut b1, mut b2) = (z, z, z);
    for (&j, qa) in nbr.iter().zip(q) {
        let dw = _mm256_sub_pd(at(w, j), wi);
        let dy = _mm256_sub_pd(at(y, j), yi);
        let (q0, q1, q2) = (_mm256_broadcast_sd(&qa[0]), _mm256_broadcast_sd(&qa[1]), _mm256_broadcast_sd(&qa[2]));
        a0 = _mm256_fmadd_pd(dw, q0, a0);
        a1 = _mm256_fmadd_pd(dw, q1, a1);
        a2 = _mm256_fmadd_pd(dw, q2, a2);
        b0 = _mm256_fmadd_pd(dy, q0, b0);
        b1 = _mm256_fmadd_pd(dy, q1, b1);
        b2 = _mm256_fmadd_pd(dy, q2, b2);
    }
    ([a0, a1, a2], [b0, b1, b2])
}

/// Pass 1 over the particles `idx`, four at a time in lanes: `b[i] = B_i` (see
/// [`b_matrix`]) from displacements `u` (velocities `v` when damped).
///
/// # Safety
/// The CPU has AVX2 and FMA; `u`, `v` and `b` have `m.n_particles()` entries (`idx` entries
/// are used with checked indexing); nothing else reaches the entries of `b` at `idx`.
#[target_feature(enable = "avx2,fma")]
unsafe fn stress_pass(m: &ParticleModel, idx: &[usize], u: &[P4], v: Option<&[P4]>, linear: bool, b: &Disjoint<'_, Cols>) {
    let law = Svk::of(&m.material);
    let damped = !linear && v.is_some() && law.is_damped();
    let z = _mm256_setzero_pd();
    for chunk in idx.chunks(4) {
        let last = chunk.len() - 1;
        let p = [chunk[0], chunk[1.min(last)], chunk[2.min(last)], chunk[3.min(last)]];
        let mut kc = [[z; 3]; 4];
        let mut kvc = [[z; 3]; 4];
        let mut rc = [[z; 3]; 4];
        let mut g = [0.0; 4];
        for (l, &i) in p.iter().enumerate() {
            let (s, e) = (m.ptr[i], m.ptr[i + 1]);
            let (nbr, q) = (&m.nbr32[s..e], &m.q4[s..e]);
            // SAFETY: neighbour indices are `< n` (built so), and the caller's contract.
            match v {
                Some(v) if damped => (kc[l], kvc[l]) = unsafe { gather_cols2(nbr, q, u, &u[i], v, &v[i]) },
                _ => kc[l] = unsafe { gather_cols(nbr, q, u, &u[i]) },
            }
            let r = &m.r4[i];
            rc[l] = [load(&r[0]), load(&r[1]), load(&r[2])];
            g[l] = m.gamma[i];
        }
        let k = to_lanes(&kc);
        let kv = if damped { Some(to_lanes(&kvc)) } else { None };
        let r = to_lanes(&rc);
        let gamma = F4(_mm256_set_pd(g[3], g[2], g[1], g[0]));
        let (bm, det) = b_matrix(&k, kv.as_ref(), &r, gamma, law, linear);
        // (No closures here: they would not inherit this function's target features.)
        let t = [
            transpose(bm[0][0].0, bm[1][0].0, bm[2][0].0, z),
            transpose(bm[0][1].0, bm[1][1].0, bm[2][1].0, z),
            transpose(bm[0][2].0, bm[1][2].0, bm[2][2].0, z),
        ];
        let det = store(det.0);
        for (l, &i) in chunk.iter().enumerate() {
            // SAFETY: the caller's contract gives this call the entry at `i`.
            let bi = unsafe { b.at(i) };
            // A particle compressed past the floor (rare) gets the barrier from the portable copy.
            *bi = if det[l] < crate::meshfree::COMPRESSION_FLOOR {
                passes::particle_stress(m, i, u, v, linear)
            } else {
                [store(t[0][l]), store(t[1][l]), store(t[2][l])]
            };
        }
    }
}

#[inline]
#[target_feature(enable = "avx2,fma")]
fn load(p: &P4) -> __m256d {
    _mm256_set_pd(p[3], p[2], p[1], p[0])
}

#[inline]
#[target_feature(enable = "avx2,fma")]
fn store(v: __m256d) -> P4 {
    let mut out = [0.0; 4];
    // Lanes one by one keeps this safe; LLVM emits one store.
    let lo = _mm256_castpd256_pd128(v);
    let hi = _mm256_extractf128_pd::<1>(v);
    out[0] = _mm_cvtsd_f64(lo);
    out[1] = _mm_cvtsd_f64(_mm_unpackhi_pd(lo, lo));
    out[2] = _mm_cvtsd_f64(hi);
    out[3] = _mm_cvtsd_f64(_mm_unpackhi_pd(hi, hi));
    out
}

/// `B_i Q_i + sum_j B_j q_ij + sum_j (gamma_i + gamma_j) w_ij (u_j - u_i)`.
///
/// # Safety
/// The CPU has AVX2 and FMA; every `nbr` entry is `<` the lengths of `u`, `b` and `gamma`;
/// `q` and `w` have `nbr.len()` entries.
#[inline]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn force(nbr: &[u32], q: &[P4], w: &[f64], u: &[P4], b: &[Cols], gamma: &[f64], ui: &P4, gi: f64, bi: &Cols, qs: &P4) -> P4 {
    // SAFETY (every `get_unchecked`): the caller's contract.
    let data = |j: u32| -> (&Cols, &P4, f64) {
        let j = j as usize;
        unsafe { (b.get_unchecked(j), u.get_unchecked(j), *gamma.get_unchecked(j)) }
    };
    let uiv = load(ui);
    let z = _mm256_setzero_pd();
    let mut a0 = _mm256_mul_pd(load(&bi[0]), _mm256_broadcast_sd(&qs[0]));
    let mut a1 = _mm256_mul_pd(load(&bi[1]), _mm256_broadcast_sd(&qs[1]));
    let mut a2 = _mm256_mul_pd(load(&bi[2]), _mm256_broadcast_sd(&qs[2]));
    let mut a3 = z;
    let (mut b0, mut b1, mut b2, mut b3) = (z, z, z, z);
    let mut pairs = nbr.chunks_exact(2).zip(q.chunks_exact(2)).zip(w.chunks_exact(2));
    for ((j, qq), ww) in &mut pairs {
        let (qa, qb) = (&qq[0], &qq[1]);
        let (ba, ua, ga) = data(j[0]);
        let (bb, ub, gb) = data(j[1]);
        a0 = _mm256_fmadd_pd(load(&ba[0]), _mm256_broadcast_sd(&qa[0]), a0);
        a1 = _mm256_fmadd_pd(load(&ba[1]), _mm256_broadcast_sd(&qa[1]), a1);
        a2 = _mm256_fmadd_pd(load(&ba[2]), _mm256_broadcast_sd(&qa[2]), a2);
        b0 = _mm256_fmadd_pd(load(&bb[0]), _mm256_broadcast_sd(&qb[0]), b0);
        b1 = _mm256_fmadd_pd(load(&bb[1]), _mm256_broadcast_sd(&qb[1]), b1);
        b2 = _mm256_fmadd_pd(load(&bb[2]), _mm256_broadcast_sd(&qb[2]), b2);
        a3 = _mm256_fmadd_pd(_mm256_set1_pd((gi + ga) * ww[0]), _mm256_sub_pd(load(ua), uiv), a3);
        b3 = _mm256_fmadd_pd(_mm256_set1_pd((gi + gb) * ww[1]), _mm256_sub_pd(load(ub), uiv), b3);
    }
    let rest = (nbr.chunks_exact(2).remainder().first(), q.chunks_exact(2).remainder().first(), w.chunks_exact(2).remainder().first());
    if let (Some(&j), Some(qa), Some(&wa)) = rest {
        let (ba, ua, ga) = data(j);
        a0 = _mm256_fmadd_pd(load(&ba[0]), _mm256_broadcast_sd(&qa[0]), a0);
        a1 = _mm256_fmadd_pd(load(&ba[1]), _mm256_broadcast_sd(&qa[1]), a1);
        a2 = _mm256_fmadd_pd(load(&ba[2]), _mm256_broadcast_sd(&qa[2]), a2);
        a3 = _mm256_fmadd_pd(_mm256_set1_pd((gi + ga) * wa), _mm256_sub_pd(load(ua), uiv), a3);
    }
    let s = _mm256_add_pd(_mm256_add_pd(_mm256_add_pd(a0, b0), _mm256_add_pd(a1, b1)), _mm256_add_pd(_mm256_add_pd(a2, b2), _mm256_add_pd(a3, b3)));
    store(s)
}
