//! Time the hybrid tick on one and on several threads: `cargo run --release --example pool_tick
//! -- MODEL.palpate [threads] [ticks]` (a 4 mm press and a 6 mm slide with the 5 mm tool at the
//! outer vertex farthest along +x, as `palpate bench haptic`'s palpation, repeated).
use palpate_core::hybrid::HybridModel;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::runtime::SimOptions;
use palpate_core::{Material, Vec3};
use palpate_haptics::{HybridPhysics, Physics};
use std::time::Instant;

fn main() {
    let arg = |k: usize| std::env::args().nth(k);
    let path = arg(1).expect("MODEL.palpate");
    let threads = arg(2).and_then(|s| s.parse().ok()).unwrap_or(2);
    let ticks: usize = arg(3).and_then(|s| s.parse().ok()).unwrap_or(4000);
    let m = HybridModel::load(std::path::Path::new(&path)).unwrap();
    let mat = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1050.0, Damping::from_paper(1.0, 1.0)).unwrap();
    let outer = m.outer_points.clone();
    let c = outer.iter().fold(Vec3::zeros(), |a, p| a + p) / outer.len() as f64;
    let p0 = *outer.iter().max_by(|a, b| a.x.total_cmp(&b.x)).unwrap();
    let n = (p0 - c).normalize();
    let t = n.cross(&Vec3::z()).normalize();
    let mut runs: Vec<(usize, HybridPhysics, Vec<f64>)> = [1, threads]
        .into_iter()
        .map(|w| (w, HybridPhysics::new(m.clone(), mat, SimOptions::default()).unwrap().with_threads(w, false).unwrap(), Vec::new()))
        .collect();
    let r = 0.005;
    for k in 0..ticks {
        let s = (k % 2000) as f64 / 2000.0;
        let depth = 0.004 * (s * 4.0).min(1.0) * if s > 0.8 { (1.0 - s) / 0.2 } else { 1.0 };
        let slide = 0.006 * ((s - 0.3).max(0.0) / 0.4).min(1.0);
        let tool = p0 + n * (r - depth + 0.002 * 0.0) + t * slide;
        for (_, ph, times) in &mut runs {
            let t0 = Instant::now();
            ph.tick(&tool, 1e-3).unwrap();
            times.push(t0.elapsed().as_secs_f64() * 1e3);
            // The servo's rest of the period (the helpers park after their spin).
            std::thread::sleep(std::time::Duration::from_micros(300));
        }
    }
    for (w, _, times) in &mut runs {
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        times.sort_by(f64::total_cmp);
        let p = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
        println!("{w} thread(s): tick ms mean {mean:.3} p50 {:.3} p99 {:.3} max {:.3}", p(0.5), p(0.99), p(1.0));
    }
}
