//! The hot loop of the particle body: stresses, pair forces and the Verlet sub-steps.
//!
//! ## Two passes per sub-step, both gathers
//! Particle `i` exerts on neighbour `j` the force `-t_ij` and on itself `+t_ij`, with
//! `t_ij = M_i q_ij + c_i w_ij u_ij` (see [`crate::meshfree`]; `q_ij = w_ij X_ij`,
//! `w_ij = V_j W_ij`, `M_i = V_i P_i A_i^-1 - c_i H_i`). Written as a scatter, every pair costs a
//! read-modify-write of `f_j`, and the accumulations form long dependency chains. Collecting
//! what particle `i` receives instead (`q_ji = -(V_i/V_j) q_ij`, `w_ji = (V_i/V_j) w_ij`):
//!
//! ```text
//! f_i = V_i [ B_i Q_i + sum_j B_j q_ij + sum_j (gamma_i + gamma_j) w_ij (u_j - u_i) ],
//! B_i = M_i / V_i = P_i A_i^-1 - gamma_i H_i,   gamma_i = c_i / V_i,   Q_i = sum_j q_ij,
//! ```
//!
//! so a sub-step is pass 1 (per active particle: gather `K = sum_j u_ij q_ij^T`, then `H`, `F`,
//! stress and `B_i`) and pass 2 (per free active particle: gather `B_j q_ij` and the hourglass
//! term), then the Verlet update. Both passes only read neighbour data. Frozen (inactive)
//! neighbours have `B_j = 0`, `gamma_j = 0`: as in the scatter form, only active particles'
//! stresses act (the paper's active set). The two forms are equal up to round-off; pairwise the
//! terms of `i <- j` and `j <- i` are equal and opposite, so momentum is conserved to round-off.
//!
//! ## SIMD
//! Per pair the work is a few 4-lane multiply-adds on padded 3-vectors ([`P4`]), with two
//! independent accumulator sets so that the adds do not wait on each other. The passes are
//! generic over `FMA`; on x86-64 CPUs with AVX2 and FMA (detected at run time) they run in a copy
//! compiled for those features, where a `P4` is one register and `a*b + c` one fused instruction;
//! elsewhere the baseline copy runs. Results differ between the two copies by round-off only.

use super::body::{ParticleModel, ParticleState, ParticleWorkspace};
use crate::math::Vec3;
use std::sync::atomic::{AtomicBool, Ordering};

/// A 3-vector padded to 4 lanes (the 4th lane is 0 on input and ignored on output).
pub(crate) type P4 = [f64; 4];
/// A 3x3 matrix as three padded columns.
pub(crate) type Cols = [P4; 3];

#[inline(always)]
pub(crate) fn p4(v: &Vec3) -> P4 {
    [v.x, v.y, v.z, 0.0]
}

#[inline(always)]
pub(crate) fn v3(p: &P4) -> Vec3 {
    Vec3::new(p[0], p[1], p[2])
}

