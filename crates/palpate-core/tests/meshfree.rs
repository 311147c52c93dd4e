//! The meshfree (particle) solid: invariants and analytic checks (paper §3.2).
//!
//! What a wrong implementation would do: an MLS gradient that is not corrected (`A^-1` missing or
//! stale) gives a wrong F for affine motions and forces under a rigid rotation; a force that is
//! not the gradient of the energy (a sign, a factor 2, a missing neighbour term, a pair counted
//! for an inactive particle) fails the finite-difference and active-set checks; a pair force
//! that is not antisymmetric drifts the momentum; a SIMD copy that skips a lane or reads a
//! padded column differs from the portable one; a stability bound that is too loose grows the
//! energy; hourglass control of the wrong sign lets particles clump; a Neo-Hookean material
//! silently run as St. Venant-Kirchhoff is refused instead.
use palpate_core::meshfree::{self, ParticleModel, ParticleModelBuilder, ParticleState, ParticleWorkspace};
use palpate_core::{Mat3, Vec3};

#[path = "support/particles.rs"]
mod particles;
use particles::{lattice, material, SPACING};

/// A cubic lattice block of `n` particles per side, spacing 1 mm, support 1.8 spacings.
fn block(n: [usize; 3], damped: bool) -> ParticleModel {
    let (pts, m) = lattice(n);
    ParticleModelBuilder::new(pts, m, material(damped), 1.8 * SPACING).build().unwrap()
}

fn interior(model: &ParticleModel, n: [usize; 3], layers: usize) -> Vec<usize> {
    let mut out = vec![];
    for k in layers..n[2] - layers {
        for j in layers..n[1] - layers {
            for i in layers..n[0] - layers {
                out.push(i + n[0] * (j + n[1] * k));
            }
        }
    }
    assert!(out.iter().all(|&i| i < model.n_particles()));
    out
}

#[test]
fn affine_motions_give_exact_deformation_gradients_everywhere() {
    let n = [5, 4, 6];
    let model = block(n, false);
    let a = Mat3::new(1.1, 0.05, -0.03, 0.02, 0.93, 0.08, -0.04, 0.06, 1.07);
    let x: Vec<Vec3> = model.rest_positions().iter().map(|p| a * p + Vec3::new(0.1, -0.2, 0.3)).collect();
    for i in 0..model.n_particles() {
        assert!((model.deformation_gradient(i, &x) - a).norm() < 1e-12, "particle {i}");
    }
}

#[test]
fn rigid_motion_gives_zero_force() {
    let model = block([5, 5, 5], true);
    let rot = nalgebra::Rotation3::from_euler_angles(0.7, -1.1, 2.3).into_inner();
    let t = Vec3::new(0.03, -0.02, 0.05);
    let x: Vec<Vec3> = model.rest_positions().iter().map(|p| rot * p + t).collect();
    let w = Vec3::new(1.5, -0.4, 2.0);
    let v: Vec<Vec3> = x.iter().map(|p| w.cross(p) + Vec3::new(0.1, 0.2, -0.3)).collect();
    let mut f = vec![Vec3::zeros(); model.n_particles()];
    model.internal_forces(&x, Some(&v), &mut f);
    // Force of a 1e-3 strain on one particle: sigma V / spacing.
    let scale = 1e-3 * model.material().young() * SPACING.powi(2);
    let worst = f.iter().map(|f| f.norm()).fold(0.0, f64::max);
    assert!(worst <= 1e-10 * scale, "{worst} vs {scale}");
    assert!(model.strain_energy(&x).abs() <= 1e-20);
}

