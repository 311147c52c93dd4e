//! Selective mass scaling of the particle body (`meshfree/mass_scaling.rs`).
//!
//! What a wrong implementation would do: a stiffness probe that misses a particle whose strain or
//! force a displacement reaches (the neighbours' neighbours, the hourglass term) gives row sums
//! below the true ones, and then the "proven" bound on the top frequency is not one (the dense
//! comparison and the bound-above-power-iteration checks catch it); scaling that touches the
//! stiffness, the volumes or fixed particles changes the statics (the static solve must not move);
//! a target taken from the wrong end of the rates scales everything or nothing.
use palpate_core::meshfree::{ParticleModel, ParticleModelBuilder};
use palpate_core::Vec3;

#[path = "support/particles.rs"]
mod particles;
use particles::{lattice, material, SPACING};

/// A lattice block with a ragged top (every other particle of its top layer removed, so that
/// the rest there are poorly supported, as a curved shell's lattice rim is), the bottom layer fixed.
fn ragged(n: [usize; 3], scaling: Option<f64>) -> ParticleModel {
    let (pts, m) = lattice(n);
    let top = (n[2] - 1) as f64 * SPACING;
    let keep: Vec<usize> = (0..pts.len()).filter(|&i| pts[i].z < top - 1e-9 || i % 2 == 0).collect();
    let pts: Vec<Vec3> = keep.iter().map(|&i| pts[i]).collect();
    let m: Vec<f64> = keep.iter().map(|&i| m[i]).collect();
    let fixed: Vec<usize> = (0..pts.len()).filter(|&i| pts[i].z < 1e-9).collect();
    let mut b = ParticleModelBuilder::new(pts, m, material(false), 1.8 * SPACING).fixed_particles(fixed).fix_unsupported(true);
    if let Some(q) = scaling {
        b = b.mass_scaling(q);
    }
    b.build().unwrap()
}

/// The dense rest-linearised stiffness over the free particles, `K[(i,a)][(k,b)]`, by probing
/// the whole body's linearised forces with each unit displacement.
fn dense_stiffness(m: &ParticleModel) -> Vec<Vec<f64>> {
    let n = m.n_particles();
    let mut k = vec![vec![0.0; 3 * n]; 3 * n];
    let mut u = vec![Vec3::zeros(); n];
    let mut f = vec![Vec3::zeros(); n];
    for j in 0..n {
        for b in 0..3 {
            u[j][b] = 1.0;
            m.linearised_forces(&u, &mut f);
            for i in 0..n {
                for a in 0..3 {
                    k[3 * i + a][3 * j + b] = -f[i][a];
                }
            }
            u[j][b] = 0.0;
        }
    }
    k
}

#[test]
fn row_sums_are_the_dense_stiffness_row_sums() {
    let m = ragged([4, 4, 4], None);
    let k = dense_stiffness(&m);
    let free: Vec<usize> = (0..m.n_particles()).filter(|&i| !m.fixed()[i]).collect();
    let scale = k.iter().flatten().fold(0.0f64, |a, &x| a.max(x.abs()));
    // Symmetric (the forces are an energy's gradient): the probe reads rows as columns.
    for &i in &free {
        for &j in &free {
            for a in 0..3 {
                for b in 0..3 {
                    assert!((k[3 * i + a][3 * j + b] - k[3 * j + b][3 * i + a]).abs() <= 1e-9 * scale, "K not symmetric at ({i},{a}),({j},{b})");
                }
            }
        }
    }
    let g = m.stiffness_row_sums();
    for i in 0..m.n_particles() {
        if m.fixed()[i] {
            assert_eq!(g[i], 0.0);
            continue;
        }
        let want = (0..3)
            .map(|a| free.iter().map(|&j| (0..3).map(|b| k[3 * i + a][3 * j + b].abs()).sum::<f64>()).sum::<f64>())
            .fold(0.0, f64::max);
        assert!((g[i] - want).abs() <= 1e-9 * want, "particle {i}: {} vs dense {}", g[i], want);
    }
}

