//! The ring of a partially active particle body: the forces the active particles exert on the
//! particles the step does not move (their frozen neighbours, fixed active particles), which the
//! hybrid runtime hands to the FEM core so that linear momentum is conserved exactly; and
//! sub-stepping with caller forces recomputed at every sub-step (`meshfree::step_with`).
//!
//! What a wrong implementation would do: a ring that misses a frozen neighbour, counts one twice
//! or leaves out the fixed active particles breaks the momentum balance of the active set plus
//! the ring; a ring force taken at the last sub-step only (not averaged over the call), or
//! divided by the wrong count, breaks it too whenever a call has several sub-steps; a gather that
//! reads a stale `B` or `gamma` of a particle that was active in an earlier call, or a stale
//! displacement, gives a force that is not minus the gradient of the active particles' energy; a
//! ring reported when every particle is active is wasted work and a wrong impulse; the AVX2 copy
//! diverging from the portable one shows as a difference between the two paths; a callback step
//! that does not write the positions back before each sub-step, or evaluates the forces at the
//! wrong time level, differs from the same sequence run one sub-step per call.
use palpate_core::meshfree::{self, ParticleModel, ParticleModelBuilder, ParticleState, ParticleWorkspace, SubStep};
use palpate_core::{Mat3, Vec3};

#[path = "support/common.rs"]
mod common;
use common::Rng;

#[path = "support/particles.rs"]
mod particles;
use particles::{lattice, material, SPACING};

/// A cubic lattice block, spacing 1 mm, support 1.8 spacings, hourglass `kappa`, `fixed` held.
fn block(n: [usize; 3], damped: bool, kappa: f64, fixed: Vec<usize>) -> ParticleModel {
    let (pts, m) = lattice(n);
    ParticleModelBuilder::new(pts, m, material(damped), 1.8 * SPACING)
        .hourglass(kappa)
        .fixed_particles(fixed)
        .build()
        .unwrap()
}

/// A random deformation (3% affine plus 3% of a spacing of noise), random velocities (1 cm/s)
/// and a random active subset of about `fraction` of the particles.
fn random_state(model: &ParticleModel, fraction: f64, seed: u64) -> ParticleState {
    let mut rng = Rng::new(seed);
    let mut st = ParticleState::rest(model);
    let a = Mat3::identity() + rng.mat3(0.03);
    for (x, x0) in st.x.iter_mut().zip(model.rest_positions()) {
        *x = a * x0 + rng.vec3(0.03 * SPACING);
    }
    for v in st.v.iter_mut() {
        *v = rng.vec3(1e-2);
    }
    st.active = (0..model.n_particles()).filter(|_| rng.unit() < fraction).collect();
    st
}

/// `sum_free m_i (v_i' - v_i) + dt sum_ring f_r` and the scale it is small against.
fn momentum_residual(model: &ParticleModel, before: &ParticleState, after: &ParticleState, ws: &ParticleWorkspace, dt: f64) -> (Vec3, f64) {
    let m = model.masses();
    let mut res = Vec3::zeros();
    let mut scale = 0.0;
    for &i in &after.active {
        if !model.fixed()[i] {
            let dp = m[i] * (after.v[i] - before.v[i]);
            res += dp;
            scale += dp.norm();
        }
    }
    for f in ws.ring_forces() {
        res += dt * f;
        scale += dt * f.norm();
    }
    (res, scale)
}

/// The ring the step must report: inactive neighbours of the active particles, then the fixed
/// active particles, as a sorted set.
fn expected_ring(model: &ParticleModel, active: &[usize]) -> Vec<usize> {
    let n = model.n_particles();
    let mut is_active = vec![false; n];
    for &i in active {
        is_active[i] = true;
    }
    let mut ring: Vec<usize> = active.iter().flat_map(|&i| model.neighbours(i).iter().copied()).filter(|&j| !is_active[j]).collect();
    ring.extend(active.iter().copied().filter(|&i| model.fixed()[i]));
    ring.sort_unstable();
    ring.dedup();
    ring
}

/// A workspace that reports the ring.
fn ring_workspace(model: &ParticleModel) -> ParticleWorkspace {
    let mut ws = ParticleWorkspace::new(model);
    ws.set_ring_forces(true);
    ws
}

