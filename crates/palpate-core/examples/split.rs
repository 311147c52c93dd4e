//! Where a step's time goes: force evaluation vs triangular solves (`cargo run --release --example split -- 10k`).
#[path = "../tests/support/protocol.rs"]
mod protocol;
use palpate_core::{step, Integrator, ModelBuilder, State, Vec3, Workspace};
use std::time::Instant;
fn main() {
    let name = std::env::args().nth(1).unwrap_or_else(|| "1350".into());
    let case = protocol::load_case(&name).unwrap();
    let model = ModelBuilder::new(case.mesh.clone(), protocol::material())
        .fixed_nodes(case.fixed.clone())
        .integrator(Integrator::BackwardEulerLinear)
        .build()
        .unwrap();
    let mut st = State::rest(&model);
    let mut ws = Workspace::new(&model);
    step(&model, &mut st, &mut ws, 1e-3).unwrap();
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    let n = 200;
    let t = Instant::now();
    for _ in 0..n {
        model.internal_forces(&st.x, None, &mut f);
    }
    let tf = t.elapsed().as_secs_f64() / n as f64;
    let t = Instant::now();
    for _ in 0..n {
        step(&model, &mut st, &mut ws, 1e-3).unwrap();
    }
    let ts = t.elapsed().as_secs_f64() / n as f64;
    let t = Instant::now();
    let m = 20;
    for k in 0..m {
        step(&model, &mut st, &mut ws, if k % 2 == 0 { 1.0001e-3 } else { 1e-3 }).unwrap();
    }
    let tfac = t.elapsed().as_secs_f64() / m as f64 - ts;
    println!("{name}: factorisation {:.1} us = {:.1} solves (model: {:.1})", tfac * 1e6, tfac / (ts - tf), model.factor_to_solve_ratio());
    println!(
        "{name}: {} tets, {} free dofs, L blocks {}: forces {:.1} us, linear step {:.1} us (solve ~ {:.1} us)",
        model.n_tets(),
        model.n_dofs(),
        model.factor_blocks(),
        tf * 1e6,
        ts * 1e6,
        (ts - tf) * 1e6
    );
}
