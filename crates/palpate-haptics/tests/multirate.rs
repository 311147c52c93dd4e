//! The multirate loop's promises (`palpate_haptics::multirate`), each a test a wrong
//! implementation fails:
//! - a local model with no stiffness (a zero-order hold of the physics' force), or one with the
//!   contact's frozen stiffness, predicts the next physics tick worse than the secant
//!   (`local_model_*`);
//! - a servo that renders a stale model as if fresh keeps pushing the hand after the physics
//!   stopped (`a_stalled_physics_fades_*`); one that ignores a silent device keeps pushing a hand
//!   that may have let go (`device_silence_*`);
//! - a local model that is not a conservative spring, or one evaluated explicitly at 4 kHz,
//!   puts energy into the user (`passivity_*`);
//! - a physics whose inputs are not recorded in the order consumed replays otherwise
//!   (`replay_*`);
//! - a servo that waits for the physics misses its periods when the physics stalls
//!   (`the_servo_keeps_its_period_*`).

mod support;

use std::sync::Arc;
use std::time::Duration;

use palpate_core::{Mat3, Vec3};
use palpate_haptics::devices::{Hand, HandParams, Scripted};
use palpate_haptics::multirate::{LocalModel, PhysicsLoop};
use palpate_haptics::record::compare;
use palpate_haptics::{
    CouplingParams, Device, DeviceInput, DeviceKind, Fault, ForceSink, HapticCore, Physics, Recording, SafetyParams, Servo, ServoConfig, Wall,
};
use support::*;

fn fast_ramp() -> SafetyParams {
    SafetyParams { ramp: 0.02, ..Default::default() }
}

#[test]
fn local_model_of_a_wall_is_its_stiffness() {
    // A lossless wall (2000 N/m): the secant is exact, and the model predicts the physics at a
    // displaced tool exactly.
    let mut pl = PhysicsLoop::new(Box::new(Wall::new(Vec3::zeros(), Vec3::z(), 2000.0, 0.0)), 1000.0, 250, 0);
    let mut m = LocalModel::default();
    for k in 0..20 {
        m = pl.tick(&Vec3::new(0.0, 0.0, -1e-4 * k as f64));
    }
    let want = Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2000.0);
    assert!((m.stiffness - want).norm() < 1e-6, "{}", m.stiffness);
    let x = m.tool + Vec3::new(0.0, 0.0, -3e-5);
    let next = pl.tick(&x);
    assert!((next.force - m.force_at(&x)).norm() < 1e-9, "{:?} vs {:?}", next.force, m.force_at(&x));
}

/// The hybrid model pressed at 10 mm/s through the physics loop at 1 kHz: the model of each tick
/// predicts the next tick's force (`F_k - K_k (x_{k+1} - x_k)`) better than holding the force,
/// and its stiffness along the normal is the quasi-static one (two held presses 0.25 mm apart,
/// settled) within a factor the press's rate explains.
#[test]
fn local_model_of_the_hybrid_predicts_the_next_tick() {
    let physics = hybrid();
    let (p, n) = probe(&physics.sim().hybrid);
    let r = physics.sim().options.tool.radius;
    let mut pl = PhysicsLoop::new(Box::new(physics), 1000.0, 250, 0);
    let at = |d: f64| p + n * (r - d);
    // 1 mm clear to 3 mm deep at 10 mm/s.
    let models: Vec<LocalModel> = (0..=400).map(|k| pl.tick(&at(-0.001 + 1e-5 * k as f64))).collect();
    let (mut err_model, mut err_hold) = (0.0, 0.0);
    for w in models[200..].windows(2) {
        err_model += (w[1].force - w[0].force_at(&w[1].tool)).norm();
        err_hold += (w[1].force - w[0].force).norm();
    }
    let m = models[400];
    let k_n = n.dot(&(m.stiffness * n));
    println!(
        "hybrid press: |F| {:.4} N at 3 mm, K_nn {k_n:.1} N/m; next-tick error: model {:.3e} N, hold {:.3e} N (sum over 200 ticks)",
        m.force.norm(),
        err_model,
        err_hold
    );
    assert!(m.force.norm() > 0.02, "the press must touch");
    assert!(err_model < 0.3 * err_hold, "the model must predict the next tick: {err_model} vs hold {err_hold}");
    // Quasi-static: hold at 3 mm, then at 3.25 mm, 0.4 s each.
    let settle = |pl: &mut PhysicsLoop, d: f64| (0..400).map(|_| pl.tick(&at(d))).last().unwrap().force;
    let f0 = settle(&mut pl, 0.003);
    let f1 = settle(&mut pl, 0.00325);
    let k_qs = n.dot(&(f1 - f0)) / 0.00025;
    println!("quasi-static normal stiffness {k_qs:.1} N/m, the press's secant {k_n:.1} N/m");
    assert!(k_qs > 0.0);
    assert!(k_n > 0.5 * k_qs && k_n < 3.0 * k_qs, "secant {k_n} N/m against the settled {k_qs} N/m");
}

