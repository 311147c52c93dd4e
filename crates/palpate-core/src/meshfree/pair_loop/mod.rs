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
//! stresses act (the paper's active set).
//!
//! ## The ring's reaction
//! For a particle `r` that does not move (frozen, or fixed and active), pass 2's gather with
//! `B_r = 0`, `gamma_r = 0` (frozen) or its own `B_r`, `gamma_r` (fixed) is exactly the force the
//! active particles exert on it, the reaction that keeps the momentum balance. It is linear in
//! the `B_j` and `u_j` of its neighbours, and `u_r` is constant over the call, so its average
//! over the `k` sub-steps is the same gather applied to the sub-step averages of `B_j` and `u_j`:
//! the loop adds up `B_j` and `u_j` of the rim (the active particles the ring reads: a few
//! adds per rim particle per sub-step) and gathers the ring once per call, instead of running
//! pass 2 on the ring at every sub-step. The two forms are equal up to round-off; pairwise the
//! terms of `i <- j` and `j <- i` are equal and opposite, so momentum is conserved to round-off.
//!
//! ## SIMD
//! Per pair the work is a few 4-lane multiply-adds on padded 3-vectors ([`P4`]), with two
//! independent accumulator sets so that the adds do not wait on each other. The sub-step
//! (`passes.rs`) is written once, generic over the copy of the two passes ([`LoopCopy`]): the
//! portable one ([`Baseline`]), or, on x86-64 CPUs with AVX2 and FMA (detected at run time), the
//! copy of `avx2.rs`, compiled for those features, where a `P4` is one register, `a*b + c` one
//! fused instruction and pass 1 runs four particles side by side in lanes. Both evaluate the
//! stress through the one law of [`crate::material::linear`]. Results differ between the two
//! copies by round-off only. `avx2.rs` is the crate's one module with `unsafe` code.

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx2;
mod disjoint;
mod passes;

pub(crate) use disjoint::Disjoint;
use passes::Verlet;

use super::{ParticleModel, ParticleState, ParticleWorkspace, SubStep};
use crate::math::Vec3;
use crate::parallel::Fork;
use std::sync::atomic::{AtomicBool, Ordering};