#[test]
fn uniform_stretch_gives_analytic_stress_and_no_interior_force() {
    let n = [7, 7, 7];
    let model = block(n, false);
    let e = 1e-3;
    let x: Vec<Vec3> = model.rest_positions().iter().map(|p| Vec3::new(p.x * (1.0 + e), p.y, p.z)).collect();
    let mut f = vec![Vec3::zeros(); model.n_particles()];
    model.internal_forces(&x, None, &mut f);
    let m = model.material();
    // Analytic: E_xx = e + e^2/2, S = lambda tr(E) I + 2 mu E, first Piola P = F S.
    let exx = e + 0.5 * e * e;
    let sxx = (m.lambda() + 2.0 * m.mu()) * exx;
    let syy = m.lambda() * exx;
    for &i in &interior(&model, n, 2) {
        let fgrad = model.deformation_gradient(i, &x);
        let s = palpate_core::material::stress(m, &palpate_core::material::green_strain(&fgrad));
        assert!((s[(0, 0)] / sxx - 1.0).abs() < 1e-9);
        assert!((s[(1, 1)] / syy - 1.0).abs() < 1e-9);
        // Interior particles (whose neighbours' neighbourhoods are complete) feel no net force.
        assert!(f[i].norm() <= 1e-9 * sxx * SPACING * SPACING, "particle {i}: {}", f[i].norm());
    }
}

#[test]
fn forces_are_minus_energy_gradient() {
    let model = block([4, 4, 4], false);
    let mut x: Vec<Vec3> = model.rest_positions().to_vec();
    for (i, p) in x.iter_mut().enumerate() {
        *p += Vec3::new(((i * 37) % 11) as f64 - 5.0, ((i * 17) % 7) as f64 - 3.0, ((i * 5) % 3) as f64 - 1.0) * 2e-5;
    }
    let mut f = vec![Vec3::zeros(); model.n_particles()];
    model.internal_forces(&x, None, &mut f);
    let h = 1e-9;
    let fmax = f.iter().map(|f| f.norm()).fold(0.0, f64::max);
    for i in [0, 5, 21, 42, 63] {
        for c in 0..3 {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i][c] += h;
            xm[i][c] -= h;
            let fd = -(model.strain_energy(&xp) - model.strain_energy(&xm)) / (2.0 * h);
            assert!((fd - f[i][c]).abs() <= 1e-5 * fmax, "particle {i} comp {c}: fd {fd} vs {}", f[i][c]);
        }
    }
}

/// With part of the body frozen, a particle's force is minus the gradient of the energy that the
/// *active* particles carry (frozen particles shape their neighbours' deformation gradients but
/// carry no stress): one Verlet sub-step from rest gives `v = h f / m`.
#[test]
fn forces_with_a_partial_active_set_are_minus_the_active_energy_gradient() {
    let model = block([6, 5, 5], false);
    let n = model.n_particles();
    let mut st = ParticleState::rest(&model);
    for (i, p) in st.x.iter_mut().enumerate() {
        *p += Vec3::new(((i * 37) % 11) as f64 - 5.0, ((i * 17) % 7) as f64 - 3.0, ((i * 5) % 3) as f64 - 1.0) * 2e-5;
    }
    // Active: the particles with x index < 4 (a slab), the rest frozen.
    st.active = (0..n).filter(|i| i % 6 < 4).collect();
    let x0 = st.x.clone();
    let active = st.active.clone();
    let energy = |x: &[Vec3]| active.iter().map(|&k| model.particle_energy(k, x)).sum::<f64>();
    let mut ws = ParticleWorkspace::new(&model);
    let h = 1e-7;
    meshfree::step_with_substeps(&model, &mut st, &mut ws, h, 1).unwrap();
    let mut fmax: f64 = 0.0;
    let mut worst: f64 = 0.0;
    for &i in &active {
        let f = st.v[i] * model.masses()[i] / h;
        fmax = fmax.max(f.norm());
        for c in 0..3 {
            let (mut xp, mut xm) = (x0.clone(), x0.clone());
            let d = 1e-9;
            xp[i][c] += d;
            xm[i][c] -= d;
            let fd = -(energy(&xp) - energy(&xm)) / (2.0 * d);
            worst = worst.max((fd - f[c]).abs());
        }
    }
    assert!(worst <= 1e-5 * fmax, "max |fd - f| = {worst:e} vs max |f| = {fmax:e}");
    // Frozen particles did not move.
    for i in (0..n).filter(|i| i % 6 >= 4) {
        assert_eq!(st.x[i], x0[i]);
    }
}

