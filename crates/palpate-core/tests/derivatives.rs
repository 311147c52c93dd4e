//! Mesh-level derivative checks by central finite differences (the unit tests in `fem::tet4`
//! check one element; these check the assembled quantities the integrators use).
//!
//! * total internal force = -grad(total strain energy) on an irregular, deformed box;
//! * `Model::node_jacobians()[i]` (the paper's per-node `J_F`, eq. 34) = `d f_i / d x_i` at rest;
//! * the full Jacobian assembled from `tet4::jacobians` = FD of `Model::internal_forces`, at rest
//!   and at a deformed state (the Newton / static-solve tangent);
//! * at rest it is symmetric, negative semi-definite, with exactly the 6 rigid modes in its
//!   null space for a free body; the damping Jacobian likewise.
//!
//! What a wrong implementation would do: the paper's literal eq. (22) (`vol/2`) makes the force
//! half the energy gradient (error 50%); a sign error flips it (200%); a missing geometric term
//! `(g_a . S g_b) I` in `K` leaves a tangent error of the size of the stress (~10% at the deformed
//! state used here) while it is invisible at rest; a per-node block taken from the wrong
//! diagonal (e.g. only one tet's, or a row of neighbours) differs by O(1); a non-symmetric or
//! indefinite rest `K` would make `M - dt^2 K` lose the positive definiteness the solvers assume.
//!
//! FD tolerances: with a step `h` the central difference has truncation `~ (h/l)^2` (l the cell
//! size, ~5 mm) and round-off `~ eps * (quantity differenced) / (h * derivative)`. For the energy
//! gradient the differenced quantity is the *total* energy, `W / |f| ~ 1 cm` here, so
//! `h = 1e-8 m` gives round-off `~2e-10` and truncation `~4e-12`; for force differences
//! `h = 1e-7 m` gives `~1e-9` either way. Tolerances are 1e-6 of the largest entry (the bugs
//! above are >= 1e-1).

#[path = "support/common.rs"]
mod common;

use common::*;
use nalgebra::{DMatrix, DVector};
use palpate_core::{Mat3, Model, ModelBuilder, Vec3};

const SIZE: [f64; 3] = [0.02, 0.015, 0.012];
const CELLS: [usize; 3] = [3, 2, 2];

fn model(fixed: Vec<usize>, phi: f64, psi: f64) -> Model {
    let mesh = perturbed_box(SIZE, CELLS, 0.2, 3);
    ModelBuilder::new(mesh, material(3.0e4, 0.4, 1000.0, phi, psi)).fixed_nodes(fixed).build().unwrap()
}

/// A generic deformed state: a finite affine map (stretch ~10%, shear, rotation) plus random
/// nodal displacements of up to 10% of the cell size.
fn deformed(model: &Model, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    let a = rotation(Vec3::new(1.0, -0.5, 0.2), 0.4) * (Mat3::identity() + rng.mat3(0.1));
    let h = SIZE[0] / CELLS[0] as f64;
    model.mesh().points().iter().map(|p| a * p + rng.vec3(0.1 * h)).collect()
}

#[test]
fn total_force_is_minus_gradient_of_total_strain_energy() {
    let model = model(vec![], 0.0, 0.0);
    let x = deformed(&model, 1);
    let scale = max_norm(&forces(&model, &x));
    let worst = energy_gradient_error(&model, &x);
    println!("max |f + dW/dx| / max|f| = {worst:.2e} (max|f| = {scale:.3e} N, W = {:.3e} J)", model.strain_energy(&x));
    assert!(worst <= 1e-6, "force is not minus the energy gradient: relative error {worst:e}");
}

#[test]
fn node_jacobians_are_the_diagonal_blocks_at_rest() {
    // Fixing nodes must not change the per-node block: the paper's J_F assumes the neighbours
    // fixed, i.e. it is d f_i / d x_i of the whole body, for fixed and free nodes alike.
    let fixed = nodes_where(&perturbed_box(SIZE, CELLS, 0.2, 3), 0, 0.0, 1e-12);
    let model = model(fixed, 0.0, 0.0);
    let x0 = model.mesh().points().to_vec();
    let jf = model.node_jacobians();
    let scale = jf.iter().map(|b| b.norm()).fold(0.0, f64::max);
    let h = 1e-7;
    let mut xp = x0.clone();
    let mut worst: f64 = 0.0;
    for i in 0..model.n_nodes() {
        for c in 0..3 {
            xp[i][c] = x0[i][c] + h;
            let fp = forces(&model, &xp)[i];
            xp[i][c] = x0[i][c] - h;
            let fm = forces(&model, &xp)[i];
            xp[i][c] = x0[i][c];
            let col = (fp - fm) / (2.0 * h);
            worst = worst.max((col - jf[i].column(c)).norm() / scale);
        }
        // Symmetric, negative definite (a node held alone against its fixed neighbours).
        assert!((jf[i] - jf[i].transpose()).norm() <= 1e-12 * scale, "J_F[{i}] not symmetric");
        let eig = jf[i].symmetric_eigenvalues();
        assert!(eig.max() < 0.0, "J_F[{i}] not negative definite: {eig:?}");
    }
    println!("max |J_F - FD| / max|J_F| = {worst:.2e} (max |J_F| = {scale:.3e} N/m)");
    assert!(worst <= 1e-6, "node_jacobians differ from FD d f_i/d x_i by {worst:e}");
}

