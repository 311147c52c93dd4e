//! Profile the hybrid tick on a model file: `cargo run --release --example tick_profile --
//! MODEL.palpate [radius_mm] [ticks]` (a 3 mm press, a 10 mm slide and a release at the outer
//! vertex farthest along +x, the tool along the direction from the outer surface's centroid;
//! damped as the bench; `DEPTH_MM` sets the press's depth, `TRACE=FILE` writes one CSV row a
//! tick; `SPLIT=1` times only the part of each tick its force depends on, as the haptic servo
//! sends it, the skin's update after it untimed). Prints the tick's mean and percentiles and the mean sub-step count; run
//! it under `perf record` for where the time goes.
#[path = "support/mod.rs"]
mod support;

use palpate_core::hybrid::HybridModel;
use palpate_core::parallel::Serial;
use palpate_core::runtime::{finish_tick, tick, tick_force_with, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::Vec3;
use std::time::Instant;
use support::{percentile, press_path, tissue};

fn main() {
    let arg = |k: usize| std::env::args().nth(k);
    let path = arg(1).expect("MODEL.palpate");
    let radius = arg(2).and_then(|s| s.parse::<f64>().ok()).unwrap_or(2.0) * 1e-3;
    let ticks = arg(3).and_then(|s| s.parse::<usize>().ok()).unwrap_or(2000);
    let m = HybridModel::load(std::path::Path::new(&path)).unwrap();
    let mat = tissue(std::env::var("UNDAMPED").is_err());
    let mut o = SimOptions::default();
    o.tool.radius = radius;
    // TOOL_K [N/m^3], TOOL_C [N s/m^3]: the contact's stiffness and damping per unit of skin area.
    let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<f64>().ok());
    if let Some(k) = env("TOOL_K") {
        o.tool.area_stiffness = Some(k);
    }
    if let Some(c) = env("TOOL_C") {
        o.tool.area_damping = c;
    }
    // SUPPORT: the kernel's support radius in lattice spacings (SimOptions::support_spacings).
    if let Some(h) = env("SUPPORT") {
        o.support_spacings = h;
    }
    // EXPLICIT: the shell's springs capped by the explicit exchange's stability
    // (SimOptions::implicit_exchange false; the default takes them implicitly).
    if std::env::var("EXPLICIT").is_ok() {
        o.implicit_exchange = false;
    }
    if std::env::var("MS").ok().as_deref() == Some("off") {
        o.mass_scaling = None;
    }
    let sim = Sim::new(m, mat, o).unwrap();
    let outer = &sim.hybrid.outer_points;
    let centroid = outer.iter().sum::<Vec3>() / outer.len() as f64;
    let p = *outer.iter().max_by(|a, b| a.x.total_cmp(&b.x)).unwrap();
    let n_in = (centroid - p).normalize();
    let tangent = n_in.cross(&Vec3::z()).normalize();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (press, hold, slide) = (ticks / 4, ticks / 10, ticks / 2);
    let mut times = Vec::with_capacity(ticks);
    let mut subs = 0usize;
    let mut last_force = 0.0;
    // DEPTH_MM: the press's depth (default 3 mm); TRACE=FILE: one CSV row a tick (k, ms, active,
    // entered, left, sub-steps, core iterations, force [N], skin vertices refreshed away from the
    // tool, core evaluations, particles the wall pushed) to tell what the slow ticks have in common.
    let depth = std::env::var("DEPTH_MM").ok().and_then(|s| s.parse::<f64>().ok()).unwrap_or(3.0) * 1e-3;
    // SPLIT: time only the force's part of each tick (runtime::tick_force_with), the skin's
    // update after it untimed, as the haptic servo sends the force before that update.
    let split = std::env::var("SPLIT").is_ok();
    let mut trace = std::env::var("TRACE").ok().map(|f| std::io::BufWriter::new(std::fs::File::create(f).unwrap()));
    for k in 0..ticks {
        let (d, s) = press_path(k, [press, hold, slide, ticks - press - hold - slide], depth, 10e-3);
        let c = p + n_in * (d - radius) + tangent * s;
        let t0 = Instant::now();
        let rep = if split {
            // The haptic servo's order: the force (timed), then the skin's update after the send.
            let rep = tick_force_with(&sim, &mut st, &mut ws, c, 1e-3, &Serial).unwrap();
            let ms = t0.elapsed();
            finish_tick(&sim, &mut st, &mut ws).unwrap();
            times.push(ms.as_secs_f64() * 1e3);
            rep
        } else {
            let rep = tick(&sim, &mut st, &mut ws, c, 1e-3).unwrap();
            times.push(t0.elapsed().as_secs_f64() * 1e3);
            rep
        };
        let ms = *times.last().unwrap();
        if std::env::var("WHY").is_ok() && k % 100 == 0 && rep.active > 0 {
            let held = sim.particles.fixed();
            let s2 = st
                .particles
                .active
                .iter()
                .filter(|&&p| !held[p])
                .map(|&p| palpate_core::runtime::stability::stretch_bound(&sim.particles.deformation_gradient(p, &st.particles.x)))
                .fold(1.0, f64::max);
            let rest = sim.shell.substeps(1e-3, 1.0, 0.0, 0.0, 64);
            let stretched = sim.shell.substeps(1e-3, s2, 0.0, 0.0, 64);
            println!("tick {k}: substeps {} (rest {rest}, with the stretch s^2 = {s2:.3}: {stretched}; the rest is contact)", rep.substeps);
        }
        if std::env::var("SPIKES").is_ok() && ms > 1.5 {
            println!(
                "tick {k}: {ms:.2} ms active {} (+{} -{}) substeps {} core iterations {} contacts {}+{}+{}",
                rep.active, rep.entered, rep.left, rep.substeps, rep.core.iterations, rep.particle_contacts, rep.skin_contacts, rep.core_contacts
            );
        }
        if let Some(t) = trace.as_mut() {
            use std::io::Write;
            // The force's components exactly (shortest round-trip), so that two traces compare bit
            // for bit after the time column is dropped (`cut -d, -f1,3-`), then the contacts.
            let f = rep.force;
            writeln!(
                t,
                "{k},{ms:.4},{},{},{},{},{},{:?},{:?},{:?},{},{},{},{},{},{},{}",
                rep.active,
                rep.entered,
                rep.left,
                rep.substeps,
                rep.core.iterations,
                f.x,
                f.y,
                f.z,
                rep.skin_refreshed,
                rep.core.evaluations,
                rep.confined,
                rep.skin_contacts,
                rep.core_contacts,
                rep.particle_contacts,
                rep.shell_failed
            )
            .unwrap();
        }
        subs += rep.substeps;
        if k == press + hold - 1 {
            last_force = rep.force.norm();
        }
    }
    if std::env::var("SPIKES").is_ok() {
        let mut out = vec![Vec3::zeros(); sim.hybrid.outer_points.len()];
        let t0 = Instant::now();
        for _ in 0..20 {
            sim.skin_positions(&st, &mut out);
        }
        println!("whole fresh skin ({} vertices): {:.3} ms", out.len(), t0.elapsed().as_secs_f64() * 1e3 / 20.0);
    }
    if let Some(t) = trace.as_mut() {
        // The final state's digest: every coordinate's bits, summed (a move that changes one bit
        // anywhere changes it).
        use std::io::Write;
        let bits = |xs: &[Vec3]| xs.iter().flat_map(|x| x.iter().map(|c| c.to_bits())).fold(0u64, u64::wrapping_add);
        let mut skin = vec![Vec3::zeros(); sim.hybrid.outer_points.len()];
        sim.skin_positions(&st, &mut skin);
        writeln!(t, "digest core {:x} particles {:x} velocities {:x} skin {:x}", bits(&st.core.x), bits(&st.particles.x), bits(&st.particles.v), bits(&skin))
            .unwrap();
    }
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let pct = |q: f64| percentile(&sorted, q);
    println!(
        "{path}: tick ms mean {:.3} p50 {:.3} p99 {:.3}; sub-steps per tick {:.1} (mass scaling {:?}); last force {:.4} N",
        times.iter().sum::<f64>() / times.len() as f64,
        pct(0.5),
        pct(0.99),
        subs as f64 / ticks as f64,
        sim.particles.mass_scaling().applied,
        last_force
    );
    let sh = &sim.shell;
    println!("shell: omega2 {:.3e} /s^2, damping {:.3e} /s, springs {:.3e} /s^2 (coupling {:.1} N/m, wall {:.1} N/m), spring damping {:.3e} /s; rest sub-steps a 1 ms tick {}, without the springs {}", sh.omega2, sh.damping, sh.spring_rate, sim.coupling.stiffness, sim.confinement.stiffness, sh.spring_damping, sh.substeps(1e-3, 1.0, 0.0, 0.0, 1000), palpate_core::runtime::Shell { spring_rate: 0.0, spring_damping: 0.0, ..*sh }.substeps(1e-3, 1.0, 0.0, 0.0, 1000));
}
