//! The hybrid tick under a hand (issue 12's tests): regions entering and leaving under a slow
//! slide must not jerk the force; the confinement keeps the active particles in their regions and
//! a held tool does not pump energy in; a deep press stays finite.
//!
//! What a wrong implementation would do: start entering particles somewhere other than where the
//! core and skin carry them, or drop leaving ones while they still carry load (a force step at
//! each region change); let the wall leak or push energy in; take the shell's explicit sub-steps
//! at the rest-linearised count while a press stretches it (a deep press diverged so).

#[path = "support/walls.rs"]
mod walls;

use palpate_core::hybrid::HybridModel;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace, TickReport};
use palpate_core::{Material, StepError, Vec3};

fn ventricle() -> &'static HybridModel {
    &walls::ventricle().1
}

fn ellipsoids() -> &'static HybridModel {
    &walls::ellipsoids().1
}

/// Myocardium as the protocol has it (30 kPa, nu 0.4), undamped: the hardest case for the
/// explicit shell.
fn tissue() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap()
}

/// The outer vertex nearest `(x_max, 0, z)` on the `+x` side and the inward horizontal normal
/// there (the protocol's probe for `z = 20 mm`).
fn probe(sim: &Sim, z: f64) -> (Vec3, Vec3) {
    let outer = &sim.hybrid.outer_points;
    let p = *outer
        .iter()
        .filter(|q| q.x > 0.0)
        .min_by(|a, b| (a.y.powi(2) + (a.z - z).powi(2)).total_cmp(&(b.y.powi(2) + (b.z - z).powi(2))))
        .unwrap();
    (p, -Vec3::new(p.x, p.y, 0.0).normalize())
}

/// Runs `path` (tool centres, one per 1 ms tick), checking every tick with `check`; panics on a
/// failed tick, naming it.
fn run(sim: &Sim, path: impl Iterator<Item = Vec3>, mut check: impl FnMut(usize, &SimState, &TickReport)) {
    let mut st = SimState::rest(sim);
    let mut ws = SimWorkspace::new(sim);
    for (k, c) in path.enumerate() {
        let r = tick(sim, &mut st, &mut ws, c, 1e-3).unwrap_or_else(|e| panic!("tick {k}: {e}"));
        check(k, &st, &r);
    }
}

#[test]
fn the_force_does_not_jerk_when_regions_enter_and_leave_under_a_slow_slide() {
    slow_slide(false);
}

/// The same, and the press toward 2 N, with the springs at `E h` and their implicit share
/// (`runtime/exchange.rs`; lifted with the exchange explicit, the 2 N press shed the shell at
/// 16.4 mm on the ventricle and this slide's force jumped 0.011 N).
#[test]
fn the_implicit_exchange_holds_a_slow_slide_and_a_press_toward_2_n() {
    slow_slide(true);
    let opts = SimOptions { implicit_exchange: true, ..SimOptions::default() };
    let fv = press_toward_2_n_with(ventricle(), 0.02, opts);
    let fe = press_toward_2_n_with(ellipsoids(), 0.02, opts);
    println!("implicit exchange, largest force over 20 mm of travel: ventricle {fv:.3} N, ellipsoids {fe:.3} N");
    assert!(fv > 0.1 && fe > 0.05, "{fv} {fe}");
}

fn slow_slide(implicit_exchange: bool) {
    let sim = Sim::new(ventricle().clone(), tissue(), SimOptions { implicit_exchange, ..SimOptions::default() }).unwrap();
    let (p, n) = probe(&sim, 0.02);
    let r = sim.options.tool.radius;
    let t = Vec3::new(0.0, 0.0, 1.0).cross(&n).normalize(); // circumferential
    let depth = 3e-3;
    // Press over 0.3 s, hold 0.1 s, slide 20 mm at 10 mm/s.
    let path: Vec<Vec3> = (0..2400)
        .map(|k| {
            let (d, s) = if k < 300 {
                ((k + 1) as f64 / 300.0 * depth, 0.0)
            } else if k < 400 {
                (depth, 0.0)
            } else {
                (depth, 0.02 * (k - 399) as f64 / 2000.0)
            };
            // The sphere tangent to the surface at depth 0, `d` into it along the inward normal.
            p - n * (r - d) + t * s
        })
        .collect();
    let (mut changes, mut last, mut worst) = (0usize, Vec3::zeros(), (0.0f64, 0usize));
    run(&sim, path.into_iter(), |k, _, rep| {
        if k >= 400 && (rep.entered > 0 || rep.left > 0) {
            changes += 1;
            let jump = (rep.force - last).norm();
            let allowed = (0.05 * rep.force.norm()).max(0.01);
            if jump / allowed > worst.0 {
                worst = (jump / allowed, k);
            }
            assert!(jump <= allowed, "tick {k}: {} in, {} out, the force jumped {jump:.4} N (|f| {:.4} N)", rep.entered, rep.left, rep.force.norm());
        }
        last = rep.force;
    });
    assert!(changes >= 20, "the slide changed the active regions at only {changes} ticks");
    println!("{changes} ticks with regions entering or leaving; worst jump {:.2} of the allowance (tick {})", worst.0, worst.1);
}