#[test]
fn gershgorin_bounds_the_top_frequency() {
    let m = ragged([6, 5, 5], None);
    let g = m.stiffness_row_sums();
    let bound = (0..m.n_particles()).filter(|&i| !m.fixed()[i]).map(|i| g[i] / m.masses()[i]).fold(0.0, f64::max);
    // omega_max carries a 2% margin over the power iteration's estimate (from below).
    let estimate = m.omega_max().powi(2) / 1.02;
    assert!(estimate <= bound * (1.0 + 1e-9), "power iteration {estimate:e} above the proven bound {bound:e}");
    assert!(estimate > 0.3 * bound, "a bound this loose would say nothing: {estimate:e} vs {bound:e}");
}

#[test]
fn scaling_bounds_the_top_frequency_and_leaves_the_statics() {
    let plain = ragged([6, 5, 5], None);
    let scaled = ragged([6, 5, 5], Some(0.8));
    let s = *scaled.mass_scaling();
    let free = (0..plain.n_particles()).filter(|&i| !plain.fixed()[i]).count();
    // The stiffest fifth is scaled (ties at the quantile aside), nothing else.
    assert!(s.scaled > 0 && s.scaled <= free / 5 + 1, "{s:?} of {free}");
    assert!(s.applied && s.max_factor > 1.0 && s.added_fraction > 0.0, "{s:?}");
    assert!(s.omega2_after <= (1.0 - palpate_core::meshfree::WORTH_IT) * s.omega2_before);
    for i in 0..plain.n_particles() {
        assert!(scaled.masses()[i] >= plain.masses()[i]);
        if plain.fixed()[i] {
            assert_eq!(scaled.masses()[i], plain.masses()[i], "a fixed particle's mass is never scaled");
        }
    }
    let added: f64 = scaled.masses().iter().zip(plain.masses()).map(|(a, b)| a - b).sum();
    assert!((added - s.added_mass).abs() <= 1e-12 * added);
    // The proven bound holds for the scaled body, and its step is longer.
    assert!(scaled.omega_max().powi(2) / 1.02 <= s.target_rate2 * (1.0 + 1e-9));
    assert!(scaled.stable_dt() > plain.stable_dt(), "{} vs {}", scaled.stable_dt(), plain.stable_dt());
    // Statics: the same equilibrium under the same load (masses are inertia only).
    let mut f = vec![Vec3::zeros(); plain.n_particles()];
    for (i, p) in plain.rest_positions().iter().enumerate() {
        if p.z > 2.5 * SPACING {
            f[i] = Vec3::new(1e-6, 0.0, -2e-6);
        }
    }
    let a = plain.static_solve_linear(&f, 1e-10, 2000).unwrap();
    let b = scaled.static_solve_linear(&f, 1e-10, 2000).unwrap();
    let du = a.iter().zip(plain.rest_positions()).map(|(x, r)| (x - r).norm()).fold(0.0, f64::max);
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).norm() <= 1e-12 * du.max(1e-30) + 1e-18, "statics moved: {x:?} vs {y:?}");
    }
}

#[test]
fn a_bad_quantile_or_gravity_is_refused() {
    let (pts, m) = lattice([3, 3, 3]);
    for q in [0.0, -0.5, 1.5, f64::NAN] {
        assert!(ParticleModelBuilder::new(pts.clone(), m.clone(), material(false), 1.8 * SPACING).mass_scaling(q).build().is_err(), "q = {q}");
    }
    let e = ParticleModelBuilder::new(pts, m, material(false), 1.8 * SPACING)
        .gravity(Vec3::new(0.0, 0.0, -9.81))
        .mass_scaling(0.9)
        .build();
    assert!(e.unwrap_err().to_string().contains("gravity"));
}
