//! Checkpoint and restore of a hybrid simulation's state (the haptic loop's last good state):
//! `SimState::clone_from` copies every field (the copy then ticks on bit for bit as the original)
//! and, once the destination has seen a state as large, allocates nothing (a derived `Clone`
//! reallocated every array and the activation's ~8 MB region table on the Rodero model: 2.5 ms,
//! two and a half haptic ticks, every quarter second).
//!
//! What a wrong implementation would do: forget a field (the Debug strings differ, or the copy's
//! next ticks do), or allocate (the counting allocator sees it).

#[path = "support/alloc.rs"]
mod alloc;
#[path = "support/press.rs"]
mod press;
#[path = "support/walls.rs"]
mod walls;

use alloc::allocations;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::{Material, Vec3};

fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::from_paper(0.5, 0.5)).unwrap()
}

/// The tool's centre at tick `k` of a press to 3 mm and a slide (regions enter and leave).
fn path(sim: &Sim, k: usize) -> Vec3 {
    let (p, out) = press::press_point(&sim.hybrid.outer_points);
    let r = sim.options.tool.radius;
    let depth = (k as f64 * 1e-4).min(3e-3) - 1e-3;
    let side = out.cross(&Vec3::z()).normalize();
    p + out * (r - depth) + side * (k.saturating_sub(40) as f64 * 2e-4)
}

#[test]
fn clone_from_copies_every_field_and_allocates_nothing_once_warm() {
    let sim = Sim::new(walls::ventricle().1.clone(), material(), SimOptions::default()).unwrap();
    let mut ws = SimWorkspace::new(&sim);
    let mut st = SimState::rest(&sim);
    let mut good = st.clone();
    let start = st.clone();
    let mut counted = None;
    let mut churn = 0;
    // Two passes of the same path: the first grows the checkpoint's arrays to their largest,
    // the second must not allocate in any checkpoint or restore.
    for pass in 0..2 {
        st.clone_from(&start);
        let before = allocations();
        for k in 0..120 {
            let r = tick(&sim, &mut st, &mut ws, path(&sim, k), 1e-3).unwrap();
            if pass == 1 {
                churn += r.entered + r.left;
                if k == 60 {
                    assert!(r.active > 50, "{r:?}");
                }
            }
            if k % 10 == 9 {
                good.clone_from(&st);
                st.clone_from(&good); // a restore to what was just saved changes nothing
            }
        }
        if pass == 1 {
            counted = Some(allocations() - before);
        }
    }
    assert!(churn > 100, "the path must make particles enter and leave: {churn}");
    assert_eq!(counted, Some(0), "checkpoints, restores or ticks allocated");
    // Every field: the Debug strings are equal, and the copy ticks on bit for bit.
    good.clone_from(&st);
    assert_eq!(format!("{good:?}"), format!("{st:?}"));
    let mut ws2 = SimWorkspace::new(&sim);
    let mut ws1 = SimWorkspace::new(&sim);
    // Workspaces carry marks keyed by their own epoch only: fresh ones on both sides.
    for k in 120..160 {
        let a = tick(&sim, &mut st, &mut ws1, path(&sim, k), 1e-3).unwrap();
        let b = tick(&sim, &mut good, &mut ws2, path(&sim, k), 1e-3).unwrap();
        assert_eq!(a.force, b.force, "tick {k}");
        assert_eq!(a.active, b.active);
    }
    assert_eq!(st.particles.x, good.particles.x);
    assert_eq!(st.core.x, good.core.x);
    assert_eq!(st.skin, good.skin);
}