#[test]
fn confinement_keeps_the_active_particles_in_their_regions_and_a_held_tool_pumps_no_energy() {
    let sim = Sim::new(ventricle().clone(), tissue(), SimOptions::default()).unwrap();
    let (p, n) = probe(&sim, 0.02);
    let r = sim.options.tool.radius;
    let depth = 4e-3;
    let path = (0..1300).map(|k| p - n * (r - depth * ((k + 1) as f64 / 300.0).min(1.0)));
    let (h, grid) = (sim.hybrid.spacing, &sim.hybrid.grid);
    let mut kinetic = Vec::new();
    let mut worst: f64 = 0.0;
    run(&sim, path, |k, st, rep| {
        // Every active particle, pulled back to the core's rest frame, lies in the allowed set
        // (its regions' voxels), or no farther outside than its anchor (its slack), give or take
        // the elastic wall's give: one voxel.
        let counts = st.activation.triangle_counts();
        for &i in &st.particles.active {
            let shift = sim.particle_tie.position(i, &st.core.x) - sim.hybrid.particles[i];
            let anchor = sim.hybrid.particles[i];
            let push = sim.confinement.push(grid, &sim.hybrid.voxel_owner, counts, &(st.particles.x[i] - shift), &anchor);
            let slack = sim.confinement.slack(grid, &sim.hybrid.voxel_owner, counts, &anchor);
            let outside = push.distance - slack.max(0.0);
            worst = worst.max(outside / grid.h);
            assert!(
                outside <= grid.h,
                "tick {k}: particle {i} is {:.2} voxels outside its regions ({:?}, slack {slack:.2e}, distance {:.2e}, voxel {:.2e}, held {}, u {:.2e})",
                outside / grid.h,
                push.placement,
                push.distance,
                grid.h,
                sim.particles.fixed()[i],
                (st.particles.x[i] - shift - anchor).norm()
            );
        }
        if k >= 300 {
            let m = sim.particles.masses();
            kinetic.push(st.particles.active.iter().map(|&i| 0.5 * m[i] * st.particles.v[i].norm_squared()).sum::<f64>());
        }
        assert!(rep.force.norm() < 1.0, "tick {k}: {:?}", rep.force);
    });
    // Held still for a second: the shell's kinetic energy does not grow (the last half's peak is
    // no more than the first half's).
    let half = kinetic.len() / 2;
    let first = kinetic[..half].iter().cloned().fold(0.0, f64::max);
    let second = kinetic[half..].iter().cloned().fold(0.0, f64::max);
    println!("worst: {worst:.2} voxels outside; kinetic peak {first:.3e} J then {second:.3e} J (spacing {h:.2e} m)");
    assert!(second <= first * 1.05 + 1e-12, "the held tool pumped energy in: peak {first:.3e} J, then {second:.3e} J");
}

/// Presses to 15 mm (three times the tool's radius, past the 6 mm wall) at 50 mm/s and holds.
fn deep_press(model: &HybridModel, z: f64) -> f64 {
    let sim = Sim::new(model.clone(), tissue(), SimOptions::default()).unwrap();
    let (p, n) = probe(&sim, z);
    let r = sim.options.tool.radius;
    let depth = 15e-3;
    let path = (0..400).map(|k| p - n * (r - depth * ((k + 1) as f64 / 300.0).min(1.0)));
    let mut fmax: f64 = 0.0;
    run(&sim, path, |_, _, rep| fmax = fmax.max(rep.force.norm()));
    fmax
}

