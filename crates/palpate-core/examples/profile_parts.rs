//! Time the parts of a backward-Euler step: `cargo run --release --example profile_parts -- 1350`.
#[path = "../tests/support/protocol.rs"]
mod protocol;
use palpate_core::{step, ModelBuilder, State, Vec3, Workspace};
use std::time::Instant;
fn main() {
    let name = std::env::args().nth(1).unwrap_or_else(|| "1350".into());
    let case = protocol::load_case(&name).unwrap();
    let model = ModelBuilder::new(case.mesh.clone(), protocol::material()).fixed_nodes(case.fixed.clone()).build().unwrap();
    let st = State::rest(&model);
    let mut out = vec![Vec3::zeros(); model.n_nodes()];
    let n = 2000;
    let t = Instant::now();
    for _ in 0..n {
        model.internal_forces(&st.x, Some(&st.v), &mut out);
    }
    println!("forces: {:.1} us", t.elapsed().as_secs_f64() / n as f64 * 1e6);
    let mut st2 = State::rest(&model);
    let mut ws = Workspace::new(&model);
    step(&model, &mut st2, &mut ws, 1e-3).unwrap();
    let t = Instant::now();
    for _ in 0..n {
        step(&model, &mut st2, &mut ws, 1e-3).unwrap();
    }
    println!("step: {:.1} us  (n_dofs {}, nnzL {})", t.elapsed().as_secs_f64() / n as f64 * 1e6, model.n_dofs(), model.factor_blocks());
}