/// The AVX2 + FMA copy of the hot loop and the portable one agree to round-off.
#[test]
fn simd_and_portable_paths_agree() {
    let model = block([6, 5, 4], true);
    let mut x: Vec<Vec3> = model.rest_positions().to_vec();
    let mut v = vec![Vec3::zeros(); model.n_particles()];
    for (i, (p, v)) in x.iter_mut().zip(&mut v).enumerate() {
        *p += Vec3::new(((i * 37) % 11) as f64 - 5.0, ((i * 17) % 7) as f64 - 3.0, ((i * 5) % 3) as f64 - 1.0) * 5e-5;
        *v = Vec3::new(((i * 7) % 5) as f64 - 2.0, ((i * 3) % 4) as f64 - 1.5, 1.0) * 1e-3;
    }
    let run = |simd: bool| {
        palpate_core::meshfree::set_simd_enabled(simd);
        let path = palpate_core::meshfree::simd_path();
        let mut f = vec![Vec3::zeros(); model.n_particles()];
        model.internal_forces(&x, Some(&v), &mut f);
        let mut st = ParticleState::rest(&model);
        st.x = x.clone();
        st.v = v.clone();
        st.active = (0..model.n_particles()).filter(|i| i % 3 != 0).collect();
        let mut ws = ParticleWorkspace::new(&model);
        for _ in 0..5 {
            meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
        }
        palpate_core::meshfree::set_simd_enabled(true);
        (path, f, st.x)
    };
    let (p_fast, f_fast, x_fast) = run(true);
    let (p_base, f_base, x_base) = run(false);
    assert_eq!(p_base, "baseline");
    let fmax = f_base.iter().map(|f| f.norm()).fold(0.0, f64::max);
    let df = f_fast.iter().zip(&f_base).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    assert!(df <= 1e-12 * fmax, "{p_fast} vs baseline: forces differ by {df:e} (max {fmax:e})");
    let dx = x_fast.iter().zip(&x_base).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    assert!(dx <= 1e-12 * SPACING, "{p_fast} vs baseline: positions differ by {dx:e} m after 5 steps");
}

#[test]
fn momentum_is_conserved_to_round_off() {
    let model = block([5, 5, 5], true);
    let mut st = ParticleState::rest(&model);
    let mut ws = ParticleWorkspace::new(&model);
    for (i, v) in st.v.iter_mut().enumerate() {
        *v = Vec3::new(((i * 37) % 11) as f64 - 4.0, ((i * 17) % 7) as f64 - 2.0, ((i * 5) % 3) as f64) * 1e-3;
    }
    let p0 = model.momentum(&st.v);
    for _ in 0..200 {
        let before = model.momentum(&st.v);
        meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
        let p = model.momentum(&st.v);
        // Per 1 ms step (several Verlet sub-steps): pairwise antisymmetric forces cancel exactly.
        assert!((p - before).norm() <= 1e-12 * p0.norm(), "{}", (p - before).norm() / p0.norm());
    }
}

/// Leapfrog's conserved ("shadow") energy: U(x_n) + 1/2 sum m v_{n-1/2} . v_{n+1/2}; the naive
/// kinetic energy of half-step velocities oscillates by O((omega dt)^2) near the stability limit.
/// One value per caller step of 1 ms, taken with the sub-steps `meshfree::step` would use.
fn shadow_energies(model: &ParticleModel, st: &mut ParticleState, ws: &mut ParticleWorkspace, steps: usize) -> Vec<f64> {
    let substeps = model.substeps(1e-3);
    let dt_sub = 1e-3 / substeps as f64;
    let mut out = Vec::with_capacity(steps);
    for _ in 0..steps {
        let mut e = 0.0;
        for s in 0..substeps {
            let v_before = st.v.clone();
            let u = model.strain_energy(&st.x);
            meshfree::step_with_substeps(model, st, ws, dt_sub, 1).unwrap();
            if s == 0 {
                e = u + 0.5 * (0..model.n_particles()).map(|i| model.masses()[i] * v_before[i].dot(&st.v[i])).sum::<f64>();
            }
        }
        out.push(e);
    }
    out
}