#[test]
fn a_15_mm_press_on_the_ventricle_stays_finite() {
    let f = deep_press(ventricle(), 0.02);
    assert!(f > 0.1 && f < 5.0, "max force {f} N");
}

#[test]
fn a_15_mm_press_on_the_ellipsoids_stays_finite() {
    let f = deep_press(ellipsoids(), 0.02);
    assert!(f > 0.01 && f < 5.0, "max force {f} N");
}

/// A hand pressing with 2 N: the tool advances at 50 mm/s until the force on it reaches 2 N, then
/// holds. These organs are soft (30 kPa, held at the base or the lower third): 2 N needs more
/// travel than the organ has (the ventricle gives ~0.5 N at 20 mm, the tool then through its
/// 6 mm wall and deep in the cavity), so the travel is capped at 20 mm; every tick must stay
/// finite. Returns the largest force \[N\].
fn press_toward_2_n(model: &HybridModel, z: f64) -> f64 {
    press_toward_2_n_with(model, z, SimOptions::default())
}

fn press_toward_2_n_with(model: &HybridModel, z: f64, options: SimOptions) -> f64 {
    let sim = Sim::new(model.clone(), tissue(), options).unwrap();
    let (p, n) = probe(&sim, z);
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (mut depth, mut fmax) = (0.0f64, 0.0f64);
    for k in 0..500 {
        let rep = tick(&sim, &mut st, &mut ws, p - n * (r - depth), 1e-3).unwrap_or_else(|e| panic!("tick {k} at {:.1} mm: {e}", depth * 1e3));
        // The shell itself holds here: the fallback (next tests) must not be what passes this.
        assert!(!rep.shell_failed, "tick {k} at {:.1} mm: the shell failed", depth * 1e3);
        fmax = fmax.max(rep.force.norm());
        if rep.force.norm() < 2.0 {
            depth = (depth + 5e-5).min(20e-3);
        }
    }
    fmax
}

#[test]
fn a_press_toward_2_n_stays_finite_on_the_ventricle_and_the_ellipsoids() {
    let fv = press_toward_2_n(ventricle(), 0.02);
    let fe = press_toward_2_n(ellipsoids(), 0.02);
    println!("largest force over 20 mm of travel: ventricle {fv:.3} N, ellipsoids {fe:.3} N");
    assert!(fv > 0.1 && fe > 0.05, "{fv} {fe}");
}

/// A hand pressing toward 5 N beside the paper's ellipsoids' held base (a fifth of the height up,
/// where the core does not move): the tool must not pass through the organ. Before the core's
/// surface met the tool as a surface (`runtime::core_contact`, 2026-11-27) it did: the force rose
/// to 0.69 N at 6 mm of travel, then the skin slipped over the sphere and the tool between the
/// coarse core's nodes, and the force turned to pull the tool in (-0.47 N at 7.5 mm) and was zero
/// past 11 mm. Now the held core stops it: 5 N is reached, and on the way the force along the
/// press never falls below its running maximum by more than a tenth of it.
#[test]
fn a_press_toward_5_n_beside_the_held_base_does_not_pass_through_the_organ() {
    let sim = Sim::new(ellipsoids().clone(), tissue(), SimOptions::default()).unwrap();
    let (lo, hi) = sim.hybrid.outer_points.iter().fold((f64::MAX, f64::MIN), |(l, h), p| (l.min(p.z), h.max(p.z)));
    let (p, n) = probe(&sim, lo + 0.2 * (hi - lo));
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (mut depth, mut top, mut gave, mut reached) = (-2e-3f64, 0.0f64, 0.0f64, None);
    for k in 0..600 {
        let rep = tick(&sim, &mut st, &mut ws, p - n * (r - depth), 1e-3).unwrap_or_else(|e| panic!("tick {k} at {:.1} mm: {e}", depth * 1e3));
        // The force along the press (the tissue pushing the tool back out).
        let along = -rep.force.dot(&n);
        top = top.max(along);
        gave = gave.max((top - along) / top.max(0.5));
        if rep.force.norm() >= 5.0 {
            reached = Some(depth);
            break;
        }
        depth = (depth + 5e-5).min(25e-3);
    }
    println!(
        "beside the held base: 5 N reached at {:?} mm of travel; the force along the press fell at most {:.1}% below its running maximum",
        reached.map(|d| d * 1e3),
        100.0 * gave
    );
    assert!(reached.is_some(), "the organ never gave 5 N over 25 mm of travel (largest along the press: {top:.3} N)");
    assert!(gave < 0.1, "the force along the press fell {:.1}% below its running maximum", 100.0 * gave);
    // Then a slide of 10 mm at 20 mm/s along the surface, the depth held: the tool's nearest
    // point on the core runs across faces, edges and vertices, and the force must not jump
    // (measured 0.046 N a tick at ~5.5 N; a side flipping at an edge would jump by 2 k d).
    let tangent = n.cross(&Vec3::z()).normalize();
    let (mut last, mut jump) = (None::<Vec3>, 0.0f64);
    for k in 0..500 {
        let slide = (2e-5 * k as f64).min(10e-3);
        let rep = tick(&sim, &mut st, &mut ws, p - n * (r - depth) + tangent * slide, 1e-3).unwrap_or_else(|e| panic!("slide tick {k}: {e}"));
        assert!(rep.force.iter().all(|c| c.is_finite()));
        if let Some(f0) = last {
            jump = jump.max((rep.force - f0).norm());
        }
        last = Some(rep.force);
    }
    println!("the slide along the held base under ~5 N: largest force change a tick {jump:.3} N");
    assert!(jump < 0.1, "the force jumped by {jump:.3} N in a tick while sliding");
}

