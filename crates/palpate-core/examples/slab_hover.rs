//! A saved hybrid model pressed at a point, tick by tick, the shell's step failing as an error
//! (no fallback): `cargo run --release --example slab_hover -- MODEL.palpate x y z nx ny nz
//! depth_mm [ticks]`. The tool's centre starts a radius plus 1 mm outside the point `(x, y, z)`
//! [m] and travels along the inward normal `n` to `depth_mm` over the first 1,000 ticks, then holds.
//! Prints every 10 ticks (and every tick once a particle moves faster than 5 cm/s): the travel,
//! the force along `n`, the active particles, the sub-steps, the fastest active particle and core
//! node, and the core step's iterations.
//!
//! Made for the thick-shell slab of VALIDATION.md (`bench/hybrid_slab.py`'s box, saved with
//! `HybridModel.save`), whose shell diverged before contact. Study switches (environment):
//! `DAMPED=1` (the paper's damping), `R` (tool radius [m]), `COUPLING_K`, `COUPLING_C`,
//! `NOHOM=1` (no homogenised core), `QN_CAP`, `QN_TOL` (the core's quasi-Newton cap and
//! tolerance), `SIGNED=1` (every tick: the fastest core node's velocity and the core's summed
//! external force along z, which show a growing tick-to-tick alternation).
#[path = "support/mod.rs"]
mod support;

use palpate_core::hybrid::HybridModel;
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::Vec3;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let f = |k: usize| a[k].parse::<f64>().unwrap();
    let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<f64>().ok());
    let m = HybridModel::load(std::path::Path::new(&a[1])).unwrap();
    let p = Vec3::new(f(2), f(3), f(4));
    let n = Vec3::new(f(5), f(6), f(7)).normalize();
    let depth = f(8) * 1e-3;
    let ticks: usize = a.get(9).map(|s| s.parse().unwrap()).unwrap_or(2000);
    let mat = support::tissue(env("DAMPED").is_some());
    let mut opts = SimOptions { shell_fallback: None, ..SimOptions::default() };
    if let Some(r) = env("R") {
        opts.tool.radius = r;
    }
    if let Some(k) = env("COUPLING_K") {
        opts.coupling = Some(palpate_core::runtime::Coupling { stiffness: k, damping: env("COUPLING_C").unwrap_or(0.0) });
    }
    if let Some(cap) = env("QN_CAP") {
        opts.integrator = palpate_core::Integrator::BackwardEulerQuasiNewton {
            max_iterations: cap as usize,
            tolerance: env("QN_TOL").unwrap_or(1e-4),
            history: palpate_core::Integrator::QUASI_NEWTON_HISTORY,
        };
    }
    if env("NOHOM").is_some() {
        opts.homogenise = false;
    }
    let sim = Sim::new(m, mat, opts).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let r = sim.options.tool.radius;
    for t in 0..ticks {
        let d = (depth * t as f64 / 1000.0).min(depth) - 1e-3;
        let c = p - n * (r - d);
        match tick(&sim, &mut st, &mut ws, c, 1e-3) {
            Ok(rep) => {
                let vmax_p = st.particles.active.iter().map(|&q| st.particles.v[q].norm()).fold(0.0, f64::max);
                let vmax_c = st.core.v.iter().map(|v| v.norm()).fold(0.0, f64::max);
                let (imax, _) = st.core.v.iter().enumerate().fold((0, 0.0), |b, (i, v)| if v.norm() > b.1 { (i, v.norm()) } else { b });
                if std::env::var_os("SIGNED").is_some() && vmax_c > 1e-12 {
                    println!("  node {imax} v {:?} fz_core_sum {:.3e}", st.core.v[imax].as_slice(), st.core.f_ext.iter().map(|f| f.z).sum::<f64>());
                }
                if t % 10 == 0 || vmax_p > 0.05 {
                    println!(
                        "{t} d {:.2} F {:.4} act {} sub {} vp {:.2e} vc {:.2e} it {}",
                        d * 1e3,
                        -rep.force.dot(&n),
                        rep.active,
                        rep.substeps,
                        vmax_p,
                        vmax_c,
                        rep.core.iterations
                    );
                }
            }
            Err(e) => {
                println!("{t} failed: {e}");
                break;
            }
        }
    }
}
