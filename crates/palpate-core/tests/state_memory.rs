//! The integrator's memory (issue 16): a state saved with [`Workspace::memory`] and restored into
//! another workspace repeats the original steps bit for bit, and returning to a recently used
//! `dt` costs no factorisation.
//!
//! What a wrong implementation would do: a restore that keeps the rest factor where the original
//! had refreshed it at a deformed state (or that resets the refresh rule's count) takes different
//! quasi-Newton iterations, caught by the bitwise comparison under a press firm enough to refresh;
//! a cache keyed wrongly, or one that hands back a refreshed factor, either refactorises
//! (counted) or changes the result against a run without the cache (compared bitwise).

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::integrate::StiffnessTerm;
use palpate_core::{step, Integrator, Model, State, Vec3, Workspace};

fn bits(v: &[Vec3]) -> Vec<u64> {
    v.iter().flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]).collect()
}

/// A firm press (2 N, enough for the quasi-Newton rule to refresh its factor) on the top node.
fn press(model: &Model, s: &mut State) {
    let pts = model.mesh().points();
    let top = (0..model.n_nodes()).max_by(|&a, &b| pts[a].z.total_cmp(&pts[b].z)).unwrap();
    s.f_ext[top] = Vec3::new(0.3, 0.0, -2.0);
}

#[test]
fn restored_state_and_memory_repeat_the_steps_bit_for_bit() {
    for integ in [Integrator::quasi_newton(), Integrator::newton(), Integrator::BackwardEulerLinear, Integrator::semi_implicit()] {
        let model = clamped_wall(integ);
        let dt = if matches!(integ, Integrator::SemiImplicit { .. }) { 1e-4 } else { 1e-3 };
        let mut s = State::rest(&model);
        let mut ws = Workspace::new(&model);
        press(&model, &mut s);
        let mut refreshed = false;
        for _ in 0..40 {
            step(&model, &mut s, &mut ws, dt).unwrap();
            refreshed |= ws.memory().refreshed_at.is_some();
        }
        if matches!(integ, Integrator::BackwardEulerQuasiNewton { .. }) {
            assert!(refreshed, "the press should make the quasi-Newton rule refresh its factor");
        }
        let (saved, mem) = (s.clone(), ws.memory());
        let mut iters_a = Vec::new();
        for _ in 0..30 {
            iters_a.push(step(&model, &mut s, &mut ws, dt).unwrap().iterations);
        }
        // Into a fresh workspace, as an unpickled body would.
        let mut ws2 = Workspace::new(&model);
        ws2.restore_memory(&model, &mem).unwrap();
        let mut s2 = saved.clone();
        let mut iters_b = Vec::new();
        for _ in 0..30 {
            iters_b.push(step(&model, &mut s2, &mut ws2, dt).unwrap().iterations);
        }
        assert_eq!(iters_a, iters_b, "{integ:?}");
        assert_eq!(bits(&s.x), bits(&s2.x), "{integ:?}: positions differ");
        assert_eq!(bits(&s.v), bits(&s2.v), "{integ:?}: velocities differ");
        assert_eq!(s.t.to_bits(), s2.t.to_bits());
        // And into the same workspace after it moved on.
        ws.restore_memory(&model, &mem).unwrap();
        let mut s3 = saved;
        for _ in 0..30 {
            step(&model, &mut s3, &mut ws, dt).unwrap();
        }
        assert_eq!(bits(&s.x), bits(&s3.x), "{integ:?}: restore into a used workspace");
    }
}

#[test]
fn alternating_two_dt_refactorises_only_the_first_time_and_changes_nothing() {
    let model = clamped_wall(Integrator::quasi_newton());
    let (dts, n) = ([1e-3, 7e-4], 20);
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    s.f_ext[0] = Vec3::new(0.0, 0.0, -1e-3); // a light load: no refresh, only dt changes
    let mut counts = Vec::new();
    for k in 0..n {
        counts.push(step(&model, &mut s, &mut ws, dts[k % 2]).unwrap().factorizations);
    }
    assert_eq!(&counts[..2], &[1, 1]);
    assert!(counts[2..].iter().all(|&c| c == 0), "refactorised on a return to a cached dt: {counts:?}");

    // The same steps with a workspace that never kept a factor (new for each step but its memory):
    // the cache changes the cost, not the result.
    let mut s_ref = State::rest(&model);
    s_ref.f_ext[0] = s.f_ext[0];
    let mut mem = Workspace::new(&model).memory();
    for k in 0..n {
        let mut w = Workspace::new(&model);
        w.restore_memory(&model, &mem).unwrap();
        step(&model, &mut s_ref, &mut w, dts[k % 2]).unwrap();
        mem = w.memory();
    }
    assert_eq!(bits(&s.x), bits(&s_ref.x));
}

