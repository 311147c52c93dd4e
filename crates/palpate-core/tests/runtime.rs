//! The hybrid tick (`runtime::tick`): the exactness of its exchanges, tick by tick.
//!
//! What a wrong implementation would do: drop the active particles' reactions on their frozen
//! neighbours, or spread a tie's force with weights that do not sum to one, or average the
//! sub-steps' reactions with the wrong weight (the total momentum of core plus particles would
//! then change with the tool away); apply the coupling's force to the particle but not its
//! opposite to the core; let an idle shell (no region active) push on the core (the core would
//! no longer move as the same core simulated alone); allocate in the tick.

#[path = "support/press.rs"]
mod press;
#[path = "support/walls.rs"]
mod walls;

use palpate_core::hybrid::HybridModel;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::runtime::{finish_tick, tick, tick_force_with, Finished, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::{step, Material, ModelBuilder, State, TetMesh, Vec3, Workspace};

fn model() -> &'static HybridModel {
    &walls::ellipsoids().1
}

fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::from_paper(0.05, 0.05)).unwrap()
}

/// A smooth velocity field over the core (a shear and a swirl) [m/s].
fn swirl(x: &Vec3) -> Vec3 {
    Vec3::new(0.02 * x.z, -0.03 * x.z, 0.01) + 3.0 * Vec3::new(-x.y, x.x, 0.0)
}

/// Momentum of the core and of the free active particles [kg m/s].
fn momentum(sim: &Sim, st: &SimState) -> Vec3 {
    let mut p = sim.core.momentum(&st.core.v);
    for &i in &st.particles.active {
        if !sim.particles.fixed()[i] {
            p += sim.particles.masses()[i] * st.particles.v[i];
        }
    }
    p
}

#[test]
fn coupling_and_ring_conserve_linear_momentum_with_the_tool_away() {
    momentum_with_the_tool_away(false);
}

/// The same with the springs at `E h` and their implicit share in the core's step
/// (`runtime/exchange.rs`: translation invariant, so the momentum stays exact).
#[test]
fn the_implicit_exchange_conserves_linear_momentum() {
    momentum_with_the_tool_away(true);
    momentum_with_the_tool(true);
}

fn momentum_with_the_tool_away(implicit_exchange: bool) {
    let sim = Sim::new(model().clone(), material(), SimOptions { hold: false, implicit_exchange, ..Default::default() }).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    for (v, x) in st.core.v.iter_mut().zip(sim.core.mesh().points()) {
        *v = swirl(x);
    }
    // Three regions, whatever the tool: their particles enter in the first tick.
    for s in [0, 1, sim.hybrid.n_regions() / 2] {
        st.activation.touch(s);
    }
    let away = Vec3::new(1.0, 1.0, 1.0);
    let first = tick(&sim, &mut st, &mut ws, away, 1e-3).unwrap();
    assert!(first.active > 50 && first.substeps > 1, "{first:?}");
    // The scale: the core's mass times its speeds (~0.05 m/s).
    let scale = sim.core.masses().iter().sum::<f64>() * 0.05;
    for k in 0..3 {
        let before = momentum(&sim, &st);
        let r = tick(&sim, &mut st, &mut ws, away, 1e-3).unwrap();
        assert_eq!((r.entered, r.left, r.particle_contacts, r.skin_contacts), (0, 0, 0, 0));
        let change = (momentum(&sim, &st) - before).norm();
        println!("tick {k}: {} active, momentum change {change:.3e} of {scale:.3e} kg m/s, confined {}", r.active, r.confined);
        assert!(change <= 1e-12 * scale, "tick {k}: momentum changed by {change:e} (scale {scale:e})");
    }
}

#[test]
fn with_the_tool_the_momentum_changes_by_its_impulse() {
    momentum_with_the_tool(false);
}

