//! The particle passes split over threads (`runtime::tick_with`, `meshfree::step_with_fork`)
//! give bitwise the tick of one thread: each particle's arithmetic is the same whichever part
//! computes it, and the parts write disjoint particles.
//!
//! What a wrong split would do: drop or repeat the particles at a part's edge (states differ),
//! let a part read a `B` another part has not written yet (a missing wait: states differ, now
//! and then), or pick another "fastest" particle than one sweep does (a different divergence
//! report).

#[path = "support/press.rs"]
mod press;
#[path = "support/walls.rs"]
mod walls;

use palpate_core::material::{Damping, Elasticity};
use palpate_core::meshfree::{self, ParticleModel, ParticleState, ParticleWorkspace, SubStep};
use palpate_core::parallel::Fork;
use palpate_core::runtime::{tick, tick_with, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::{Material, Vec3};

/// `ways` parts on scoped threads, started afresh at every fork (slow, and simple: a test's).
struct Threads(usize);

// SAFETY: `job(k)` once for each `k < ways`, all joined before `fork` returns (the scope).
unsafe impl Fork for Threads {
    fn ways(&self) -> usize {
        self.0
    }
    fn fork(&self, job: &(dyn Fn(usize) + Sync)) {
        std::thread::scope(|s| {
            for k in 1..self.0 {
                s.spawn(move || job(k));
            }
            job(0);
        });
    }
}

fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::from_paper(0.05, 0.05)).unwrap()
}

/// The ellipsoids' sim, the press point, its inward normal, a tangent there and the tool radius
/// \[m\].
fn press_case() -> (Sim, Vec3, Vec3, Vec3, f64) {
    let (_, model) = walls::ellipsoids();
    let sim = Sim::new(model.clone(), material(), SimOptions::default()).unwrap();
    let (p0, n) = press::press_point(&sim.hybrid.outer_points);
    let t = n.cross(&Vec3::z()).normalize();
    let r = sim.options.tool.radius;
    (sim, p0, n, t, r)
}

fn same_state(a: &SimState, b: &SimState) -> bool {
    a.core.x == b.core.x && a.core.v == b.core.v && a.particles.x == b.particles.x && a.particles.v == b.particles.v && a.skin == b.skin && a.tool == b.tool
}

#[test]
fn a_press_and_slide_split_over_threads_is_bitwise_the_serial_one() {
    let (sim, p0, n, t, r) = press_case();
    let mut serial = (SimState::rest(&sim), SimWorkspace::new(&sim));
    let mut split: Vec<(Threads, SimState, SimWorkspace)> = [2, 3].into_iter().map(|w| (Threads(w), SimState::rest(&sim), SimWorkspace::new(&sim))).collect();
    let (mut busiest, mut moved) = (0, 0);
    for k in 0..160usize {
        // 4 mm in over 80 ticks, then a 6 mm slide: regions enter and leave.
        let depth = 4e-3 * (k.min(80) as f64 / 80.0);
        let slide = 6e-3 * (k.saturating_sub(80) as f64 / 80.0);
        let tool = p0 + n * (r - depth) + t * slide;
        let a = tick(&sim, &mut serial.0, &mut serial.1, tool, 1e-3).unwrap();
        busiest = busiest.max(a.active);
        moved += a.entered + a.left;
        for (fork, st, ws) in &mut split {
            let b = tick_with(&sim, st, ws, tool, 1e-3, &*fork).unwrap();
            assert_eq!(a.force, b.force, "tick {k}, {} ways", fork.0);
            assert_eq!((a.active, a.substeps), (b.active, b.substeps), "tick {k}, {} ways", fork.0);
            assert!(same_state(&serial.0, st), "tick {k}, {} ways: the states differ", fork.0);
        }
    }
    // The comparison covered a busy shell whose regions changed.
    assert!(busiest > 100 && moved > 50, "active at most {busiest}, {moved} entered or left");
}

/// A hand's worst on two threads: a 15 mm press in 60 ticks, then a 0.5 m/s slide (the simulated
/// tool follows at its step cap): finite, and bitwise the serial run.
#[test]
fn a_deep_press_and_fast_slide_on_two_threads_stay_finite_and_serial() {
    let (sim, p0, n, t, r) = press_case();
    let (mut a, mut wa) = (SimState::rest(&sim), SimWorkspace::new(&sim));
    let (mut b, mut wb) = (SimState::rest(&sim), SimWorkspace::new(&sim));
    let mut fmax = 0.0f64;
    for k in 0..120usize {
        let depth = 15e-3 * (k.min(60) as f64 / 60.0);
        let slide = 0.5e-3 * k.saturating_sub(60) as f64;
        let tool = p0 + n * (r - depth) + t * slide;
        let x = tick(&sim, &mut a, &mut wa, tool, 1e-3).unwrap();
        let y = tick_with(&sim, &mut b, &mut wb, tool, 1e-3, &Threads(2)).unwrap();
        assert!(x.force.iter().all(|f| f.is_finite()) && x.force == y.force, "tick {k}");
        assert!(same_state(&a, &b), "tick {k}: the states differ");
        fmax = fmax.max(x.force.norm());
    }
    assert!(fmax > 0.1, "the press must load the tool: {fmax} N");
}

#[test]
fn an_active_list_with_a_repeat_runs_on_one_thread_and_gives_the_serial_step() {
    let (_, model) = walls::ellipsoids();
    let sim = Sim::new(model.clone(), material(), SimOptions::default()).unwrap();
    let m: &ParticleModel = &sim.particles;
    let mut a = ParticleState::rest(m);
    a.active = (0..300).collect();
    a.active.push(17); // a repeat: its parts would share particle 17
    for (i, v) in a.v.iter_mut().enumerate() {
        *v = Vec3::new((i % 7) as f64 * 1e-3, -((i % 5) as f64) * 1e-3, 2e-3);
    }
    let mut b = a.clone();
    let (mut wa, mut wb) = (ParticleWorkspace::new(m), ParticleWorkspace::new(m));
    let none = |_: &SubStep<'_>, _: &mut [Vec3]| {};
    meshfree::step_with(m, &mut a, &mut wa, 1e-3, 12, none).unwrap();
    meshfree::step_with_fork(m, &mut b, &mut wb, 1e-3, 12, &Threads(2), none).unwrap();
    assert!(a.x == b.x && a.v == b.v);
}
