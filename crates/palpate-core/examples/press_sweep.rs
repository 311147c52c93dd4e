//! Study: the runtime_hand test's press toward 2 N (50 mm/s until the force reaches 2 N, travel
//! capped at 20 mm, from 5 mm outside, 600 ticks) at 24 probe points of a model (4 heights x 6 angles around its
//! vertical axis, inward horizontal presses), printing per point the largest force, the most
//! sub-steps a tick took, how often the shell's step failed (and was shed: `shell_fallback`), the
//! ticks the shell was off and the largest tick-to-tick force change, with the shell on, over
//! the shed tick and the 10 after it, and with the shell off.
//!
//! `cargo run --release --example press_sweep -- [ventricle|ellipsoids|MODEL_FILE] [damped] [nofallback]`
//! (`POINT=zi,ti` runs one point: height `zi` in 1..=4, angle `ti` in 0..6; `TRACE=1` prints
//! each tick's force, sub-steps, active set and contacts, `TRACE=2` also the skin vertices inside
//! the tool, `TRACE=3` the core's surface contact; `TOOL_K`, `TOOL_C`: the contact's
//! stiffness \[N/m^3\] and damping \[N s/m^3\] per unit of skin area; `HOLD_MM`: press to that depth and
//! hold, whatever the force). Per point it also prints how far the force along the press fell
//! below its running maximum while the tool went on in ("gave way": the organ letting the tool
//! through, a slope the tool slid down, or a hollow wall caving in).
//!
//! Measured 2026-11-26 on the synthetic ventricle, undamped: 18 of the 24 shells failed (from
//! 17-20 mm of travel at mid-height, from 6-11 mm beside the held base); see
//! `runtime::stability` for the trace and why. From 5 mm outside (2026-11-27,
//! docs/history/benchmarks-log.md#eighth-session-2026-11-27-a-hard-press-held-on-the-rodero-ventricle-no-longer-chatters):
//! 15 of 24 undamped and 9 damped on the synthetic ventricle, 1 and 0 on the Rodero ventricle,
//! 0 on the ellipsoids.
#[path = "support/mod.rs"]
mod support;

use palpate_core::hybrid::HybridModel;
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::Vec3;
use support::tissue;

struct Outcome {
    fmax: f64,
    most_substeps: usize,
    shed: Vec<(usize, f64)>,
    off: usize,
    /// Largest tick-to-tick force change with the shell on, and off (core and skin alone).
    jump: f64,
    jump_off: f64,
    /// Largest change over the shed tick and the 10 after it.
    jump_shed: f64,
    /// The press's force along its direction at the end, and the largest fall of that force
    /// below its running maximum while the tool went on pressing in (the organ giving way under
    /// the tool: a tool that slips through the surface).
    f_end: f64,
    gave_way: f64,
    /// The largest change of the force's magnitude in a tick until it first reaches 5 N (what a
    /// device renders at most).
    jump_to_5n: f64,
    error: Option<String>,
}

/// The outer vertex nearest the ray from the outer surface's centroid along `theta` at height `z`.
fn probe(sim: &Sim, z: f64, theta: f64) -> (Vec3, Vec3) {
    let dir = Vec3::new(theta.cos(), theta.sin(), 0.0);
    let outer = &sim.hybrid.outer_points;
    let c = outer.iter().fold(Vec3::zeros(), |a, b| a + b) / outer.len() as f64;
    let off_ray = |q: &Vec3| {
        let d = q - c;
        let r = d - dir * d.dot(&dir);
        r.x.powi(2) + r.y.powi(2) + (q.z - z).powi(2)
    };
    let p = *outer.iter().filter(|q| (*q - c).dot(&dir) > 0.0).min_by(|a, b| off_ray(a).total_cmp(&off_ray(b))).unwrap();
    (p, -dir)
}