/// The tick looks only at the skin vertices that can be within the tool's reach (the live list,
/// rebuilt at each whole update of the skin) and updates only those near the tool: under a
/// pressed slide at the tool's top speed, every vertex within the tool's reach
/// must still be where the core and the particles put it, every tick (a live list that forgot
/// the tool's travel, or vertices that moved, would leave some stale: contact and activation
/// would then miss them).
#[test]
fn the_skin_within_the_tools_reach_is_fresh_every_tick_under_a_fast_slide() {
    let sim = Sim::new(ventricle().clone(), tissue(), SimOptions::default()).unwrap();
    let (p, n) = probe(&sim, 0.02);
    let r = sim.options.tool.radius;
    let reach = r + sim.options.activation_margin;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let mut fresh = vec![Vec3::zeros(); st.skin.len()];
    let (mut checked, mut worst) = (0usize, 0.0f64);
    for k in 0..300 {
        // Pressed in, sliding to and fro around the axis, up to 0.5 m/s (the simulated tool's top
        // speed), over 40 degrees of arc.
        let turn = nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), 0.35 * ((k as f64) * 0.025).sin());
        let c = turn * (p + n * (4e-3 - r));
        tick(&sim, &mut st, &mut ws, c, 1e-3).unwrap_or_else(|e| panic!("tick {k}: {e}"));
        let tool = st.tool.unwrap();
        sim.skin_positions(&st, &mut fresh);
        for (v, f) in fresh.iter().enumerate() {
            if (f - tool).norm() < reach + 1e-3 {
                let d = (st.skin[v] - f).norm();
                worst = worst.max(d);
                assert!(d < 1e-9, "tick {k}: skin vertex {v} within reach is {d:.3e} m from where it is");
                checked += 1;
            }
        }
    }
    println!("{checked} skin vertices within reach checked, worst {worst:.2e} m from fresh");
    assert!(checked > 300);
}

/// Largest speed \[m/s\] of an active particle relative to the active particles' mass-weighted
/// mean velocity (what `palpate_core::divergence` bounds).
fn active_relative_speed(sim: &Sim, st: &SimState) -> f64 {
    let (m, v, active) = (sim.particles.masses(), &st.particles.v, &st.particles.active);
    let total: f64 = active.iter().map(|&p| m[p]).sum();
    let mean = active.iter().map(|&p| m[p] * v[p]).sum::<Vec3>() / total.max(f64::MIN_POSITIVE);
    active.iter().map(|&p| (v[p] - mean).norm()).fold(0.0, f64::max)
}