fn excited(model: &ParticleModel) -> ParticleState {
    let mut st = ParticleState::rest(model);
    for (i, x) in st.x.iter_mut().enumerate() {
        *x += Vec3::new(((i * 37) % 11) as f64 - 5.0, ((i * 17) % 7) as f64 - 3.0, ((i * 5) % 3) as f64 - 1.0) * 2e-8;
    }
    st
}

#[test]
fn undamped_energy_does_not_grow_over_10000_steps() {
    let model = block([4, 4, 4], false);
    let mut st = excited(&model);
    let mut ws = ParticleWorkspace::new(&model);
    let e = shadow_energies(&model, &mut st, &mut ws, 10_000);
    let e0 = e[0];
    let mean = |w: &[f64]| w.iter().sum::<f64>() / w.len() as f64;
    let (first, last) = (mean(&e[..1000]), mean(&e[9000..]));
    let drift = (last - first) / first;
    let emax = e.iter().cloned().fold(0.0, f64::max);
    eprintln!("shadow energy: E0 {e0:e}, mean of the first / last 1000 steps {first:e} / {last:e} (drift {drift:e}), max {emax:e}");
    // The shadow energy is exact only for linear forces: the Green-strain terms (strain ~1e-4
    // here) make it wander by O(strain), bounded and of either sign (measured: |drift| <= 1.3e-4
    // for sub-steps from 0.3 to 1.0 of the stable step). An unstable or non-symplectic scheme
    // grows steadily, by orders of magnitude over 10,000 steps.
    assert!(drift.abs() <= 1e-3, "energy drifted: {first} -> {last}");
    assert!(emax <= e0 * (1.0 + 2e-3), "energy grew: max {emax} vs {e0}");
}

#[test]
fn damped_energy_decays() {
    let model = block([4, 4, 4], true);
    let mut st = excited(&model);
    let mut ws = ParticleWorkspace::new(&model);
    let e = shadow_energies(&model, &mut st, &mut ws, 300);
    // Compared 10 ms apart (the shadow energy of single sub-steps may wiggle), until round-off.
    for w in e.windows(11).step_by(10) {
        if w[0] < 1e-9 * e[0] {
            break;
        }
        assert!(w[10] <= w[0] * (1.0 + 1e-9), "energy rose from {} to {}", w[0], w[10]);
    }
    assert!(e.last().unwrap() < &(0.01 * e[0]), "damped energy barely decayed: {} of {}", e.last().unwrap(), e[0]);
}

/// The zero-energy-mode safeguard: a block clamped at its base, pushed by a point load on one
/// top particle, must keep its particles apart and ordered. Without hourglass control the same
/// load excites the modes the MLS gradient cannot see: the non-affine part of the motion is
/// much larger (this is what makes the test able to fail).
#[test]
fn hourglass_control_keeps_particles_from_clumping_or_crossing() {
    let n = [6, 6, 6];
    let build = |kappa: f64| {
        let (pts, m) = lattice(n);
        let fixed: Vec<usize> = (0..n[0] * n[1]).collect();
        ParticleModelBuilder::new(pts, m, material(true), 1.8 * SPACING)
            .fixed_particles(fixed)
            .hourglass(kappa)
            .build()
            .unwrap()
    };
    let top_centre = 3 + n[0] * (3 + n[1] * (n[2] - 1));
    let run = |model: &ParticleModel| {
        let mut st = ParticleState::rest(model);
        let mut ws = ParticleWorkspace::new(model);
        st.f_ext[top_centre] = Vec3::new(0.0, 0.0, -2e-3); // 2 mN on one particle: ~10% local strain
        for _ in 0..300 {
            meshfree::step(model, &mut st, &mut ws, 1e-3).unwrap();
        }
        // Smallest neighbour distance / rest distance, smallest det F, and the non-affine residual.
        let mut min_ratio = f64::INFINITY;
        let mut min_det = f64::INFINITY;
        let mut residual = 0.0;
        for i in 0..model.n_particles() {
            let f = model.deformation_gradient(i, &st.x);
            min_det = min_det.min(f.determinant());
            for &j in model.neighbours(i) {
                let r0 = model.rest_positions()[j] - model.rest_positions()[i];
                let r = st.x[j] - st.x[i];
                min_ratio = min_ratio.min(r.norm() / r0.norm());
                residual += (r - f * r0).norm_squared();
            }
        }
        (min_ratio, min_det, residual.sqrt())
    };
    let (ratio, det, res_hg) = run(&build(palpate_core::meshfree::DEFAULT_HOURGLASS));
    assert!(ratio > 0.5, "particles clumped: neighbour distance down to {ratio} of rest");
    assert!(det > 0.5, "inverted or crushed neighbourhood: det F = {det}");
    let (_, _, res_free) = run(&build(0.0));
    eprintln!("non-affine residual after 0.3 s: {res_hg:.3e} m with hourglass control, {res_free:.3e} m without");
    assert!(res_free > 1.5 * res_hg, "hourglass control made no difference: {res_free} vs {res_hg}");
}

