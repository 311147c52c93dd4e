//! The compressible Neo-Hookean law on meshes (the element-level checks are in `fem::tet4` and
//! `material::neo_hookean`): assembled derivatives, the patch test, exact and small-load static
//! solutions, and the uniaxial comparison with St. Venant-Kirchhoff printed in VALIDATION.md.
//!
//! What a wrong implementation would do:
//! * `nh_total_force_and_jacobian_match_finite_differences`: a dispatch that reaches only some
//!   code paths (e.g. `Model::strain_energy` or `internal_forces` still SVK while `tet4::forces`
//!   is NH) makes the force differ from the energy gradient by the SVK/NH difference (~10% at the
//!   deformed state here, ~O(1) at the compressed one); a tangent assembled from the SVK blocks
//!   differs from the FD Jacobian by as much; both are checked at a generic deformed state and
//!   at a strong compression (J ~ 0.4) where the laws differ the most.
//! * `nh_patch_test`: a non-uniform `F` or wrong assembly (interior residuals of the size of an
//!   element force), or an element stress not equal to the independently computed
//!   `P = mu F + (lambda ln J - mu) F^-T` (e.g. `F^-1` for `F^-T`, `J` missing) at a large strain.
//! * `nh_static_bar_matches_exact_solution`: with Poisson's ratio 0 the affine field
//!   `x = (s X, Y, Z)` is an exact equilibrium for both laws (lateral stress vanishes: for NH
//!   `P = mu (F - F^-T)`, for SVK `P = F S` with `S = E E_green`), with nominal stress
//!   `mu (s - 1/s)` (NH) or `E s (s^2 - 1)/2` (SVK). A static solve that used the SVK forces
//!   for an NH material (a dispatch that misses `tet4::forces`) misses the NH stretch by 1.5% in
//!   tension and 9% in compression;
//!   at a compression of 0.3 E, beyond SVK's limit point (-E / (3 sqrt 3) = -0.19 E), only NH has
//!   an equilibrium, and the solve must find it.
//! * `nh_static_box_agrees_with_svk_at_small_load`: a law with other Lame constants (or a factor
//!   error) disagrees with SVK by O(1) at any load; a correct one agrees to O(strain): the
//!   relative difference of the displacement fields is below |u|_max / L and grows ~10x per 10x load.
//! * `uniaxial_stress_table`: SVK's nominal stress must go back toward 0 as the stretch goes to 0
//!   while NH's keeps growing in magnitude; both must agree with linear elasticity near stretch 1.
//!
//! FD tolerances as in `derivatives.rs` (1e-6 of the largest entry; the bugs are >= 1e-2).

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::fem::tet4;
use palpate_core::integrate::{static_solve, StaticOptions};
use palpate_core::material::{Damping, Elasticity, Law};
use palpate_core::mesh::generate::box_mesh;
use palpate_core::{Mat3, Material, Model, ModelBuilder, TetMesh, Vec3};

const E: f64 = 3.0e4;

fn nh(young: f64, poisson: f64) -> Material {
    material(young, poisson, 1000.0, 0.0, 0.0).with_law(Law::NeoHookean)
}

/// Neo-Hookean first Piola stress, computed independently of the crate's kernels (no cofactor,
/// no Taylor extension: valid for J >= J_MIN).
fn nh_piola(f: &Mat3, lambda: f64, mu: f64) -> Mat3 {
    let j = f.determinant();
    let f_inv_t = f.try_inverse().unwrap().transpose();
    mu * f + (lambda * j.ln() - mu) * f_inv_t
}

#[test]
fn nh_total_force_and_jacobian_match_finite_differences() {
    let size = [0.02, 0.015, 0.012];
    let cells = [3, 2, 2];
    let mesh = perturbed_box(size, cells, 0.2, 3);
    let model = ModelBuilder::new(mesh, nh(E, 0.4)).build().unwrap();
    let mut rng = Rng::new(9);
    let hcell = size[0] / cells[0] as f64;
    let generic = rotation(Vec3::new(1.0, -0.5, 0.2), 0.4) * (Mat3::identity() + rng.mat3(0.1));
    let squeeze = Mat3::from_diagonal(&Vec3::new(0.5, 0.9, 0.9)); // J ~ 0.4
    for (what, a) in [("deformed", generic), ("compressed (J ~ 0.4)", squeeze)] {
        let x: Vec<Vec3> = model.mesh().points().iter().map(|p| a * p + rng.vec3(0.05 * hcell)).collect();
        let j_min = model
            .mesh()
            .tets()
            .iter()
            .zip(model.rest())
            .map(|(t, r)| tet4::deformation_gradient(&t.map(|i| x[i]), r).determinant())
            .fold(f64::INFINITY, f64::min);
        assert!(j_min > 0.2, "{what}: set-up inverted or over-compressed an element (J = {j_min})");
        // Total force = -grad(total energy).
        let worst = energy_gradient_error(&model, &x);
        println!("{what}: max |f + dW/dx| / max|f| = {worst:.2e}");
        assert!(worst <= 1e-6, "{what}: force is not minus the energy gradient ({worst:e})");
        // Assembled tangent = FD of the assembled force.
        let k = dense_jacobian(&model, &x);
        let fd = fd_jacobian(&model, &x, 1e-7);
        let err = (&k - &fd).amax() / k.amax();
        println!("{what}: max |K - FD| / max|K| = {err:.2e}");
        assert!(err <= 1e-6, "{what}: assembled NH tangent differs from FD by {err:e}");
    }
}

