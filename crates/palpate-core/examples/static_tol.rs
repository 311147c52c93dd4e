#[path = "../tests/support/protocol.rs"]
mod protocol;
use palpate_core::integrate::{static_solve, StaticOptions};
use palpate_core::{ModelBuilder, Vec3};
fn main() {
    for name in ["190", "1350", "10k"] {
        let case = protocol::load_case(name).unwrap();
        let model = ModelBuilder::new(case.mesh.clone(), protocol::material()).fixed_nodes(case.fixed.clone()).build().unwrap();
        for scale in [1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 1e-1, 1.0] {
            let mut f = vec![Vec3::zeros(); model.n_nodes()];
            for &i in &case.loaded {
                f[i] = case.f_node * scale;
            }
            match static_solve(&model, &f, &StaticOptions::default()) {
                Ok(s) => println!("{name} x{scale:e}: ok, {} iterations, residual {:.2e}", s.iterations, s.residual),
                Err(e) => println!("{name} x{scale:e}: FAIL {e}"),
            }
        }
    }
}