/// `a * b + c`, fused where the copy is compiled with FMA.
#[inline(always)]
fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// `acc += s * x` on 4 lanes.
#[inline(always)]
fn axpy<const FMA: bool>(acc: &mut P4, s: f64, x: &P4) {
    for l in 0..4 {
        acc[l] = madd::<FMA>(s, x[l], acc[l]);
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

/// The arithmetic the per-particle algebra needs, for one particle (`f64`) or several particles
/// side by side in SIMD lanes (`avx::F4`): the algebra is written once, over this trait.
pub(crate) trait Lane: Copy {
    fn splat(x: f64) -> Self;
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    /// `self * b + c`.
    fn madd(self, b: Self, c: Self) -> Self;
}

impl Lane for f64 {
    #[inline(always)]
    fn splat(x: f64) -> Self { x }
    #[inline(always)]
    fn add(self, o: Self) -> Self { self + o }
    #[inline(always)]
    fn sub(self, o: Self) -> Self { self - o }
    #[inline(always)]
    fn mul(self, o: Self) -> Self { self * o }
    #[inline(always)]
    fn madd(self, b: Self, c: Self) -> Self { self * b + c }
}

/// A 3x3 matrix as rows, `m[a][b]`.
pub(crate) type M3<T> = [[T; 3]; 3];

/// `a b`.
#[inline(always)]
fn mm<T: Lane>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut c = [[T::splat(0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][2].madd(b[2][j], a[i][1].madd(b[1][j], a[i][0].mul(b[0][j])));
        }
    }
    c
}

/// `(a^T b + b^T a) / 2`.
#[inline(always)]
fn sym_atb<T: Lane>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut d = [[T::splat(0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            d[i][j] = a[2][i].madd(b[2][j], a[1][i].madd(b[1][j], a[0][i].mul(b[0][j])));
        }
    }
    let half = T::splat(0.5);
    let mut e = d;
    for i in 0..3 {
        for j in 0..3 {
            e[i][j] = half.mul(d[i][j].add(d[j][i]));
        }
    }
    e
}

/// `s += lam tr(e) I + 2 mu e`.
#[inline(always)]
fn add_isotropic<T: Lane>(s: &mut M3<T>, e: &M3<T>, lam: f64, mu: f64) {
    let t = T::splat(lam).mul(e[0][0].add(e[1][1]).add(e[2][2]));
    let two_mu = T::splat(2.0 * mu);
    for i in 0..3 {
        for j in 0..3 {
            s[i][j] = two_mu.madd(e[i][j], s[i][j]);
        }
        s[i][i] = s[i][i].add(t);
    }
}

/// The material constants the per-particle algebra reads.
#[derive(Clone, Copy)]
pub(crate) struct Law {
    lam: f64,
    mu: f64,
    /// `(phi, psi)` when damped.
    viscous: Option<(f64, f64)>,
}

impl Law {
    pub(crate) fn of(m: &ParticleModel) -> Law {
        let mat = &m.material;
        let d = mat.damping();
        Law { lam: mat.lambda(), mu: mat.mu(), viscous: if mat.is_undamped() { None } else { Some((d.phi, d.psi)) } }
    }
}

/// `B = (F S - gamma K) R` from `K = sum_j u_ij q_ij^T` (and `K_v`, the same of the velocities)
/// and `R = A^-1`: `H = K R`, `F = I + H`, `E = (F^T F - I)/2`, `S = lam tr(E) I + 2 mu E`
/// (eq. 9) plus, with `L = K_v R`, the viscous `phi tr(nu) I + 2 psi nu`,
/// `nu = (F^T L + L^T F)/2` (eq. 10-11). `B` is `P A^-1 - gamma H`. `linear`: the small-strain
/// stress with `F = I` (`E = sym H`, no viscous part).
#[inline(always)]
pub(crate) fn b_matrix<T: Lane>(k: &M3<T>, kv: Option<&M3<T>>, r: &M3<T>, gamma: T, law: Law, linear: bool) -> M3<T> {
    let h = mm(k, r);
    let zero = T::splat(0.0);
    let half = T::splat(0.5);
    let mut st = [[zero; 3]; 3];
    let p = if linear {
        let mut eps = h;
        for a in 0..3 {
            for b in 0..3 {
                eps[a][b] = half.mul(h[a][b].add(h[b][a]));
            }
        }
        add_isotropic(&mut st, &eps, law.lam, law.mu);
        st
    } else {
        let mut f = h;
        for a in 0..3 {
            f[a][a] = f[a][a].add(T::splat(1.0));
        }
        let mut green = sym_atb(&f, &f);
        for a in 0..3 {
            for b in 0..3 {
                green[a][b] = half.mul(green[a][b]);
            }
            green[a][a] = green[a][a].sub(half);
        }
        add_isotropic(&mut st, &green, law.lam, law.mu);
        if let (Some(kv), Some((phi, psi))) = (kv, law.viscous) {
            let l = mm(kv, r);
            add_isotropic(&mut st, &sym_atb(&f, &l), phi, psi);
        }
        mm(&f, &st)
    };
    let mut pk = p;
    let ng = zero.sub(gamma);
    for a in 0..3 {
        for b in 0..3 {
            pk[a][b] = ng.madd(k[a][b], p[a][b]);
        }
    }
    mm(&pk, r)
}

/// `K = sum_j (w_j - w_i) q_ij^T` (rows) over one particle's pairs, for a padded field `w`.
#[inline(always)]
fn gather_rows<const FMA: bool>(nbr: &[u32], q: &[P4], w: &[P4], wi: &P4) -> M3<f64> {
    let mut r0 = [[0.0f64; 4]; 3];
    let mut r1 = [[0.0f64; 4]; 3];
    let pairs = nbr.len() / 2;
    for k in 0..pairs {
        let (ja, jb) = (nbr[2 * k] as usize, nbr[2 * k + 1] as usize);
        let (qa, qb) = (&q[2 * k], &q[2 * k + 1]);
        let da = sub(&w[ja], wi);
        let db = sub(&w[jb], wi);
        for a in 0..3 {
            axpy::<FMA>(&mut r0[a], da[a], qa);
            axpy::<FMA>(&mut r1[a], db[a], qb);
        }
    }
    if nbr.len() % 2 == 1 {
        let last = nbr.len() - 1;
        let d = sub(&w[nbr[last] as usize], wi);
        for a in 0..3 {
            axpy::<FMA>(&mut r0[a], d[a], &q[last]);
        }
    }
    let r = [add(&r0[0], &r1[0]), add(&r0[1], &r1[1]), add(&r0[2], &r1[2])];
    [[r[0][0], r[0][1], r[0][2]], [r[1][0], r[1][1], r[1][2]], [r[2][0], r[2][1], r[2][2]]]
}

/// Pass 1 for particle `i` (one at a time): its `B_i` as padded columns, from displacements `u`
/// (and velocities `v` for the viscous stress); see [`b_matrix`].
#[inline(always)]
fn particle_stress<const FMA: bool>(m: &ParticleModel, i: usize, u: &[P4], v: Option<&[P4]>, linear: bool) -> Cols {
    let (s, e) = (m.ptr[i], m.ptr[i + 1]);
    let nbr = &m.nbr32[s..e];
    let q = &m.q4[s..e];
    let k = gather_rows::<FMA>(nbr, q, u, &u[i]);
    let law = Law::of(m);
    let kv = match (v, law.viscous) {
        (Some(v), Some(_)) if !linear => Some(gather_rows::<FMA>(nbr, q, v, &v[i])),
        _ => None,
    };
    // A^-1 is stored once, as padded columns (for the SIMD copy): row a is (c0[a], c1[a], c2[a]).
    let rc = &m.r4[i];
    let r = [[rc[0][0], rc[1][0], rc[2][0]], [rc[0][1], rc[1][1], rc[2][1]], [rc[0][2], rc[1][2], rc[2][2]]];
    let b = b_matrix(&k, kv.as_ref(), &r, m.gamma[i], law, linear);
    [[b[0][0], b[1][0], b[2][0], 0.0], [b[0][1], b[1][1], b[2][1], 0.0], [b[0][2], b[1][2], b[2][2], 0.0]]
}

/// Pass 2 for particle `i`: the internal force it receives, from the `B` of pass 1 and
/// `gamma` (`gamma_j`, zero for frozen particles).
#[inline(always)]
fn particle_force<const FMA: bool>(m: &ParticleModel, i: usize, u: &[P4], b: &[Cols], gamma: &[f64]) -> P4 {
    let (s, e) = (m.ptr[i], m.ptr[i + 1]);
    let nbr = &m.nbr32[s..e];
    let q = &m.q4[s..e];
    let w = &m.w[s..e];
    let (ui, gi) = (&u[i], gamma[i]);
    let bi = &b[i];
    let qs = &m.qsum4[i];
    #[cfg(target_arch = "x86_64")]
    let sum = if FMA {
        // SAFETY: as in `stress_pass`.
        #[allow(unsafe_code)]
        unsafe {
            avx::force(nbr, q, w, u, b, gamma, ui, gi, bi, qs)
        }
    } else {
        force_sum::<FMA>(nbr, q, w, u, b, gamma, ui, gi, bi, qs)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let sum = force_sum::<FMA>(nbr, q, w, u, b, gamma, ui, gi, bi, qs);
    let vi = m.volume[i];
    [vi * sum[0], vi * sum[1], vi * sum[2], 0.0]
}

/// `B_i Q_i + sum_j B_j q_ij + sum_j (gamma_i + gamma_j) w_ij (u_j - u_i)` (portable copy).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn force_sum<const FMA: bool>(nbr: &[u32], q: &[P4], w: &[f64], u: &[P4], b: &[Cols], gamma: &[f64], ui: &P4, gi: f64, bi: &Cols, qs: &P4) -> P4 {
    let mut acc = [0.0f64; 4];
    let mut hg = [0.0f64; 4];
    for c in 0..3 {
        axpy::<FMA>(&mut acc, qs[c], &bi[c]);
    }
    for ((&j, qp), &wp) in nbr.iter().zip(q).zip(w) {
        let j = j as usize;
        for c in 0..3 {
            axpy::<FMA>(&mut acc, qp[c], &b[j][c]);
        }
        axpy::<FMA>(&mut hg, (gi + gamma[j]) * wp, &sub(&u[j], ui));
    }
    add(&acc, &hg)
}

/// Pass 1 over the particles `idx`: `b[i] = B_i`.
#[inline(always)]
fn stress_pass<const FMA: bool>(m: &ParticleModel, idx: &[usize], u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols]) {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: `FMA = true` copies are only instantiated inside the `avx2,fma` entry points,
        // which run only after `has_avx2_fma()` and check that `u`, `v` and `b` have one entry
        // per particle; `idx` holds particle indices (validated by the caller).
        #[allow(unsafe_code)]
        unsafe {
            avx::stress_pass(m, idx, u, v, linear, b)
        };
        return;
    }
    for &i in idx {
        b[i] = particle_stress::<FMA>(m, i, u, v, linear);
    }
}