#[test]
fn nh_patch_test() {
    let size = [0.03, 0.02, 0.025];
    let mat = nh(E, 0.4);
    let mut rng = Rng::new(42);
    let small = Mat3::identity() + rng.mat3(1e-3);
    let large = rotation(Vec3::new(0.3, -1.0, 0.5), 0.7) * (Mat3::identity() + rng.mat3(0.2));
    let squeeze = Mat3::new(0.45, 0.05, 0.0, 0.0, 0.8, 0.1, 0.02, 0.0, 0.85); // J ~ 0.3
    for (mname, mesh) in [("regular 3x3x3", box_mesh(size, [3, 3, 3])), ("irregular 4x3x5 (20%)", perturbed_box(size, [4, 3, 5], 0.2, 11))] {
        let model = ModelBuilder::new(mesh.clone(), mat).build().unwrap();
        let area = boundary_area_vectors(&mesh);
        for (aname, a) in [("small strain", small), ("large strain + rotation", large), ("compression J ~ 0.3", squeeze)] {
            assert!(a.determinant() > 0.2, "set-up");
            let b = rng.vec3(0.01);
            let x: Vec<Vec3> = mesh.points().iter().map(|p| a * p + b).collect();
            let p_exact = nh_piola(&a, mat.lambda(), mat.mu());
            let mut elem_scale: f64 = 0.0;
            for (t, r) in mesh.tets().iter().zip(model.rest()) {
                let fe = tet4::forces(&t.map(|i| x[i]), None, r, &mat);
                let p = piola_from_forces(&fe, &t.map(|i| mesh.points()[i]), r.volume);
                let rel = (p - p_exact).norm() / p_exact.norm();
                assert!(rel <= 1e-9, "{mname}, {aname}: element stress differs from NH P by {rel:e}");
                elem_scale = elem_scale.max(fe.iter().map(|v| v.norm()).fold(0.0, f64::max));
            }
            let f = forces(&model, &x);
            let (mut worst_int, mut worst_bnd): (f64, f64) = (0.0, 0.0);
            for i in 0..mesh.n_nodes() {
                let err = (f[i] + p_exact * area[i]).norm() / elem_scale;
                if area[i] == Vec3::zeros() {
                    worst_int = worst_int.max(err);
                } else {
                    worst_bnd = worst_bnd.max(err);
                }
            }
            println!("{mname}, {aname}: interior {worst_int:.2e}, boundary {worst_bnd:.2e}");
            assert!(worst_int <= 1e-10 && worst_bnd <= 1e-10, "{mname}, {aname}: interior {worst_int:e}, boundary {worst_bnd:e}");
        }
    }
}

/// Length (along X) and width of the block of `nh_static_bar_matches_exact_solution` \[m\]: a
/// squat slab, so that the compressed equilibrium is stable (a slender bar would buckle).
const BAR_L: f64 = 0.01;
const BAR_W: f64 = 0.02;

/// A 1 x 2 x 2 cm slab, 2 x 4 x 4 cells, clamped at X = 0 (nu = 0: the affine field is exact).
fn bar(law: Law) -> (Model, TetMesh) {
    let mesh = box_mesh([BAR_L, BAR_W, BAR_W], [2, 4, 4]);
    let fixed = nodes_where(&mesh, 0, 0.0, 1e-12);
    let m = Material::new(Elasticity::YoungPoisson { young: E, poisson: 0.0 }, 1000.0, Damping::NONE).unwrap().with_law(law);
    (ModelBuilder::new(mesh.clone(), m).fixed_nodes(fixed).build().unwrap(), mesh)
}