fn momentum_with_the_tool(implicit_exchange: bool) {
    let sim = Sim::new(model().clone(), material(), SimOptions { hold: false, implicit_exchange, ..Default::default() }).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (p0, n) = press::press_point(&sim.hybrid.outer_points);
    let r = sim.options.tool.radius;
    let (mut contacts, mut checked) = (0, 0);
    for k in 0..20 {
        // Pressing in at 0.05 mm per tick, from 0.3 mm outside (a short press: longer and deeper
        // ones are not yet stable, see runtime/tick.rs).
        let depth = -3e-4 + 5e-5 * k as f64;
        let before = momentum(&sim, &st);
        let rep = tick(&sim, &mut st, &mut ws, p0 + n * (r - depth), 1e-3).unwrap();
        contacts += rep.particle_contacts + rep.skin_contacts;
        if rep.entered > 0 || rep.left > 0 {
            continue; // entering particles bring the core's momentum with them
        }
        let change = momentum(&sim, &st) - before;
        let impulse = -rep.force * 1e-3;
        checked += (rep.particle_contacts + rep.skin_contacts > 0) as usize;
        assert!((change - impulse).norm() <= 1e-12 * impulse.norm() + 1e-15, "tick {k}: momentum change {change:?}, tool impulse on the tissue {impulse:?}");
    }
    assert!(contacts > 0 && checked > 0, "the tool never touched ({contacts} contacts, {checked} ticks checked with contact)");
}

/// A haptic servo sends the force first and updates the skin after (`tick_force_with`, then
/// `finish_tick`), and the core's step too when the tool has nothing of the core within reach;
/// a caller that never finishes has that work paid at the start of its next tick, and a
/// snapshot taken while it is owed carries the debt. All three give the whole tick's
/// forces and states bit for bit over a press and a slide with regions entering and leaving.
/// What a wrong split would do: update the skin with the wrong tool or the shed skin's fade one
/// tick off (the finished copy would differ), or drop an owed update (the unfinished copy's
/// next contact would meet a stale skin).
#[test]
fn the_skin_updated_after_the_force_changes_no_result() {
    skin_updated_after_the_force(false);
}

/// The same with the implicit exchange: its potential in an owed core step is rebuilt from the
/// state (a restored snapshot included), so the split tick still changes nothing.
#[test]
fn with_the_implicit_exchange_the_split_tick_changes_no_result() {
    skin_updated_after_the_force(true);
}

fn skin_updated_after_the_force(implicit_exchange: bool) {
    // The paper's softer core: its bend carries the far skin past half the live margin.
    let sim = Sim::new(walls::ellipsoids_papers_core().clone(), material(), SimOptions { implicit_exchange, ..Default::default() }).unwrap();
    let (p0, n) = press::press_point(&sim.hybrid.outer_points);
    let t = n.cross(&Vec3::z()).normalize();
    let r = sim.options.tool.radius;
    let fresh = || (SimState::rest(&sim), SimWorkspace::new(&sim));
    let ((mut a, mut wa), (mut b, mut wb), (mut c, mut wc)) = (fresh(), fresh(), fresh());
    let serial = palpate_core::parallel::Serial;
    let (mut entered, mut left, mut refreshed, mut deferred) = (0, 0, 0, 0);
    for k in 0..400 {
        // In 3 mm over 150 ticks, then a 12 mm slide, then out.
        let depth = if k < 150 {
            3e-3 * k as f64 / 150.0
        } else if k < 330 {
            3e-3
        } else {
            3e-3 * (400 - k) as f64 / 70.0
        } - 5e-4;
        let slide = 12e-3 * ((k as f64 - 150.0) / 180.0).clamp(0.0, 1.0);
        let c_tool = p0 + n * (r - depth) + t * slide;
        let ra = tick(&sim, &mut a, &mut wa, c_tool, 1e-3).unwrap();
        let mut rb = tick_force_with(&sim, &mut b, &mut wb, c_tool, 1e-3, &serial).unwrap();
        let done = finish_tick(&sim, &mut b, &mut wb).unwrap();
        rb.skin_refreshed = done.skin_refreshed;
        if let Some(core) = done.core {
            rb.core = core;
            deferred += 1;
        }
        let rc = tick_force_with(&sim, &mut c, &mut wc, c_tool, 1e-3, &serial).unwrap();
        assert_eq!(ra, rb, "tick {k}: finished after the force");
        assert_eq!(ra.force, rc.force, "tick {k}: never finished");
        assert_eq!(rc.skin_refreshed, 0);
        (entered, left, refreshed) = (entered + ra.entered, left + ra.left, refreshed + ra.skin_refreshed);
        if k == 200 {
            // Owed here: the snapshot carries it.
            let (s, w) = SimState::restore(&sim, &c.snapshot(&wc)).unwrap();
            (c, wc) = (s, w);
        }
    }
    finish_tick(&sim, &mut c, &mut wc).unwrap();
    assert_eq!(finish_tick(&sim, &mut c, &mut wc).unwrap(), Finished::default(), "nothing is owed twice");
    for (x, y) in [
        (&a.skin, &b.skin),
        (&a.skin, &c.skin),
        (&a.particles.x, &b.particles.x),
        (&a.particles.x, &c.particles.x),
        (&a.core.x, &c.core.x),
    ] {
        assert!(x == y, "the states differ");
    }
    assert!(entered > 0 && left > 0 && refreshed > 0, "regions entered {entered}, left {left}; far skin refreshed {refreshed}");
    assert!(deferred > 100, "the core's step was left to the finish in {deferred} ticks of 400");
}

