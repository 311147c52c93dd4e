//! Quick timing of the benchmark protocol from Rust: `cargo run --release --example protocol -- 1350`.
#[path = "../tests/support/protocol.rs"]
mod protocol;

use palpate_core::integrate::{static_solve, StaticOptions};
use palpate_core::probe::{run_probe, ProbeOptions};
use palpate_core::{Integrator, ModelBuilder, State, Vec3, Workspace};
use std::time::Instant;

fn main() {
    let name = std::env::args().nth(1).unwrap_or_else(|| "190".into());
    let steps: usize = std::env::args().nth(2).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let case = protocol::load_case(&name).expect("shared meshes");
    let mut integrators = vec![Integrator::semi_implicit(), Integrator::BackwardEulerLinear];
    if case.mesh.n_tets() < 2000 {
        integrators.push(Integrator::newton());
    }
    for integ in integrators {
        let t0 = Instant::now();
        let model = ModelBuilder::new(case.mesh.clone(), protocol::material())
            .fixed_nodes(case.fixed.clone())
            .integrator(integ)
            .build()
            .unwrap();
        let build = t0.elapsed().as_secs_f64();
        let mut f = vec![Vec3::zeros(); model.n_nodes()];
        for &i in &case.loaded {
            f[i] = case.f_node;
        }
        let stat = static_solve(&model, &f, &StaticOptions::default()).unwrap();
        let u_static: Vec<Vec3> = stat.x.iter().zip(model.mesh().points()).map(|(x, x0)| x - x0).collect();
        let mut st = State::rest(&model);
        let mut ws = Workspace::new(&model);
        let load = [protocol::probe_load(&case, protocol::FORCE, 0.0)];
        let run = run_probe(&model, &mut st, &mut ws, &load, &ProbeOptions::new(steps, protocol::DT, f64::INFINITY), &mut protocol::WallClock::new());
        if let Some(stop) = &run.stop {
            println!("{name:>5} {:?}: UNSTABLE: {stop}", integ);
        }
        if run.steps <= steps / 2 {
            continue;
        }
        let num: f64 = run.mean_disp.iter().zip(&u_static).map(|(m, u)| (m - u).norm_squared()).sum::<f64>().sqrt();
        let den: f64 = u_static.iter().map(|u| u.norm_squared()).sum::<f64>().sqrt();
        println!(
            "{name:>5} {:?}: build {:.3}s nnzL {} | {:.0} steps/s | max|u| {:.3e} m | rel L2 vs static {:.3}% | static iters {}",
            integ,
            build,
            model.factor_blocks(),
            run.steps as f64 / run.wall_s,
            run.max_disp,
            100.0 * num / den,
            stat.iterations
        );
    }
}