/// The loop holds the device 12 mm into a wall; the physics stops publishing (no new model):
/// full force for half the stall timeout, then a linear fade to zero at 30 ms, at 1 and
/// 4 kHz; the stall is logged once; the next model ramps the force in again.
#[test]
fn a_stalled_physics_fades_to_zero_within_30ms() {
    for rate in [1000.0, 4000.0] {
        let dt = 1.0 / rate;
        let mut core = HapticCore::new(Box::new(Wall::new(Vec3::zeros(), Vec3::z(), 2000.0, 0.0)), rate, CouplingParams::default(), fast_ramp(), 250, 0);
        let dev = DeviceInput::at(Vec3::new(0.0, 0.0, -0.012));
        // A model as the wall's at the device (2000 N/m x 12 mm = 24 N: past the 3 N limit).
        let model = |tick: u64| LocalModel {
            tick,
            tool: dev.position,
            force: Vec3::new(0.0, 0.0, 24.0),
            stiffness: Mat3::from_diagonal(&Vec3::new(0.0, 0.0, 2000.0)),
            faults: 0,
        };
        let ticks = (0.3 / dt) as u64;
        for k in 1..=ticks {
            core.render(Some(dev), Some(model(k)));
        }
        let full = core.render(Some(dev), Some(model(ticks + 1))).force.norm();
        assert!((full - 3.0).abs() < 1e-9, "{rate} Hz: at the limit before the stall: {full}");
        // The stall: no model from now on.
        let mut forces = vec![];
        for _ in 0..(0.05 / dt) as usize {
            forces.push(core.render(Some(dev), None).force.norm());
        }
        let at = |t: f64| forces[(t / dt).round() as usize - 1];
        assert!(at(0.014) > 2.99, "{rate} Hz: full force 14 ms into the stall: {}", at(0.014));
        // Half way through the fade (22.5 ms): the felt force is halved, less what the proxy
        // relaxed toward the device (its tissue force faded too).
        assert!(at(0.0225) <= 1.5 + 1e-9 && at(0.0225) > 0.75, "{rate} Hz: fading at 22.5 ms: {}", at(0.0225));
        assert!(forces.windows(2).all(|w| w[1] <= w[0] + 1e-12), "{rate} Hz: the fade never rises");
        assert_eq!(at(0.030), 0.0, "{rate} Hz: zero at 30 ms");
        assert!(forces[(0.030 / dt) as usize..].iter().all(|&f| f == 0.0));
        assert_eq!(core.stalls(), 1);
        assert!(matches!(core.fault_log()[0].fault, Fault::Stall(s) if (s - 0.015).abs() < 2.0 * dt));
        // An event, not a fault: logged, not counted.
        assert!(!core.fault_log()[0].counted && core.faults() == 0);
        // The physics back: ramped in (fast_ramp: 20 ms), not a step.
        let back = core.render(Some(dev), Some(model(ticks + 2))).force.norm();
        assert!(back > 0.0 && back < 1.0, "{rate} Hz: ramped back in: {back}");
    }
}

