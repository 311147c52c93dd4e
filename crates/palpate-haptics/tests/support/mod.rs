//! Shared set-ups of the haptic tests: a small hybrid model (the paper's ellipsoids, built once
//! per test binary), a probe point and a press-slide-release script on it, and physics wrappers
//! that inject faults.
#![allow(dead_code)]

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use palpate_core::hybrid::{build, shapes, HybridModel, HybridOptions};
use palpate_core::material::{Damping, Elasticity};
use palpate_core::runtime::SimOptions;
use palpate_core::{Material, StepError, Vec3};
use palpate_haptics::{Device, DeviceInput, DeviceKind, ForceSink, HybridPhysics, Identity, Physics};

/// The paper's concentric ellipsoids, at the default build options.
pub fn ellipsoids() -> &'static HybridModel {
    static M: OnceLock<HybridModel> = OnceLock::new();
    M.get_or_init(|| build(&shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap(), &HybridOptions::default()).unwrap())
}

/// Myocardium-like, damped (the runtime tests' material).
pub fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::from_paper(0.5, 0.5)).unwrap()
}

pub fn hybrid() -> HybridPhysics {
    HybridPhysics::new(ellipsoids().clone(), material(), SimOptions::default()).unwrap()
}

/// The probe: the outer vertex with the largest x near z = -5 mm (below the equator, above the
/// held lower 30%), and the outward normal there (radial in x, y).
pub fn probe(m: &HybridModel) -> (Vec3, Vec3) {
    let p = *m.outer_points.iter().filter(|q| q.z.abs() < 0.006).max_by(|a, b| a.x.total_cmp(&b.x)).unwrap();
    (p, Vec3::new(p.x, p.y, 0.0).normalize())
}

/// Knots of a press to `depth` [m] over 0.3 s, a 0.2 s hold, a `slide` [m] along z over 0.3 s and
/// a release to the start over 0.3 s, for a tool of `radius` starting 2 mm clear.
pub fn press_slide_release(point: Vec3, normal: Vec3, radius: f64, depth: f64, slide: f64) -> (Vec<f64>, Vec<Vec3>) {
    let c = |d: f64, s: f64| point + normal * (radius - d) + Vec3::z() * s;
    (vec![0.0, 0.3, 0.5, 0.8, 1.1], vec![c(-0.002, 0.0), c(depth, 0.0), c(depth, 0.0), c(depth, slide), c(-0.002, slide)])
}

/// Forces sent, with when (a test sink; allocation is fine in a test).
#[derive(Default)]
pub struct LogSink(pub Mutex<Vec<(Instant, Vec3)>>);

impl ForceSink for LogSink {
    fn send(&self, f: &Vec3) {
        self.0.lock().unwrap().push((Instant::now(), *f));
    }
}

/// Wraps a physics and, at tick `at` (counted from the first tick, restores included), stalls
/// for `stall`, returns a NaN force (`nan`) or corrupts the inner physics first (`corrupt`: as
/// a bad state would be); with `bad_state_from = Some(k)`, its state reads as non-finite from
/// its `k`-th tick after the start or the last restore while its force stays finite (a NaN where
/// the tick does not look, met only by `is_finite`). Counts restores.
pub struct Faulty<P: Physics> {
    pub inner: P,
    pub at: u64,
    pub stall: Option<Duration>,
    /// Work on the CPU this long at tick `at` (the thread's CPU clock, so the time is the
    /// physics' own however busy the machine is).
    pub burn: Option<Duration>,
    pub nan: bool,
    pub corrupt: Option<fn(&mut P)>,
    pub bad_state_from: Option<u64>,
    pub ticks: u64,
    /// Ticks since the start or the last restore (for `bad_state_from`).
    pub since_restore: u64,
    pub stalled_at: Arc<Mutex<Option<Instant>>>,
    pub restores: Arc<AtomicU64>,
    /// Called at each checkpoint, before the inner physics keeps its state.
    pub on_checkpoint: Option<Box<dyn FnMut() + Send>>,
    /// Called at each finish (the tick's rest after its send), before the inner physics'.
    pub on_finish: Option<Box<dyn FnMut() + Send>>,
    /// The finish of this tick fails (as an owed core step of the hybrid model may).
    pub finish_fails_at: Option<u64>,
}

