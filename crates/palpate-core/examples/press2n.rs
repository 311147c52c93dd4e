//! Study: the runtime_hand test's press toward 2 N (50 mm/s, capped at 20 mm) with the shell's
//! mass scaling set by `MS` (a quantile; `MS=off`), printing the sub-steps and the fastest
//! particle near the end: `cargo run --release --example press2n -- [ventricle|ellipsoids]`.
#[path = "support/mod.rs"]
mod support;

use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use support::{probe, tissue, wall_model};

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "ventricle".into());
    let m = wall_model(&which);
    let mat = tissue(std::env::var("DAMPED").is_ok());
    let mut o = SimOptions::default();
    o.mass_scaling = match std::env::var("MS").ok().as_deref() {
        Some("off") => None,
        Some(q) => Some(q.parse().unwrap()),
        None => o.mass_scaling,
    };
    let sim = Sim::new(m, mat, o).unwrap();
    println!("mass scaling {:?}: rest omega^2 {:.3e}", sim.particles.mass_scaling(), sim.particles.omega_max().powi(2));
    // The probe as tests/runtime_hand.rs: the outer vertex nearest (x_max, 0, 20 mm), the inward
    // radial normal.
    let (p, outward) = probe(&sim, 0.02);
    let n = -outward;
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let mut depth = 0.0f64;
    for k in 0..500 {
        match tick(&sim, &mut st, &mut ws, p - n * (r - depth), 1e-3) {
            Ok(rep) => {
                if k % 25 == 0 || k > 380 {
                    let vmax = st.particles.active.iter().map(|&i| st.particles.v[i].norm()).fold(0.0, f64::max);
                    let dmin = st
                        .particles
                        .active
                        .iter()
                        .map(|&i| sim.particles.deformation_gradient(i, &st.particles.x).determinant())
                        .fold(f64::INFINITY, f64::min);
                    println!(
                        "tick {k}: depth {:.2} mm force {:.3} N active {} substeps {} vmax {vmax:.3} m/s min det F {dmin:.3}",
                        depth * 1e3,
                        rep.force.norm(),
                        rep.active,
                        rep.substeps
                    );
                }
                if rep.force.norm() < 2.0 {
                    depth = (depth + 5e-5).min(20e-3);
                }
            }
            Err(e) => {
                println!("tick {k} at {:.1} mm: {e}", depth * 1e3);
                return;
            }
        }
    }
    println!("finite over 500 ticks");
}
