//! The hybrid tick with the tool away from the organ (the tick's fixed cost: the core's step and
//! the skin's upkeep): `cargo run --release --example idle_tick -- MODEL.palpate [ticks]`.
#[path = "support/mod.rs"]
mod support;

use palpate_core::hybrid::HybridModel;
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::Vec3;
use std::time::Instant;
use support::{percentile, tissue};

fn main() {
    let arg = |k: usize| std::env::args().nth(k);
    let path = arg(1).expect("MODEL.palpate");
    let ticks = arg(2).and_then(|s| s.parse::<usize>().ok()).unwrap_or(3000);
    let m = HybridModel::load(std::path::Path::new(&path)).unwrap();
    let sim = Sim::new(m, tissue(true), SimOptions::default()).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let far = Vec3::new(10.0, 10.0, 10.0);
    let mut times = Vec::with_capacity(ticks);
    let mut iters = 0;
    for _ in 0..ticks {
        let t0 = Instant::now();
        let r = tick(&sim, &mut st, &mut ws, far, 1e-3).unwrap();
        times.push(t0.elapsed().as_secs_f64() * 1e3);
        iters += r.core.iterations;
    }
    println!("the first ticks [ms]: {:.3?}", &times[..times.len().min(4)]);
    let mean = times.iter().sum::<f64>() / ticks as f64;
    times.sort_by(f64::total_cmp);
    println!(
        "{path}: idle tick ms mean {mean:.4} p50 {:.4} p99 {:.4}; core iterations per tick {:.2}",
        percentile(&times, 0.5),
        percentile(&times, 0.99),
        iters as f64 / ticks as f64
    );
}