fn sorted(v: &[usize]) -> Vec<usize> {
    let mut v = v.to_vec();
    v.sort_unstable();
    v
}

/// Momentum over the active set plus the ring, over one 1 ms step of several sub-steps, damped
/// (the viscous stress acts on the ring too), with and without fixed particles among the active.
#[test]
fn active_set_plus_ring_conserves_momentum_exactly() {
    for with_fixed in [false, true] {
        let fixed: Vec<usize> = if with_fixed { (0..336).step_by(7).collect() } else { vec![] };
        let model = block([8, 7, 6], true, meshfree::DEFAULT_HOURGLASS, fixed);
        let mut st = random_state(&model, 0.3, 11);
        let before = st.clone();
        let mut ws = ring_workspace(&model);
        let dt = 1e-3;
        let rep = meshfree::step(&model, &mut st, &mut ws, dt).unwrap();
        assert!(rep.substeps >= 3, "the test needs several sub-steps per call, got {}", rep.substeps);
        assert_eq!(ws.ring().len(), ws.ring_forces().len());
        assert_eq!(sorted(ws.ring()), expected_ring(&model, &st.active), "ring is not the frozen neighbours plus the fixed active particles, each once");
        assert_eq!(ws.ring().len(), expected_ring(&model, &st.active).len(), "a ring particle is listed twice");
        let (res, scale) = momentum_residual(&model, &before, &st, &ws, dt);
        eprintln!("fixed {with_fixed}: {} active, ring {}, momentum residual {:.2e} of {:.2e}", st.active.len(), ws.ring().len(), res.norm(), scale);
        assert!(res.norm() <= 1e-12 * scale, "momentum residual {:e} vs scale {scale:e}", res.norm());
        // Without the ring the active set alone does not conserve momentum (what makes the
        // check able to fail).
        let ring_impulse: Vec3 = ws.ring_forces().iter().map(|f| dt * f).sum();
        assert!(ring_impulse.norm() > 1e-6 * scale);
    }
}

/// One sub-step from rest velocities: the ring force is minus the gradient, with respect to the
/// ring particle's position, of the elastic energy (with or without hourglass control) of the
/// active particles. Fixed active particles included.
#[test]
fn ring_forces_are_minus_the_active_energy_gradient() {
    for kappa in [meshfree::DEFAULT_HOURGLASS, 0.0] {
        let n = [7, 6, 5];
        let model = block(n, false, kappa, vec![3, 50, 101, 170]);
        let mut st = random_state(&model, 0.3, 5);
        st.active.extend([3, 50, 101, 170]);
        st.active.sort_unstable();
        st.active.dedup();
        let x0 = st.x.clone();
        let active = st.active.clone();
        let energy = |x: &[Vec3]| active.iter().map(|&k| model.particle_energy(k, x)).sum::<f64>();
        let mut ws = ring_workspace(&model);
        meshfree::step_with_substeps(&model, &mut st, &mut ws, 1e-7, 1).unwrap();
        assert!(ws.ring().iter().filter(|&&r| model.fixed()[r]).count() == 4);
        let fmax = ws.ring_forces().iter().map(|f| f.norm()).fold(0.0, f64::max);
        let mut worst: f64 = 0.0;
        for (&r, f) in ws.ring().iter().zip(ws.ring_forces()) {
            for c in 0..3 {
                let (mut xp, mut xm) = (x0.clone(), x0.clone());
                let d = 1e-9;
                xp[r][c] += d;
                xm[r][c] -= d;
                let fd = -(energy(&xp) - energy(&xm)) / (2.0 * d);
                worst = worst.max((fd - f[c]).abs());
            }
        }
        eprintln!("kappa {kappa}: ring {}, max |fd - f| {worst:.2e}, max |f| {fmax:.2e}", ws.ring().len());
        assert!(fmax > 0.0);
        assert!(worst <= 1e-5 * fmax, "kappa {kappa}: max |fd - f| = {worst:e} vs max |f| = {fmax:e}");
    }
}

