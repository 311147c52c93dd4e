//! The indentation reference (`integrate::indent`, issue 33) against Hertz and against itself.
//!
//! A rigid frictionless sphere on a thick slab held at its base follows Hertz,
//! `F = 4/3 E/(1 - nu^2) sqrt(R) d^(3/2)`, while the contact radius `a = sqrt(R d)` is small
//! against the slab (here `a / thickness` <= 0.15) and large against the mesh (here at least
//! six elements across), and the strain `a / R` small (a St. Venant-Kirchhoff body stiffens or
//! softens at large strain, Hertz is linear).
//!
//! What a wrong implementation would do: a nodal contact on a coarse mesh is a point load (force
//! below Hertz and independent of R); a force summed with the wrong sign or a penalty that does
//! not drop out of the indentation shifts the curve; a halved stiffness halves it; a contact that
//! ignores the curvature of the sphere gives `F ~ d` (a flat punch) instead of `d^1.5`.

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::integrate::{indent, IndentOptions, Indenter};
use palpate_core::mesh::generate::box_mesh;
use palpate_core::{Model, ModelBuilder, TetMesh, Vec3};

const E: f64 = 3.0e4;
const NU: f64 = 0.4;

/// A slab `2 half x 2 half x depth` \[m\], top face at z = 0, base (z = -depth) held, its cells
/// graded toward the top centre (`x = half sinh(b s) / sinh(b)` per axis: a monotone map of
/// each axis keeps every cell a box, so the Kuhn tets stay valid).
fn graded_slab(half: f64, depth: f64, cells: [usize; 3], grade: f64) -> Model {
    let unit = box_mesh([2.0, 2.0, 1.0], cells);
    let map = |s: f64| if grade == 0.0 { s } else { (grade * s).sinh() / grade.sinh() };
    let pts: Vec<[f64; 3]> = unit
        .points()
        .iter()
        .map(|p| {
            let (sx, sy) = (p.x - 1.0, p.y - 1.0);
            // z: 0 at the top (s = 1), -depth at the base, graded toward the top.
            let sz = 1.0 - p.z;
            [half * map(sx), half * map(sy), -depth * map(sz)]
        })
        .collect();
    let tets: Vec<[i64; 4]> = unit.tets().iter().map(|t| t.map(|i| i as i64)).collect();
    let (mesh, _) = TetMesh::from_arrays(&pts, &tets).expect("graded slab is valid");
    let base = nodes_where(&mesh, 2, -depth, 1e-9 * depth);
    ModelBuilder::new(mesh, material(E, NU, 1000.0, 0.0, 0.0)).fixed_nodes(base).build().expect("slab model")
}

fn hertz(r: f64, d: f64) -> f64 {
    4.0 / 3.0 * E / (1.0 - NU * NU) * r.sqrt() * d.powf(1.5)
}

fn press(model: &Model, r: f64, travels: &[f64]) -> Vec<(f64, f64, f64)> {
    let ind = Indenter { start: Vec3::new(0.0, 0.0, r + 1e-3), direction: Vec3::new(0.0, 0.0, -1.0), radius: r };
    let pts = indent(model, &ind, travels, &IndentOptions::default()).expect("indentation converges");
    pts.iter()
        .map(|p| {
            // The force on the sphere is along +z (pushed back) and has no sideways part.
            assert!(p.force.z > 0.0, "force {:?}", p.force);
            assert!(p.force.xy().norm() <= 1e-2 * p.force.z, "sideways force {:?}", p.force);
            println!("travel {:.3} mm: {} iterations, {} factorisations", p.travel * 1e3, p.iterations, p.factorisations);
            (p.indentation, p.force.z, p.penetration)
        })
        .collect()
}

#[test]
fn a_sphere_on_a_thick_slab_follows_hertz() {
    let model = graded_slab(0.015, 0.015, [18, 18, 12], 3.8);
    let r = 0.005;
    let travels = [0.4e-3, 0.8e-3];
    let rows = press(&model, r, &travels);
    let mut prev = 0.0;
    for (d, f, pen) in &rows {
        let h = hertz(r, *d);
        println!(
            "R = {:.1} mm, indentation {:.4} mm (penetration {:.2} um): F = {:.5e} N, Hertz {:.5e} N, ratio {:.4}",
            r * 1e3,
            d * 1e3,
            pen * 1e6,
            f,
            h,
            f / h
        );
        assert!((f / h - 1.0).abs() < 0.12, "F / Hertz = {}", f / h);
        assert!(*pen < 0.02 * d, "the penalty penetrates {pen} at indentation {d}");
        assert!(*f > prev);
        prev = *f;
    }
    // The exponent of F(d): 1.5 (a flat punch would give 1).
    let p = (rows[1].1 / rows[0].1).ln() / (rows[1].0 / rows[0].0).ln();
    println!("exponent {p:.3}");
    assert!((p - 1.5).abs() < 0.1, "exponent {p}");
}

#[test]
fn bad_indenters_are_refused_with_a_reason() {
    let model = graded_slab(0.01, 0.01, [4, 4, 3], 0.0);
    let ok = Indenter { start: Vec3::new(0.0, 0.0, 0.01), direction: Vec3::new(0.0, 0.0, -1.0), radius: 0.005 };
    let opts = IndentOptions::default();
    let msg = |ind: Indenter, travels: &[f64]| match indent(&model, &ind, travels, &opts) {
        Err(palpate_core::SolveError::Invalid(m)) => m,
        other => panic!("expected Invalid, got {other:?}"),
    };
    assert!(msg(Indenter { radius: -1.0, ..ok }, &[1e-4]).contains("radius"));
    assert!(msg(Indenter { radius: f64::NAN, ..ok }, &[1e-4]).contains("radius"));
    assert!(msg(Indenter { direction: Vec3::new(0.0, 0.0, -2.0), ..ok }, &[1e-4]).contains("unit vector"));
    assert!(msg(Indenter { start: Vec3::new(f64::INFINITY, 0.0, 0.0), ..ok }, &[1e-4]).contains("finite"));
    assert!(msg(ok, &[2e-4, 1e-4]).contains("increasing"));
    assert!(msg(ok, &[f64::NAN]).contains("increasing"));
    // A path beside the body meets nothing.
    assert!(msg(Indenter { start: Vec3::new(0.5, 0.0, 0.01), ..ok }, &[1e-4]).contains("meets no boundary"));
    // No travel: nothing to do, no error.
    assert!(indent(&model, &ok, &[], &opts).expect("empty").is_empty());
}
