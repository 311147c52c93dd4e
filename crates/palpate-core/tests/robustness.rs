//! Robustness of the step API: no allocation in the loop, typed errors instead of panics, and a
//! state left exactly as it was when a step fails.
//!
//! What a wrong implementation would do: a `Vec` built inside `step` (a scratch buffer, a
//! `collect`, a cloned factor) is counted by the allocator of support/alloc.rs; a step that writes the state
//! before detecting a NaN leaves a half-updated state (caught by the bitwise comparison); an
//! unchecked `dt` or force panics or silently produces NaN; a builder that accepts an
//! out-of-range fixed node panics later, inside `step`.

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::mesh::generate::{truncated_ellipsoid_wall, TruncatedEllipsoidWall};
use palpate_core::meshfree;
use palpate_core::{step, Integrator, Model, ModelBuilder, ModelError, SolveError, State, StepError, Vec3, Workspace};

#[path = "support/alloc.rs"]
mod alloc;
#[path = "support/press.rs"]
mod press;
use alloc::allocations;

/// Bitwise equality of two states (NaN-safe, unlike `==`).
fn same_state(a: &State, b: &State) -> bool {
    let bits = |v: &[Vec3]| v.iter().flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]).collect::<Vec<_>>();
    bits(&a.x) == bits(&b.x) && bits(&a.v) == bits(&b.v) && a.t.to_bits() == b.t.to_bits() && bits(&a.f_ext) == bits(&b.f_ext)
}

/// The small wall of `clamped_wall(integ)` after one warm-up step (which allocates the lazy parts, e.g.
/// the first factorisation), and its topmost node, where the tests press.
fn warmed_up(integ: Integrator) -> (Model, State, Workspace, usize) {
    let model = clamped_wall(integ);
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    let pts = model.mesh().points();
    let top = (0..model.n_nodes()).max_by(|&a, &b| pts[a].z.total_cmp(&pts[b].z)).unwrap();
    step(&model, &mut s, &mut ws, 1e-3).unwrap();
    (model, s, ws, top)
}

#[test]
fn step_allocates_nothing_after_the_first_step() {
    for (name, integ) in SCHEMES {
        let (model, mut s, mut ws, top) = warmed_up(integ);
        // The factor of the second dt is allocated once, when first seen (the dt cache).
        ws.prepare(&model, 5e-4).unwrap();
        let before = allocations();
        for k in 0..100 {
            // A changing load and, every 10th step, a different dt (a cached factor / new filters).
            s.f_ext[top] = Vec3::new(0.01 * (k as f64 * 0.1).sin(), 0.0, -0.01);
            let dt = if k % 10 == 5 { 5e-4 } else { 1e-3 };
            step(&model, &mut s, &mut ws, dt).unwrap();
        }
        let n = allocations() - before;
        println!("{name}: {n} allocations in 100 steps");
        assert_eq!(n, 0, "{name}: step allocated {n} times in 100 steps");
    }
}