/// A particle that was active in an earlier call and is now a frozen neighbour of the ring must
/// not leak its old stress or hourglass coefficient into the ring's gather.
#[test]
fn ring_forces_do_not_depend_on_earlier_active_sets() {
    let model = block([7, 6, 5], false, meshfree::DEFAULT_HOURGLASS, vec![]);
    let st0 = random_state(&model, 0.3, 21);
    let run = |warm: bool| {
        let mut st = st0.clone();
        let mut ws = ring_workspace(&model);
        if warm {
            // Everything active once (every particle gets a B and gamma), then back.
            let mut all = st0.clone();
            all.active = (0..model.n_particles()).collect();
            meshfree::step_with_substeps(&model, &mut all, &mut ws, 1e-7, 1).unwrap();
        }
        meshfree::step_with_substeps(&model, &mut st, &mut ws, 1e-7, 1).unwrap();
        (ws.ring().to_vec(), ws.ring_forces().to_vec())
    };
    let (ring_a, f_a) = run(false);
    let (ring_b, f_b) = run(true);
    assert_eq!(ring_a, ring_b);
    assert_eq!(f_a, f_b, "ring forces depend on what was active before");
}

#[test]
fn ring_is_empty_when_every_particle_is_active_and_none_fixed() {
    let model = block([6, 5, 5], true, meshfree::DEFAULT_HOURGLASS, vec![]);
    let mut st = random_state(&model, 0.3, 3);
    st.active = (0..model.n_particles()).collect();
    let mut ws = ring_workspace(&model);
    meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
    assert!(ws.ring().is_empty() && ws.ring_forces().is_empty());
    // With a partial active set it is not, and a failed step clears it.
    st.active.truncate(40);
    meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
    assert!(!ws.ring().is_empty());
    assert!(meshfree::step(&model, &mut st, &mut ws, f64::NAN).is_err());
    assert!(ws.ring().is_empty() && ws.ring_forces().is_empty(), "a failed step left a ring");
    // Fixed particles, all active: the ring is the fixed particles, and it holds the momentum.
    let fixed: Vec<usize> = (0..30).collect();
    let model = block([6, 5, 5], true, meshfree::DEFAULT_HOURGLASS, fixed.clone());
    let mut st = random_state(&model, 1.0, 3);
    st.active = (0..model.n_particles()).collect();
    let before = st.clone();
    let mut ws = ring_workspace(&model);
    meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
    assert_eq!(sorted(ws.ring()), fixed);
    let (res, scale) = momentum_residual(&model, &before, &st, &ws, 1e-3);
    assert!(res.norm() <= 1e-12 * scale, "{:e} vs {scale:e}", res.norm());
}

/// The ring is opt-in, and computing it does not change the motion (bitwise), with several
/// sub-steps, damping and fixed particles.
#[test]
fn the_ring_is_off_by_default_and_does_not_change_the_motion() {
    let model = block([8, 7, 6], true, meshfree::DEFAULT_HOURGLASS, vec![5, 77, 200]);
    let st0 = random_state(&model, 0.3, 23);
    let mut off = st0.clone();
    let mut ws_off = ParticleWorkspace::new(&model);
    assert!(!ws_off.ring_forces_enabled());
    let mut on = st0.clone();
    let mut ws_on = ring_workspace(&model);
    for _ in 0..3 {
        meshfree::step(&model, &mut off, &mut ws_off, 1e-3).unwrap();
        meshfree::step(&model, &mut on, &mut ws_on, 1e-3).unwrap();
        assert!(ws_off.ring().is_empty() && ws_off.ring_forces().is_empty());
        assert!(!ws_on.ring().is_empty());
        assert_eq!(off, on, "computing the ring changed the motion");
    }
    ws_on.set_ring_forces(false);
    meshfree::step(&model, &mut on, &mut ws_on, 1e-3).unwrap();
    assert!(ws_on.ring().is_empty());
}

