//! A full-FEM body as the servo's physics ([`FemPhysics`]), each promise a test that a wrong
//! implementation fails.
//!
//! What a wrong implementation would do:
//! - a force on the tool that is not the reaction of what the nodes received (a sign, a missed
//!   node, a force computed at another position than the one applied), or contact forces that
//!   leak momentum (`reaction_*`, `momentum_*`);
//! - a contact that adds something with the tool away (a stale external force, a damping term
//!   with the tool far, a different step) (`no_contact_*`);
//! - a contact stiffness that ignores the step's stability (a 15 mm press blows up), a restore
//!   that forgets a field (`hard_press_*`), or a failed step that leaves the contact forces or
//!   the tool moved (`a_diverging_step_*`);
//! - a tick or a checkpoint that allocates (`tick_*`);
//! - a hand's worst through the loop (a 5 N press, a 0.5 m/s slide) that reaches a non-finite
//!   force or state (`hand_worst_*`).

#[path = "../../palpate-core/tests/support/alloc.rs"]
mod alloc;

use alloc::allocations;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::mesh::generate::{ellipsoid_wall, EllipsoidWall};
use palpate_core::{step, Integrator, Material, Model, ModelBuilder, State, StepError, Vec3, Workspace};
use palpate_haptics::devices::Scripted;
use palpate_haptics::{CouplingParams, FemOptions, FemPhysics, HapticCore, Physics, SafetyParams};

const DT: f64 = 1e-3;

fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::from_paper(0.5, 0.5)).unwrap()
}

/// The paper's ellipsoids model (192 tets, 54 nodes; `palpate bench`'s `ellipsoid_192`), its
/// base half (z <= 0) held, with `gravity` and `integrator`.
fn ellipsoid(gravity: Vec3, integrator: Integrator, fixed_base: bool) -> Model {
    let mesh = ellipsoid_wall(&EllipsoidWall::default());
    let fixed: Vec<usize> = if fixed_base { (0..mesh.n_nodes()).filter(|&i| mesh.points()[i].z <= 1e-9).collect() } else { vec![] };
    ModelBuilder::new(mesh, material()).fixed_nodes(fixed).gravity(gravity).integrator(integrator).build().unwrap()
}

/// The free boundary node with the largest x above the equator, and its outward direction.
fn probe(p: &FemPhysics) -> (Vec3, Vec3) {
    let m = p.model();
    let i = *p.boundary_nodes().iter().filter(|&&i| !m.fixed()[i] && m.mesh().points()[i].z > 0.005).max_by(|&&a, &&b| m.mesh().points()[a].x.total_cmp(&m.mesh().points()[b].x)).unwrap();
    let x = m.mesh().points()[i];
    (x, Vec3::new(x.x, x.y, 0.0).normalize())
}

/// The tool centre at tick `k` of a press `depth` \[m\] into the surface at `(p, n)` over 300
/// ticks (starting 2 mm clear), a hold, then a slide along z at `slide_speed` \[m/s\].
fn path(p: Vec3, n: Vec3, r: f64, depth: f64, slide_speed: f64, k: usize) -> Vec3 {
    let d = -0.002 + (depth + 0.002) * (k as f64 / 300.0).min(1.0);
    let s = slide_speed * DT * k.saturating_sub(400) as f64;
    p + n * (r - d) + Vec3::z() * s
}

#[test]
fn reaction_is_exactly_the_opposite_of_the_forces_on_the_nodes() {
    let mut ph = FemPhysics::new(ellipsoid(Vec3::zeros(), Integrator::default(), true), FemOptions::default()).unwrap();
    let (p, n) = probe(&ph);
    let r = FemOptions::default().tool.radius;
    let mut touched = 0;
    for k in 0..600 {
        let f = ph.tick(&path(p, n, r, 0.008, 0.1, k), DT).unwrap();
        // The step's external forces are the tick's contact forces, in node order: their sum's
        // opposite, bit for bit (the same additions in the same order).
        let sum = ph.state().f_ext.iter().fold(Vec3::zeros(), |a, f| a + f);
        assert_eq!(f, -sum, "tick {k}");
        if f.norm() > 0.0 {
            touched += 1;
        }
    }
    assert!(touched > 300, "the press must touch: {touched} ticks");
}