/// A device that stops sending for 0.2 s while pressing a wall: the force holds for the safety's
/// 50 ms, fades to zero within the next 30 ms, logged once; the device's return ramps it in. In
/// both loops.
#[test]
fn device_silence_fades_to_zero_and_resumes_through_the_ramp() {
    for multirate in [false, true] {
        let rate = 1000.0;
        let sink: Arc<LogSink> = Arc::default();
        let mut dev = Pressing { z: |_t: f64| -0.012, silent: |t: f64| (0.3..0.5).contains(&t), sink: sink.clone(), ticks: 700 };
        let mut core = HapticCore::new(Box::new(Wall::new(Vec3::zeros(), Vec3::z(), 2000.0, 0.0)), rate, CouplingParams::default(), fast_ramp(), 250, 700);
        if multirate {
            core.run_offline_multirate(&mut dev, 700, 250.0);
        } else {
            core.run_offline(&mut dev, 700);
        }
        let rec = core.recording().unwrap();
        let f = |t: f64| rec.ticks[(t * rate) as usize - 1].force.norm();
        let label = if multirate { "multirate" } else { "single-rate" };
        assert!(f(0.29) > 2.9, "{label}: pressing before the silence: {}", f(0.29));
        assert!(f(0.345) > 2.9, "{label}: held through the first 50 ms: {}", f(0.345));
        assert!(f(0.365) < 2.0 && f(0.365) > 0.5, "{label}: fading: {}", f(0.365));
        assert_eq!(f(0.381), 0.0, "{label}: zero within 30 ms of the fade's start");
        assert!((381..499).all(|ms| f(ms as f64 * 1e-3) == 0.0), "{label}: zero while silent");
        assert_eq!(core.silences(), 1, "{label}");
        assert!(
            core.fault_log().iter().any(|r| matches!(r.fault, Fault::DeviceSilent(s) if (s - 0.05).abs() < 0.002) && !r.counted),
            "{label}: logged as an event"
        );
        assert_eq!(core.faults(), 0, "{label}: a silence is not a fault");
        let back = f(0.502);
        assert!(back > 0.0 && back < 0.5, "{label}: ramped in after the silence: {back}");
        assert!(f(0.6) > 2.9, "{label}: full force again");
    }
}

/// Presses 6 mm into an undamped stiff wall (10,000 N/m) and back, 0.25 s each way, through the
/// multirate loop: the energy put into the user is not positive, servo at 1 and 4 kHz, physics
/// at 1 kHz and 250 Hz.
#[test]
fn passivity_against_a_stiff_wall_at_both_rates() {
    let nolimit = SafetyParams { max_force: 100.0, max_rate: 1e6, ramp: 0.0, stall_timeout: 0.03, silence: 0.05 };
    for (rate, physics_rate) in [(1000.0, 1000.0), (1000.0, 250.0), (4000.0, 1000.0), (4000.0, 250.0)] {
        let stiff = Wall::new(Vec3::zeros(), Vec3::z(), 1e4, 0.0);
        let mut core = HapticCore::new(Box::new(stiff), rate, CouplingParams::default(), nolimit, 250, 10_000);
        let z = |t: f64| if t < 0.25 { 0.002 - 0.032 * t } else { 0.002 - 0.032 * (0.5 - t).max(0.0) };
        let ticks = (0.6 * rate) as u64;
        let mut dev = pressing(z, Arc::new(LogSink::default()), ticks);
        core.run_offline_multirate(&mut dev, ticks, physics_rate);
        let rec = core.take_recording().unwrap();
        let forces: Vec<Vec3> = rec.ticks.iter().map(|t| t.force).collect();
        let xs: Vec<Vec3> = rec.ticks.iter().map(|t| t.input.position).collect();
        let e = energy_into_user(&forces, &xs);
        let fmax = forces.iter().map(|f| f.norm()).fold(0.0, f64::max);
        println!("wall, servo {rate} Hz, physics {physics_rate} Hz: max force {fmax:.2} N, energy into the user {e:.3e} J");
        assert!(fmax > 1.0, "the press must push");
        assert!(e <= 0.0, "servo {rate} Hz, physics {physics_rate} Hz: the device put {e} J into the user");
    }
}