/// Issue 15, item 4, in the hybrid tick: a shell under-stepped by its sub-step cap (9
/// sub-steps of a 1 ms tick where its stability asks for ~12 at rest) diverges under a light
/// press. The tick must fail with `StepError::Diverging` (the particle step's speed bound), every
/// value finite, the core and the particles' motion as at the tick's start, within 6 ticks of the
/// fastest active particle passing the wave speed `c_p`; without the bound it runs on to
/// `NonFinite` and this test fails.
#[test]
fn an_under_stepped_shell_is_reported_diverging_when_it_starts() {
    // The shell's own failure, as the tick reports it without the fallback (see the next test).
    let options = SimOptions { max_substeps: 9, shell_fallback: None, ..SimOptions::default() };
    let sim = Sim::new(ventricle().clone(), tissue(), options).unwrap();
    let c = tissue().wave_speed();
    let (p, n) = probe(&sim, 0.02);
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let mut passed_c = None;
    for k in 0..2000 {
        let depth = 3e-3 * ((k + 1) as f64 / 100.0).min(1.0);
        let (core_x, core_v, px, pv, was_active) =
            (st.core.x.clone(), st.core.v.clone(), st.particles.x.clone(), st.particles.v.clone(), st.particles.active.clone());
        match tick(&sim, &mut st, &mut ws, p - n * (r - depth), 1e-3) {
            Ok(_) => {
                let s = active_relative_speed(&sim, &st);
                if s > c {
                    passed_c.get_or_insert(k);
                }
            }
            Err(e) => {
                let StepError::Diverging { speed, bound, .. } = e else {
                    panic!("tick {k}: {e} (expected Diverging)")
                };
                println!("tick {k}: {e}; first past c_p at {passed_c:?}");
                assert!(speed > bound);
                assert!(st.core.x == core_x && st.core.v == core_v, "the core was not restored");
                // The free particles active before and after: as they were (the activation keeps
                // the tick's update, so entering and leaving particles are at their ties, and the
                // held ones follow the core).
                for &q in was_active.iter().filter(|&&q| st.particles.active.contains(&q) && !sim.particles.fixed()[q]) {
                    assert!(st.particles.x[q] == px[q] && st.particles.v[q] == pv[q], "particle {q} was not restored");
                }
                assert!(st.core.x.iter().chain(&st.particles.x).chain(&st.particles.v).all(|p| p.iter().all(|c| c.is_finite())));
                let first = passed_c.unwrap_or(k);
                assert!(k - first <= 6, "reported at tick {k}, {} ticks after passing c_p", k - first);
                return;
            }
        }
    }
    panic!("no divergence reported in 2000 ticks");
}