/// The AVX2 + FMA copy and the portable one give the same ring forces and both balance the
/// momentum. (The only test of this file that switches the process-wide SIMD flag.)
#[test]
fn ring_forces_agree_between_simd_and_portable_paths() {
    let model = block([8, 7, 6], true, meshfree::DEFAULT_HOURGLASS, vec![5, 77, 200]);
    let st0 = random_state(&model, 0.3, 17);
    let run = |simd: bool| {
        meshfree::set_simd_enabled(simd);
        let path = meshfree::simd_path();
        let mut st = st0.clone();
        let mut ws = ring_workspace(&model);
        meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
        meshfree::set_simd_enabled(true);
        let (res, scale) = momentum_residual(&model, &st0, &st, &ws, 1e-3);
        assert!(res.norm() <= 1e-12 * scale, "{path}: momentum residual {:e} vs {scale:e}", res.norm());
        (path, ws.ring().to_vec(), ws.ring_forces().to_vec(), st.x)
    };
    let (p_fast, ring_fast, f_fast, x_fast) = run(true);
    let (p_base, ring_base, f_base, x_base) = run(false);
    assert_eq!(p_base, "baseline");
    assert_eq!(ring_fast, ring_base);
    let fmax = f_base.iter().map(|f| f.norm()).fold(0.0, f64::max);
    let df = f_fast.iter().zip(&f_base).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    eprintln!("{p_fast} vs baseline: ring forces differ by {df:.2e} (max {fmax:.2e})");
    assert!(df <= 1e-12 * fmax, "{p_fast} vs baseline: ring forces differ by {df:e} (max {fmax:e})");
    let dx = x_fast.iter().zip(&x_base).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    assert!(dx <= 1e-12 * SPACING);
}

/// `k` calls of one sub-step `h` run the same leapfrog sequence as one call of `k` sub-steps:
/// equal to round-off (not bitwise: each call re-derives `u = x - X`), and the call's ring force
/// is the mean of the single calls' ones.
#[test]
fn k_single_substep_calls_equal_one_call_of_k_substeps_to_round_off() {
    let model = block([8, 7, 6], true, meshfree::DEFAULT_HOURGLASS, vec![]);
    let st0 = random_state(&model, 0.3, 29);
    let k = 5;
    let h = 0.9 * model.stable_dt();
    let mut one = st0.clone();
    let mut ws = ring_workspace(&model);
    meshfree::step_with_substeps(&model, &mut one, &mut ws, k as f64 * h, k).unwrap();
    let f_one = ws.ring_forces().to_vec();
    let mut many = st0.clone();
    let mut f_mean = vec![Vec3::zeros(); f_one.len()];
    for _ in 0..k {
        meshfree::step_with_substeps(&model, &mut many, &mut ws, h, 1).unwrap();
        for (m, f) in f_mean.iter_mut().zip(ws.ring_forces()) {
            *m += f / k as f64;
        }
    }
    let dx = one.x.iter().zip(&many.x).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    let du = one.x.iter().zip(&st0.x).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    let dv = one.v.iter().zip(&many.v).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    let fmax = f_one.iter().map(|f| f.norm()).fold(0.0, f64::max);
    let df = f_one.iter().zip(&f_mean).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    eprintln!(
        "1 call x {k} vs {k} calls x 1: |dx| {dx:.2e} m (motion {du:.2e}), |dv| {dv:.2e} m/s, ring |df| {df:.2e} N (max {fmax:.2e}), bitwise {}",
        one.x == many.x
    );
    assert!(dx <= 1e-12 * SPACING, "{dx:e}");
    // A round-off difference in x comes back in v amplified by the stiffest mode.
    assert!(dv <= 1e-12 * SPACING * model.omega_max(), "{dv:e}");
    assert!(df <= 1e-10 * fmax, "{df:e} vs {fmax:e}");
    assert!((one.t - many.t).abs() <= 1e-15);
}

/// A position- and velocity-dependent external force (a penalty wall with damping, as a tool
/// contact), recomputed at every sub-step.
fn wall(x: Vec3, v: Vec3) -> Vec3 {
    let z0 = 3.5 * SPACING;
    if x.z > z0 {
        Vec3::new(0.0, 0.0, -0.1 * (x.z - z0) - 1e-5 * v.z)
    } else {
        Vec3::zeros()
    }
}