#[test]
fn stable_dt_is_tight() {
    // Just above the computed limit (without the safety factor) the scheme must blow up.
    let model = block([5, 5, 5], false);
    let dt_crit = model.stable_dt() / palpate_core::meshfree::STABILITY_SAFETY;
    let run = |dt: f64| {
        let mut st = ParticleState::rest(&model);
        let mut ws = ParticleWorkspace::new(&model);
        for (i, x) in st.x.iter_mut().enumerate() {
            *x += Vec3::new(((i * 37) % 11) as f64 - 5.0, 0.0, 0.0) * 1e-9;
        }
        for _ in 0..3000 {
            if meshfree::step_with_substeps(&model, &mut st, &mut ws, dt, 1).is_err() {
                return false;
            }
            if st.x.iter().zip(model.rest_positions()).any(|(x, x0)| (x - x0).norm() > 1e-3) {
                return false;
            }
        }
        true
    };
    assert!(run(0.98 * dt_crit), "unstable below the computed limit");
    assert!(!run(1.1 * dt_crit), "stable well above the computed limit: the bound is not tight");
}

/// The checkerboard (hourglass) mode of a lattice, `u_i = (-1)^(i+j+k) e_x` on the interior
/// particles, is invisible to the MLS gradient of every particle whose neighbourhood it covers
/// (face neighbours cancel in pairs, edge neighbours move with the particle): without control
/// its stiffness comes only from the few particles near the boundary. The hourglass term must
/// make it stiff (the safeguard the issue asks for, tested on the operator itself).
#[test]
fn hourglass_control_stiffens_the_checkerboard_mode() {
    let n = 9;
    let rayleigh = |kappa: f64| {
        let mut pts = Vec::new();
        let mut u = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    pts.push(Vec3::new(i as f64, j as f64, k as f64) * SPACING);
                    let inner = [i, j, k].iter().all(|&c| c >= 2 && c < n - 2);
                    let sign = if (i + j + k) % 2 == 0 { 1.0 } else { -1.0 };
                    u.push(if inner { Vec3::new(sign * 1e-9, 0.0, 0.0) } else { Vec3::zeros() });
                }
            }
        }
        let m = vec![1000.0 * SPACING.powi(3); pts.len()];
        let model = ParticleModelBuilder::new(pts, m, material(false), 1.8 * SPACING).hourglass(kappa).build().unwrap();
        let mut f = vec![Vec3::zeros(); model.n_particles()];
        model.linearised_forces(&u, &mut f);
        let utku: f64 = -u.iter().zip(&f).map(|(u, f)| u.dot(f)).sum::<f64>();
        let utmu: f64 = u.iter().zip(model.masses()).map(|(u, m)| m * u.norm_squared()).sum();
        // omega^2 of the mode, in units of (P-wave speed / spacing)^2.
        utku / utmu / (model.material().wave_speed() / SPACING).powi(2)
    };
    let with = rayleigh(palpate_core::meshfree::DEFAULT_HOURGLASS);
    let without = rayleigh(0.0);
    eprintln!("checkerboard mode omega^2 (c_p/spacing)^-2: {with:.3e} with hourglass control, {without:.3e} without");
    // Measured 2026-11-22: about 3.3x stiffer with the default kappa = 0.5.
    assert!(with > 3.0 * without, "hourglass control does not stiffen the checkerboard mode: {with} vs {without}");
}