#[test]
fn momentum_of_a_free_body_changes_by_the_tools_impulse() {
    // A free body, no gravity, Newton to a tight tolerance: the step's momentum change is
    // `dt sum f_ext`, so it must be minus the tool's force times dt.
    let model = ellipsoid(Vec3::zeros(), Integrator::BackwardEulerNewton { max_iterations: 50, tolerance: 1e-12 }, false);
    let mut ph = FemPhysics::new(model, FemOptions::default()).unwrap();
    let (p, n) = probe(&ph);
    let r = FemOptions::default().tool.radius;
    let mut worst: f64 = 0.0;
    let mut impulse = Vec3::zeros();
    for k in 0..200 {
        let before = ph.model().momentum(&ph.state().v);
        let f = ph.tick(&path(p, n, r, 0.004, 0.0, k), DT).unwrap();
        let change = ph.model().momentum(&ph.state().v) - before;
        impulse += f * DT;
        worst = worst.max((change + f * DT).norm() / (f.norm() * DT).max(1e-9));
    }
    assert!(impulse.norm() > 1e-5, "the press must push: {impulse:?}");
    assert!(worst < 1e-6, "momentum change differs from the tool's impulse by {worst:e} of it");
}

#[test]
fn no_contact_is_the_fem_stepped_alone_bit_for_bit() {
    let g = Vec3::new(0.0, 0.0, -9.81);
    let mut ph = FemPhysics::new(ellipsoid(g, Integrator::default(), true), FemOptions::default()).unwrap();
    let alone = ellipsoid(g, Integrator::default(), true);
    let (mut st, mut ws) = (State::rest(&alone), Workspace::new(&alone));
    let far = Vec3::new(0.5, 0.0, 0.0);
    for k in 0..300 {
        // Near, but not touching (10 mm clear of the probe node at first), then away.
        let f = ph.tick(&(far + Vec3::new(0.0, 0.0, 1e-4 * k as f64)), DT).unwrap();
        step(&alone, &mut st, &mut ws, DT).unwrap();
        assert_eq!(f, Vec3::zeros());
    }
    assert!(st.x.iter().zip(alone.mesh().points()).any(|(x, x0)| (x - x0).norm() > 1e-6), "gravity must move the body");
    assert_eq!(ph.state().x, st.x);
    assert_eq!(ph.state().v, st.v);
    assert_eq!(ph.state().t, st.t);
}

#[test]
fn hard_press_15mm_stays_finite_and_restore_returns_the_checkpoint() {
    let mut ph = FemPhysics::new(ellipsoid(Vec3::zeros(), Integrator::default(), true), FemOptions::default()).unwrap();
    let (p, n) = probe(&ph);
    let r = FemOptions::default().tool.radius;
    let mut fmax: f64 = 0.0;
    let mut saved = None;
    for k in 0..900 {
        // 15 mm into the surface, then a 0.5 m/s slide along z.
        match ph.tick(&path(p, n, r, 0.015, 0.5, k), DT) {
            Ok(f) => {
                assert!(f.iter().all(|c| c.is_finite()), "tick {k}");
                fmax = fmax.max(f.norm());
            }
            Err(e) => panic!("tick {k}: {e}"),
        }
        assert!(ph.is_finite(), "tick {k}");
        if k == 350 {
            ph.checkpoint();
            saved = Some((format!("{:?}", ph.state()), ph.tool()));
        }
    }
    println!("15 mm press on ellipsoid_192: max tissue force {fmax:.3} N, contact {:?}", ph.contact_tool(DT));
    // The node-only contact on this coarse mesh: the probe node slides off the sphere's side
    // past ~0.7 N (its stiffness capped by the node's mass at 1 kHz, see FemPhysics).
    assert!(fmax > 0.4, "a 15 mm press must push: {fmax} N");
    ph.restore();
    assert_eq!(Some((format!("{:?}", ph.state()), ph.tool())), saved);
}

