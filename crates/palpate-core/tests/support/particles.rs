//! Particle-body set-ups shared by the meshfree tests: the material and the cubic lattice.
#![allow(dead_code)]

use palpate_core::material::{Damping, Elasticity};
use palpate_core::{Material, Vec3};

/// Lattice spacing \[m\].
pub const SPACING: f64 = 1e-3;

/// Soft tissue (E = 30 kPa, nu = 0.4, 1000 kg/m^3), damped or not.
pub fn material(damped: bool) -> Material {
    let d = if damped { Damping { phi: 0.5, psi: 0.5 } } else { Damping::NONE };
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, d).unwrap()
}

/// Cubic lattice points of spacing 1 mm, `n` per side (x fastest) and their masses.
pub fn lattice(n: [usize; 3]) -> (Vec<Vec3>, Vec<f64>) {
    let mut pts = Vec::new();
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                pts.push(Vec3::new(i as f64, j as f64, k as f64) * SPACING);
            }
        }
    }
    let m = vec![1000.0 * SPACING.powi(3); pts.len()];
    (pts, m)
}
