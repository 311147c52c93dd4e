//! The benchmark protocol (`shared/bench/PROTOCOL.md`) on the shared gmsh meshes: a left-
//! ventricle wall, base clamped, a 0.2 N probe load on the outer surface ramped over 0.1 s,
//! 1000 steps of 1 ms. Skipped (with a note) when the shared meshes are not present.
//!
//! Checks: backward Euler (rest-linearised) on lv_190 and lv_1350 stays finite with
//! max |u| < 2 cm (the static answer is ~2 mm), and the mean displacement over the second half
//! (0.5-1 s, load constant) is within 5% (relative L2 over all nodes) of `static_solve`; the
//! semi-implicit scheme on lv_190 stays finite and bounded.
//!
//! What a wrong implementation would do: an unstable or energy-pumping scheme exceeds the bound
//! or goes non-finite; a scheme that converges to the wrong equilibrium (e.g. a linearised
//! force, or a load applied to the wrong nodes) misses the static answer by far more than 5%
//! (BE's mean matches it to ~1e-5 in practice: its steady state is the exact nonlinear
//! equilibrium, and BE damps the oscillation within the first half).

#[path = "support/common.rs"]
mod common;
#[path = "support/protocol.rs"]
mod protocol;

use common::max_norm;
use palpate_core::integrate::{static_solve, StaticOptions};
use palpate_core::probe::{run_probe, NoClock, ProbeOptions};
use palpate_core::{Integrator, ModelBuilder, State, Vec3, Workspace};

/// Runs the protocol; returns (max |u| over the run, rel L2 of the second-half mean vs static).
fn run(name: &str, integ: Integrator) -> Option<(f64, f64)> {
    let Some(case) = protocol::load_case(name) else {
        println!("SKIP: shared mesh lv_{name} not found (set PALPATE_SHARED)");
        return None;
    };
    let model = ModelBuilder::new(case.mesh.clone(), protocol::material())
        .fixed_nodes(case.fixed.clone())
        .integrator(integ)
        .build()
        .unwrap();
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    for &i in &case.loaded {
        f[i] = case.f_node;
    }
    let stat = static_solve(&model, &f, &StaticOptions::default()).unwrap();
    let u_static: Vec<Vec3> = stat.x.iter().zip(model.mesh().points()).map(|(x, x0)| x - x0).collect();

    let steps = 1000;
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    let load = protocol::probe_load(&case, protocol::FORCE, 0.0);
    let run = run_probe(&model, &mut s, &mut ws, &[load], &ProbeOptions::new(steps, protocol::DT, f64::INFINITY), &mut NoClock);
    if let Some(stop) = &run.stop {
        panic!("lv_{name} {integ:?}: {stop}");
    }
    let (umax, mean) = (run.max_disp, run.mean_disp);
    let num: f64 = mean.iter().zip(&u_static).map(|(m, u)| (m - u).norm_squared()).sum::<f64>().sqrt();
    let den: f64 = u_static.iter().map(|u| u.norm_squared()).sum::<f64>().sqrt();
    println!(
        "lv_{name} ({} tets) {integ:?}: max|u| {umax:.3e} m (static max {:.3e}), second-half mean vs static: rel L2 {:.3e}",
        model.n_tets(),
        max_norm(&u_static),
        num / den
    );
    Some((umax, num / den))
}

#[test]
fn backward_euler_linear_matches_static_on_protocol_meshes() {
    for name in ["190", "1350"] {
        let Some((umax, rel)) = run(name, Integrator::BackwardEulerLinear) else { return };
        assert!(umax.is_finite() && umax < 0.02, "lv_{name}: max |u| = {umax:e} m");
        assert!(rel <= 0.05, "lv_{name}: second-half mean differs from static by {rel:e} (rel L2)");
    }
}

/// The semi-implicit scheme is over-damped and lags the equilibrium on finer meshes (measured
/// 1.1% on lv_190, 23% on lv_1350), so only stability is required here; the lag on lv_190 is
/// printed and bounded loosely (10%) to catch a gross change.
#[test]
fn semi_implicit_is_stable_on_lv_190() {
    let Some((umax, rel)) = run("190", Integrator::semi_implicit()) else { return };
    assert!(umax.is_finite() && umax < 0.02, "lv_190 semi-implicit: max |u| = {umax:e} m");
    assert!(rel <= 0.10, "lv_190 semi-implicit: second-half mean lags static by {rel:e}");
}