#[test]
fn a_diverging_step_is_an_error_and_leaves_the_state_as_before() {
    let mut ph = FemPhysics::new(ellipsoid(Vec3::zeros(), Integrator::default(), true), FemOptions::default()).unwrap();
    let (p, n) = probe(&ph);
    let r = FemOptions::default().tool.radius;
    for k in 0..200 {
        ph.tick(&path(p, n, r, 0.004, 0.0, k), DT).unwrap();
    }
    // A node's position turned non-finite (as a corrupted state would be): the step fails.
    let i = ph.boundary_nodes().iter().copied().find(|&i| !ph.model().fixed()[i]).unwrap();
    ph.state_mut().x[i] = Vec3::new(f64::NAN, 0.0, 0.0);
    let (before, tool) = (format!("{:?}", ph.state()), ph.tool());
    let e = ph.tick(&path(p, n, r, 0.004, 0.0, 200), DT).unwrap_err();
    assert!(matches!(e, StepError::Diverging { .. } | StepError::NonFinite { .. }), "{e}");
    assert_eq!(format!("{:?}", ph.state()), before, "the state (f_ext included) must be as before the tick");
    assert_eq!(ph.tool(), tool);
    // And a bad input changes nothing.
    assert!(ph.tick(&Vec3::new(f64::NAN, 0.0, 0.0), DT).is_err());
    assert!(ph.tick(&p, 0.0).is_err());
    assert_eq!(format!("{:?}", ph.state()), before);
}

#[test]
fn tick_checkpoint_and_restore_allocate_nothing_once_warm() {
    let mut ph = FemPhysics::new(ellipsoid(Vec3::zeros(), Integrator::default(), true), FemOptions::default()).unwrap();
    let (p, n) = probe(&ph);
    let r = FemOptions::default().tool.radius;
    let mut surf = vec![Vec3::zeros(); ph.surface_len()];
    let mut inner = vec![Vec3::zeros(); ph.interior_capacity()];
    let mut run = |ph: &mut FemPhysics, ks: std::ops::Range<usize>| {
        for k in ks {
            ph.tick(&path(p, n, r, 0.010, 0.3, k), DT).unwrap();
            if k % 50 == 0 {
                ph.checkpoint();
                ph.restore();
            }
            ph.surface(&mut surf);
            ph.interior(&mut inner);
        }
    };
    run(&mut ph, 0..20);
    let before = allocations();
    run(&mut ph, 20..800);
    assert_eq!(allocations() - before, 0, "ticks, checkpoints or restores allocated");
    // The surface is the boundary nodes, as simulated.
    assert_eq!(surf[0], ph.state().x[ph.boundary_nodes()[0]]);
    assert_eq!(inner, ph.state().x);
}

#[test]
fn hand_worst_5n_press_and_fast_slide_through_the_loop_stay_finite() {
    let ph = FemPhysics::new(ellipsoid(Vec3::zeros(), Integrator::default(), true), FemOptions::default()).unwrap();
    let (p, n) = probe(&ph);
    let r = FemOptions::default().tool.radius;
    // The hand aims 25 mm into the tissue (a 5 N-scale push against the coupling), then slides
    // 50 mm along z at 0.5 m/s and back, then lets go.
    let c = |d: f64, s: f64| p + n * (r - d) + Vec3::z() * s;
    let times = vec![0.0, 0.6, 0.9, 1.0, 1.1, 1.3];
    let knots = vec![c(-0.003, 0.0), c(-0.003, 0.0), c(0.025, 0.0), c(0.025, 0.05), c(0.025, 0.0), c(-0.003, 0.0)];
    let mut dev = Scripted::new(times, knots).unwrap();
    let safety = SafetyParams { max_force: 5.0, ..Default::default() };
    let mut core = HapticCore::new(Box::new(ph), 1000.0, CouplingParams::default(), safety, 250, 2000);
    core.run_offline(&mut dev, 2000);
    let rec = core.take_recording().unwrap();
    let fmax = rec.ticks.iter().map(|t| t.tissue.norm()).fold(0.0, f64::max);
    println!("hand's worst on ellipsoid_192: max tissue force {fmax:.3} N, max sent {:.3} N, faults {}", core.max_force(), core.faults());
    assert!(rec.ticks.iter().all(|t| t.force.iter().chain(t.tissue.iter()).chain(t.tool.iter()).all(|c| c.is_finite())));
    assert!(core.physics().is_finite());
    assert!(fmax > 0.4, "the press must push: {fmax} N");
    assert!(core.max_force() <= 5.0 + 1e-9);
    assert_eq!(core.faults(), 0, "no fault: the physics must not diverge");
}