/// Forces of every particle (all active) into `out`: `linear` selects the rest-linearised
/// operator. `b`, `gamma` are scratch of length `n`.
#[inline(always)]
fn all_forces_impl<const FMA: bool>(m: &ParticleModel, u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols], gamma: &mut [f64], out: &mut [P4]) {
    let n = m.n_particles();
    let all: Vec<usize> = (0..n).collect();
    stress_pass::<FMA>(m, &all, u, v, linear, b);
    gamma.copy_from_slice(&m.gamma);
    for i in 0..n {
        out[i] = particle_force::<FMA>(m, i, u, b, gamma);
    }
}

/// `substeps` Verlet sub-steps of length `h` over the active particles (see
/// [`ParticleModel::step_with_substeps`], which validated the state and filled `ws.u`, `ws.v`
/// and `ws.touched`).
#[inline(always)]
fn substeps_impl<const FMA: bool>(m: &ParticleModel, state: &mut ParticleState, ws: &mut ParticleWorkspace, h: f64, substeps: usize) {
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
            ws.acc_ext[i] = p4(&(state.f_ext[i] / m.mass[i] + m.gravity));
        }
    }
    let damped = !m.material.is_undamped();
    for _ in 0..substeps {
        stress_pass::<FMA>(m, &state.active, &ws.u, if damped { Some(&ws.v) } else { None }, false, &mut ws.b);
        // Forces and, in the same sweep, Verlet in velocity form (v += h a, u += h v) into the
        // other displacement buffer: this sweep still reads the current displacements of the
        // neighbours. (Velocities are read again only by the next sub-step's pass 1.)
        for &i in &ws.free {
            let f = particle_force::<FMA>(m, i, &ws.u, &ws.b, &ws.gamma);
            let (ae, im) = (&ws.acc_ext[i], m.inv_mass[i]);
            let (v, u, un) = (&mut ws.v[i], &ws.u[i], &mut ws.u_next[i]);
            for l in 0..3 {
                v[l] = madd::<FMA>(h, madd::<FMA>(f[l], im, ae[l]), v[l]);
                un[l] = madd::<FMA>(h, v[l], u[l]);
            }
        }
        std::mem::swap(&mut ws.u, &mut ws.u_next);
        // Frozen and fixed particles keep their displacement in both buffers.
    }
    for &i in &ws.free {
        state.v[i] = v3(&ws.v[i]);
        state.x[i] = m.rest[i] + v3(&ws.u[i]);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn substeps_avx2(m: &ParticleModel, state: &mut ParticleState, ws: &mut ParticleWorkspace, h: f64, substeps: usize) {
    substeps_impl::<true>(m, state, ws, h, substeps)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn all_forces_avx2(m: &ParticleModel, u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols], gamma: &mut [f64], out: &mut [P4]) {
    all_forces_impl::<true>(m, u, v, linear, b, gamma, out)
}

static SIMD_ENABLED: AtomicBool = AtomicBool::new(true);

/// Allow (default) or forbid the AVX2 + FMA copy of the particle hot loop, process-wide: for
/// comparing the two copies and testing the portable one on a CPU that has AVX2.
pub fn set_simd_enabled(enabled: bool) {
    SIMD_ENABLED.store(enabled, Ordering::Relaxed);
}

/// The copy of the particle hot loop that runs: `"avx2+fma"` or `"baseline"` (portable).
pub fn simd_path() -> &'static str {
    if has_avx2_fma() {
        "avx2+fma"
    } else {
        "baseline"
    }
}