/// The tool against what moves with the core (the skin where no particle carries it, the core's
/// surface) is taken inside the core's implicit step, whose minimisation leaves a residual that
/// sums to its tolerance, not to zero: reported as the contact's forces at the end of the step,
/// the momentum missed the tool's impulse by that residual. Pressed with the shell shed (a shell
/// under-stepped to 3 sub-steps fails at once), every tick's momentum change is the tool's
/// impulse to round-off.
#[test]
fn with_the_shell_shed_the_momentum_changes_by_the_tools_impulse() {
    let sim = Sim::new(model().clone(), material(), SimOptions { hold: false, max_substeps: 3, ..Default::default() }).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let (p0, n) = press::press_point(&sim.hybrid.outer_points);
    let r = sim.options.tool.radius;
    let (mut shed, mut checked) = (false, 0);
    for k in 0..60 {
        let depth = -3e-4 + 1e-4 * k as f64;
        let before = momentum(&sim, &st);
        let rep = tick(&sim, &mut st, &mut ws, p0 + n * (r - depth), 1e-3).unwrap();
        shed |= rep.shell_failed;
        if !rep.shell_off || rep.skin_contacts + rep.core_contacts == 0 {
            continue;
        }
        let change = momentum(&sim, &st) - before;
        let impulse = -rep.force * 1e-3;
        assert!((change - impulse).norm() <= 1e-12 * impulse.norm() + 1e-15, "tick {k}: momentum change {change:?}, tool impulse on the tissue {impulse:?}");
        checked += 1;
    }
    assert!(shed && checked > 10, "the shell was shed ({shed}) and the core pressed directly ({checked} ticks)");
}