/// The standard palpation of the hybrid model (a 5 mm press, hold, 4 mm slide, release) through
/// the multirate loop: passive at servo 1 and 4 kHz with the physics at 1 kHz and 250 Hz, no
/// fault, and the rendered force within 10% RMS of the single-rate loop's.
#[test]
fn passivity_on_the_hybrid_model_at_both_rates() {
    let physics = hybrid();
    let (p, n) = probe(&physics.sim().hybrid);
    let r = physics.sim().options.tool.radius;
    let (mut times, mut knots) = press_slide_release(p, n, r, 0.005, 0.004);
    // Clear of the surface until the ramp is over (see haptic_loop.rs).
    times.iter_mut().for_each(|t| *t += 0.6);
    times.insert(0, 0.0);
    knots.insert(0, knots[0]);
    let run = |rate: f64, physics_rate: Option<f64>| {
        let mut dev = Scripted::new(times.clone(), knots.clone()).unwrap();
        let ticks = (1.8 * rate) as u64;
        let mut core = HapticCore::new(Box::new(hybrid()), rate, CouplingParams::default(), SafetyParams::default(), 250, ticks as usize);
        match physics_rate {
            Some(pr) => core.run_offline_multirate(&mut dev, ticks, pr),
            None => core.run_offline(&mut dev, ticks),
        };
        assert_eq!(core.faults(), 0);
        core.take_recording().unwrap()
    };
    let single = run(1000.0, None);
    let f_single: Vec<Vec3> = single.ticks.iter().map(|t| t.force).collect();
    let jump_single = f_single.windows(2).map(|w| (w[1] - w[0]).norm()).fold(0.0, f64::max);
    println!("hybrid palpation, single-rate 1000 Hz: largest change in a period {jump_single:.4} N");
    let rms = |f: &[Vec3]| (f.iter().map(|v| v.norm_squared()).sum::<f64>() / f.len() as f64).sqrt();
    for (rate, pr) in [(1000.0, 1000.0), (1000.0, 250.0), (4000.0, 1000.0), (4000.0, 250.0)] {
        let rec = run(rate, Some(pr));
        let forces: Vec<Vec3> = rec.ticks.iter().map(|t| t.force).collect();
        let xs: Vec<Vec3> = rec.ticks.iter().map(|t| t.input.position).collect();
        let e = energy_into_user(&forces, &xs);
        // The single-rate force at the same times (every rate/1000-th servo tick).
        let step = (rate / 1000.0) as usize;
        let same: Vec<Vec3> = (0..f_single.len()).map(|k| forces[(k + 1) * step - 1]).collect();
        let diff: Vec<Vec3> = same.iter().zip(&f_single).map(|(a, b)| a - b).collect();
        let rel = rms(&diff) / rms(&f_single);
        let fmax = forces.iter().map(|f| f.norm()).fold(0.0, f64::max);
        let (at, jump) = forces.windows(2).map(|w| (w[1] - w[0]).norm()).enumerate().fold((0, 0.0), |a, (k, j)| if j > a.1 { (k, j) } else { a });
        println!(
            "  largest change at {:.4} s: {:?} -> {:?}, model ticks {} {}",
            (at + 1) as f64 / rate,
            forces[at],
            forces[at + 1],
            rec.model_ticks[at],
            rec.model_ticks[at + 1]
        );
        println!("hybrid palpation, servo {rate} Hz, physics {pr} Hz: max force {fmax:.3} N, largest change in a servo period {jump:.4} N, energy into the user {e:.3e} J, RMS difference from single-rate {:.1}%", rel * 100.0);
        assert!(fmax > 0.05, "the press must touch");
        assert!(e <= 0.0, "servo {rate} Hz, physics {pr} Hz: the device put {e} J into the user");
        assert!(rel < 0.10, "servo {rate} Hz, physics {pr} Hz: {:.1}% RMS from the single-rate loop", rel * 100.0);
        // The largest change is the coupling's damper at the script's corner (slide to release:
        // the device's velocity turns by ~27 mm/s, times 2 N s/m), the same in both loops.
        assert!(jump <= 1.1 * jump_single, "servo {rate} Hz, physics {pr} Hz: the force changed {jump} N in a period (single-rate: {jump_single} N)");
    }
}