#[inline]
fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        SIMD_ENABLED.load(Ordering::Relaxed) && std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Run the sub-steps with the best copy this CPU supports.
pub(crate) fn run_substeps(m: &ParticleModel, state: &mut ParticleState, ws: &mut ParticleWorkspace, h: f64, substeps: usize) {
    let n = m.n_particles();
    // The unchecked neighbour indexing of the SIMD copy relies on these (the caller has
    // already returned an error for a mismatched workspace or an out-of-range active index).
    assert!(ws.u.len() == n && ws.u_next.len() == n && ws.v.len() == n && ws.b.len() == n && ws.gamma.len() == n);
    assert!(state.active.iter().all(|&i| i < n));
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the only requirement of a `target_feature` function is that the CPU has the
        // features, which `has_avx2_fma` has just checked.
        #[allow(unsafe_code)]
        unsafe {
            return substeps_avx2(m, state, ws, h, substeps);
        }
    }
    substeps_impl::<false>(m, state, ws, h, substeps)
}

/// Forces of every particle with the best copy this CPU supports.
pub(crate) fn all_forces(m: &ParticleModel, u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols], gamma: &mut [f64], out: &mut [P4]) {
    let n = m.n_particles();
    assert!(u.len() == n && v.is_none_or(|v| v.len() == n) && b.len() == n && gamma.len() == n && out.len() == n);
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: as in `run_substeps`.
        #[allow(unsafe_code)]
        unsafe {
            return all_forces_avx2(m, u, v, linear, b, gamma, out);
        }
    }
    all_forces_impl::<false>(m, u, v, linear, b, gamma, out)
}

