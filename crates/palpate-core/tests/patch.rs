//! Patch test: a linear tetrahedral mesh must reproduce every affine deformation exactly.
//!
//! For `x = A X + b` every tet has `F = A`, hence the same Green strain and stress, the internal
//! force on every interior node cancels, and the force on a boundary node is exactly the traction
//! of the uniform stress on its share of the boundary faces, `f_i = -P * sum_{faces} A_f N_f / 3`.
//! The same holds for the viscous force of a uniform velocity gradient `v = G X + c`.
//!
//! What a wrong implementation would do:
//! * a wrong shape-function gradient (e.g. `grad N_0` not `-(g1+g2+g3)`, a transposed `Dm^-1`)
//!   gives `F != A` on some tets and a non-zero net force on interior nodes;
//! * an assembly error (a node's contribution scattered to the wrong index) leaves interior
//!   residuals of the size of an element force;
//! * the paper's literal eq. (22) (`vol/2` with the 1/2-Green strain) halves the recovered stress;
//! * a stress not equal to `F S` (e.g. `S` alone, or a small-strain Cauchy stress) fails the
//!   comparison with the independently computed SVK Piola stress at the large (0.2) strain.
//!
//! Tolerances: all tets see identical `F` up to round-off. Positions are `O(L)` with `L = 3 cm`,
//! differences over a cell `h ~ 1 cm`, so `F` carries an absolute error `~ eps L / h ~ 1e-15`, and
//! the Green strain `E = (F^T F - I)/2` an absolute error `~1e-15`: relative to a strain of `1e-3`
//! that is `~1e-12` (the stress comparison allows `1e-9`). Interior nodal forces are sums of
//! ~24 element forces each accurate to that relative level, so their residual is `~1e-12` of the
//! element force scale: `1e-10` leaves a margin of 100 and still fails by 9 orders of magnitude
//! for any of the bugs above.

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::fem::tet4;
use palpate_core::mesh::generate::box_mesh;
use palpate_core::{Mat3, ModelBuilder, TetMesh, Vec3};

const SIZE: [f64; 3] = [0.03, 0.02, 0.025];
const CELLS: [usize; 3] = [3, 3, 3];

fn meshes() -> Vec<(&'static str, TetMesh)> {
    vec![
        ("regular 3x3x3", box_mesh(SIZE, CELLS)),
        ("irregular 3x3x3 (20%)", perturbed_box(SIZE, CELLS, 0.2, 7)),
        ("irregular 4x3x5 (20%)", perturbed_box(SIZE, [4, 3, 5], 0.2, 11)),
    ]
}

fn affine_maps() -> Vec<(&'static str, Mat3, Vec3)> {
    let mut rng = Rng::new(42);
    // General (non-symmetric) gradients: stretch, shear and rotation all present.
    let small = Mat3::identity() + rng.mat3(1e-3);
    let g = rng.mat3(0.2);
    let large = rotation(Vec3::new(0.3, -1.0, 0.5), 0.7) * (Mat3::identity() + g);
    assert!(large.determinant() > 0.2, "test set-up: A must not invert");
    vec![("small strain ~1e-3", small, rng.vec3(0.01)), ("large strain ~0.2 + rotation", large, rng.vec3(0.05))]
}

/// Check nodal forces against the traction of a uniform Piola stress `p` (see module docs),
/// returning (worst interior residual / element scale, worst boundary mismatch / element scale).
fn check_against_traction(mesh: &TetMesh, forces: &[Vec3], p: &Mat3, elem_scale: f64, what: &str) {
    let area = boundary_area_vectors(mesh);
    let mut worst_int: f64 = 0.0;
    let mut worst_bnd: f64 = 0.0;
    for i in 0..mesh.n_nodes() {
        let expect = -(p * area[i]);
        let err = (forces[i] - expect).norm() / elem_scale;
        if area[i] == Vec3::zeros() {
            worst_int = worst_int.max(err);
        } else {
            worst_bnd = worst_bnd.max(err);
        }
    }
    println!("{what}: interior |f|/scale {worst_int:.2e}, boundary |f - traction|/scale {worst_bnd:.2e}");
    assert!(worst_int <= 1e-10, "{what}: interior net force {worst_int:e} of the element force scale");
    assert!(worst_bnd <= 1e-10, "{what}: boundary force differs from the uniform traction by {worst_bnd:e}");
}