/// The per-sub-step external-force callback of [`super::step_with`].
pub(crate) type ExtForce<'f> = &'f mut dyn FnMut(&SubStep<'_>, &mut [Vec3]);

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

/// One copy of the two passes of a sub-step. Both take per-particle arrays `u`, `v`, `b`,
/// `gamma` of one entry per particle of `m` (they panic otherwise) and particle indices `idx`.
#[allow(unsafe_code)]
pub(crate) trait LoopCopy: Copy + Sync {
    /// `true` when `a * b + c` is one fused operation in this copy.
    const FMA: bool;
    /// Pass 1 over the particles `idx`: `b[i] = B_i` (see [`passes::b_matrix`]) from
    /// displacements `u` (and velocities `v` when damped); `linear`: the rest-linearised stress.
    ///
    /// # Safety
    /// While it runs, nothing else reaches the entries of `b` at `idx` (another part of a split
    /// pass has other particles).
    unsafe fn stress_pass(self, m: &ParticleModel, idx: &[usize], u: &[P4], v: Option<&[P4]>, linear: bool, b: &Disjoint<'_, Cols>);
    /// Pass 2 over the particles `idx`: `sink(i, f_i)` with the internal force `f_i` particle `i`
    /// receives, from the `B` of pass 1 and `gamma` (`gamma_j`, zero for frozen particles);
    /// `sink` is called once per entry of `idx`, in its order.
    fn force_pass(self, m: &ParticleModel, idx: &[usize], u: &[P4], b: &[Cols], gamma: &[f64], sink: impl FnMut(usize, P4));
    /// Pass 2 and the Verlet update over the free particles `idx` ([`passes::verlet_impl`]):
    /// the fastest of them and its squared speed relative to the mean velocity.
    ///
    /// # Safety
    /// While it runs, nothing else reaches the entries of `s.vel` and `s.u_next` at `idx`.
    unsafe fn verlet_pass(self, m: &ParticleModel, idx: &[usize], s: &Verlet<'_, '_>) -> (usize, f64);
}

/// The portable copy (any CPU; the reference the AVX2 copy is tested against).
#[derive(Clone, Copy)]
pub(crate) struct Baseline;

impl LoopCopy for Baseline {
    const FMA: bool = false;
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn stress_pass(self, m: &ParticleModel, idx: &[usize], u: &[P4], v: Option<&[P4]>, linear: bool, b: &Disjoint<'_, Cols>) {
        for &i in idx {
            // SAFETY: the caller's contract (entry `i` is this call's alone).
            *unsafe { b.at(i) } = passes::particle_stress(m, i, u, v, linear);
        }
    }
    #[inline(always)]
    fn force_pass(self, m: &ParticleModel, idx: &[usize], u: &[P4], b: &[Cols], gamma: &[f64], mut sink: impl FnMut(usize, P4)) {
        for &i in idx {
            sink(i, passes::particle_force(m, i, u, b, gamma));
        }
    }
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn verlet_pass(self, m: &ParticleModel, idx: &[usize], s: &Verlet<'_, '_>) -> (usize, f64) {
        // SAFETY: the caller's contract.
        unsafe { passes::verlet_impl(self, m, idx, s) }
    }
}

static SIMD_ENABLED: AtomicBool = AtomicBool::new(true);

/// Allow (default) or forbid the AVX2 + FMA copies of the hot loops (the particle passes and the
/// FEM's element loop, `fem/lanes.rs`), process-wide: for comparing the copies and testing the
/// portable ones on a CPU that has AVX2.
pub fn set_simd_enabled(enabled: bool) {
    SIMD_ENABLED.store(enabled, Ordering::Relaxed);
}

/// Whether [`set_simd_enabled`] allows the SIMD copies.
pub(crate) fn simd_allowed() -> bool {
    SIMD_ENABLED.load(Ordering::Relaxed)
}

/// The copy of the particle hot loop that runs: `"avx2+fma"` or `"baseline"` (portable).
pub fn simd_path() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    if avx2_copy().is_some() {
        return "avx2+fma";
    }
    "baseline"
}

/// The AVX2 + FMA copy, if this CPU has it and it is allowed.
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx2_copy() -> Option<avx2::Avx2> {
    if SIMD_ENABLED.load(Ordering::Relaxed) {
        avx2::Avx2::detect()
    } else {
        None
    }
}

/// Run the sub-steps with the best copy this CPU supports; stops early at a particle over the
/// material's speed bound and returns it with its speed ([`passes::substeps_impl`]).
pub(crate) fn run_substeps(
    m: &ParticleModel,
    state: &mut ParticleState,
    ws: &mut ParticleWorkspace,
    h: f64,
    substeps: usize,
    ext: Option<ExtForce<'_>>,
    fork: &dyn Fork,
) -> Option<(usize, f64)> {
    let n = m.n_particles();
    // The caller has already returned an error for a mismatched workspace or an out-of-range
    // active index; the passes check the lengths again (their unchecked reads rely on them).
    assert!(ws.u.len() == n && ws.u_next.len() == n && ws.v.len() == n && ws.b.len() == n && ws.gamma.len() == n);
    assert!(state.active.iter().all(|&i| i < n));
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = avx2_copy() {
        return simd.run_substeps(m, state, ws, h, substeps, ext, fork);
    }
    passes::substeps_impl(Baseline, m, state, ws, h, substeps, ext, fork)
}

/// Forces of every particle with the best copy this CPU supports.
pub(crate) fn all_forces(m: &ParticleModel, u: &[P4], v: Option<&[P4]>, linear: bool, b: &mut [Cols], gamma: &mut [f64], out: &mut [P4]) {
    let n = m.n_particles();
    assert!(u.len() == n && v.is_none_or(|v| v.len() == n) && b.len() == n && gamma.len() == n && out.len() == n);
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = avx2_copy() {
        return simd.all_forces(m, u, v, linear, b, gamma, out);
    }
    passes::all_forces_impl(Baseline, m, u, v, linear, b, gamma, out)
}

/// Pass 1 for one particle (portable copy): its `B_i` from displacements `u` (no velocity).
/// For the stiffness probes of [`super::ParticleModel::stiffness_row_sums`].
pub(crate) fn stress_of(m: &ParticleModel, i: usize, u: &[P4], linear: bool) -> Cols {
    passes::particle_stress(m, i, u, None, linear)
}

/// Pass 2 for one particle (portable copy): the internal force it receives from `B` and `gamma`.
pub(crate) fn force_of(m: &ParticleModel, i: usize, u: &[P4], b: &[Cols], gamma: &[f64]) -> P4 {
    passes::particle_force(m, i, u, b, gamma)
}