/// The loads above are gentle (0.01 N): the minimising integrators take one iteration per step
/// and their line search accepts the first trial, so the L-BFGS two-loop, the curvature-pair ring,
/// the line search's shortened trials and Newton's CG iterations are not all exercised. Here a
/// 2 N press and release on the apex of the small wall at dt = 4 ms (max |u| ~8 cm, every tet
/// inverted at some point) makes them run; the test checks that the window did contain
/// multi-iteration steps and rejected line-search trials (else it would pass vacuously), and that
/// nothing was allocated. A `Vec` built on any of those paths (e.g. a fresh direction buffer per
/// iteration, a `collect` in the line search, a growing history) makes it fail.
#[test]
fn step_allocates_nothing_under_a_firm_press() {
    let schemes = [
        ("BE quasi-Newton (default)", Integrator::quasi_newton()),
        ("BE Newton (default)", Integrator::newton()),
        ("semi-implicit, stable filter", Integrator::SemiImplicit { filter: palpate_core::integrate::Filter::Stable }),
    ];
    for (name, integ) in schemes {
        let (model, mut s, mut ws, top) = warmed_up(integ);
        // The factors of the two dt are allocated once, when first seen (the dt cache).
        ws.prepare(&model, 4e-3).unwrap();
        ws.prepare(&model, 2e-3).unwrap();
        let before = allocations();
        let (mut max_iterations, mut rejected_trials, mut max_inverted) = (0, 0, 0);
        for k in 0..100 {
            // 2 N pressed for 10 steps, released for 10, swinging sideways, at dt = 4 ms with 2 ms
            // every 10th step (refactorisation): at dt = 1 ms the full L-BFGS step is nearly always
            // accepted at once; at 4 ms the rest Hessian misses more curvature and trials get cut.
            let r = if (k / 10) % 2 == 0 { 1.0 } else { 0.0 };
            s.f_ext[top] = Vec3::new(0.8 * (k as f64 * 0.15).sin(), 0.3, -1.8).normalize() * (2.0 * r);
            let dt = if k % 10 == 5 { 2e-3 } else { 4e-3 };
            let rep = step(&model, &mut s, &mut ws, dt).unwrap_or_else(|e| panic!("{name}: step {k}: {e}"));
            max_iterations = max_iterations.max(rep.iterations);
            // One evaluation per accepted trial, plus the start if not cached: more means rejected trials.
            rejected_trials += rep.evaluations.saturating_sub(rep.iterations + 1);
            max_inverted = max_inverted.max(rep.inverted);
        }
        let n = allocations() - before;
        println!(
            "{name}: {n} allocations in 100 steps under 2 N (max iterations {max_iterations}, rejected line-search trials >= {rejected_trials}, max inverted {max_inverted}, max|u| {:.2e} m)",
            max_norm(&s.displacements(&model))
        );
        assert_eq!(n, 0, "{name}: step allocated {n} times in 100 steps under a 2 N press");
        if !matches!(integ, Integrator::SemiImplicit { .. }) {
            assert!(max_iterations >= 3, "{name}: at most {max_iterations} iterations per step: the press does not exercise the iterations");
            assert!(rejected_trials > 0, "{name}: no rejected line-search trial: the line search's shortening is not exercised");
        }
    }
}

#[test]
fn allocation_counter_works() {
    // Guard against a vacuous pass of the test above.
    let before = allocations();
    let v: Vec<u64> = std::hint::black_box((0..100).collect());
    assert!(allocations() > before && v.len() == 100);
}

#[test]
fn non_finite_external_force_is_refused_and_state_unchanged() {
    for (name, integ) in SCHEMES {
        let model = clamped_wall(integ);
        let mut s = State::rest(&model);
        let mut ws = Workspace::new(&model);
        for _ in 0..3 {
            step(&model, &mut s, &mut ws, 1e-3).unwrap();
        }
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let node = model.n_nodes() - 2;
            s.f_ext[node] = Vec3::new(0.0, bad, 0.0);
            let before = s.clone();
            let r = step(&model, &mut s, &mut ws, 1e-3);
            assert_eq!(r, Err(StepError::NonFiniteForce { node }), "{name}: {bad}");
            assert!(same_state(&s, &before), "{name}: state changed by a refused step");
            s.f_ext[node] = Vec3::zeros();
        }
        // And the simulation carries on normally afterwards.
        step(&model, &mut s, &mut ws, 1e-3).unwrap();
    }
}

/// A NaN or infinite position or velocity set between steps is refused with the node named and
/// the state left as it was (every scheme); before, the minimising schemes stepped a NaN velocity
/// into a finite one without a word.
#[test]
fn a_non_finite_state_given_to_the_step_is_refused_and_left_alone() {
    for (name, integ) in SCHEMES {
        let (model, mut s, mut ws, _) = warmed_up(integ);
        let node = model.n_nodes() - 2;
        let good = s.clone();
        for bad in [f64::NAN, f64::INFINITY] {
            for velocity in [false, true] {
                (if velocity { &mut s.v } else { &mut s.x })[node].y = bad;
                let before = s.clone();
                let r = step(&model, &mut s, &mut ws, 1e-3);
                assert!(
                    matches!(r, Err(StepError::NonFinite { node: n, .. }) if n == node),
                    "{name}: {bad} in {} gave {r:?}",
                    if velocity { "v" } else { "x" }
                );
                assert!(same_state(&s, &before), "{name}: state changed by a refused step");
                s.clone_from(&good);
            }
        }
        step(&model, &mut s, &mut ws, 1e-3).unwrap();
    }
}

