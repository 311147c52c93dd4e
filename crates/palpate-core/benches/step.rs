//! Criterion benchmarks of one 1 ms step under the protocol's probe load (shared/bench/PROTOCOL.md),
//! single thread, on the paper's ~188-tet ellipsoid wall and the four shared meshes.
//!
//! `cargo bench -p palpate-core --bench step` (the shared meshes are found beside the repository
//! or through `PALPATE_SHARED`; missing ones are skipped).
#[path = "../tests/support/protocol.rs"]
mod protocol;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use palpate_core::mesh::generate::{ellipsoid_wall, EllipsoidWall};
use palpate_core::probe::apply_loads;
use palpate_core::{step, Integrator, Model, ModelBuilder, State, Workspace};

fn ellipsoid_case() -> protocol::Case {
    // The paper's Ellipsoids Model (192 tets), in mesh units so that the protocol's load applies:
    // semi-axes 2.0/2.0/3.5 and 2.6/2.6/4.2 (x 1 cm); the base (z <= 0) half is held fixed.
    let mesh = ellipsoid_wall(&EllipsoidWall { inner: [2.0, 2.0, 3.5], outer: [2.6, 2.6, 4.2], ..EllipsoidWall::default() });
    let pts: Vec<[f64; 3]> = mesh.points().iter().map(|p| [p.x, p.y, p.z]).collect();
    let tets: Vec<[i64; 4]> = mesh.tets().iter().map(|t| t.map(|i| i as i64)).collect();
    protocol::case_from_mesh_units(&pts, &tets)
}

/// The protocol case compiled for `integ`, at rest.
fn body(case: &protocol::Case, integ: Integrator) -> (Model, State, Workspace) {
    let model = ModelBuilder::new(case.mesh.clone(), protocol::material())
        .fixed_nodes(case.fixed.clone())
        .integrator(integ)
        .build()
        .expect("model");
    let (state, ws) = (State::rest(&model), Workspace::new(&model));
    (model, state, ws)
}

fn bench_steps(c: &mut Criterion) {
    let mut cases = vec![("ellipsoid_192".to_string(), ellipsoid_case())];
    for name in ["190", "1350", "10k", "50k"] {
        if let Some(case) = protocol::load_case(name) {
            cases.push((format!("lv_{name}"), case));
        }
    }
    let mut group = c.benchmark_group("step_1ms");
    group.sample_size(20);
    for (name, case) in &cases {
        let mut integrators = vec![("quasi_newton", Integrator::quasi_newton()), ("backward_euler_linear", Integrator::BackwardEulerLinear)];
        // The semi-implicit scheme is unstable at 1 ms on the 48k-tet mesh (BENCHMARKS.md).
        if case.mesh.n_tets() < 20_000 {
            integrators.push(("semi_implicit", Integrator::semi_implicit()));
        }
        if case.mesh.n_tets() < 2000 {
            integrators.push(("backward_euler_newton", Integrator::newton()));
        }
        for (iname, integ) in integrators {
            let (model, mut state, mut ws) = body(case, integ);
            for &i in &case.loaded {
                state.f_ext[i] = case.f_node;
            }
            // Warm up into the loaded regime (and make the first-step factorisation).
            for _ in 0..50 {
                step(&model, &mut state, &mut ws, protocol::DT).expect("stable");
            }
            group.bench_with_input(BenchmarkId::new(iname, name), &(), |b, _| b.iter(|| step(&model, &mut state, &mut ws, protocol::DT).expect("stable")));
        }
    }
    group.finish();

    // A firm press: 2 N on the same nodes, held (after the 0.1 s ramp and 0.4 s of hold), where
    // the rest-linearised step blows up; the default integrator's steady cost there.
    let mut group = c.benchmark_group("step_1ms_2N_hold");
    group.sample_size(20);
    for (name, case) in cases.iter().filter(|(n, _)| n == "lv_190" || n == "lv_1350") {
        for (iname, integ) in [("quasi_newton", Integrator::quasi_newton()), ("backward_euler_newton", Integrator::newton())] {
            let (model, mut state, mut ws) = body(case, integ);
            let load = [protocol::probe_load(case, 2.0, 0.0)];
            for _ in 0..500 {
                apply_loads(&load, &mut state.f_ext, state.t + protocol::DT);
                step(&model, &mut state, &mut ws, protocol::DT).expect("stable");
            }
            group.bench_with_input(BenchmarkId::new(iname, name), &(), |b, _| b.iter(|| step(&model, &mut state, &mut ws, protocol::DT).expect("stable")));
        }
    }
    group.finish();
}

criterion_group!(benches, bench_steps);
criterion_main!(benches);