#[test]
fn prepare_factorises_ahead_without_changing_the_next_steps() {
    let model = clamped_wall(Integrator::quasi_newton());
    let mut ws = Workspace::new(&model);
    let mut s = State::rest(&model);
    press(&model, &mut s);
    assert!(ws.prepare(&model, 5e-4).unwrap());
    assert!(!ws.prepare(&model, 5e-4).unwrap(), "prepared twice");
    let mut s_ref = s.clone();
    let mut ws_ref = Workspace::new(&model);
    for _ in 0..10 {
        step(&model, &mut s, &mut ws, 1e-3).unwrap();
        step(&model, &mut s_ref, &mut ws_ref, 1e-3).unwrap();
    }
    assert_eq!(bits(&s.x), bits(&s_ref.x));
    assert_eq!(step(&model, &mut s, &mut ws, 5e-4).unwrap().factorizations, 0);
    assert!(ws.prepare(&model, f64::NAN).is_err());
    assert_eq!(palpate_core::integrate::DT_CACHE_SIZE, 3);
}

/// A potential stiff against the nodes' inertia: springs of `k` [N/m] from the top nodes to
/// targets `a` (the hybrid shell's coupling springs in miniature), with or without its
/// stiffness offered to the factor.
struct Anchors {
    nodes: Vec<usize>,
    targets: Vec<Vec3>,
    k: f64,
    offer: bool,
}

impl palpate_core::integrate::CorePotential for Anchors {
    fn energy_forces(&self, x: &[Vec3], f: &mut [Vec3]) -> f64 {
        let mut u = 0.0;
        for (&i, a) in self.nodes.iter().zip(&self.targets) {
            let d = x[i] - a;
            u += 0.5 * self.k * d.norm_squared();
            f[i] -= self.k * d;
        }
        u
    }

    fn stiffness_terms(&self, emit: &mut dyn FnMut(StiffnessTerm)) {
        if self.offer {
            for &i in &self.nodes {
                emit(StiffnessTerm { id: i as u32, nodes: [i, i, i], weights: [1.0, 0.0, 0.0], stiffness: self.k });
            }
        }
    }
}

/// A potential's stiffness terms (`stiffness_terms`) are held in the factor: the steps take one
/// iteration where, not offered, they keep taking several; and the memory carries them (held at
/// a refresh or added by rank updates since), so that a restored workspace repeats the steps bit
/// for bit (without them it would hold none and iterate differently).
#[test]
fn a_potentials_stiffness_terms_are_held_in_the_factor_and_in_the_memory() {
    let model = clamped_wall(Integrator::quasi_newton());
    let pts = model.mesh().points();
    let ztop = pts.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let nodes: Vec<usize> = (0..model.n_nodes()).filter(|&i| pts[i].z > ztop - 4e-3 && !model.fixed()[i]).collect();
    let m_top = nodes.iter().map(|&i| model.masses()[i]).fold(f64::MAX, f64::min);
    // 20x the lightest top node's inertia m / dt^2 at dt = 1 ms.
    let k = 20.0 * m_top / 1e-6;
    let targets: Vec<Vec3> = nodes.iter().map(|&i| pts[i] + Vec3::new(0.0, 0.0, -2e-5)).collect();
    let run = |offer: bool| {
        let pot = Anchors { nodes: nodes.clone(), targets: targets.clone(), k, offer };
        let mut s = State::rest(&model);
        let mut ws = Workspace::new(&model);
        let mut iters = Vec::new();
        for _ in 0..60 {
            iters.push(palpate_core::integrate::step_with_potential(&model, &mut s, &mut ws, 1e-3, &pot).unwrap().iterations);
        }
        iters
    };
    let (with, without) = (run(true), run(false));
    let late = |v: &[usize]| v[40..].iter().sum::<usize>() as f64 / 20.0;
    assert!(late(&with) < 1.2, "offered: {with:?}");
    assert!(late(&without) >= 2.0, "not offered: {without:?}");

    // Under a firm press the factor is refreshed with the terms held, then terms come and go
    // (rank updates): a restore remakes both, bit for bit.
    let pot_at = |step: usize| {
        // Every fifth step a different third of the anchors is off.
        let off = (step / 5) % 3;
        let keep: Vec<usize> = (0..nodes.len()).filter(|j| j % 3 != off).collect();
        Anchors {
            nodes: keep.iter().map(|&j| nodes[j]).collect(),
            targets: keep.iter().map(|&j| targets[j] + Vec3::new(0.0, 0.0, -2e-3)).collect(),
            k,
            offer: true,
        }
    };
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    press(&model, &mut s);
    let mut n = 0;
    while n < 300 && !(ws.memory().refreshed_at.is_some() && !ws.memory().base_terms.is_empty() && !ws.memory().term_updates.is_empty()) {
        palpate_core::integrate::step_with_potential(&model, &mut s, &mut ws, 1e-3, &pot_at(n)).unwrap();
        n += 1;
    }
    let mem = ws.memory();
    assert!(mem.refreshed_at.is_some() && !mem.base_terms.is_empty() && !mem.term_updates.is_empty(), "after {n} steps: {mem:?}");
    let saved = s.clone();
    let steps = |s: &mut State, ws: &mut Workspace| {
        (n..n + 20)
            .map(|j| palpate_core::integrate::step_with_potential(&model, s, ws, 1e-3, &pot_at(j)).unwrap().iterations)
            .collect::<Vec<_>>()
    };
    let a = steps(&mut s, &mut ws);
    let mut ws2 = Workspace::new(&model);
    ws2.restore_memory(&model, &mem).unwrap();
    let mut s2 = saved.clone();
    let b = steps(&mut s2, &mut ws2);
    assert_eq!(a, b);
    assert_eq!(bits(&s.x), bits(&s2.x), "positions differ after the restore");
    // A memory that dropped the held terms remakes another factor: the steps differ.
    let mut ws3 = Workspace::new(&model);
    ws3.restore_memory(&model, &palpate_core::StepMemory { base_terms: Vec::new(), term_updates: Vec::new(), ..mem.clone() })
        .unwrap();
    let mut s3 = saved;
    steps(&mut s3, &mut ws3);
    assert_ne!(bits(&s.x), bits(&s3.x), "the held terms should matter");
    // Out-of-range nodes, non-finite or non-positive values and a term removed that was not held
    // are refused.
    let term = StiffnessTerm { id: 7, nodes: [nodes[0], nodes[0], nodes[0]], weights: [1.0, 0.0, 0.0], stiffness: k };
    for bad in [
        StiffnessTerm { nodes: [model.n_nodes(), 0, 0], ..term },
        StiffnessTerm { weights: [f64::NAN, 0.0, 0.0], ..term },
        StiffnessTerm { stiffness: -1.0, ..term },
    ] {
        let bad = palpate_core::StepMemory { term_updates: vec![(bad, true)], ..mem.clone() };
        assert!(Workspace::new(&model).restore_memory(&model, &bad).is_err(), "{bad:?}");
    }
    let bad = palpate_core::StepMemory { term_updates: vec![(term, false)], ..mem };
    assert!(Workspace::new(&model).restore_memory(&model, &bad).is_err());
}