/// The fallback (`SimOptions::shell_fallback`, default): the same under-stepped shell's failed
/// step does not fail the tick. The tick sheds the shell (no particle active, every one at its
/// tie), the tool meets the skin and the core (the hand still feels the press), the shell stays
/// off for the pause (0.1 s, 100 ticks) and, past it, while the tool still presses; once the tool is
/// lifted clear of the skin (within the activation margin) its regions enter again. Every value
/// stays finite.
#[test]
fn a_failed_shell_step_is_shed_and_the_tick_goes_on_with_the_core() {
    let options = SimOptions { max_substeps: 9, ..SimOptions::default() };
    let pause = (options.shell_fallback.unwrap() / 1e-3).round() as u64;
    let sim = Sim::new(ventricle().clone(), tissue(), options).unwrap();
    let (p, n) = probe(&sim, 0.02);
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (mut failed_at, mut touched_after_lift) = (None, 0);
    let (mut restored, mut checked_restore) = (None, false);
    for k in 0..600 {
        // Pressed to 3 mm and held until 150 ticks past the failure, then lifted 0.5 mm clear.
        let lifted = failed_at.is_some_and(|f| k > f + pause as usize + 50);
        let depth = if lifted { -0.5e-3 } else { 3e-3 * ((k + 1) as f64 / 100.0).min(1.0) };
        let rep = tick(&sim, &mut st, &mut ws, p - n * (r - depth), 1e-3).unwrap_or_else(|e| panic!("tick {k}: {e} (the fallback should have caught it)"));
        assert!(rep.force.iter().all(|c| c.is_finite()) && st.core.x.iter().chain(&st.skin).all(|x| x.iter().all(|c| c.is_finite())), "tick {k}: not finite");
        if let Some((mut st2, mut ws2)) = restored.take() {
            // The copy restored after the last tick, given this tick's input.
            let rep2 = tick(&sim, &mut st2, &mut ws2, p - n * (r - depth), 1e-3).unwrap();
            assert!(rep2.shell_off && rep2.active == 0, "a restored state's shell came back during its pause: {rep2:?}");
            assert_eq!(rep2.force, rep.force, "tick {k}: the restored state's force differs (its fade or pause was not restored)");
            checked_restore = true;
        }
        match failed_at {
            None if rep.shell_failed => {
                assert_eq!((rep.active, st.particles.active.len()), (0, 0), "tick {k}: the shell was not shed");
                failed_at = Some(k);
            }
            None => {}
            Some(f) if !lifted => {
                assert!(rep.shell_off && rep.active == 0 && !rep.shell_failed, "tick {k}: the shell is back under the held press ({rep:?})");
                if k == f + 10 {
                    // The pause and the skin's fade are part of the state: a restored state stays
                    // off as the original, and its next tick gives the same force, bit for bit.
                    restored = Some(SimState::restore(&sim, &st.snapshot(&ws)).unwrap());
                }

                // 0.0099 N at tick 5 (0.15 mm deep, 2026-12-08: the shed shell's share fading
                // out of the core's stiffness with its skin); any press gives more than 5 mN.
                assert!(rep.force.norm() > 0.005 && rep.skin_contacts > 0, "tick {k}: the tool should meet the skin, force {:.4} N", rep.force.norm());
                let _ = f;
            }
            Some(f) => {
                // Lifted (the simulated tool rises 0.5 mm a tick): the shell stays off while it
                // touches and one tick after; then the regions within the margin enter again
                // (and this under-stepped shell may fail again, caught the same way).
                if rep.skin_contacts + rep.core_contacts > 0 {
                    assert!(rep.shell_off, "tick {k}: the shell came back while the tool touches");
                    touched_after_lift = k;
                } else if !rep.shell_off {
                    assert_eq!(k, touched_after_lift + 2, "tick {k}: the shell came back late or early");
                    assert!(rep.active > 0 || rep.shell_failed, "tick {k}: the shell did not come back (failed at {f}): {rep:?}");
                    println!(
                        "shell failed at tick {f}, off until the tool let go, back at tick {k}: {} particles entered, failed again: {}",
                        rep.entered, rep.shell_failed
                    );
                    assert!(checked_restore, "the restored state was never ticked");
                    return;
                }
            }
        }
    }
    panic!("the shell failed at {failed_at:?} and did not come back");
}