#[test]
fn affine_deformation_gives_uniform_stress_and_zero_interior_force() {
    let mat = material(3.0e4, 0.4, 1000.0, 0.0, 0.0);
    for (mname, mesh) in meshes() {
        let interior = boundary_area_vectors(&mesh).iter().filter(|a| **a == Vec3::zeros()).count();
        assert!(interior >= 8, "{mname}: test needs interior nodes");
        let model = ModelBuilder::new(mesh.clone(), mat).build().unwrap();
        let rest_pts = mesh.points();
        for (aname, a, b) in affine_maps() {
            let x: Vec<Vec3> = rest_pts.iter().map(|p| a * p + b).collect();
            let p_exact = svk_piola(&a, mat.lambda(), mat.mu());
            let mut elem_scale: f64 = 0.0;
            for (t, r) in mesh.tets().iter().zip(model.rest()) {
                let xe = t.map(|i| x[i]);
                let f = tet4::deformation_gradient(&xe, r);
                assert!((f - a).norm() <= 1e-12 * a.norm(), "{mname}, {aname}: F != A ({:e})", (f - a).norm());
                let fe = tet4::forces(&xe, None, r, &mat);
                let p = piola_from_forces(&fe, &t.map(|i| rest_pts[i]), r.volume);
                let rel = (p - p_exact).norm() / p_exact.norm();
                assert!(rel <= 1e-9, "{mname}, {aname}: element stress differs from SVK P = F S by {rel:e}");
                elem_scale = elem_scale.max(fe.iter().map(|v| v.norm()).fold(0.0, f64::max));
            }
            let mut forces = vec![Vec3::zeros(); mesh.n_nodes()];
            model.internal_forces(&x, None, &mut forces);
            let total: Vec3 = forces.iter().sum();
            assert!(total.norm() <= 1e-12 * elem_scale * mesh.n_tets() as f64, "{mname}, {aname}: net force {total:?}");
            check_against_traction(&mesh, &forces, &p_exact, elem_scale, &format!("{mname}, {aname}"));
        }
    }
}

/// A uniform material velocity gradient `v = G X + c` gives `Fdot = G` in every tet, the viscous
/// stress `F S_v(nu)`, `nu = sym(F^T G)`, everywhere, and zero net viscous force on interior nodes.
/// A wrong strain rate (e.g. `sym(G)` without `F^T`, or the paper's doubled eq. 10 rate) fails the
/// stress comparison at the large deformation.
#[test]
fn uniform_velocity_gradient_gives_uniform_viscous_stress() {
    let (phi, psi) = (3.0, 7.0);
    let mat = material(3.0e4, 0.4, 1000.0, phi, psi);
    let mut rng = Rng::new(5);
    for (mname, mesh) in meshes() {
        let model = ModelBuilder::new(mesh.clone(), mat).build().unwrap();
        let rest_pts = mesh.points();
        for (aname, a, b) in affine_maps() {
            let g = rng.mat3(2.0); // [1/s]
            let c = rng.vec3(0.1);
            let x: Vec<Vec3> = rest_pts.iter().map(|p| a * p + b).collect();
            let v: Vec<Vec3> = rest_pts.iter().map(|p| g * p + c).collect();
            let nu = 0.5 * (a.transpose() * g + g.transpose() * a);
            let p_exact = a * (Mat3::identity() * (phi * nu.trace()) + 2.0 * psi * nu);
            let mut elem_scale: f64 = 0.0;
            for (t, r) in mesh.tets().iter().zip(model.rest()) {
                let (xe, ve) = (t.map(|i| x[i]), t.map(|i| v[i]));
                let fdot = tet4::deformation_gradient(&ve, r);
                assert!((fdot - g).norm() <= 1e-12 * g.norm(), "{mname}: Fdot != G");
                let fv = tet4::forces(&xe, Some(&ve), r, &mat);
                let fe = tet4::forces(&xe, None, r, &mat);
                let visc = [fv[0] - fe[0], fv[1] - fe[1], fv[2] - fe[2], fv[3] - fe[3]];
                let p = piola_from_forces(&visc, &t.map(|i| rest_pts[i]), r.volume);
                let rel = (p - p_exact).norm() / p_exact.norm();
                assert!(rel <= 1e-9, "{mname}, {aname}: viscous stress differs by {rel:e}");
                elem_scale = elem_scale.max(visc.iter().map(|v| v.norm()).fold(0.0, f64::max));
            }
            let mut f_all = vec![Vec3::zeros(); mesh.n_nodes()];
            let mut f_el = vec![Vec3::zeros(); mesh.n_nodes()];
            model.internal_forces(&x, Some(&v), &mut f_all);
            model.internal_forces(&x, None, &mut f_el);
            let visc: Vec<Vec3> = f_all.iter().zip(&f_el).map(|(a, b)| a - b).collect();
            check_against_traction(&mesh, &visc, &p_exact, elem_scale, &format!("viscous: {mname}, {aname}"));
        }
    }
}