/// A multirate recording replays bit for bit: offline (through a file) and from the real-time
/// threads, whose interleaving of physics and servo ticks the clock decided.
#[test]
fn replay_of_a_multirate_run_is_bit_identical() {
    let physics = hybrid();
    let (p, n) = probe(&physics.sim().hybrid);
    let r = physics.sim().options.tool.radius;
    let (times, knots) = press_slide_release(p, n, r, 0.004, 0.004);
    let rate = 2000.0;
    let ticks = (1.1 * rate) as usize;
    // Offline.
    let mut dev = Scripted::new(times.clone(), knots.clone()).unwrap();
    let mut core = HapticCore::new(Box::new(physics), rate, CouplingParams::default(), fast_ramp(), 100, ticks);
    core.run_offline_multirate(&mut dev, ticks as u64, 500.0);
    let rec = core.take_recording().unwrap();
    assert!(rec.ticks.iter().map(|t| t.force.norm()).fold(0.0, f64::max) > 0.05, "the press must touch");
    assert_eq!(rec.targets.len(), 550);
    let dir = std::env::temp_dir().join(format!("palpate-multirate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("press.palprec");
    rec.save(&path).unwrap();
    let loaded = Recording::load(&path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(
        (loaded.physics_rate_hz, loaded.model_ticks.len(), loaded.targets.len(), loaded.safety, loaded.ticks.len()),
        (rec.physics_rate_hz, rec.model_ticks.len(), rec.targets.len(), rec.safety, rec.ticks.len())
    );
    assert!(loaded == rec, "the file round-trips the multirate fields");
    let mut again = HapticCore::new(Box::new(hybrid()), rate, loaded.coupling, loaded.safety, 100, ticks);
    assert_eq!(again.replay_multirate(&loaded), Ok(ticks as u64));
    let rep = again.take_recording().unwrap();
    assert_eq!(compare(&rec, &rep), None, "offline replay differs");
    // The replay ticks the physics as far as the servo rendered (the run's last physics tick
    // came after its last servo tick's model).
    assert!(rep.targets.len() + 1 >= rec.targets.len() && rep.targets[..] == rec.targets[..rep.targets.len()]);

    // Real time: the physics thread at 500 Hz beside the servo at 2 kHz.
    let dev = Scripted::new(times, knots).unwrap();
    let safety = SafetyParams { stall_timeout: 10.0, ..fast_ramp() };
    let cfg = ServoConfig {
        rate_hz: rate,
        physics_rate_hz: Some(500.0),
        safety: Some(safety),
        record_ticks: ticks,
        checkpoint_every: 100,
        unsafe_limits: true,
        ..Default::default()
    };
    let core = HapticCore::with_config(Box::new(hybrid()), &cfg, &dev).unwrap();
    let report = Servo::start(core, Box::new(dev), &cfg).unwrap().join();
    let ps = report.physics.clone().expect("the physics thread's statistics");
    println!("real time: servo {:.0} Hz achieved, {} overruns; physics {:.0} Hz achieved ({} ticks, compute p50 {:.3} ms p99 {:.3} ms, lag p99 {:.3} ms, late {}, skipped {})", report.stats.achieved_hz, report.stats.overruns, ps.achieved_hz, ps.ticks, ps.compute_p50 * 1e3, ps.compute_p99 * 1e3, ps.lag_p99 * 1e3, ps.late, ps.skipped);
    let mut rt = report.core;
    let rec = rt.take_recording().unwrap();
    assert_eq!(rec.physics_rate_hz, Some(500.0));
    assert_eq!(rec.ticks.len(), ticks);
    assert!(ps.ticks > 0 && !rec.targets.is_empty());
    let mut again = HapticCore::new(Box::new(hybrid()), rate, rec.coupling, rec.safety, 100, ticks);
    assert_eq!(again.replay_multirate(&rec), Ok(ticks as u64));
    let rep = again.take_recording().unwrap();
    if let Some(k) = compare(&rec, &rep) {
        let first_model = rec.model_ticks.iter().position(|&m| m > 0).unwrap_or(0);
        panic!("the real-time run's replay differs at servo tick {k} (model {} there; first model at tick {first_model}; recorded {:?} {:?}, replayed {:?} {:?}; inputs {:?} {:?})", rec.model_ticks[k], rec.ticks[k].force, rec.ticks[k].tool, rep.ticks[k].force, rep.ticks[k].tool, rec.ticks[k].has_input, rep.ticks[k].has_input);
    }
    // The servo was never held by the physics: the hybrid model at 500 Hz.
    assert_eq!(rt.physics().identity(), hybrid().identity(), "the physics is back in the core");
}

/// A physics thread that stalls 200 ms in a tick: the servo keeps rendering every period (the
/// stall is not its own), the force fades to zero within 30 ms of the last model, and comes back
/// through the ramp.
#[test]
fn the_servo_keeps_its_period_while_the_physics_stalls() {
    let mut faulty = Faulty::new(Wall::new(Vec3::zeros(), Vec3::z(), 2000.0, 0.0), 300);
    faulty.stall = Some(Duration::from_millis(200));
    let stalled_at = faulty.stalled_at.clone();
    let log = Arc::new(LogSink::default());
    log.0.lock().unwrap().reserve(20_000);
    let dev = pressing(|_t: f64| -0.012, log.clone(), 1200);
    let cfg = ServoConfig { rate_hz: 1000.0, physics_rate_hz: Some(1000.0), safety: Some(fast_ramp()), ..Default::default() };
    let core = HapticCore::with_config(Box::new(faulty), &cfg, &dev).unwrap();
    let report = Servo::start(core, Box::new(dev), &cfg).unwrap().join();
    let t_stall = stalled_at.lock().unwrap().expect("the stall happened");
    let sends = log.0.lock().unwrap().clone();
    let during: Vec<_> = sends.iter().filter(|(t, _)| *t > t_stall && (*t - t_stall) < Duration::from_millis(190)).collect();
    // Sends went on through the stall (a servo waiting for the physics would send none).
    assert!(during.len() > 100, "{} sends during the 200 ms stall", during.len());
    let zero_at = during.iter().find(|(_, f)| *f == Vec3::zeros()).expect("a zero force during the stall").0;
    let after = (zero_at - t_stall).as_secs_f64();
    // The fade's 30 ms from the last model (published before the stall began), and 10 ms for a
    // loaded machine.
    assert!(after <= 0.030 + 0.010, "force zero {:.1} ms after the stall began", after * 1e3);
    assert!(during.iter().filter(|(t, _)| *t > zero_at).all(|(_, f)| *f == Vec3::zeros()), "zero until the physics is back");
    assert_eq!(report.watchdog_trips, 0, "the servo itself never stalled");
    assert_eq!(report.core.faults(), 0);
    assert!(report.core.stalls() >= 1);
    let last = sends.last().unwrap().1;
    assert_eq!(last, Vec3::zeros(), "the last act sends zero");
    let before_end = sends[sends.len() - 2].1;
    assert!(before_end.norm() > 2.9, "the force is back after the stall: {before_end:?}");
}

/// The simulated hand (`Hand`) with its target on a script `path(t)`.
struct GuidedHand<P: Fn(f64) -> Vec3 + Send> {
    hand: Hand,
    target: Arc<palpate_haptics::snapshot::Vec3Cell>,
    path: P,
    ticks: u64,
}

impl<P: Fn(f64) -> Vec3 + Send> Device for GuidedHand<P> {
    fn read(&mut self, tick: u64, dt: f64) -> Option<DeviceInput> {
        self.target.set(&(self.path)((tick + 1) as f64 * dt));
        self.hand.read(tick, dt)
    }
    fn sink(&self) -> Arc<dyn ForceSink> {
        self.hand.sink()
    }
    fn kind(&self) -> DeviceKind {
        DeviceKind::Simulated
    }
    fn finished(&self, ticks: u64, _dt: f64) -> bool {
        ticks >= self.ticks
    }
}

/// The worst a hand gives, through the multirate loop on the hybrid model: a stiff arm (500 N/m,
/// critically damped) pulling toward a point 25 mm past the surface (12 N if the surface held
/// it there, past the 3 N limit; the ellipsoids' 6 mm wall gives way to ~0.65 N), a slide of its target 40 mm along the wall and back at up to
/// 0.2 m/s while pressing, then letting go. At servo 1 and 4 kHz with the physics at 1 kHz, and
/// at 4 kHz with the physics at 250 Hz: every force finite and within the limit, no change in a
/// period past the safety's rate limit, no fault, no energy into the user, and the press felt
/// as the single-rate loop renders it (the force at the hold, and with the physics at 1 kHz
/// through the slide, within 10%: a local model that lets the tool sink, or one too stiff to
/// follow the slide, would not be).
#[test]
fn a_hard_press_and_a_fast_slide_through_the_multirate_loop() {
    let physics = hybrid();
    let (p, n) = probe(&physics.sim().hybrid);
    let r = physics.sim().options.tool.radius;
    let clear = p + n * (r + 0.003);
    let deep = p + n * (r - 0.025);
    let smooth = |s: f64| {
        let s = s.clamp(0.0, 1.0);
        s * s * (3.0 - 2.0 * s)
    };
    // 0.6 s clear (the start-up ramp), 0.4 s in, 0.3 s hold, 0.3 s slide 40 mm up and 0.3 s back,
    // 0.4 s out.
    let path = move |t: f64| {
        let slide = if t < 1.3 {
            0.0
        } else if t < 1.6 {
            0.04 * smooth((t - 1.3) / 0.3)
        } else {
            0.04 * (1.0 - smooth((t - 1.6) / 0.3))
        };
        let press = if t < 0.6 {
            0.0
        } else if t < 1.9 {
            smooth((t - 0.6) / 0.4)
        } else {
            1.0 - smooth((t - 1.9) / 0.4)
        };
        clear + (deep - clear) * press + Vec3::z() * slide
    };
    let arm = HandParams { mass: 0.1, stiffness: 500.0, damping: 14.0 };
    let limits = SafetyParams::default();
    let run = |rate: f64, pr: Option<f64>| {
        let ticks = (2.5 * rate) as u64;
        let hand = Hand::new(arm, clear);
        let target = hand.target();
        let mut dev = GuidedHand { hand, target, path, ticks };
        let mut core = HapticCore::new(Box::new(hybrid()), rate, CouplingParams::default(), limits, 250, ticks as usize);
        let ran = match pr {
            Some(pr) => core.run_offline_multirate(&mut dev, ticks, pr),
            None => core.run_offline(&mut dev, ticks),
        };
        assert_eq!(ran, ticks);
        assert_eq!(core.faults(), 0, "{:?}", core.fault_log());
        let rec = core.take_recording().unwrap();
        let forces: Vec<Vec3> = rec.ticks.iter().map(|t| t.force).collect();
        let xs: Vec<Vec3> = rec.ticks.iter().map(|t| t.input.position).collect();
        (forces, xs)
    };
    // The force at the hold (1.25 s) and its mean through the slide (1.35-1.85 s), every 1 ms.
    let felt = |f: &[Vec3], rate: f64| {
        let at = |t: f64| f[(t * rate) as usize - 1].norm();
        (at(1.25), (0..500).map(|k| at(1.35 + k as f64 * 1e-3)).sum::<f64>() / 500.0)
    };
    let (single, _) = run(1000.0, None);
    let (hold0, slide0) = felt(&single, 1000.0);
    println!("hard press, single-rate 1000 Hz: force at the hold {hold0:.3} N, mean through the slide {slide0:.3} N");
    assert!(hold0 > 0.3, "the press must push: {hold0} N");
    for (rate, pr) in [(1000.0, 1000.0), (4000.0, 1000.0), (4000.0, 250.0)] {
        let (forces, xs) = run(rate, Some(pr));
        let fmax = forces.iter().map(|f| f.norm()).fold(0.0, f64::max);
        let step = forces.windows(2).map(|w| (w[1] - w[0]).norm()).fold(0.0, f64::max);
        let e = energy_into_user(&forces, &xs);
        let (hold, slide) = felt(&forces, rate);
        println!("hard press, servo {rate} Hz, physics {pr} Hz: max force {fmax:.3} N, at the hold {hold:.3} N, mean through the slide {slide:.3} N, largest change in a period {step:.4} N, energy into the user {e:.3e} J");
        assert!(forces.iter().all(|f| f.iter().all(|c| c.is_finite())));
        assert!(fmax <= limits.max_force + 1e-9, "rendered {fmax} N");
        assert!(step <= limits.max_rate / rate + 1e-9, "the force changed {step} N in a period");
        assert!((hold - hold0).abs() < 0.1 * hold0, "at the hold {hold} N against the single-rate loop's {hold0} N");
        if pr >= 1000.0 {
            assert!((slide - slide0).abs() < 0.1 * slide0, "through the slide {slide} N against the single-rate loop's {slide0} N");
        } else {
            // The simulated tool's top speed is a speed (SimOptions::max_tool_speed, 0.5 m/s), so
            // a 250 Hz physics follows the slide's 0.2 m/s peak too: measured 0.52 N against
            // 0.44 (+18%, the 4 ms tick's lag behind the proxy); with the core under the active
            // shell at the build's active factor (2026-12-08), 0.449 N against 0.356 (+26%: the
            // same lag, 0.09 N, over a softer tissue's force). When it was a step of 0.5 mm a
            // tick (0.125 m/s at 250 Hz) the coupling dragged the hand: 1.10 N, 2.03 N at most.
            assert!((slide - slide0).abs() < 0.35 * slide0, "through the slide {slide} N against the single-rate loop's {slide0} N");
        }
        assert!(e <= 0.0, "the device put {e} J into the user");
    }
}