/// The hand's worst where the shell cannot follow: a press toward 2 N beside the held base of the
/// synthetic ventricle (z = 33.6 mm, 6 mm below the base; measured: the SVK core's elements
/// under the tool collapse there from ~6.5 mm of travel (measured 2026-12-07, with a contact
/// of 60-170 N/m a skin vertex alike), the shell's ties turned with them
/// distort the particles past what the sub-step cap holds, and the shell's step diverges).
/// With the fallback every tick succeeds, the force stays finite and bounded, and the shell is
/// shed at most once per pause.
#[test]
fn a_press_toward_2_n_beside_the_held_base_never_fails_a_tick() {
    let sim = Sim::new(ventricle().clone(), tissue(), SimOptions::default()).unwrap();
    let (p, n) = probe(&sim, 0.0336);
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (mut depth, mut fmax, mut failures, mut off) = (0.0f64, 0.0f64, 0, 0);
    // The largest tick-to-tick force change from the shed tick on (the shell off).
    let (mut last, mut shed_at, mut off_jump) = (Vec3::zeros(), None, 0.0f64);
    for k in 0..500 {
        let rep = tick(&sim, &mut st, &mut ws, p - n * (r - depth), 1e-3).unwrap_or_else(|e| panic!("tick {k} at {:.1} mm: {e}", depth * 1e3));
        assert!(rep.force.iter().all(|c| c.is_finite()), "tick {k}: force not finite");
        if rep.shell_failed {
            shed_at = Some(k);
        }
        if shed_at.is_some() {
            off_jump = off_jump.max((rep.force - last).norm());
        }
        last = rep.force;
        fmax = fmax.max(rep.force.norm());
        failures += rep.shell_failed as usize;
        off += rep.shell_off as usize;
        if rep.force.norm() < 2.0 {
            depth = (depth + 5e-5).min(20e-3);
        }
    }
    println!("beside the base: largest force {fmax:.3} N, shell shed {failures} times, off {off} ticks of 500, largest force change a tick from the shed on {off_jump:.3} N");
    // Before 2026-11-27 this was 1.53 N: the contact held explicitly over the core's step
    // chattered, and the skin went back to its ties at once (runtime::core_contact, SkinLift).
    // Measured since: 0.112 N, at the shed tick (0.25 -> 0.14 N: the core, pressed directly
    // now, gives way where the particles held), then at most 0.05 N a tick. With the contact per
    // unit of skin area (2026-12-07; this skin's vertices carry 2.0 mm^2, 172 N/m each) the
    // shell fails at 6.55 mm of travel (6.35-6.55 mm with 3e7-8.6e7 N/m^3: the core's collapse,
    // not the contact, sets it); its last ticks before the shed climb to the sub-step cap and
    // the force spikes 0.28 -> 0.36 N, so the largest change is 0.179 N, of which the shed
    // itself (0.28 -> 0.20 N) is 0.08 N; 0.087 and 0.109 N with 6e7 and 3e7 N/m^3. With the
    // core under the shell at the build's active factor (2026-12-08) the shell fails at 7.9 mm,
    // and the largest change was 0.245 N three ticks after the shed, the core under the tool
    // stiffening at once from the active factor to the wall's (0.56 -> 1.96); with the shell's
    // share fading out with its skin (homogenised_core::softened_tets) it is 0.113 N, the shed.
    assert!(off_jump < 0.2, "from the shed on the force changed by {off_jump:.3} N in a tick");
    assert!(fmax < 5.0, "largest force {fmax} N");
    assert!(failures <= 5, "{failures} failures in 500 ticks: more than one per pause");
    assert!(st.skin.iter().chain(&st.core.x).all(|x| x.iter().all(|c| c.is_finite())));
}

/// A press to 8 mm and a release: the skin away from the tool is refreshed by sweeps, a slice a
/// tick, never all at once after the first tick (a whole update of a fine skin is a tick's budget
/// several times over), and every stored vertex stays within the margin of its place.
#[test]
fn the_far_skin_is_refreshed_a_slice_a_tick_and_stays_within_its_margin() {
    use palpate_core::runtime::tick::{SKIN_LIVE_MARGIN, SKIN_SWEEP_TICKS};
    let sim = Sim::new(ventricle().clone(), tissue(), SimOptions::default()).unwrap();
    let (p, n) = probe(&sim, 0.02);
    let r = sim.options.tool.radius;
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let n_skin = st.skin.len();
    let slice = n_skin.div_ceil(SKIN_SWEEP_TICKS);
    let mut fresh = vec![Vec3::zeros(); n_skin];
    let (mut total, mut most, mut worst) = (0usize, 0usize, 0.0f64);
    for k in 0..700 {
        let depth = if k < 400 { 8e-3 * k as f64 / 400.0 } else { 8e-3 * (700 - k) as f64 / 300.0 } - 2e-3;
        let rep = tick(&sim, &mut st, &mut ws, p - n * (r - depth), 1e-3).unwrap_or_else(|e| panic!("tick {k}: {e}"));
        if k > 0 {
            total += rep.skin_refreshed;
            most = most.max(rep.skin_refreshed);
        }
        sim.skin_positions(&st, &mut fresh);
        worst = worst.max((0..n_skin).map(|v| (st.skin[v] - fresh[v]).norm()).fold(0.0, f64::max));
    }
    println!("{total} far skin vertices refreshed over 699 ticks, at most {most} in one (a slice is {slice} of {n_skin}); stored skin at most {worst:.2e} m from its place");
    assert!(total > 2 * n_skin, "the press must make the skin be refreshed: {total}");
    assert!(most <= slice, "a tick refreshed {most} far vertices at once (a slice is {slice})");
    assert!(worst <= SKIN_LIVE_MARGIN, "a stored skin vertex is {worst:e} m from its place");
}
