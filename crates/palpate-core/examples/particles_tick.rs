//! Time one 1 ms tick of a particle block: `cargo run --release --example particles_tick -- 600`.
use palpate_core::material::{Damping, Elasticity};
use palpate_core::meshfree::{self, ParticleModelBuilder, ParticleState, ParticleWorkspace};
use palpate_core::{Material, Vec3};
use std::time::Instant;

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(600);
    let support: f64 = std::env::args().nth(2).and_then(|s| s.parse().ok()).unwrap_or(1.8);
    let kappa: f64 = std::env::args().nth(3).and_then(|s| s.parse().ok()).unwrap_or(palpate_core::meshfree::DEFAULT_HOURGLASS);
    let s = 0.9e-3;
    let side = (n as f64).cbrt().ceil() as usize;
    let mut pts = Vec::new();
    'outer: for k in 0..side {
        for j in 0..side {
            for i in 0..side {
                if pts.len() == n {
                    break 'outer;
                }
                pts.push(Vec3::new(i as f64, j as f64, k as f64) * s);
            }
        }
    }
    let m = vec![1000.0 * s * s * s; pts.len()];
    let mat = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap();
    let t0 = Instant::now();
    let fixed: Vec<usize> = (0..side * side).collect();
    let model = ParticleModelBuilder::new(pts, m, mat, support * s).fixed_particles(fixed).hourglass(kappa).build().unwrap();
    let build = t0.elapsed().as_secs_f64();
    let mut st = ParticleState::rest(&model);
    let mut ws = ParticleWorkspace::new(&model);
    let top = model.n_particles() - 1;
    st.f_ext[top] = Vec3::new(0.0, 0.0, -1e-4);
    let sub = model.substeps(1e-3);
    meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
    let ticks = 2000;
    let mut times = Vec::with_capacity(ticks);
    for _ in 0..ticks {
        let t = Instant::now();
        meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(|a, b| a.total_cmp(b));
    let med = times[ticks / 2];
    let pairs = model.n_pairs();
    println!(
        "N {} | mean neighbours {:.1} | build {:.3} s | stable dt {:.2e} s -> {} sub-steps per 1 ms | tick median {:.1} us (min {:.1}) | {:.1} ns per pair-substep",
        model.n_particles(),
        pairs as f64 / model.n_particles() as f64,
        build,
        model.stable_dt(),
        sub,
        med * 1e6,
        times[0] * 1e6,
        med * 1e9 / (pairs * sub) as f64
    );
}