impl<P: Physics> Faulty<P> {
    pub fn new(inner: P, at: u64) -> Faulty<P> {
        Faulty {
            inner,
            at,
            stall: None,
            burn: None,
            nan: false,
            corrupt: None,
            bad_state_from: None,
            ticks: 0,
            since_restore: 0,
            stalled_at: Arc::default(),
            restores: Arc::default(),
            on_checkpoint: None,
            on_finish: None,
            finish_fails_at: None,
        }
    }
}

impl<P: Physics> Physics for Faulty<P> {
    fn tick(&mut self, tool: &Vec3, dt: f64) -> Result<Vec3, StepError> {
        let k = self.ticks;
        self.ticks += 1;
        self.since_restore += 1;
        if k == self.at {
            if let Some(d) = self.stall {
                *self.stalled_at.lock().unwrap() = Some(Instant::now());
                std::thread::sleep(d);
            }
            if let Some(d) = self.burn {
                let c0 = palpate_haptics::realtime::thread_cpu_time().expect("a thread CPU clock");
                while palpate_haptics::realtime::thread_cpu_time().unwrap() - c0 < d.as_secs_f64() {
                    std::hint::spin_loop();
                }
            }
            if let Some(corrupt) = self.corrupt {
                corrupt(&mut self.inner);
            }
        }
        let f = self.inner.tick(tool, dt)?;
        Ok(if k == self.at && self.nan { Vec3::new(f64::NAN, f.y, f.z) } else { f })
    }
    fn tool(&self) -> Option<Vec3> {
        self.inner.tool()
    }
    fn max_tool_speed(&self) -> f64 {
        self.inner.max_tool_speed()
    }
    fn finish(&mut self) -> Result<(), StepError> {
        if let Some(f) = &mut self.on_finish {
            f();
        }
        if self.finish_fails_at.is_some_and(|k| k + 1 == self.ticks) {
            return Err(StepError::NonFiniteTool);
        }
        self.inner.finish()
    }
    fn checkpoint(&mut self) {
        if let Some(f) = &mut self.on_checkpoint {
            f();
        }
        self.inner.checkpoint()
    }
    fn restore(&mut self) {
        self.restores.fetch_add(1, Ordering::Relaxed);
        self.since_restore = 0;
        self.inner.restore()
    }
    fn is_finite(&self) -> bool {
        self.inner.is_finite() && self.bad_state_from.is_none_or(|k| self.since_restore < k)
    }
    fn identity(&self) -> Identity {
        self.inner.identity()
    }
}

/// The energy the device put into the user [J]: the force held over each tick (zero-order hold)
/// times the hand's displacement over it, `sum_k F_k . (x_{k+1} - x_k)`.
pub fn energy_into_user(forces: &[Vec3], positions: &[Vec3]) -> f64 {
    forces.iter().zip(positions.windows(2)).map(|(f, w)| f.dot(&(w[1] - w[0]))).sum()
}

/// A device at `z(t)` on the z axis \[m\], silent (no sample) while `silent(t)`, for `ticks`
/// ticks, reporting through `sink`.
pub struct Pressing<F: Fn(f64) -> f64 + Send, S: Fn(f64) -> bool + Send> {
    pub z: F,
    pub silent: S,
    pub sink: Arc<dyn ForceSink>,
    pub ticks: u64,
}

/// A device at `z(t)` that never falls silent.
pub fn pressing<F: Fn(f64) -> f64 + Send>(z: F, sink: Arc<dyn ForceSink>, ticks: u64) -> Pressing<F, fn(f64) -> bool> {
    Pressing { z, silent: |_| false, sink, ticks }
}

impl<F: Fn(f64) -> f64 + Send, S: Fn(f64) -> bool + Send> Device for Pressing<F, S> {
    fn read(&mut self, tick: u64, dt: f64) -> Option<DeviceInput> {
        let t = (tick + 1) as f64 * dt;
        (!(self.silent)(t)).then(|| DeviceInput::at(Vec3::new(0.0, 0.0, (self.z)(t))))
    }
    fn sink(&self) -> Arc<dyn ForceSink> {
        self.sink.clone()
    }
    fn kind(&self) -> DeviceKind {
        DeviceKind::Simulated
    }
    fn finished(&self, ticks: u64, _dt: f64) -> bool {
        ticks >= self.ticks
    }
}
