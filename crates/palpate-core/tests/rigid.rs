//! Rigid motions are force-free: the Green strain (and palpate's strain rate `dE/dt`) vanish for
//! `x = R X + t` and `v = w x (x - c) + v0`, whatever the rotation angle.
//!
//! What a wrong implementation would do: a small-strain (co-rotation-free linear) element, or a
//! strain rate `sym(Fdot)` instead of `sym(F^T Fdot)`, gives forces of the size of an O(1) strain
//! under a finite rotation, i.e. ~1e3 times the reference force of a 1e-3 strain used below; a
//! mesh-level assembly error that drops or duplicates a tet's contribution also leaves a
//! non-zero force (a rigid motion is force-free only if every tet's forces are).
//!
//! Tolerance: `F = R` up to an absolute round-off `~ eps |x| / h ~ 1e-15` (translations are kept
//! at the body size, a few cm: round-off grows with `|x|`, and a 2 m shift of this 5 cm body
//! measured 1.6e-10), so the Green strain is
//! `~1e-15` where the reference is `1e-3`: the force ratio is `~1e-12`; 1e-10 leaves a margin of 100.

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::mesh::generate::{ellipsoid_wall, EllipsoidWall};
use palpate_core::{Mat3, ModelBuilder, Vec3};

fn wall_model(phi: f64, psi: f64) -> palpate_core::Model {
    let mesh = ellipsoid_wall(&EllipsoidWall { subdivisions: 2, ..EllipsoidWall::default() });
    ModelBuilder::new(mesh, material(3.0e4, 0.4, 1060.0, phi, psi)).build().unwrap()
}

/// Largest nodal elastic force of the uniform strain `eps_mag * (a fixed symmetric unit tensor)`.
fn reference_strain_force(model: &palpate_core::Model, eps_mag: f64) -> f64 {
    let s = Mat3::new(1.0, 0.3, -0.2, 0.3, -0.5, 0.4, -0.2, 0.4, 0.8).normalize();
    let a = Mat3::identity() + eps_mag * s;
    let x: Vec<Vec3> = model.mesh().points().iter().map(|p| a * p).collect();
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    model.internal_forces(&x, None, &mut f);
    max_norm(&f)
}

#[test]
fn rigid_rotation_and_translation_give_zero_elastic_force() {
    let model = wall_model(0.0, 0.0);
    let scale = reference_strain_force(&model, 1e-3);
    assert!(scale > 0.0);
    let x_ref: Vec<Vec3> = model.mesh().points().iter().map(|p| p * (1.0 + 1e-3)).collect();
    let w_ref = model.strain_energy(&x_ref);
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    let mut worst: f64 = 0.0;
    for (axis, angle, t) in [
        (Vec3::z(), 0.0, Vec3::new(0.01, -0.02, 0.03)), // pure translation
        (Vec3::new(1.0, 2.0, -0.5), 0.3, Vec3::zeros()),
        (Vec3::new(-0.3, 0.4, 1.0), 2.5, Vec3::new(0.03, 0.015, -0.04)),
        (Vec3::x(), std::f64::consts::PI, Vec3::new(0.0, 0.02, 0.0)), // half turn
    ] {
        let r = rotation(axis, angle);
        let x: Vec<Vec3> = model.mesh().points().iter().map(|p| r * p + t).collect();
        model.internal_forces(&x, None, &mut f);
        let ratio = max_norm(&f) / scale;
        worst = worst.max(ratio);
        assert!(ratio <= 1e-10, "rotation {angle} rad about {axis:?}: max |f| = {ratio:e} of a 1e-3 strain's force");
        // Energy is quadratic in the (round-off) strain: (1e-15 / 1e-3)^2 ~ 1e-24 of the reference.
        let w = model.strain_energy(&x);
        assert!(w.abs() <= 1e-16 * w_ref, "rigid motion stores energy {w:e} J (reference {w_ref:e} J)");
    }
    println!("worst rigid-motion force / 1e-3-strain force: {worst:.2e} (reference {scale:.3e} N)");
}

/// A damped body moving rigidly (spinning and drifting) in a rotated configuration feels no
/// viscous force. Reference scale: the viscous force of a pure strain-rate field of the same
/// velocity-gradient magnitude as the spin.
#[test]
fn rigid_velocity_field_gives_zero_viscous_force() {
    let model = wall_model(30.0, 70.0);
    let pts = model.mesh().points();
    let w = Vec3::new(3.0, -1.0, 2.0); // [rad/s]
    let v0 = Vec3::new(0.2, 0.1, -0.4); // [m/s]
    let mut f_all = vec![Vec3::zeros(); model.n_nodes()];
    let mut f_el = vec![Vec3::zeros(); model.n_nodes()];

    // Reference: v = |w| S X, S symmetric unit (a genuine strain rate), at rest.
    let s = Mat3::new(1.0, 0.3, -0.2, 0.3, -0.5, 0.4, -0.2, 0.4, 0.8).normalize();
    let v_ref: Vec<Vec3> = pts.iter().map(|p| w.norm() * (s * p)).collect();
    model.internal_forces(pts, Some(&v_ref), &mut f_all);
    let scale = max_norm(&f_all);
    assert!(scale > 0.0);

    let mut worst: f64 = 0.0;
    for (axis, angle, t) in [(Vec3::z(), 0.0, Vec3::zeros()), (Vec3::new(-0.3, 0.4, 1.0), 2.5, Vec3::new(0.03, 0.015, -0.04))] {
        let r = rotation(axis, angle);
        let x: Vec<Vec3> = pts.iter().map(|p| r * p + t).collect();
        let c = Vec3::new(0.3, -0.1, 0.2); // any centre: rigid either way
        let v: Vec<Vec3> = x.iter().map(|p| w.cross(&(p - c)) + v0).collect();
        model.internal_forces(&x, Some(&v), &mut f_all);
        model.internal_forces(&x, None, &mut f_el);
        let visc: Vec<Vec3> = f_all.iter().zip(&f_el).map(|(a, b)| a - b).collect();
        let ratio = max_norm(&visc) / scale;
        let total = max_norm(&f_all) / scale;
        worst = worst.max(ratio).max(total);
        assert!(ratio <= 1e-10, "rotation {angle}: viscous force {ratio:e} of the reference");
        assert!(total <= 1e-10, "rotation {angle}: total internal force {total:e} of the reference");
    }
    println!("worst rigid-velocity viscous force / reference: {worst:.2e} (reference {scale:.3e} N)");
}
