//! The body of quadratic (10-node) tets (`fem/tet10.rs`, `ModelBuilder::order`): the same
//! checks as the linear tet's, and what it is for, bending without locking.
//!
//! What a wrong implementation would do: a wrong quadrature weight scales the stiffness (the
//! cantilever off by that factor); a wrong edge-node numbering breaks the patch test and the
//! energy gradient; a negative or row-sum lumped mass breaks the momentum or the energy test; a
//! contact sampled only at the vertices makes the sphere a point load on a coarse mesh.
//!
//! `cargo test --release -p palpate-core --test quadratic -- --nocapture` prints the figures
//! (recorded in VALIDATION.md).

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::integrate::{indent, static_solve, IndentOptions, Indenter, StaticOptions};
use palpate_core::mesh::generate::box_mesh;
use palpate_core::{step, Integrator, Law, Model, ModelBuilder, Order, State, TetMesh, Vec3, Workspace};

/// Consistent nodal loads of a uniform traction (total `total`) over the boundary faces with
/// `on_face` true at their three vertices, on a quadratic body: a straight 6-node triangle's
/// vertices carry nothing of a uniform load and its edge nodes a third each.
fn quadratic_face_loads(model: &Model, on_face: impl Fn(&Vec3) -> bool, total: Vec3) -> Vec<Vec3> {
    let x = model.rest_positions();
    let nv = model.mesh().n_nodes();
    let edge_of = |a: usize, b: usize| nv + model.edges().iter().position(|e| *e == [a.min(b), a.max(b)]).expect("a face's edge is an edge");
    let faces: Vec<[usize; 3]> = model.mesh().boundary_faces().into_iter().filter(|f| f.iter().all(|&i| on_face(&x[i]))).collect();
    let area = |f: &[usize; 3]| 0.5 * (x[f[1]] - x[f[0]]).cross(&(x[f[2]] - x[f[0]])).norm();
    let total_area: f64 = faces.iter().map(area).sum();
    let mut out = vec![Vec3::zeros(); model.n_nodes()];
    for f in &faces {
        let share = total * (area(f) / total_area / 3.0);
        for (a, b) in [(0, 1), (1, 2), (0, 2)] {
            out[edge_of(f[a], f[b])] += share;
        }
    }
    out
}

/// A cantilever of quadratic tets one or two elements across bends like the beam (linear tets
/// of the same mesh are 5x too stiff: tests/cantilever.rs), and refines toward it.
#[test]
fn a_coarse_quadratic_cantilever_bends_like_a_beam() {
    let (l, h, e, nu): (f64, f64, f64, f64) = (0.1, 0.01, 1.0e5, 0.3);
    let i_sec = h.powi(4) / 12.0;
    let p = 1e-4 * l * 3.0 * e * i_sec / l.powi(3);
    let delta_eb = p * l.powi(3) / (3.0 * e * i_sec);
    let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
    let delta_t = delta_eb + p * l / (kappa * e / (2.0 * (1.0 + nu)) * h * h);
    let mut ratios = Vec::new();
    for cells in [[4, 1, 1], [8, 1, 1], [16, 2, 2]] {
        let mesh = box_mesh([l, h, h], cells);
        let fixed = nodes_where(&mesh, 0, 0.0, 1e-12);
        let model = ModelBuilder::new(mesh, material(e, nu, 1000.0, 0.0, 0.0)).order(Order::Quadratic).fixed_nodes(fixed).build().unwrap();
        let f = quadratic_face_loads(&model, |q| (q.x - l).abs() < 1e-12, Vec3::new(0.0, 0.0, -p));
        let sol = static_solve(&model, &f, &StaticOptions { tolerance: 1e-6, ..StaticOptions::default() }).unwrap();
        let (mut num, mut den) = (0.0, 0.0);
        for ((fi, x), x0) in f.iter().zip(&sol.x).zip(model.rest_positions()) {
            num += fi.z.abs() * -(x.z - x0.z);
            den += fi.z.abs();
        }
        let ratio = num / den / delta_t;
        println!("quadratic cantilever {cells:?}: {} tets, {} nodes, tip deflection / Timoshenko {ratio:.4}", model.n_tets(), model.n_nodes());
        ratios.push(ratio);
    }
    // Four elements long and one across: within 10% (linear tets 8x1x1: 0.19).
    assert!((ratios[0] - 1.0).abs() < 0.10, "{ratios:?}");
    assert!((ratios[1] - 1.0).abs() < 0.05, "{ratios:?}");
    assert!((ratios[2] - 1.0).abs() < 0.02, "{ratios:?}");
}