/// The two pair loops written with AVX2 + FMA intrinsics (4 lanes = one `__m256d`).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx {
    use super::{b_matrix, Cols, Lane, Law, M3, P4};
    use crate::meshfree::body::ParticleModel;
    use std::arch::x86_64::*;

    /// Four particles side by side, one per AVX lane.
    ///
    /// Invariant: values of this type exist only inside functions compiled with
    /// `target_feature(enable = "avx2,fma")` (which run only on CPUs that have both), so the
    /// intrinsics in its methods, inlined there, always meet their feature requirement.
    #[derive(Clone, Copy)]
    pub(super) struct F4(__m256d);

    // SAFETY (every `unsafe` below): the invariant of `F4`.
    impl Lane for F4 {
        #[inline(always)]
        fn splat(x: f64) -> Self { unsafe { F4(_mm256_set1_pd(x)) } }
        #[inline(always)]
        fn add(self, o: Self) -> Self { unsafe { F4(_mm256_add_pd(self.0, o.0)) } }
        #[inline(always)]
        fn sub(self, o: Self) -> Self { unsafe { F4(_mm256_sub_pd(self.0, o.0)) } }
        #[inline(always)]
        fn mul(self, o: Self) -> Self { unsafe { F4(_mm256_mul_pd(self.0, o.0)) } }
        #[inline(always)]
        fn madd(self, b: Self, c: Self) -> Self { unsafe { F4(_mm256_fmadd_pd(self.0, b.0, c.0)) } }
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

    /// Pass 1 over the particles `idx`, four at a time in lanes: `b[i] = B_i` (see
    /// [`b_matrix`]) from displacements `u` (velocities `v` when damped).
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `u`, `v` and `b` have `m.n_particles()` entries and every `idx`
    /// entry is smaller.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn stress_pass(m: &ParticleModel, idx: &[usize], u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols]) {
        let law = Law::of(m);
        let damped = !linear && v.is_some() && law.viscous.is_some();
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
                kc[l] = unsafe { gather_cols(nbr, q, u, &u[i]) };
                if damped {
                    if let Some(v) = v {
                        kvc[l] = unsafe { gather_cols(nbr, q, v, &v[i]) };
                    }
                }
                let r = &m.r4[i];
                rc[l] = [load(&r[0]), load(&r[1]), load(&r[2])];
                g[l] = m.gamma[i];
            }
            let k = to_lanes(&kc);
            let kv = if damped { Some(to_lanes(&kvc)) } else { None };
            let r = to_lanes(&rc);
            let gamma = F4(_mm256_set_pd(g[3], g[2], g[1], g[0]));
            let bm = b_matrix(&k, kv.as_ref(), &r, gamma, law, linear);
            for c in 0..3 {
                let t = transpose(bm[0][c].0, bm[1][c].0, bm[2][c].0, z);
                for (l, &i) in chunk.iter().enumerate() {
                    b[i][c] = store(t[l]);
                }
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
    pub(super) unsafe fn force(nbr: &[u32], q: &[P4], w: &[f64], u: &[P4], b: &[Cols], gamma: &[f64], ui: &P4, gi: f64, bi: &Cols, qs: &P4) -> P4 {
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
}
