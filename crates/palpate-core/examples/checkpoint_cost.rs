//! What a checkpoint of the hybrid state costs (the haptic loop's last good state, every 250
//! ticks), part by part: `cargo run --release --example checkpoint_cost -- MODEL.palpate [n]`.
//! Presses the tool 4 mm in at the outer vertex farthest along +x (so that regions are active),
//! then times `n` (default 200) copies of the whole state, of its parts, and a finiteness scan
//! of the state's positions and velocities (what `HybridPhysics::is_finite` reads); medians.
//! Measured 2026-11-27 on Rodero (266 active): the whole copy 94 us (the particles' arrays 42,
//! the skin 16, the activation 12), the scan 60 us (as one integer fold of the exponent bits,
//! no early exit, 108 us: not vectorised).
#[path = "support/mod.rs"]
mod support;

use palpate_core::hybrid::HybridModel;
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::Vec3;
use std::time::Instant;
use support::{percentile, tissue};

fn median_us(n: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..n)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    t.sort_by(f64::total_cmp);
    percentile(&t, 0.5)
}

fn main() {
    let arg = |k: usize| std::env::args().nth(k);
    let path = arg(1).expect("MODEL.palpate");
    let n = arg(2).and_then(|s| s.parse::<usize>().ok()).unwrap_or(200);
    let m = HybridModel::load(std::path::Path::new(&path)).unwrap();
    let sim = Sim::new(m, tissue(true), SimOptions::default()).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let outer = &sim.hybrid.outer_points;
    let p = *outer.iter().max_by(|a, b| a.x.total_cmp(&b.x)).unwrap();
    let r = sim.options.tool.radius;
    for k in 0..400 {
        let depth = (k as f64 * 2e-5).min(4e-3) - 2e-3;
        tick(&sim, &mut st, &mut ws, p + Vec3::x() * (r - depth), 1e-3).unwrap();
    }
    let mut good = st.clone();
    let finite = |v: &[Vec3]| v.iter().all(|q| q.iter().all(|c| c.is_finite()));
    println!("{path}: {} active particles of {}, {} skin vertices", st.particles.active.len(), st.particles.x.len(), st.skin.len());
    println!("  whole state (SimState::clone_from): {:.1} us", median_us(n, || good.clone_from(&st)));
    println!("  particles (x, v, f_ext, active):     {:.1} us", median_us(n, || good.particles.clone_from(&st.particles)));
    println!("  skin:                                {:.1} us", median_us(n, || good.skin.clone_from(&st.skin)));
    println!("  activation:                          {:.1} us", median_us(n, || good.activation.clone_from(&st.activation)));
    println!("  core:                                {:.1} us", median_us(n, || good.core.clone_from(&st.core)));
    let mut ok = true;
    println!(
        "  finiteness scan (core, particles x v, skin): {:.1} us",
        median_us(n, || ok &= finite(&st.core.x) && finite(&st.core.v) && finite(&st.particles.x) && finite(&st.particles.v) && finite(&st.skin))
    );
    assert!(ok);
}