/// An affine motion gives every quadrature point the same F: no force inside, and on the
/// boundary the traction of that stress, integrated with the quadratic faces' weights (edge
/// nodes a third of each face's traction, vertices none).
#[test]
fn patch_test_and_energy_gradient() {
    let mesh = perturbed_box([0.02, 0.015, 0.01], [3, 2, 2], 0.2, 7);
    for law in [Law::StVenantKirchhoff, Law::NeoHookean] {
        let model = ModelBuilder::new(mesh.clone(), material(3.0e4, 0.4, 1000.0, 0.0, 0.0).with_law(law))
            .order(Order::Quadratic)
            .build()
            .unwrap();
        let a = palpate_core::Mat3::new(1.08, 0.05, -0.03, 0.02, 0.95, 0.06, -0.04, 0.03, 1.1);
        let x: Vec<Vec3> = model.rest_positions().iter().map(|p| a * p + Vec3::new(0.01, -0.02, 0.005)).collect();
        let f = forces(&model, &x);
        // The first Piola stress of F = A, from one element's energy gradient would be circular:
        // take the law's own, through a one-tet linear body (tested against the analytic stress
        // in tests/patch.rs).
        let one = TetMesh::from_arrays(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], &[[0, 1, 2, 3]]).unwrap().0;
        let lin = ModelBuilder::new(one, *model.material()).build().unwrap();
        let xl: Vec<Vec3> = lin.rest_positions().iter().map(|p| a * p).collect();
        let fl = forces(&lin, &xl);
        // f_i = -V P grad N_i on the unit tet: grad N_1..3 = e_1..3, V = 1/6.
        let piola = palpate_core::Mat3::from_columns(&[fl[1], fl[2], fl[3]]) * -6.0;
        let x0 = model.rest_positions();
        let nv = model.mesh().n_nodes();
        let mut expect = vec![Vec3::zeros(); model.n_nodes()];
        for fc in model.mesh().boundary_faces() {
            // Outward area vector of the rest face (boundary faces are outward-oriented).
            let n_area = 0.5 * (x0[fc[1]] - x0[fc[0]]).cross(&(x0[fc[2]] - x0[fc[0]]));
            let t = -(piola * n_area) / 3.0;
            for (i, j) in [(0, 1), (1, 2), (0, 2)] {
                let k = model.edges().iter().position(|e| *e == [fc[i].min(fc[j]), fc[i].max(fc[j])]).unwrap();
                expect[nv + k] += t;
            }
        }
        let scale = max_norm(&f);
        let err = f.iter().zip(&expect).map(|(g, e)| (g - e).norm()).fold(0.0, f64::max) / scale;
        println!("{law:?}: affine patch, max |f - traction| / max |f| = {err:.2e}");
        assert!(err < 1e-10, "{law:?}: {err:e}");
        // Forces are minus the energy's gradient at a general (non-affine) state.
        let mut rng = Rng::new(3);
        let xr: Vec<Vec3> = x.iter().map(|p| p + rng.vec3(3e-4)).collect();
        let g = energy_gradient_error(&model, &xr);
        println!("{law:?}: |f + dW/dx| / max |f| = {g:.2e}");
        assert!(g < 1e-6, "{law:?}: {g:e}");
    }
}