#[test]
fn bad_time_steps_are_refused() {
    for (name, integ) in SCHEMES {
        let model = clamped_wall(integ);
        let mut s = State::rest(&model);
        let mut ws = Workspace::new(&model);
        for dt in [0.0, -1e-3, f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -0.0] {
            let before = s.clone();
            let r = step(&model, &mut s, &mut ws, dt);
            assert!(matches!(r, Err(StepError::BadTimeStep(d)) if d.to_bits() == dt.to_bits()), "{name}: dt {dt} gave {r:?}");
            assert!(same_state(&s, &before), "{name}: state changed");
        }
    }
}

/// A 1e12 N force (a ~1e16 m/s^2 acceleration of a 0.1 g node) drives the state to overflow.
/// Every step must return Ok or a typed error — never panic — and a failed step must leave the
/// state bit-for-bit as it was.
#[test]
fn huge_forces_give_typed_errors_and_restore_the_state() {
    for (name, integ) in SCHEMES {
        let model = clamped_wall(integ);
        let mut s = State::rest(&model);
        let mut ws = Workspace::new(&model);
        let top = (0..model.n_nodes()).max_by(|&a, &b| model.mesh().points()[a].z.total_cmp(&model.mesh().points()[b].z)).unwrap();
        s.f_ext[top] = Vec3::new(1e12, -3e11, 5e11);
        let mut first_error = None;
        let mut errors = 0;
        let mut unconverged = 0;
        for k in 0..200 {
            let before = s.clone();
            match step(&model, &mut s, &mut ws, 1e-3) {
                Ok(rep) => {
                    unconverged += !rep.converged as usize;
                    assert!(s.x.iter().chain(&s.v).all(|p| p.iter().all(|c| c.is_finite())), "{name}: Ok step left a non-finite state");
                }
                Err(e) => {
                    match &e {
                        StepError::NonFinite { node, .. } | StepError::Diverging { node, .. } => assert!(*node < model.n_nodes()),
                        StepError::Solve(SolveError::NonFinite { .. } | SolveError::NotPositiveDefinite { .. }) => {}
                        other => panic!("{name}: unexpected error {other:?}"),
                    }
                    assert!(same_state(&s, &before), "{name}: a failed step changed the state");
                    errors += 1;
                    first_error.get_or_insert((k, e));
                }
            }
        }
        println!(
            "{name}: first error {first_error:?}, {errors} failed steps of 200, {unconverged} accepted unconverged, max|u| {:.2e} m",
            max_norm(&s.displacements(&model))
        );
    }
}

#[test]
fn all_nodes_fixed_is_a_valid_model() {
    for (name, integ) in SCHEMES {
        let p = TruncatedEllipsoidWall::with_resolution(3);
        let mesh = truncated_ellipsoid_wall(&p);
        let all: Vec<usize> = (0..mesh.n_nodes()).collect();
        let model = ModelBuilder::new(mesh, material(3.0e4, 0.4, 1000.0, 0.0, 0.0))
            .fixed_nodes(all)
            .gravity(Vec3::new(0.0, 0.0, -9.81))
            .integrator(integ)
            .build()
            .unwrap();
        let mut s = State::rest(&model);
        s.f_ext[3] = Vec3::new(1.0, 0.0, 0.0);
        let mut ws = Workspace::new(&model);
        step(&model, &mut s, &mut ws, 1e-3).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(s.x, model.mesh().points(), "{name}: a fixed node moved");
        assert!(s.v.iter().all(|v| *v == Vec3::zeros()));
    }
}

#[test]
fn model_builder_rejects_bad_input() {
    let p = TruncatedEllipsoidWall::with_resolution(3);
    let mesh = truncated_ellipsoid_wall(&p);
    let n = mesh.n_nodes();
    let mat = material(3.0e4, 0.4, 1000.0, 0.0, 0.0);
    let b = || ModelBuilder::new(mesh.clone(), mat);

    assert_eq!(b().fixed_nodes(vec![0, n]).build().unwrap_err(), ModelError::FixedOutOfRange { node: n, n_nodes: n });
    assert!(matches!(b().fixed_nodes(vec![usize::MAX]).build(), Err(ModelError::FixedOutOfRange { .. })));
    for g in [Vec3::new(f64::NAN, 0.0, 0.0), Vec3::new(0.0, f64::INFINITY, 0.0), Vec3::new(0.0, 0.0, f64::NEG_INFINITY)] {
        assert!(matches!(b().gravity(g).build(), Err(ModelError::Gravity(..))), "gravity {g:?} accepted");
    }
    for (max_iterations, tolerance) in [(0, 1e-8), (8, 0.0), (8, -1e-8), (8, 1.0), (8, 2.0), (8, f64::NAN), (8, f64::INFINITY)] {
        let r = b().integrator(Integrator::BackwardEulerNewton { max_iterations, tolerance }).build();
        assert!(matches!(r, Err(ModelError::Integrator(_))), "Newton ({max_iterations}, {tolerance}) accepted");
    }
    // Duplicated fixed nodes are harmless.
    assert!(b().fixed_nodes(vec![0, 0, 1]).build().is_ok());
    assert!(b().integrator(Integrator::newton()).build().is_ok());
}

