//! A scripted press and slide on a built hybrid model, tick by tick:
//! `cargo run --release --example touch -- [ventricle|ellipsoids] [depth_mm] [slide_mm]`.
//! Prints, every 50 ticks, the tool depth, the force on the tool, the active particles and the
//! tick time; then the tick-time percentiles.
//!
//! Study switches (environment): `UNDAMPED=1` (no viscosity), `FORCE=2` (stop advancing once the
//! force reaches 2 N), `TOOL_K`, `TOOL_C` (contact stiffness [N/m^3], damping [N s/m^3] per unit of skin area), `MARGIN`
//! (activation margin [mm]), `COUPLING_K`, `COUPLING_C`, `DEBUG=1` (every 5 ticks: the fastest
//! active particle, the smallest det F, the core's displacement).
#[path = "support/mod.rs"]
mod support;

use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::Vec3;
use std::time::Instant;
use support::{percentile, press_path, probe, tissue, wall_model};

fn main() {
    let arg = |k: usize| std::env::args().nth(k);
    let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<f64>().ok());
    let which = arg(1).unwrap_or_else(|| "ventricle".into());
    let depth_max = arg(2).and_then(|s| s.parse::<f64>().ok()).unwrap_or(5.0) * 1e-3;
    let slide = arg(3).and_then(|s| s.parse::<f64>().ok()).unwrap_or(10.0) * 1e-3;
    let m = wall_model(&which);
    let mat = tissue(env("UNDAMPED").is_none());
    let mut opts = SimOptions::default();
    if let Some(k) = env("COUPLING_K") {
        opts.coupling = Some(palpate_core::runtime::Coupling { stiffness: k, damping: env("COUPLING_C").unwrap_or(0.0) });
    }
    if let Some(k) = env("TOOL_K") {
        opts.tool.area_stiffness = Some(k);
    }
    if let Some(c) = env("TOOL_C") {
        opts.tool.area_damping = c;
    }
    if let Some(m) = env("MARGIN") {
        opts.activation_margin = m * 1e-3;
    }
    let sim = Sim::new(m, mat, opts).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    // The probe point: the outer vertex nearest to (x_max, 0, 20 mm); normal: radial from the axis.
    let (p, n) = probe(&sim, 0.02);
    let tangent = Vec3::new(0.0, 0.0, 1.0);
    let r = sim.options.tool.radius;
    let dt = 1e-3;
    let (t_press, t_hold, t_slide, t_release) = (500, 200, 1000, 300);
    let total = t_press + t_hold + t_slide + t_release;
    let mut times = Vec::with_capacity(total);
    let mut actives = Vec::with_capacity(total);
    let mut fmax: f64 = 0.0;
    // FORCE=2: press until the force reaches 2 N (then hold there).
    let force_target = env("FORCE");
    let mut frozen: Option<f64> = None;
    for k in 0..total {
        let (depth, s) = press_path(k, [t_press, t_hold, t_slide, t_release], depth_max, slide);
        let depth = match (force_target, frozen) {
            (Some(_), Some(d)) => d.min(depth),
            _ => depth,
        };
        let c = p + n * (r - depth) + tangent * s;
        let t0 = Instant::now();
        let rep = match tick(&sim, &mut st, &mut ws, c, dt) {
            Ok(r) => r,
            Err(e) => {
                println!("tick {k}: {e}");
                return;
            }
        };
        times.push(t0.elapsed().as_secs_f64() * 1e3);
        if rep.active > 0 {
            actives.push(rep.active);
        }
        fmax = fmax.max(rep.force.norm());
        if let Some(ft) = force_target {
            if frozen.is_none() && rep.force.norm() >= ft {
                frozen = Some(depth);
                println!("tick {k}: {ft} N reached at depth {:.2} mm", depth * 1e3);
            }
        }
        if std::env::var("DEBUG").is_ok() && k % 5 == 0 {
            let umax = st.particles.active.iter().map(|&i| (st.particles.x[i] - sim.hybrid.particles[i]).norm()).fold(0.0, f64::max);
            let vmax = st.particles.active.iter().map(|&i| st.particles.v[i].norm()).fold(0.0, f64::max);
            let ucore = st.core.x.iter().zip(&sim.hybrid.core_points).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
            let fcore = st.core.f_ext.iter().map(|f| f.norm()).fold(0.0, f64::max);
            let (iv, _) = st.particles.active.iter().map(|&i| (i, st.particles.v[i].norm())).fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
            let off = (st.particles.x[iv] - sim.particle_tie.position(iv, &st.core.x)).norm();
            eprintln!(
                "   vmax particle {iv}: coupled {} held {} nbrs {} tool dist {:.2e} tie off {:.2e} depth {:.2e}",
                sim.coupled[iv],
                sim.particles.fixed()[iv],
                sim.particles.neighbours(iv).len(),
                (st.particles.x[iv] - c).norm(),
                off,
                sim.particle_tie.offsets()[iv].norm()
            );
            let (jm, dm) = st
                .particles
                .active
                .iter()
                .map(|&i| (i, sim.particles.deformation_gradient(i, &st.particles.x).determinant()))
                .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
            eprintln!("   min det F {dm:.3} at {jm}");
            eprintln!("dbg {k}: active umax {umax:.3e} vmax {vmax:.3e} core umax {ucore:.3e} fcore max {fcore:.3e} confined {}", rep.confined);
        }
        if k % 50 == 0 || k + 1 == total {
            println!(
                "tick {k:5}: depth {:5.2} mm slide {:5.2} mm | force {:7.4} N (normal {:7.4}) | contacts {:3} + skin {:2} + core {} | active {:4} (+{} -{}) substeps {:2} confined {:3} | core it {} | {:.3} ms",
                depth * 1e3, s * 1e3, rep.force.norm(), -rep.force.dot(&n), rep.particle_contacts, rep.skin_contacts, rep.core_contacts, rep.active, rep.entered, rep.left, rep.substeps, rep.confined, rep.core.iterations, times[k]
            );
        }
    }
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let pct = |q: f64| percentile(&sorted, q);
    let (amean, amax) = if actives.is_empty() {
        (0.0, 0)
    } else {
        (actives.iter().sum::<usize>() as f64 / actives.len() as f64, *actives.iter().max().unwrap())
    };
    println!(
        "{which}: {} core tets, {} particles | tick ms mean {:.3} p50 {:.3} p99 {:.3} max {:.3} | active mean {amean:.0} max {amax} | max force {fmax:.3} N",
        sim.core.n_tets(),
        sim.n_particles(),
        times.iter().sum::<f64>() / times.len() as f64,
        pct(0.5),
        pct(0.99),
        sorted[sorted.len() - 1]
    );
}
