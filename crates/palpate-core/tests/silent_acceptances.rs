//! Issue 35 item 6, "no silent acceptance": inputs the core took without a word, each now refused
//! where it enters the core, with the element and the reason (the Python corpus has the same cases
//! through the binding and the readers: python/tests/corpus_cases.py `_silent_cases`).

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::hybrid::file::{from_bytes, to_bytes};
use palpate_core::hybrid::{build, shapes, HybridOptions, Spacing};
use palpate_core::integrate::{static_solve, StaticOptions};
use palpate_core::mesh::generate::{box_mesh, TruncatedEllipsoidWall};
use palpate_core::probe::{ProbeLoad, Ramp};
use palpate_core::{LoadError, MeshError, ModelBuilder, SolveError, TetMesh, Vec3};

fn bar() -> (palpate_core::Model, Vec<usize>) {
    let mesh = box_mesh([0.01, 0.01, 0.04], [2, 2, 8]);
    let fixed = nodes_where(&mesh, 2, 0.0, 1e-9);
    let top = nodes_where(&mesh, 2, 0.04, 1e-9);
    (ModelBuilder::new(mesh, material(3e4, 0.4, 1000.0, 0.0, 0.0)).fixed_nodes(fixed).build().unwrap(), top)
}

/// A mesh written twice into one file (every node copied, every tet repeated on the copies) was
/// a valid mesh of twice the volume and mass.
#[test]
fn a_tet_repeated_on_copied_nodes_is_a_duplicate() {
    let mesh = box_mesh([0.01, 0.01, 0.01], [1, 1, 1]);
    let p: Vec<[f64; 3]> = mesh.points().iter().map(|v| [v.x, v.y, v.z]).collect();
    let t: Vec<[i64; 4]> = mesh.tets().iter().map(|t| t.map(|i| i as i64)).collect();
    let n = p.len() as i64;
    let twice_p: Vec<[f64; 3]> = p.iter().chain(p.iter()).copied().collect();
    let twice_t: Vec<[i64; 4]> = t.iter().copied().chain(t.iter().map(|t| t.map(|i| i + n))).collect();
    let e = TetMesh::from_arrays(&twice_p, &twice_t).unwrap_err();
    assert!(matches!(e, MeshError::CoincidentTet { tet, other: 0, .. } if tet == t.len()), "{e}");
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("tet {}: duplicate of tet 0", t.len())) && msg.contains("count twice"), "{msg}");
    // The mesh once is fine.
    assert!(TetMesh::from_arrays(&p, &t).is_ok());
}

#[test]
fn static_solve_refuses_zero_load_steps() {
    let (model, top) = bar();
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    f[top[0]] = Vec3::new(0.0, 0.0, -0.01);
    let opts = StaticOptions { load_steps: 0, ..Default::default() };
    let e = static_solve(&model, &f, &opts).unwrap_err();
    assert!(matches!(&e, SolveError::Invalid(m) if m.contains("load_steps = 0")), "{e}");
    assert!(static_solve(&model, &f, &StaticOptions { load_steps: 1, ..Default::default() }).is_ok());
}

#[test]
fn a_force_over_the_bound_is_refused_where_it_enters() {
    let (model, top) = bar();
    let ramp = Ramp { start: 0.0, duration: 0.0 };
    let e = ProbeLoad::new(model.n_nodes(), top.clone(), Vec3::new(0.0, 0.0, -1e300), ramp).unwrap_err();
    assert!(matches!(e, LoadError::ForceTooLarge { .. }), "{e}");
    assert!(ProbeLoad::new(model.n_nodes(), top.clone(), Vec3::new(0.0, 0.0, -1e6), ramp).is_ok(), "the bound itself is allowed");
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    f[top[0]] = Vec3::new(0.0, 1e300, 0.0);
    let e = static_solve(&model, &f, &StaticOptions::default()).unwrap_err();
    assert!(matches!(&e, SolveError::Invalid(m) if m.contains(&format!("node {}", top[0]))), "{e}");
}

/// A crafted model file (the checksum made right again) whose particle lattice spacing or voxel
/// grid spacing is negative, zero or NaN: the lattice spacing loaded (a negative shell volume,
/// a failure only at the first tick), the voxel spacing was refused as "voxel grid inconsistent".
#[test]
fn a_model_file_with_a_bad_spacing_is_refused_naming_it() {
    let p = TruncatedEllipsoidWall { circumferential: 8, longitudinal: 3, ..Default::default() };
    let wall = shapes::truncated_ventricle(&p).expect("the coarse ventricle wall");
    let o = HybridOptions { spacing: Spacing::Count(100), field_voxels: 1000, ..Default::default() };
    let good = build(&wall, &o).expect("the small model builds");
    assert!(from_bytes(&to_bytes(&good), "good.palpate").is_ok());
    for bad in [-good.spacing, 0.0, f64::NAN] {
        let mut m = good.clone();
        m.spacing = bad;
        let e = from_bytes(&to_bytes(&m), "bad.palpate").unwrap_err().to_string();
        assert!(e.contains("bad.palpate") && e.contains("particle lattice spacing"), "{e}");
    }
    for bad in [-good.grid.h, 0.0, f64::NAN] {
        let mut m = good.clone();
        m.grid.h = bad;
        let e = from_bytes(&to_bytes(&m), "bad.palpate").unwrap_err().to_string();
        assert!(e.contains("bad.palpate") && e.contains("voxel grid spacing"), "{e}");
    }
}