/// The particle step allocates nothing after the first call either: full body, a partial active
/// set, damping and gravity, the SIMD and the portable copies.
#[test]
fn particle_step_allocates_nothing_after_the_first_step() {
    use palpate_core::material::{Damping, Elasticity};
    use palpate_core::meshfree::{set_simd_enabled, ParticleModelBuilder, ParticleState, ParticleWorkspace};
    let s = 1e-3;
    let mut pts = vec![];
    for k in 0..6 {
        for j in 0..5 {
            for i in 0..5 {
                pts.push(Vec3::new(i as f64, j as f64, k as f64) * s);
            }
        }
    }
    let m = vec![1000.0 * s * s * s; pts.len()];
    let mat = palpate_core::Material::new(Elasticity::YoungPoisson { young: 3e4, poisson: 0.4 }, 1000.0, Damping { phi: 0.5, psi: 0.5 }).unwrap();
    let model = ParticleModelBuilder::new(pts, m, mat, 1.8 * s)
        .fixed_particles((0..25).collect())
        .gravity(Vec3::new(0.0, 0.0, -9.81))
        .build()
        .unwrap();
    for simd in [true, false] {
        set_simd_enabled(simd);
        let mut st = ParticleState::rest(&model);
        let mut ws = ParticleWorkspace::new(&model);
        meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap(); // warm-up
        let before = allocations();
        for k in 0..50 {
            st.f_ext[149] = Vec3::new(0.0, 1e-4 * (k as f64).sin(), -1e-4);
            if k == 25 {
                st.active.retain(|&i| i % 2 == 0 || i >= 100);
            }
            meshfree::step(&model, &mut st, &mut ws, 1e-3).unwrap();
        }
        let n = allocations() - before;
        assert_eq!(n, 0, "simd {simd}: the particle step allocated {n} times in 50 steps");
    }
    set_simd_enabled(true);
}

/// The hybrid tick allocates nothing either: a press on the ellipsoid model with particles
/// entering, in contact and confined (what a wrong implementation would do: grow a list of
/// active particles, of ring forces or of touched regions inside the tick).
#[test]
fn the_hybrid_tick_allocates_nothing() {
    use palpate_core::hybrid::{build, shapes, HybridOptions};
    use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
    let m = build(&shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap(), &HybridOptions::default()).unwrap();
    let mat = palpate_core::Material::new(
        palpate_core::material::Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 },
        1000.0,
        palpate_core::material::Damping::NONE,
    )
    .unwrap();
    let sim = Sim::new(m, mat, SimOptions::default()).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (p0, n) = press::press_point(&sim.hybrid.outer_points);
    let r = sim.options.tool.radius;
    let (mut active, mut contacts, mut entered) = (0, 0, 0);
    // Warm-up: the first tick at a dt factorises the core.
    tick(&sim, &mut st, &mut ws, p0 + n * (r + 2e-3), 1e-3).unwrap();
    let before = allocations();
    for k in 0..30 {
        let rep = tick(&sim, &mut st, &mut ws, p0 + n * (r + 1e-3 - 1e-4 * k as f64), 1e-3).unwrap();
        active = active.max(rep.active);
        contacts += rep.particle_contacts;
        entered += rep.entered;
    }
    let during = allocations() - before;
    assert!(active > 0 && contacts > 0 && entered > 0, "the press did not exercise the tick (active {active}, contacts {contacts}, entered {entered})");
    assert_eq!(during, 0, "the hybrid tick allocated {during} times");
}