/// Many terms at once (every free node anchored, as a first touch activates a region): the factor
/// is remade holding them (a refresh) rather than updated term by term, which would cost more
/// than a factorisation; the memory says so (the terms as its base, no update), and a restore
/// repeats the steps bit for bit. A memory that gives base terms without `refreshed_at` is the
/// rest matrix with them, remade so.
#[test]
fn many_terms_at_once_remake_the_factor_and_restore_bit_for_bit() {
    let model = clamped_wall(Integrator::quasi_newton());
    let pts = model.mesh().points();
    let nodes: Vec<usize> = (0..model.n_nodes()).filter(|&i| !model.fixed()[i]).collect();
    let k = 10.0 * nodes.iter().map(|&i| model.masses()[i]).fold(f64::MAX, f64::min) / 1e-6;
    let pot = Anchors { nodes: nodes.clone(), targets: nodes.iter().map(|&i| pts[i] + Vec3::new(0.0, 0.0, -1e-5)).collect(), k, offer: true };
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    let first = palpate_core::integrate::step_with_potential(&model, &mut s, &mut ws, 1e-3, &pot).unwrap();
    let mem = ws.memory();
    assert!(mem.refreshed_at.is_some() && mem.base_terms.len() == nodes.len() && mem.term_updates.is_empty(), "{mem:?}");
    assert_eq!(first.factorizations, 2, "the rest factor, then the factor with the terms");
    assert_eq!(first.iterations, 1);
    let saved = s.clone();
    let steps = |s: &mut State, ws: &mut Workspace| {
        (0..10)
            .map(|_| palpate_core::integrate::step_with_potential(&model, s, ws, 1e-3, &pot).unwrap().iterations)
            .collect::<Vec<_>>()
    };
    let a = steps(&mut s, &mut ws);
    assert!(a.iter().all(|&i| i == 1), "{a:?}");
    let mut ws2 = Workspace::new(&model);
    ws2.restore_memory(&model, &mem).unwrap();
    let mut s2 = saved.clone();
    assert_eq!(steps(&mut s2, &mut ws2), a);
    assert_eq!(bits(&s.x), bits(&s2.x));
    // The rest matrix with the terms, from a memory that says so: the steps take one iteration
    // (it holds the terms) and differ from the refreshed factor's.
    let mut ws3 = Workspace::new(&model);
    ws3.restore_memory(&model, &palpate_core::StepMemory { refreshed_at: None, ..mem }).unwrap();
    let mut s3 = saved;
    assert!(steps(&mut s3, &mut ws3).iter().all(|&i| i == 1));
    assert_ne!(bits(&s.x), bits(&s3.x));
}