/// Root of `g(s) = p` on `[lo, hi]` by bisection (g increasing there).
fn bisect(g: impl Fn(f64) -> f64, p: f64, mut lo: f64, mut hi: f64) -> f64 {
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(mid) < p {
            lo = mid
        } else {
            hi = mid
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn nh_static_bar_matches_exact_solution() {
    let mu = E / 2.0; // nu = 0
    let nh_stress = |s: f64| mu * (s - 1.0 / s);
    let svk_stress = |s: f64| E * s * (s * s - 1.0) / 2.0;
    let opts = StaticOptions { tolerance: 1e-9, ..StaticOptions::default() };
    for (p_rel, svk_too) in [(0.1, true), (-0.15, true), (-0.3, false)] {
        let p = p_rel * E;
        for law in [Law::NeoHookean, Law::StVenantKirchhoff] {
            if law == Law::StVenantKirchhoff && !svk_too {
                continue; // beyond SVK's limit point: no equilibrium on the stable branch
            }
            let (model, mesh) = bar(law);
            let s = match law {
                Law::NeoHookean => bisect(nh_stress, p, 0.05, 3.0),
                Law::StVenantKirchhoff => bisect(svk_stress, p, 1.0 / 3f64.sqrt(), 3.0),
            };
            let f = face_loads(&mesh, |q| (q.x - BAR_L).abs() < 1e-12, Vec3::new(p * BAR_W * BAR_W, 0.0, 0.0));
            let sol = static_solve(&model, &f, &opts).unwrap_or_else(|e| panic!("{law}, p = {p_rel} E: {e}"));
            let mut worst: f64 = 0.0;
            for (xi, xr) in sol.x.iter().zip(mesh.points()) {
                let expect = Vec3::new(s * xr.x, xr.y, xr.z);
                worst = worst.max((xi - expect).norm());
            }
            let u_tip = (s - 1.0).abs() * BAR_L;
            println!(
                "{law}, nominal stress {p_rel} E: exact stretch {s:.6}, max |x - exact| / |u_tip| = {:.2e} ({} Newton iterations)",
                worst / u_tip,
                sol.iterations
            );
            assert!(worst <= 1e-6 * u_tip, "{law}, p = {p_rel} E: off the exact affine solution by {:e} of the tip displacement", worst / u_tip);
        }
    }
    // The laws differ: the NH and SVK stretches at -0.15 E are 9% apart (a solve using the wrong
    // law fails the 1e-6 comparison above by far).
    let (s_nh, s_svk) = (bisect(nh_stress, -0.15 * E, 0.05, 3.0), bisect(svk_stress, -0.15 * E, 1.0 / 3f64.sqrt(), 3.0));
    assert!((s_nh - s_svk).abs() > 0.05, "{s_nh} vs {s_svk}");
}

#[test]
fn nh_static_box_agrees_with_svk_at_small_load() {
    // A 4 x 1 x 1 cm cantilever, clamped at X = 0, with a transverse tip load.
    let mesh = perturbed_box([0.04, 0.01, 0.01], [8, 2, 2], 0.15, 5);
    let fixed = nodes_where(&mesh, 0, 0.0, 1e-12);
    let svk = ModelBuilder::new(mesh.clone(), material(E, 0.4, 1000.0, 0.0, 0.0)).fixed_nodes(fixed.clone()).build().unwrap();
    let neo = ModelBuilder::new(mesh.clone(), nh(E, 0.4)).fixed_nodes(fixed).build().unwrap();
    let opts = StaticOptions { tolerance: 1e-8, ..StaticOptions::default() };
    let mut rel_prev = 0.0;
    for total in [1e-5, 1e-4, 1e-3] {
        let f = face_loads(&mesh, |q| (q.x - 0.04).abs() < 1e-12, Vec3::new(0.0, 0.0, -total));
        let us: Vec<Vec3> = static_solve(&svk, &f, &opts).unwrap().x.iter().zip(mesh.points()).map(|(x, p)| x - p).collect();
        let sol = static_solve(&neo, &f, &opts).unwrap();
        let un: Vec<Vec3> = sol.x.iter().zip(mesh.points()).map(|(x, p)| x - p).collect();
        let norm = |v: &[Vec3]| v.iter().map(|u| u.norm_squared()).sum::<f64>().sqrt();
        let diff: Vec<Vec3> = un.iter().zip(&us).map(|(a, b)| a - b).collect();
        let rel = norm(&diff) / norm(&us);
        let tip = max_norm(&us);
        println!("tip load {total:e} N: max |u| {tip:.3e} m (|u|/L = {:.1e}), NH vs SVK rel. L2 {rel:.2e}, {} Newton iterations", tip / 0.04, sol.iterations);
        // O(strain): measured ~0.2 |u|/L; a law with other Lame constants would differ by O(1).
        assert!(rel <= tip / 0.04, "load {total}: NH and SVK differ by {rel:e}, more than O(strain)");
        if rel_prev > 0.0 {
            // Ten times the load, about ten times the (first-order-in-strain) relative difference.
            assert!(rel / rel_prev > 5.0 && rel / rel_prev < 20.0, "difference ratio {}", rel / rel_prev);
        }
        rel_prev = rel;
    }
}

/// Homogeneous uniaxial stress (lateral faces traction-free) of a single tetrahedron, E = 30 kPa,
/// nu = 0.4: for each axial stretch, the lateral stretch `t` is the root of `P_yy = 0`, both read
/// from `tet4::forces` (the element's nodal forces give `P`). Prints the VALIDATION.md table:
/// `cargo test --release -p palpate-core --test neo_hookean uniaxial_stress_table -- --nocapture`.
#[test]
fn uniaxial_stress_table() {
    let u = [Vec3::zeros(), Vec3::new(0.01, 0.0, 0.0), Vec3::new(0.0, 0.01, 0.0), Vec3::new(0.0, 0.0, 0.01)];
    let rest = palpate_core::fem::TetRest::new(&u);
    let piola = |m: &Material, f: &Mat3| piola_from_forces(&tet4::forces(&u.map(|p| f * p), None, &rest, m), &u, rest.volume);
    let svk = material(E, 0.4, 1000.0, 0.0, 0.0);
    let neo = svk.with_law(Law::NeoHookean);
    // P_yy(t) at axial stretch s; lateral stretch from bisection on [0.3, 3] (P_yy increasing in t).
    let uniaxial = |m: &Material, s: f64| {
        let pyy = |t: f64| piola(m, &Mat3::from_diagonal(&Vec3::new(s, t, t)))[(1, 1)];
        let t = bisect(pyy, 0.0, 0.3, 3.0);
        let p = piola(m, &Mat3::from_diagonal(&Vec3::new(s, t, t)));
        assert!(p[(1, 1)].abs() <= 1e-8 * p[(0, 0)].abs().max(1.0) && p[(2, 2)].abs() <= 1e-8 * p[(0, 0)].abs().max(1.0), "lateral stress not zero");
        (p[(0, 0)], t)
    };
    println!("| stretch | linear E(s-1) [kPa] | SVK P_xx [kPa] | SVK lateral stretch | SVK J | NH P_xx [kPa] | NH lateral stretch | NH J |");
    println!("|---|---|---|---|---|---|---|---|");
    let mut rows = vec![];
    for s in [0.1, 0.3, 0.5, 0.7, 0.9, 0.99, 1.01, 1.1, 1.5] {
        let (ps, ts) = uniaxial(&svk, s);
        let (pn, tn) = uniaxial(&neo, s);
        println!("| {s} | {:.3} | {:.3} | {ts:.4} | {:.3} | {:.3} | {tn:.4} | {:.3} |", E * (s - 1.0) / 1e3, ps / 1e3, s * ts * ts, pn / 1e3, s * tn * tn);
        rows.push((s, ps, pn));
    }
    // SVK's exact uniaxial-stress curve: P = E s (s^2 - 1) / 2 (lateral Green strain -nu E_xx).
    for &(s, ps, _) in &rows {
        assert!((ps - E * s * (s * s - 1.0) / 2.0).abs() <= 1e-6 * E, "SVK at s = {s}");
    }
    // Near s = 1 both agree with linear elasticity to O(strain).
    for &(s, ps, pn) in rows.iter().filter(|r| (r.0 - 1.0f64).abs() < 0.02) {
        let lin = E * (s - 1.0);
        assert!((ps - lin).abs() <= 0.03 * lin.abs() && (pn - lin).abs() <= 0.03 * lin.abs(), "s = {s}: {ps} {pn} vs {lin}");
    }
    // SVK softens toward zero stress under strong compression; NH keeps stiffening.
    let at = |s: f64| rows.iter().find(|r| r.0 == s).copied().unwrap();
    assert!(at(0.1).1.abs() < at(0.3).1.abs() && at(0.3).1.abs() < at(0.5).1.abs(), "SVK should soften below s = 1/sqrt(3)");
    assert!(at(0.1).2 < at(0.3).2 && at(0.3).2 < at(0.5).2 && at(0.5).2 < at(0.7).2, "NH compressive stress should grow monotonically");
}