#[test]
fn an_idle_shell_leaves_the_core_as_the_core_alone() {
    // The paper's softer core (not homogenised): swirled, it carries the skin past twice the
    // live margin.
    let sim = Sim::new(walls::ellipsoids_papers_core().clone(), material(), SimOptions { homogenise: false, ..Default::default() }).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    let pts: Vec<[f64; 3]> = sim.hybrid.core_points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tets: Vec<[i64; 4]> = sim.hybrid.core_tets.iter().map(|t| t.map(|i| i as i64)).collect();
    let (mesh, _) = TetMesh::from_arrays(&pts, &tets).unwrap();
    let fixed: Vec<usize> = (0..sim.core.n_nodes()).filter(|&i| sim.core.fixed()[i]).collect();
    // The same core, carrying the same shell mass (the idle shell rides on it).
    // The runtime's core material: the tissue's stiffened by the model's homogenisation (no
    // particle is active: none of it is softened).
    let alone = ModelBuilder::new(mesh, material().stiffened(sim.core_stiffening()).unwrap())
        .fixed_nodes(fixed)
        .attached_masses(sim.shell_mass.clone())
        .build()
        .unwrap();
    let mut s = State::rest(&alone);
    let mut w = Workspace::new(&alone);
    for ((a, b), x) in st.core.v.iter_mut().zip(s.v.iter_mut()).zip(sim.core.mesh().points()) {
        *a = swirl(x) * 0.01;
        *b = *a;
    }
    for (i, f) in sim.core.fixed().iter().enumerate() {
        if *f {
            st.core.v[i] = Vec3::zeros();
            s.v[i] = Vec3::zeros();
        }
    }
    for _ in 0..20 {
        let r = tick(&sim, &mut st, &mut ws, Vec3::new(1.0, 1.0, 1.0), 1e-3).unwrap();
        assert_eq!(r.active, 0);
        step(&alone, &mut s, &mut w, 1e-3).unwrap();
    }
    assert_eq!(st.core.x, s.x, "the hybrid core moved differently from the core alone");
    assert_eq!(st.core.v, s.v);
    // The skin follows its core faces (the whole skin, fresh: `Sim::skin_positions`; the state's
    // skin is fresh near the tool, far away here, and as of the last whole update elsewhere).
    let mut skin = vec![Vec3::zeros(); st.skin.len()];
    sim.skin_positions(&st, &mut skin);
    let worst = (0..skin.len()).map(|v| (skin[v] - sim.skin.position(v, &st.core.x)).norm()).fold(0.0, f64::max);
    assert!(worst < 1e-15, "{worst:e}");
    // The state's skin, updated here only where the core's motion may have carried it farther
    // than half the live margin, is never farther than that margin from its place.
    let stale = (0..skin.len()).map(|v| (st.skin[v] - skin[v]).norm()).fold(0.0, f64::max);
    assert!(stale <= palpate_core::runtime::tick::SKIN_LIVE_MARGIN, "a stored skin vertex is {stale:e} m from its place");
    // Swirled faster, the core carries the skin past the margin: whole updates keep it close.
    for v in st.core.v.iter_mut().zip(sim.core.mesh().points()).filter(|(v, _)| **v != Vec3::zeros()).map(|(v, _)| v) {
        *v *= 600.0;
    }
    let (mut worst, mut moved) = (0.0f64, 0.0f64);
    for _ in 0..40 {
        tick(&sim, &mut st, &mut ws, Vec3::new(1.0, 1.0, 1.0), 1e-3).unwrap();
        sim.skin_positions(&st, &mut skin);
        worst = worst.max((0..skin.len()).map(|v| (st.skin[v] - skin[v]).norm()).fold(0.0, f64::max));
        moved = moved.max((0..skin.len()).map(|v| (skin[v] - sim.hybrid.outer_points[v]).norm()).fold(0.0, f64::max));
    }
    println!("skin moved up to {moved:.2e} m, stored skin at most {worst:.2e} m from its place");
    assert!(moved > 2.0 * palpate_core::runtime::tick::SKIN_LIVE_MARGIN, "the test did not move the skin enough: {moved:e} m");
    assert!(worst <= palpate_core::runtime::tick::SKIN_LIVE_MARGIN, "a stored skin vertex is {worst:e} m from its place");
}

#[test]
fn bad_tool_positions_and_time_steps_are_refused_and_leave_the_state() {
    let sim = Sim::new(model().clone(), material(), SimOptions::default()).unwrap();
    let mut st = SimState::rest(&sim);
    let mut ws = SimWorkspace::new(&sim);
    for (tool, dt) in [(Vec3::new(f64::NAN, 0.0, 0.0), 1e-3), (Vec3::zeros(), 0.0), (Vec3::zeros(), f64::INFINITY)] {
        assert!(tick(&sim, &mut st, &mut ws, tool, dt).is_err());
        assert_eq!(st.ticks, 0);
        assert_eq!(st.core.x, sim.core.mesh().points().to_vec());
    }
}