/// The default integrator on a free, damped quadratic body: linear momentum exact, the energy
/// never rising, and the HRZ masses positive and summing to the body's mass.
#[test]
fn free_body_keeps_its_momentum_and_loses_energy() {
    let mesh = perturbed_box([0.02, 0.015, 0.01], [3, 2, 2], 0.2, 11);
    let model = ModelBuilder::new(mesh.clone(), material(3.0e4, 0.4, 1000.0, 0.5, 0.5)).order(Order::Quadratic).build().unwrap();
    let volume: f64 = mesh
        .tets()
        .iter()
        .map(|t| palpate_core::mesh::signed_volume(&mesh.points()[t[0]], &mesh.points()[t[1]], &mesh.points()[t[2]], &mesh.points()[t[3]]))
        .sum();
    let total: f64 = model.masses().iter().sum();
    assert!(model.masses().iter().all(|&m| m > 0.0));
    assert!((total - 1000.0 * volume).abs() < 1e-12 * total);
    let mut s = State::rest(&model);
    let mut rng = Rng::new(5);
    for (x, v) in s.x.iter_mut().zip(s.v.iter_mut()) {
        *x += rng.vec3(5e-4);
        *v = rng.vec3(0.05) + Vec3::new(0.1, -0.2, 0.05);
    }
    let mut ws = Workspace::new(&model);
    let p0 = model.momentum(&s.v);
    let energy = |s: &State| model.kinetic_energy(&s.v) + model.strain_energy(&s.x);
    let mut e_prev = energy(&s);
    for k in 0..100 {
        step(&model, &mut s, &mut ws, 1e-3).unwrap();
        let dp = (model.momentum(&s.v) - p0).norm() / p0.norm();
        assert!(dp < 1e-12, "step {k}: momentum error {dp:e}");
        let e = energy(&s);
        assert!(e <= e_prev * (1.0 + 1e-12), "step {k}: energy rose {e_prev} -> {e}");
        e_prev = e;
    }
    // The paper's semi-implicit filter is refused on quadratic tets (a clear error, not a blow-up).
    let err = ModelBuilder::new(mesh, material(3.0e4, 0.4, 1000.0, 0.0, 0.0))
        .order(Order::Quadratic)
        .integrator(Integrator::semi_implicit())
        .build()
        .unwrap_err();
    assert!(err.to_string().contains("semi-implicit"), "{err}");
}

/// Hertz on a slab: quadratic tets at half the resolution (about the same number of nodes as
/// tests/indentation.rs's linear slab) are at least as close, the contact sampled on the curved
/// faces' six nodes.
#[test]
fn a_sphere_on_a_coarse_quadratic_slab_follows_hertz() {
    let (e, nu, r): (f64, f64, f64) = (3.0e4, 0.4, 0.005);
    let (half, depth, grade): (f64, f64, f64) = (0.015, 0.015, 3.8);
    let unit = box_mesh([2.0, 2.0, 1.0], [9, 9, 6]);
    let map = |s: f64| (grade * s).sinh() / grade.sinh();
    let pts: Vec<[f64; 3]> = unit.points().iter().map(|p| [half * map(p.x - 1.0), half * map(p.y - 1.0), -depth * map(1.0 - p.z)]).collect();
    let tets: Vec<[i64; 4]> = unit.tets().iter().map(|t| t.map(|i| i as i64)).collect();
    let (mesh, _) = TetMesh::from_arrays(&pts, &tets).unwrap();
    let base = nodes_where(&mesh, 2, -depth, 1e-9 * depth);
    let model = ModelBuilder::new(mesh, material(e, nu, 1000.0, 0.0, 0.0)).order(Order::Quadratic).fixed_nodes(base).build().unwrap();
    let ind = Indenter { start: Vec3::new(0.0, 0.0, r + 1e-3), direction: Vec3::new(0.0, 0.0, -1.0), radius: r };
    let pts = indent(&model, &ind, &[0.4e-3, 0.8e-3], &IndentOptions::default()).expect("indentation converges");
    let mut rows = Vec::new();
    for p in &pts {
        let hertz = 4.0 / 3.0 * e / (1.0 - nu * nu) * r.sqrt() * p.indentation.powf(1.5);
        let ratio = p.force.z / hertz;
        println!(
            "quadratic slab ({} tets, {} nodes): indentation {:.4} mm, F = {:.5e} N, Hertz {:.5e} N, ratio {ratio:.4}",
            model.n_tets(),
            model.n_nodes(),
            p.indentation * 1e3,
            p.force.z,
            hertz
        );
        assert!(p.force.xy().norm() <= 1e-2 * p.force.z);
        assert!((ratio - 1.0).abs() < 0.08, "F / Hertz = {ratio}");
        rows.push((p.indentation, p.force.z));
    }
    let exponent = (rows[1].1 / rows[0].1).ln() / (rows[1].0 / rows[0].0).ln();
    println!("exponent {exponent:.3}");
    assert!((exponent - 1.5).abs() < 0.1, "exponent {exponent}");
}