fn press(sim: &Sim, z: f64, theta: f64) -> Outcome {
    let (p, n) = probe(sim, z, theta);
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(sim);
    let mut ws = SimWorkspace::new(sim);
    let mut o = Outcome {
        fmax: 0.0,
        most_substeps: 0,
        shed: vec![],
        off: 0,
        jump: 0.0,
        jump_off: 0.0,
        jump_shed: 0.0,
        f_end: 0.0,
        gave_way: 0.0,
        jump_to_5n: 0.0,
        error: None,
    };
    let mut below_5n = true;
    let mut f_top = 0.0f64;
    // From 5 mm outside the probe vertex: a tool starting tangent to it is already up to 4 mm
    // into the skin beside it where the surface slants (the Rodero ventricle), a first-tick
    // jump of the script, not of the tissue.
    let (mut depth, mut last) = (-5e-3f64, None::<Vec3>);
    for k in 0..600 {
        match tick(sim, &mut st, &mut ws, p - n * (r - depth), 1e-3) {
            Ok(rep) => {
                if std::env::var("TRACE").is_ok() {
                    // Where the core and the active particles are along the press (mm past the
                    // probe), near the tool: what moves back and forth in a chatter.
                    let c = p - n * (r - depth);
                    let along = |x: &Vec3| (x - p).dot(&n) * 1e3;
                    let near: Vec<usize> = sim.core_surface.iter().copied().filter(|&a| (st.core.x[a] - c).norm() < 2.0 * r).collect();
                    let core_mm = near.iter().map(|&a| along(&st.core.x[a])).sum::<f64>() / near.len().max(1) as f64;
                    let close: Vec<usize> = st.particles.active.iter().copied().filter(|&q| (st.particles.x[q] - c).norm() < 1.5 * r).collect();
                    let part_mm = close.iter().map(|&q| along(&st.particles.x[q])).sum::<f64>() / close.len().max(1) as f64;
                    if std::env::var("TRACE").as_deref() == Ok("3") {
                        let faces: Vec<usize> = (0..sim.hybrid.core_faces.len()).collect();
                        let beneath = palpate_core::runtime::CoreContact::centre_is_beneath(sim, &st.core.x, &c);
                        let cc = palpate_core::runtime::CoreContact { sim, centre: c, skin: &[], core: &faces, lift: &[], lift_scale: 0.0, beneath };
                        if let Some((t, w, pc)) = cc.surface(&st.core.x) {
                            let [a, b, cn] = sim.hybrid.core_faces[t];
                            let nf = (st.core.x[b] - st.core.x[a]).cross(&(st.core.x[cn] - st.core.x[a])).normalize();
                            println!(
                                "    core face {t} {:?} w {:.3?} depth {:.2} mm dir {:.2?} face normal {:.2?} press {:.2?} beneath {beneath}",
                                [a, b, cn],
                                w,
                                pc.depth * 1e3,
                                pc.normal.as_slice(),
                                nf.as_slice(),
                                n.as_slice()
                            );
                        }
                    }
                    if std::env::var("TRACE").as_deref() == Ok("2") {
                        for (v, x) in st.skin.iter().enumerate() {
                            let d = x - c;
                            if d.norm() < r {
                                let a = d.dot(&n);
                                println!(
                                    "    skin {v}: along {:.2} mm, lateral {:.2} mm, depth {:.2} mm",
                                    a * 1e3,
                                    (d - n * a).norm() * 1e3,
                                    (r - d.norm()) * 1e3
                                );
                            }
                        }
                    }
                    print!("  core {core_mm:.3} mm ({} nodes), particles {part_mm:.3} mm ({}),", near.len(), close.len());
                    println!(
                        "  tick {k} depth {:.2} mm: force {:.3} N (along the press {:.3} N), sub-steps {}, active {} (+{} -{}), contacts {}+{}+{}, confined {}, max depth {:.2} mm{}{}",
                        depth * 1e3,
                        rep.force.norm(),
                        -rep.force.dot(&n),
                        rep.substeps,
                        rep.active,
                        rep.entered,
                        rep.left,
                        rep.particle_contacts,
                        rep.skin_contacts,
                        rep.core_contacts,
                        rep.confined,
                        rep.max_depth * 1e3,
                        if rep.shell_failed { " SHELL FAILED" } else { "" },
                        if rep.shell_off { " (shell off)" } else { "" }
                    );
                }
                if rep.shell_failed {
                    o.shed.push((k, depth));
                }
                o.off += rep.shell_off as usize;
                if let Some(f0) = last {
                    let near_shed = o.shed.last().is_some_and(|&(s, _)| k <= s + 10);
                    let j = if near_shed {
                        &mut o.jump_shed
                    } else if rep.shell_off {
                        &mut o.jump_off
                    } else {
                        &mut o.jump
                    };
                    *j = j.max((rep.force - f0).norm());
                    below_5n &= f0.norm() < 5.0 && rep.force.norm() < 5.0;
                    if below_5n {
                        o.jump_to_5n = o.jump_to_5n.max((rep.force.norm() - f0.norm()).abs());
                    }
                }
                last = Some(rep.force);
                let along = -rep.force.dot(&n);
                f_top = f_top.max(along);
                o.gave_way = o.gave_way.max(f_top - along);
                o.f_end = along;
                o.fmax = o.fmax.max(rep.force.norm());
                o.most_substeps = o.most_substeps.max(rep.substeps);
                // HOLD_MM: press to that depth and hold it, whatever the force (no feedback).
                match std::env::var("HOLD_MM").ok().and_then(|s| s.parse::<f64>().ok()) {
                    Some(hold) => depth = (depth + 5e-5).min(hold * 1e-3),
                    None if rep.force.norm() < 2.0 => depth = (depth + 5e-5).min(20e-3),
                    None => {}
                }
            }
            Err(e) => {
                o.error = Some(format!("tick {k} at {:.1} mm: {e}", depth * 1e3));
                return o;
            }
        }
    }
    o
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map_or("ventricle", |s| s.as_str());
    let (damped, fallback) = (args.iter().any(|a| a == "damped"), !args.iter().any(|a| a == "nofallback"));
    let model: HybridModel = match which {
        "ventricle" | "ellipsoids" => support::wall_model(which),
        f => HybridModel::load(std::path::Path::new(f)).unwrap(),
    };
    let mut options = SimOptions { shell_fallback: if fallback { SimOptions::default().shell_fallback } else { None }, ..SimOptions::default() };
    // TOOL_K [N/m^3], TOOL_C [N s/m^3]: the contact's stiffness and damping per unit of skin area.
    let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<f64>().ok());
    if let Some(k) = env("TOOL_K") {
        options.tool.area_stiffness = Some(k);
    }
    if let Some(c) = env("TOOL_C") {
        options.tool.area_damping = c;
    }
    let sim = Sim::new(model, tissue(damped), options).unwrap();
    let (lo, hi) = palpate_core::runtime::scale::bounding_box(&sim.hybrid.outer_points);
    let mut failed = 0;
    for zi in 1..=4 {
        let z = lo.z + (hi.z - lo.z) * zi as f64 / 5.0;
        for ti in 0..6 {
            // POINT=zi,ti: one point only (zi in 1..=4, ti in 0..6).
            if let Ok(pt) = std::env::var("POINT") {
                if pt != format!("{zi},{ti}") {
                    continue;
                }
            }
            let theta = ti as f64 * std::f64::consts::PI / 3.0 + 0.3;
            let o = press(&sim, z, theta);
            failed += (!o.shed.is_empty() || o.error.is_some()) as usize;
            let shed: Vec<String> = o.shed.iter().map(|(k, d)| format!("{k} ({:.1} mm)", d * 1e3)).collect();
            println!(
                "z {:5.1} mm, theta {:.2}: max force {:.3} N (at the end {:.3} N, gave way by {:.3} N; largest change a tick until 5 N {:.3} N), most sub-steps {:2}, shell shed at ticks [{}], {} ticks off, largest force change {:.3} N (at the shed: {:.3} N, shell off: {:.3} N){}",
                z * 1e3,
                theta,
                o.fmax,
                o.f_end,
                o.gave_way,
                o.jump_to_5n,
                o.most_substeps,
                shed.join(", "),
                o.off,
                o.jump,
                o.jump_shed,
                o.jump_off,
                o.error.map(|e| format!(", STOPPED {e}")).unwrap_or_default()
            );
        }
    }
    println!("{which} ({}): the shell failed at {failed} of 24 points", if damped { "damped" } else { "undamped" });
}
