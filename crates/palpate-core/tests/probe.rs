//! The probe load and the probe run (`palpate_core::probe`), the one run loop behind the
//! binding's `run_probe` / `run_loads`, the scene runner, the examples and the protocol tests.
//!
//! What a wrong implementation would do: sample the ramp at the step's start (the first step
//! would carry no load, and every caller would lag the protocol by one step); leave a force on a
//! node no load names; average the wrong half of the run; keep stepping after a failed step or
//! past the wall-clock cap; or time the bookkeeping with the step.

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::mesh::generate::box_mesh;
use palpate_core::probe::{run_probe, NoClock, ProbeLoad, ProbeOptions, ProbeStop, Ramp, StepClock};
use palpate_core::{step, ModelBuilder, State, Vec3, Workspace};

/// A clock that advances one second at every read: each step then takes exactly 1 s.
struct Ticks(f64);

impl StepClock for Ticks {
    fn now(&mut self) -> f64 {
        self.0 += 1.0;
        self.0
    }
}

fn bar() -> (palpate_core::Model, Vec<usize>) {
    let mesh = box_mesh([0.01, 0.01, 0.04], [2, 2, 8]);
    let fixed = nodes_where(&mesh, 2, 0.0, 1e-9);
    let top = nodes_where(&mesh, 2, 0.04, 1e-9);
    let model = ModelBuilder::new(mesh, material(3e4, 0.4, 1000.0, 0.0, 0.0)).fixed_nodes(fixed).build().unwrap();
    (model, top)
}

#[test]
fn run_matches_a_hand_written_loop_with_the_load_at_each_steps_end() {
    let (model, top) = bar();
    let total = Vec3::new(0.01, 0.0, -0.02);
    let dt = 1e-3;
    let load = ProbeLoad::new(model.n_nodes(), top.clone(), total, Ramp { start: 0.0, duration: 5.0 * dt }).unwrap();
    let steps = 20;
    let mut s = State::rest(&model);
    s.f_ext[0] = Vec3::new(1.0, 1.0, 1.0); // not a loaded node: the run must clear it
    let mut ws = Workspace::new(&model);
    let run = run_probe(&model, &mut s, &mut ws, std::slice::from_ref(&load), &ProbeOptions::new(steps, dt, 0.02), &mut NoClock);
    assert_eq!(run.stop, None);
    assert_eq!((run.steps, run.step_s.len(), run.probe_disp.len()), (steps, steps, steps));
    assert!(run.stable);

    // The same by hand: the step from t to t + dt carries the load at t + dt.
    let mut h = State::rest(&model);
    let mut ws2 = Workspace::new(&model);
    let mut mean = vec![Vec3::zeros(); model.n_nodes()];
    let mut umax: f64 = 0.0;
    for k in 0..steps {
        let scale = ((k + 1) as f64 / 5.0).min(1.0);
        for f in h.f_ext.iter_mut() {
            *f = Vec3::zeros();
        }
        for &i in &top {
            h.f_ext[i] = total * (scale / top.len() as f64);
        }
        step(&model, &mut h, &mut ws2, dt).unwrap();
        let u = h.displacements(&model);
        umax = umax.max(max_norm(&u));
        if k >= steps / 2 {
            mean.iter_mut().zip(&u).for_each(|(m, u)| *m += u / (steps - steps / 2) as f64);
        }
    }
    let close = |a: &Vec3, b: &Vec3| (a - b).norm() <= 1e-12 * (1.0 + b.norm()) + 1e-15;
    assert!(s.x.iter().zip(&h.x).all(|(a, b)| close(a, b)), "final positions differ from the hand-written loop");
    assert!(run.mean_disp.iter().zip(&mean).all(|(a, b)| close(a, b)), "second-half mean differs");
    assert!((run.max_disp - umax).abs() <= 1e-12 * umax);
    assert!(s.f_ext[0] == Vec3::zeros() && s.f_ext[top[0]] == total / top.len() as f64);
    let second = &run.probe_disp[steps / 2..];
    assert!((run.probe_disp_avg - second.iter().sum::<f64>() / second.len() as f64).abs() < 1e-15);
    assert_eq!(run.totals.steps, steps);
}

#[test]
fn a_failing_step_stops_the_run_and_leaves_the_state() {
    let (model, top) = bar();
    let load = ProbeLoad::new(model.n_nodes(), top, Vec3::new(0.0, 0.0, -0.1), Ramp { start: 0.0, duration: 0.0 }).unwrap();
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    let run = run_probe(&model, &mut s, &mut ws, &[load], &ProbeOptions::new(10, -1.0, 0.02), &mut NoClock);
    assert_eq!(run.steps, 0);
    assert!(!run.stable);
    assert!(matches!(run.stop, Some(ProbeStop::Step { step: 1, steps: 10, .. })), "{:?}", run.stop);
    assert_eq!(s.x, model.mesh().points().to_vec());
    assert!(run.probe_disp_avg.is_nan());
}

#[test]
fn the_wall_clock_cap_stops_the_run_and_only_steps_are_timed() {
    let (model, top) = bar();
    let load = ProbeLoad::new(model.n_nodes(), top, Vec3::new(0.0, 0.0, -0.1), Ramp { start: 0.0, duration: 0.01 }).unwrap();
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    let opts = ProbeOptions { max_wall_s: Some(2.5), ..ProbeOptions::new(10, 1e-3, 0.02) };
    let run = run_probe(&model, &mut s, &mut ws, &[load], &opts, &mut Ticks(0.0));
    // Each step reads the clock twice (1 s apart); bookkeeping is not timed.
    assert_eq!(run.step_s, vec![1.0, 1.0, 1.0]);
    assert_eq!(run.wall_s, 3.0);
    assert_eq!(run.stop, Some(ProbeStop::WallCap { step: 3, steps: 10, cap: 2.5 }));
}

#[test]
fn a_second_run_ramps_again_from_its_own_start() {
    let (model, top) = bar();
    let mut s = State::rest(&model);
    let mut ws = Workspace::new(&model);
    let total = Vec3::new(0.0, 0.0, -0.1);
    let first = ProbeLoad::new(model.n_nodes(), top.clone(), total, Ramp { start: s.t, duration: 0.01 }).unwrap();
    run_probe(&model, &mut s, &mut ws, &[first], &ProbeOptions::new(30, 1e-3, 0.02), &mut NoClock);
    let second = ProbeLoad::new(model.n_nodes(), top.clone(), total, Ramp { start: s.t, duration: 0.01 }).unwrap();
    run_probe(&model, &mut s, &mut ws, &[second], &ProbeOptions::new(1, 1e-3, 0.02), &mut NoClock);
    // One step into a 10-step ramp: a tenth of the load.
    assert!((s.f_ext[top[0]] - total * (0.1 / top.len() as f64)).norm() < 1e-12 * total.norm());
}