#[test]
fn assembled_jacobian_matches_finite_differences_at_rest_and_deformed() {
    let model = model(vec![], 0.0, 0.0);
    let rest = model.mesh().points().to_vec();
    for (what, x) in [("rest", rest.clone()), ("deformed", deformed(&model, 2))] {
        let k = dense_jacobian(&model, &x);
        let fd = fd_jacobian(&model, &x, 1e-7);
        let scale = k.amax();
        let err = (&k - &fd).amax() / scale;
        println!("{what}: max |K - FD| / max|K| = {err:.2e}");
        assert!(err <= 1e-6, "{what}: assembled Jacobian differs from FD by {err:e}");
        if what == "rest" {
            // The assembled diagonal blocks are the per-node J_F.
            for (i, b) in model.node_jacobians().iter().enumerate() {
                let d = k.fixed_view::<3, 3>(3 * i, 3 * i).into_owned();
                assert!((d - b).norm() <= 1e-12 * scale, "node {i}: diagonal block != node_jacobians");
            }
        }
    }
}

#[test]
fn rest_jacobian_is_symmetric_negative_semidefinite_with_six_rigid_modes() {
    let model = model(vec![], 0.0, 0.0);
    let x0 = model.mesh().points().to_vec();
    let k = dense_jacobian(&model, &x0);
    let scale = k.amax();
    let asym = (&k - k.transpose()).amax() / scale;
    assert!(asym <= 1e-13, "K not symmetric: {asym:e}");

    // x^T K x <= 0 for random x (round-off allowance: 1e-12 |K| |x|^2).
    let mut rng = Rng::new(9);
    let n = k.nrows();
    for _ in 0..500 {
        let v = DVector::from_fn(n, |_, _| rng.sym(1.0));
        let q = v.dot(&(&k * &v));
        assert!(q <= 1e-12 * scale * v.norm_squared(), "x^T K x = {q:e} > 0");
    }

    // Spectrum: all eigenvalues <= 0, exactly 6 (the rigid modes) at zero, the rest clearly
    // negative (a spurious zero-energy mode would show up as a 7th zero).
    let eig = nalgebra::SymmetricEigen::new(k.clone()).eigenvalues;
    let mut e: Vec<f64> = eig.iter().copied().collect();
    e.sort_by(|a, b| b.total_cmp(a)); // descending: zeros first
    let lmax = e.iter().map(|v| v.abs()).fold(0.0, f64::max);
    println!("eigenvalues / |lambda|max, largest 8: {:?}", e.iter().take(8).map(|v| v / lmax).collect::<Vec<_>>());
    assert!(e[0] <= 1e-12 * lmax, "positive eigenvalue {:e}", e[0]);
    assert!(e[5].abs() <= 1e-12 * lmax, "fewer than 6 zero modes: {:?}", &e[..7]);
    assert!(e[6] <= -1e-6 * lmax, "a 7th (spurious) zero mode: {:e}", e[6]);

    // The rigid modes explicitly: translations and infinitesimal rotations are in the null space.
    type Mode = Box<dyn Fn(&Vec3) -> Vec3>;
    let modes: Vec<Mode> = vec![
        Box::new(|_| Vec3::x()),
        Box::new(|_| Vec3::y()),
        Box::new(|_| Vec3::z()),
        Box::new(|p| Vec3::x().cross(p)),
        Box::new(|p| Vec3::y().cross(p)),
        Box::new(|p| Vec3::z().cross(p)),
    ];
    for m in &modes {
        let v = DVector::from_iterator(
            n,
            x0.iter().flat_map(|p| {
                let u = m(p);
                [u.x, u.y, u.z]
            }),
        );
        let kv = (&k * &v).amax();
        assert!(kv <= 1e-12 * scale * v.amax() * (n as f64).sqrt(), "rigid mode not in the null space: {kv:e}");
    }
}

#[test]
fn damping_jacobian_matches_finite_differences_and_is_negative_semidefinite() {
    let model = model(vec![], 30.0, 70.0);
    let x0 = model.mesh().points().to_vec();
    let n = model.n_nodes();
    // Assemble D = df/dv at rest from tet4::jacobians.
    let mut d = DMatrix::<f64>::zeros(3 * n, 3 * n);
    for (t, r) in model.mesh().tets().iter().zip(model.rest()) {
        let (_, de) = palpate_core::fem::tet4::jacobians(&t.map(|i| x0[i]), r, model.material());
        let de = de.expect("damped material has a damping Jacobian");
        for a in 0..4 {
            for b in 0..4 {
                for p in 0..3 {
                    for q in 0..3 {
                        d[(3 * t[a] + p, 3 * t[b] + q)] += de[a][b][(p, q)];
                    }
                }
            }
        }
    }
    // FD in v (the viscous force is linear in v, so differences are exact up to round-off).
    let h = 1e-3;
    let mut v = vec![Vec3::zeros(); n];
    let (mut fp, mut fm) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
    let scale = d.amax();
    let mut worst: f64 = 0.0;
    for j in 0..n {
        for c in 0..3 {
            v[j][c] = h;
            model.internal_forces(&x0, Some(&v), &mut fp);
            v[j][c] = -h;
            model.internal_forces(&x0, Some(&v), &mut fm);
            v[j][c] = 0.0;
            for i in 0..n {
                for r in 0..3 {
                    worst = worst.max(((fp[i][r] - fm[i][r]) / (2.0 * h) - d[(3 * i + r, 3 * j + c)]).abs() / scale);
                }
            }
        }
    }
    println!("max |D - FD| / max|D| = {worst:.2e}");
    assert!(worst <= 1e-9, "damping Jacobian differs from FD by {worst:e}");
    assert!((&d - d.transpose()).amax() <= 1e-13 * scale, "D not symmetric");
    let e = nalgebra::SymmetricEigen::new(d).eigenvalues;
    assert!(e.max() <= 1e-12 * scale, "D has a positive eigenvalue {:e}", e.max());
}