#[test]
fn step_with_recomputes_external_forces_at_every_substep() {
    let model = block([8, 7, 6], true, meshfree::DEFAULT_HOURGLASS, vec![]);
    let mut st0 = random_state(&model, 0.3, 41);
    for (i, f) in st0.f_ext.iter_mut().enumerate() {
        *f = Vec3::new(1e-6 * (i % 3) as f64, 0.0, -2e-6);
    }
    let k = 4;
    let h = 0.9 * model.stable_dt();
    let mut ws = ring_workspace(&model);

    // A callback that changes nothing is step_with_substeps, bitwise.
    let mut a = st0.clone();
    meshfree::step_with_substeps(&model, &mut a, &mut ws, k as f64 * h, k).unwrap();
    let f_a = ws.ring_forces().to_vec();
    let mut b = st0.clone();
    let mut calls = vec![];
    meshfree::step_with(&model, &mut b, &mut ws, k as f64 * h, k, |s: &SubStep, _f: &mut [Vec3]| calls.push((s.index, s.t, s.h))).unwrap();
    assert_eq!((a.x.clone(), a.v.clone()), (b.x.clone(), b.v.clone()));
    assert_eq!(f_a, ws.ring_forces());
    assert_eq!(calls.len(), k);
    for (s, &(index, t, hh)) in calls.iter().enumerate() {
        assert_eq!(index, s);
        assert!((t - (st0.t + s as f64 * h)).abs() <= 1e-18 && hh == h);
    }

    // The wall through step_with equals the wall applied by hand, one sub-step per call.
    let mut with = st0.clone();
    let mut impulse = Vec3::zeros();
    let before = with.clone();
    meshfree::step_with(&model, &mut with, &mut ws, k as f64 * h, k, |s: &SubStep, f: &mut [Vec3]| {
        for &i in s.active {
            let w = wall(s.x[i], s.v[i]);
            f[i] += w;
            impulse += s.h * f[i];
        }
    })
    .unwrap();
    let (res, scale) = momentum_residual(&model, &before, &with, &ws, k as f64 * h);
    assert!((res - impulse).norm() <= 1e-12 * scale, "momentum with sub-step forces: {:e} vs {scale:e}", (res - impulse).norm());
    let mut by_hand = st0.clone();
    for _ in 0..k {
        for &i in &by_hand.active {
            by_hand.f_ext[i] = st0.f_ext[i] + wall(by_hand.x[i], by_hand.v[i]);
        }
        meshfree::step_with_substeps(&model, &mut by_hand, &mut ws, h, 1).unwrap();
    }
    let dx = with.x.iter().zip(&by_hand.x).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    let dv = with.v.iter().zip(&by_hand.v).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    // The wall acted (else the comparison shows nothing): without it the result differs.
    let dwall = with.v.iter().zip(&a.v).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    eprintln!("step_with vs one sub-step per call: |dx| {dx:.2e} m, |dv| {dv:.2e} m/s; wall effect on v {dwall:.2e}");
    assert!(dwall > 1e-5);
    assert!(dx <= 1e-12 * SPACING && dv <= 1e-12 * SPACING * model.omega_max(), "{dx:e} {dv:e}");
    // state.f_ext is the caller's, not the callback's.
    assert_eq!(with.f_ext, st0.f_ext);
}

#[test]
fn non_finite_callback_forces_fail_the_step_and_leave_the_state() {
    let model = block([6, 5, 5], false, meshfree::DEFAULT_HOURGLASS, vec![]);
    let st0 = random_state(&model, 0.3, 7);
    let mut st = st0.clone();
    let mut ws = ring_workspace(&model);
    let target = st.active[0];
    let r = meshfree::step_with(&model, &mut st, &mut ws, 1e-3, 3, |s: &SubStep, f: &mut [Vec3]| {
        if s.index == 2 {
            f[target] = Vec3::new(f64::NAN, 0.0, f64::INFINITY);
        }
        // Writes to inactive entries are ignored, out-of-range ones are the caller's (slices).
        f[f.len() - 1] += Vec3::new(1.0, 0.0, 0.0);
    });
    assert!(r.is_err());
    assert_eq!(st, st0, "a failed step changed the state");
    assert!(ws.ring().is_empty());
    // Bad arguments are errors, not panics.
    assert!(meshfree::step_with(&model, &mut st, &mut ws, 1e-3, 0, |_: &SubStep, _: &mut [Vec3]| {}).is_err());
    let mut bad = st0.clone();
    bad.active.push(10_000);
    assert!(meshfree::step_with(&model, &mut bad, &mut ws, 1e-3, 2, |_: &SubStep, _: &mut [Vec3]| {}).is_err());
}