/// The particle hot loop (and its AVX2 copy) implements the St. Venant-Kirchhoff stress only. A
/// Neo-Hookean material must be refused with a typed error naming the law, never silently run
/// as SVK. What it catches: a builder that ignores `Material::law`.
#[test]
fn neo_hookean_material_is_refused_with_a_typed_error() {
    use palpate_core::material::Law;
    use palpate_core::{MaterialError, ModelError};
    let (pts, m) = lattice([4, 4, 4]);
    let nh = material(false).with_law(Law::NeoHookean);
    let err = ParticleModelBuilder::new(pts.clone(), m.clone(), nh, 1.8 * SPACING).build().unwrap_err();
    assert_eq!(err, ModelError::Material(MaterialError::UnsupportedLaw { law: Law::NeoHookean, solver: "the particle solid (meshfree)" }));
    let msg = err.to_string();
    assert!(msg.contains("St. Venant-Kirchhoff law only") && msg.contains("Neo-Hookean"), "{msg}");
    // The same material with the SVK law builds.
    ParticleModelBuilder::new(pts, m, nh.with_law(Law::StVenantKirchhoff), 1.8 * SPACING).build().unwrap();
}

/// A particle compressed below `COMPRESSION_FLOOR` (and one turned inside out) gets the barrier:
/// the force stays minus the energy gradient (the barrier is in the energy), both copies of the
/// loop agree, and the barrier pushes an inverted block back toward positive volume.
#[test]
fn compression_barrier_is_an_energy_and_pushes_inverted_particles_out() {
    let model = block([4, 4, 4], false);
    let rest: Vec<Vec3> = model.rest_positions().to_vec();
    let c: Vec3 = rest.iter().sum::<Vec3>() / rest.len() as f64;
    for squash in [0.3, -0.4] {
        // x' = c + diag(squash, 1, 1) (x - c): J = squash for the interior.
        let mut x: Vec<Vec3> = rest.iter().map(|p| c + (p - c).component_mul(&Vec3::new(squash, 1.0, 1.0))).collect();
        for (i, p) in x.iter_mut().enumerate() {
            *p += Vec3::new(((i * 37) % 11) as f64 - 5.0, ((i * 17) % 7) as f64 - 3.0, ((i * 5) % 3) as f64 - 1.0) * 2e-6;
        }
        let j = model.deformation_gradient(21, &x).determinant();
        assert!(j < meshfree::COMPRESSION_FLOOR, "the test must reach the barrier: J = {j}");
        let forces = |simd: bool| {
            meshfree::set_simd_enabled(simd);
            let mut f = vec![Vec3::zeros(); model.n_particles()];
            model.internal_forces(&x, None, &mut f);
            meshfree::set_simd_enabled(true);
            f
        };
        let (f, f_base) = (forces(true), forces(false));
        let fmax = f.iter().map(|f| f.norm()).fold(0.0, f64::max);
        let df = f.iter().zip(&f_base).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
        assert!(df <= 1e-12 * fmax, "SIMD and portable differ by {df:e}");
        let h = 1e-10;
        for i in [0, 5, 21, 42, 63] {
            for k in 0..3 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[i][k] += h;
                xm[i][k] -= h;
                let fd = -(model.strain_energy(&xp) - model.strain_energy(&xm)) / (2.0 * h);
                assert!((fd - f[i][k]).abs() <= 1e-5 * fmax, "J {squash}: particle {i} comp {k}: fd {fd} vs {}", f[i][k]);
            }
        }
        // Along the squashed axis the forces spread the block apart again.
        let push: f64 = (0..x.len()).map(|i| f[i].x * (x[i].x - c.x).signum() * squash.signum()).sum();
        assert!(push > 0.0, "J {squash}: net push {push}");
    }
    // Without the barrier (above the floor) the energy is the paper's alone.
    assert_eq!(meshfree::barrier_energy_density(&material(false), 0.8), 0.0);
}
