//! The servo loop: [`HapticCore`], one deterministic tick (device sample in, force out), and
//! [`Servo`], the native thread that runs it at 250 Hz-4 kHz against the wall clock, with a
//! watchdog thread beside it.
//!
//! # A tick ([`HapticCore::step`])
//! 1. The device's sample (a missing or non-finite one holds the last; non-finite ones counted).
//! 2. The simulation ticks with its tool at the coupling's proxy: the tissue's force on it.
//! 3. The coupling ([`crate::coupling`]) moves the proxy and gives the force to render.
//! 4. The safety layer ([`crate::safety`]): ramp, force limit, rate limit.
//! 5. A fault (the physics tick failed, or a force or the proxy is not finite) zeroes the
//!    force *this* tick, restores the simulation's last good state, puts the proxy at its tool,
//!    restarts the ramp, and is logged.
//! 6. After the force is sent ([`HapticCore::after_send`]): the part of the tick its force does
//!    not depend on ([`Physics::finish`]: the hybrid model's skin update, 40-90 us on the Rodero
//!    ventricle, ~10% of a pressing tick, and its core's step when the tool has nothing of the
//!    core within reach, ~20%; a failure there is a fault as a failed tick's); then every
//!    `checkpoint_every` ticks without a fault (and with a finite state) the state becomes the
//!    last good one; a state found non-finite there is a fault (the force zeroed at once, the
//!    state restored).
//!
//! The checkpoint comes after the send because it is the tick's largest fixed cost and its
//! force does not depend on it: on the Rodero ventricle (28,039 particles, a 31,788-vertex skin)
//! the copy and the finiteness scan take ~0.15-0.25 ms. Taken before the send, a checkpoint
//! landing on a pressing tick (0.7-0.85 ms) made that tick late: in a quiet 20 s palpation at
//! 1 kHz, 43 of 63 overruns fell on the checkpoint's ticks (every 250th, 2026-11-27). After the
//! send it uses the tick's slack, and delays the next tick only when this one left too little.
//!
//! Everything in a tick depends on the inputs and the tick count only (nominal `dt`), so
//! [`HapticCore::run_offline`] and the real-time thread give the same forces for the same
//! inputs (record and replay).
//!
//! # The thread ([`Servo::start`])
//! Absolute-deadline pacing: tick `k` starts at `t0 + k T`; after the work, the thread sleeps
//! until `spin` before the next deadline and spins the rest (an OS sleep overshoots by tens to
//! hundreds of microseconds; spinning only the last part keeps the period tight without burning
//! a core). A tick that ends after its deadline is an overrun (counted, its time logged); one
//! that ends more than a whole period late re-anchors the schedule (the missed deadlines are not
//! caught up in a burst, which would feed the simulation several ticks in a row with one device
//! sample each). The thread never waits on Python, the disk, the network or a reader: readers
//! take [`Snapshot`]s through a seqlock, recording and statistics go to buffers sized at start.
//!
//! # Two rates ([`ServoConfig::physics_rate_hz`], [`crate::multirate`])
//! With a physics rate set, the physics leaves the servo thread: [`Servo::start`] runs a physics
//! thread that ticks on its own clock and publishes a local model after each tick, and the
//! servo renders every period from it ([`HapticCore::render`]: the proxy against the model's
//! force and stiffness, then the safety layer), with no physics in its period at all. A physics
//! that stalls fades out within the stall timeout instead of holding the servo; the watchdog
//! then guards the servo thread alone. Measured on the Rodero palpation (BENCHMARKS.md), a
//! physics tick slower than the period no longer costs the hand a period.
//!
//! # Device silence
//! A device that sends no new sample for the safety's `silence` (50 ms) has its force faded to
//! zero over 30 ms, in both loops (logged as [`Fault::DeviceSilent`], not a fault path); its
//! return ramps the force in again.
//!
//! # The watchdog
//! A second thread checks the servo's heartbeat (the end time of its last tick) every
//! millisecond. When the physics has not completed a tick for `stall_timeout` (30 ms), it zeroes
//! the device's force through the device's [`ForceSink`] (which the servo thread, stuck in the
//! physics, cannot) and raises a flag; the servo, once its tick returns, takes the fault path
//! (zero, restore, ramp, log) instead of sending its stale force.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use palpate_core::{StepError, Vec3};

use crate::coupling::{CouplingParams, VirtualCoupling};
use crate::device::{Device, DeviceInput, ForceSink};
use crate::multirate::{LocalModel, ModelCell, PhysicsLoop, PhysicsStats, Recovering};
use crate::physics::Physics;
use crate::realtime::Realtime;
use crate::record::{Recording, TickRecord};
use crate::safety::{Safety, SafetyParams};
use crate::snapshot::{Mailbox, Snapshot, SnapshotCell, Vec3Cell};
use crate::stats::{Stats, TickTimes};

/// Rates the servo accepts \[Hz\].
pub const MIN_RATE_HZ: f64 = 250.0;
pub const MAX_RATE_HZ: f64 = 4000.0;

/// Why a tick took the fault path.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// The simulation's tick failed (it left its state as before the tick).
    Step(StepError),
    /// The tissue's force, the proxy or the rendered force was not finite.
    NonFinite,
    /// The simulation did not complete a tick for this long \[s\] (the watchdog; in the
    /// multirate loop, the local model's age when its fade began: logged, not a fault path).
    Stall(f64),
    /// No new device sample for this long \[s\]: the force fades to zero (logged when the fade
    /// begins; not a fault path).
    DeviceSilent(f64),
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fault::Step(e) => write!(f, "the simulation's tick failed: {e}"),
            Fault::NonFinite => write!(f, "non-finite force, tool position or state"),
            Fault::Stall(s) => write!(f, "the simulation missed ticks for {:.1} ms", s * 1e3),
            Fault::DeviceSilent(s) => write!(f, "the device sent no sample for {:.1} ms: force faded to zero", s * 1e3),
        }
    }
}

/// A fault, when it happened (tick and simulated time \[s\]).
#[derive(Debug, Clone, PartialEq)]
pub struct FaultRecord {
    pub tick: u64,
    pub time: f64,
    pub fault: Fault,
    /// A fault path (counted in [`HapticCore::faults`]: the tick's force zeroed and the physics
    /// restored, or a non-finite model), or false for an event logged only (a device silence's
    /// or a stale model's fade beginning, the servo thread's watchdog trip).
    pub counted: bool,
}

/// At most this many faults are logged (later ones are counted only).
pub const FAULT_LOG: usize = 256;

/// The servo's configuration (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoConfig {
    /// Tick rate \[Hz\], 250 to 4000 (default 1000): the servo's (the device's) rate.
    pub rate_hz: f64,
    /// The physics thread's rate \[Hz\] (100 to `rate_hz`): `Some` runs the multirate loop
    /// ([`crate::multirate`]: the servo renders from a local model the physics publishes and
    /// never waits for it); `None` (the default) the single-rate loop, a physics tick inside
    /// every servo period.
    pub physics_rate_hz: Option<f64>,
    /// The coupling; `None`: the device's defaults ([`crate::DeviceKind::defaults`]).
    pub coupling: Option<CouplingParams>,
    /// The safety layer; `None`: the device's defaults.
    pub safety: Option<SafetyParams>,
    /// Ticks between last-good checkpoints (default 250: a quarter second at 1 kHz; a checkpoint
    /// of the hybrid state costs ~0.15 ms on the Rodero ventricle, see [`crate::HybridPhysics`]).
    pub checkpoint_every: u64,
    /// Ticks recorded for replay (0: none; the buffer is allocated at start, so that the servo
    /// never allocates; ticks past it are not recorded but counted,
    /// [`HapticCore::recording_dropped`]).
    pub record_ticks: usize,
    /// Ticks whose period and compute time are kept for the percentiles (the latest, a ring;
    /// default 600,000: 10 min at 1 kHz, 4.8 MB).
    pub stats_ticks: usize,
    /// Stop after this many ticks (`None`: when the device is finished or on [`ServoHandle::stop`]).
    pub max_ticks: Option<u64>,
    /// The last part of each wait that is spun rather than slept \[s\], 0 to 1 s (default 200 us).
    /// A whole period or more: the servo never sleeps and keeps its core busy. Measured on the
    /// Rodero palpation at 1 kHz (2026-11-26,
    /// docs/history/benchmarks-log.md#2026-11-26-fifth-session-the-tick-in-morton-order-load-07-10-1412-1420-utc):
    /// the compute p99 4-20% lower in every pair of
    /// runs; the overruns, which come in the machine's bursts, fewer in three of five runs and
    /// more in two. Not with `realtime`.
    pub spin: f64,
    /// Ticks between surface snapshots for a viewer ([`ServoHandle::surface`]; default 32:
    /// 31 Hz at 1 kHz; 0: none) while someone reads them (a read within the last
    /// [`IDLE_SNAPSHOT_TICKS`] ticks); with no reader, one every [`IDLE_SNAPSHOT_TICKS`] ticks.
    /// (A snapshot copies the whole skin, 0.76 MB on Rodero, in the servo thread: a headless
    /// loop should not pay it 31 times a second.)
    pub surface_every: u64,
    /// Run the servo under `SCHED_FIFO` (and the watchdog one level above it), so that the
    /// machine's other work cannot preempt a tick ([`crate::realtime`]); refused without
    /// privilege, which [`ServoReport::realtime`] says. Default false. Set `spin` to 0 with it
    /// (the module says why).
    pub realtime: bool,
    /// Accept a force limit or a coupling beyond the device class's rating, or a watchdog or
    /// silence timeout over 100 ms ([`crate::safety::check_limits`]); the caller logs it.
    /// Default false.
    pub unsafe_limits: bool,
}

/// Without a reader, the surface and interior snapshots are refreshed about once every this many
/// ticks (0.5 s at 1 kHz: a reader's first read is at most about that old); a read makes them
/// follow [`ServoConfig::surface_every`] again for as many ticks.
pub const IDLE_SNAPSHOT_TICKS: u64 = 512;

impl Default for ServoConfig {
    fn default() -> Self {
        ServoConfig {
            rate_hz: 1000.0,
            physics_rate_hz: None,
            coupling: None,
            safety: None,
            checkpoint_every: 250,
            record_ticks: 0,
            stats_ticks: 600_000,
            max_ticks: None,
            spin: 200e-6,
            surface_every: 32,
            realtime: false,
            unsafe_limits: false,
        }
    }
}

impl ServoConfig {
    pub fn check(&self) -> Result<(), String> {
        if !(self.rate_hz >= MIN_RATE_HZ && self.rate_hz <= MAX_RATE_HZ) {
            return Err(format!("rate = {} Hz must be within {MIN_RATE_HZ} to {MAX_RATE_HZ} Hz", self.rate_hz));
        }
        if let Some(p) = self.physics_rate_hz {
            let lo = crate::multirate::MIN_PHYSICS_RATE_HZ;
            if !(p >= lo && p <= self.rate_hz) {
                return Err(format!("physics rate = {p} Hz must be within {lo} Hz and the servo's rate ({} Hz)", self.rate_hz));
            }
        }
        if let Some(c) = &self.coupling {
            c.check()?;
        }
        if let Some(s) = &self.safety {
            s.check()?;
        }
        if self.checkpoint_every == 0 {
            return Err("checkpoint_every must be at least 1 tick".into());
        }
        if !(0.0..=1.0).contains(&self.spin) {
            return Err(format!("spin = {} s must be within 0 to 1 s", self.spin));
        }
        Ok(())
    }
    /// The tick \[s\].
    pub fn dt(&self) -> f64 {
        1.0 / self.rate_hz
    }
}

/// What one tick did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickOut {
    /// The force to send \[N\] (after the safety layer).
    pub force: Vec3,
    /// The coupling's force before the safety layer \[N\].
    pub raw_force: Vec3,
    /// The tissue's force on the simulated tool \[N\].
    pub tissue: Vec3,
    /// The proxy (the simulated tool) \[m\], and the device \[m\].
    pub tool: Vec3,
    pub device: Vec3,
    pub buttons: u32,
    /// Did this tick take the fault path?
    pub fault: bool,
}

/// The deterministic part of the loop: physics, coupling, safety, fault handling, recording.
pub struct HapticCore {
    physics: Box<dyn Physics>,
    coupling: VirtualCoupling,
    safety: Safety,
    dt: f64,
    checkpoint_every: u64,
    tick: u64,
    input: Option<DeviceInput>,
    tissue: Vec3,
    faults: u64,
    fault_log: Vec<FaultRecord>,
    bad_inputs: u64,
    recording: Option<Recording>,
    /// Ticks that found the recording's buffer full (not recorded: the recording is the run's
    /// first `record_ticks` ticks).
    recording_dropped: u64,
    /// The largest force sent \[N\], and the energy the device has put into the user \[J\]:
    /// `sum F_k . (x_{k+1} - x_k)` (the force held over a tick times the hand's move; negative
    /// for a passive loop: the user does the work).
    max_force: f64,
    energy: f64,
    last_sent: Option<(Vec3, Vec3)>,
    /// Ticks since the device's last new (finite) sample, and whether its silence's fade was
    /// logged; fades logged (device silences, stale local models).
    since_sample: u64,
    silent: bool,
    silences: u64,
    /// Multirate ([`HapticCore::render`]): the local model rendered from, the ticks since it
    /// arrived, whether its staleness was logged, the proxy's speed limit \[m/s\].
    model: LocalModel,
    model_age: u64,
    stale: bool,
    stalls: u64,
    tool_speed: f64,
    physics_dt: f64,
    /// The weight the model's and the device's fades left on the force (it falls with a fade
    /// at once and recovers at the fade's own slope: a model that arrives after a partial fade
    /// brings the force back over milliseconds, not in a step).
    weight: Recovering,
    silence_w: Recovering,
}

impl HapticCore {
    /// A loop over `physics` at `rate_hz` with these coupling and safety parameters, recording
    /// up to `record_ticks` ticks.
    pub fn new(
        physics: Box<dyn Physics>,
        rate_hz: f64,
        coupling: CouplingParams,
        safety: SafetyParams,
        checkpoint_every: u64,
        record_ticks: usize,
    ) -> HapticCore {
        let recording = (record_ticks > 0).then(|| Recording {
            rate_hz,
            identity: physics.identity(),
            coupling,
            safety,
            faults: 0,
            ticks: Vec::with_capacity(record_ticks),
            physics_rate_hz: None,
            model_ticks: Vec::new(),
            targets: Vec::new(),
        });
        HapticCore {
            physics,
            coupling: VirtualCoupling::new(coupling, Vec3::zeros()),
            safety: Safety::new(safety),
            dt: 1.0 / rate_hz,
            checkpoint_every: checkpoint_every.max(1),
            tick: 0,
            input: None,
            tissue: Vec3::zeros(),
            faults: 0,
            fault_log: Vec::with_capacity(FAULT_LOG),
            bad_inputs: 0,
            recording,
            recording_dropped: 0,
            max_force: 0.0,
            energy: 0.0,
            last_sent: None,
            since_sample: 0,
            silent: false,
            silences: 0,
            model: LocalModel::default(),
            model_age: 0,
            stale: false,
            stalls: 0,
            tool_speed: f64::INFINITY,
            physics_dt: 0.0,
            weight: Recovering::default(),
            silence_w: Recovering::default(),
        }
    }

    /// With a [`ServoConfig`] and the device's defaults for what it leaves `None`.
    pub fn with_config(physics: Box<dyn Physics>, config: &ServoConfig, device: &dyn Device) -> Result<HapticCore, String> {
        config.check()?;
        let (c, s) = device.kind().defaults();
        let (coupling, safety) = (config.coupling.unwrap_or(c), config.safety.unwrap_or(s));
        if !config.unsafe_limits {
            crate::safety::check_limits(device.kind(), &coupling, &safety).map_err(|e| format!("{e} (unsafe_limits to allow it)"))?;
        }
        Ok(HapticCore::new(physics, config.rate_hz, coupling, safety, config.checkpoint_every, config.record_ticks))
    }

    /// One whole tick with the device's sample (`None`: no new sample): [`HapticCore::tick_force`]
    /// then [`HapticCore::after_send`], for callers that send the force afterwards.
    pub fn step(&mut self, sample: Option<DeviceInput>) -> TickOut {
        let mut out = self.tick_force(sample);
        self.after_send(&mut out);
        out
    }

    /// The part of a tick the force depends on (steps 1-5 of the module docs), recorded: send
    /// its force, then call [`HapticCore::after_send`].
    pub fn tick_force(&mut self, sample: Option<DeviceInput>) -> TickOut {
        self.take_sample(sample);
        self.tick += 1;
        let Some(input) = self.input else {
            // No sample yet: nothing to simulate against.
            let z = Vec3::zeros();
            return TickOut { force: self.safety.zero(), raw_force: z, tissue: z, tool: z, device: z, buttons: 0, fault: false };
        };
        let mut out = TickOut {
            force: Vec3::zeros(),
            raw_force: Vec3::zeros(),
            tissue: Vec3::zeros(),
            tool: self.coupling.proxy,
            device: input.position,
            buttons: input.buttons,
            fault: false,
        };
        let fault = match self.physics.tick(&self.coupling.proxy, self.dt) {
            Err(e) => Some(Fault::Step(e)),
            Ok(f) if !f.iter().all(|c| c.is_finite()) => Some(Fault::NonFinite),
            Ok(f) => {
                self.tissue = f;
                let c = self.coupling.step(&input.position, &f, self.dt, self.physics.max_tool_speed());
                if c.force.iter().all(|x| x.is_finite()) && self.coupling.proxy.iter().all(|x| x.is_finite()) {
                    out.raw_force = c.force;
                    let w = self.silence_weight();
                    out.force = self.safe(&c.force, w);
                    None
                } else {
                    Some(Fault::NonFinite)
                }
            }
        };
        if let Some(f) = fault {
            self.fault(f, &mut out);
        }
        out.tissue = self.tissue;
        out.tool = self.coupling.proxy;
        self.account(&out);
        self.record(input, sample.is_some(), &out);
        out
    }

    /// A device sample in: a new finite one is taken (the first puts the proxy at the device, at
    /// rest), a non-finite one counted; either way the silence's count.
    fn take_sample(&mut self, sample: Option<DeviceInput>) {
        match sample {
            Some(s) if s.is_finite() => {
                if self.input.is_none() {
                    // First sample: the proxy starts at the device, at rest.
                    self.coupling.reset(s.position);
                }
                self.input = Some(s);
                self.since_sample = 0;
            }
            Some(_) => {
                self.bad_inputs += 1;
                self.since_sample += 1;
            }
            None => self.since_sample += 1,
        }
    }

    /// The device's silence as a weight on the force (1: a fresh sample; 0: silent for the
    /// safety's `silence` plus [`crate::multirate::SILENCE_FADE`]); the fade's start is logged.
    fn silence_weight(&mut self) -> f64 {
        let t = self.since_sample as f64 * self.dt;
        let start = self.safety.params.silence;
        let w_now = crate::multirate::fade(t, start, start + crate::multirate::SILENCE_FADE);
        if w_now < 1.0 && !self.silent {
            self.silent = true;
            self.silences += 1;
            self.log(Fault::DeviceSilent(t), false);
        } else if w_now == 1.0 {
            self.silent = false;
        }
        self.silence_w.follow(w_now, self.dt, crate::multirate::SILENCE_FADE)
    }

    /// The safety layer on `force` faded by `weight`: at zero weight the force is zero and the
    /// ramp starts again (so a device or a physics that comes back is ramped in).
    fn safe(&mut self, force: &Vec3, weight: f64) -> Vec3 {
        if weight > 0.0 {
            // Capped first, so that the fade is the felt force's, not a request's far past the
            // limit (24 N asked, 3 N felt, stayed 3 N until the weight fell under 1/8).
            let capped = force.cap_magnitude(self.safety.params.max_force);
            self.safety.apply(&(capped * weight), self.dt)
        } else {
            self.safety.zero()
        }
    }

    /// Logs `fault` at the last tick; `counted`: a fault path (see [`FaultRecord::counted`]),
    /// which the caller counts.
    pub(crate) fn log(&mut self, fault: Fault, counted: bool) {
        if self.fault_log.len() < FAULT_LOG {
            self.fault_log
                .push(FaultRecord { tick: self.tick.saturating_sub(1), time: self.tick.saturating_sub(1) as f64 * self.dt, fault, counted });
        }
    }

    /// One servo tick of the multirate loop ([`crate::multirate`]): the device's sample in,
    /// `fresh` the physics' newest model if one arrived since the last tick, the force out. The
    /// proxy moves against the local model through the coupling; a model older than a third of
    /// the stall timeout fades to zero at the stall timeout; a model whose fault count changed
    /// takes the fault path (zero now, the proxy at the restored tool, the ramp again). Allocates
    /// nothing; depends on its inputs and the tick count only.
    pub fn render(&mut self, sample: Option<DeviceInput>, fresh: Option<LocalModel>) -> TickOut {
        self.take_sample(sample);
        self.tick += 1;
        let mut fault = false;
        if let Some(m) = fresh {
            if m.faults != self.model.faults {
                fault = true;
            }
            if self.stale && m.tick != self.model.tick {
                self.stale = false;
            }
            self.model = m;
            self.model_age = 0;
        } else {
            self.model_age += 1;
        }
        let z = Vec3::zeros();
        let Some(input) = self.input else {
            return TickOut { force: self.safety.zero(), raw_force: z, tissue: z, tool: z, device: z, buttons: 0, fault: false };
        };
        let mut out = TickOut { force: z, raw_force: z, tissue: z, tool: self.coupling.proxy, device: input.position, buttons: input.buttons, fault };
        if self.model.tick == 0 {
            // No model yet: the proxy waits at the device for the physics' first tick.
            self.coupling.reset(input.position);
            out.force = self.safety.zero();
        } else if fault {
            out.force = self.safety.zero();
            self.coupling.reset(self.model.tool);
            self.faults += 1;
            if let Some(r) = &mut self.recording {
                r.faults += 1;
            }
        } else {
            let age = self.model_age as f64 * self.dt;
            let stall = self.safety.params.stall_timeout;
            // Full force for half the stall timeout, or two physics periods at a slow physics
            // rate (a model is that old between ticks in the normal course). A third (10 ms)
            // faded the force 7 times a minute beside a 250 Hz physics whose ticks took up to
            // 12 ms on a busy machine (2026-12-06).
            let hold = (0.5 * stall).max(2.0 * self.physics_dt).min(0.9 * stall);
            let w_now = crate::multirate::fade(age, hold, stall);
            let w_model = self.weight.follow(w_now, self.dt, stall - hold);
            if w_now < 1.0 && !self.stale {
                self.stale = true;
                self.stalls += 1;
                self.log(Fault::Stall(age), false);
            }
            let c = self.coupling.step_local(&input.position, &self.model, w_model, self.dt, self.tool_speed);
            if c.force.iter().all(|x| x.is_finite()) && self.coupling.proxy.iter().all(|x| x.is_finite()) {
                let w = w_model.min(self.silence_weight());
                out.raw_force = c.force;
                out.force = self.safe(&c.force, w);
                self.tissue = self.model.force_at(&self.coupling.proxy) * w_model;
            } else {
                // A non-finite model: zero, the proxy back at the model's tool.
                out.force = self.safety.zero();
                self.coupling.reset(self.model.tool);
                self.tissue = z;
                out.fault = true;
                self.faults += 1;
                self.log(Fault::NonFinite, true);
            }
        }
        out.tissue = self.tissue;
        out.tool = self.coupling.proxy;
        self.account(&out);
        self.record(input, sample.is_some(), &out);
        if let Some(r) = &mut self.recording {
            if r.model_ticks.len() < r.model_ticks.capacity() {
                r.model_ticks.push(self.model.tick);
            }
        }
        out
    }

    /// Runs the multirate loop without a clock until the device is finished or `max_ticks`
    /// servo ticks: the physics ticks `physics_rate_hz` times a second of servo ticks (every
    /// `rate / physics_rate` servo ticks when that is whole), with the proxy as that servo tick
    /// left it, and its model is rendered from the next servo tick on. The physics' faults join
    /// the core's log. Tests and replays; the real-time loop is [`Servo::start`] with
    /// [`ServoConfig::physics_rate_hz`].
    pub fn run_offline_multirate(&mut self, device: &mut dyn Device, max_ticks: u64, physics_rate_hz: f64) -> u64 {
        let mut physics = self.begin_multirate(physics_rate_hz);
        let sink = device.sink();
        let ratio = physics_rate_hz * self.dt;
        let (mut n, mut pending) = (0, None);
        while n < max_ticks && !device.finished(self.tick, self.dt) {
            let s = device.read(self.tick, self.dt);
            let out = self.render(s, pending.take());
            if out.fault {
                sink.zeroed();
            } else {
                sink.send(&out.force);
            }
            n += 1;
            // Physics ticks due by the end of this servo tick.
            if self.input.is_some() && ((self.tick as f64 * ratio + 1e-9).floor() as u64) > physics.ticks() {
                let mut m = physics.tick(&self.coupling.proxy);
                if let Some(f) = physics.finish() {
                    m = f;
                }
                pending = Some(m);
            }
        }
        self.end_multirate(physics);
        n
    }

    /// Replays a multirate recording ([`crate::Recording::physics_rate_hz`]) bit for bit,
    /// whatever the timing of the run that made it: the physics ticks with the recorded targets,
    /// and each servo tick renders the recorded device sample from the model of the physics tick
    /// it rendered from then (a model replaced by a fault in its tick's finish is replayed as the
    /// replacement). Returns the servo ticks replayed; compare this core's recording with `rec`
    /// ([`crate::record::compare`]).
    pub fn replay_multirate(&mut self, rec: &Recording) -> Result<u64, String> {
        let rate = rec.physics_rate_hz.ok_or("not a multirate recording (no physics rate)")?;
        if rec.model_ticks.len() != rec.ticks.len() {
            return Err(format!("the recording has {} model ticks for {} servo ticks", rec.model_ticks.len(), rec.ticks.len()));
        }
        let mut pl = self.begin_multirate(rate);
        let (mut seen, mut model, mut n) = (0u64, LocalModel::default(), 0u64);
        for (t, &want) in rec.ticks.iter().zip(&rec.model_ticks) {
            while pl.ticks() < want {
                let Some(target) = rec.targets.get(pl.ticks() as usize) else {
                    let at = pl.ticks();
                    self.end_multirate(pl);
                    return Err(format!("the recording's physics targets end at physics tick {at}, its servo ticks need {want}"));
                };
                model = pl.tick(target);
                if let Some(f) = pl.finish() {
                    model = f;
                }
            }
            let fresh = (want != seen).then_some(model);
            seen = want;
            self.render(t.has_input.then_some(t.input), fresh);
            n += 1;
        }
        self.end_multirate(pl);
        Ok(n)
    }

    /// The physics taken out of the core into a [`PhysicsLoop`] at `physics_rate_hz` (the
    /// recording set up for multirate).
    pub(crate) fn begin_multirate(&mut self, physics_rate_hz: f64) -> PhysicsLoop {
        let physics = std::mem::replace(&mut self.physics, Box::new(crate::physics::Idle::default()));
        let cap = self.recording.as_ref().map_or(0, |r| r.ticks.capacity());
        // The physics ticks on its own clock: when the servo runs slower than its rate (a busy
        // machine: 1.7 of 2 kHz in CI), more physics ticks fall within the recorded servo ticks
        // than the nominal ratio gives. Room for twice that (24 bytes a target), so that a
        // servo running at half its rate still replays.
        let nominal = (cap as f64 * physics_rate_hz * self.dt).ceil() as usize;
        let p = PhysicsLoop::new(physics, physics_rate_hz, self.checkpoint_every, 2 * nominal + 64);
        self.tool_speed = p.tool_speed();
        self.physics_dt = p.dt();
        if let Some(r) = &mut self.recording {
            r.physics_rate_hz = Some(physics_rate_hz);
            r.model_ticks = Vec::with_capacity(cap);
        }
        p
    }

    /// The physics back in the core after a multirate run: its faults logged (at their physics
    /// ticks' times) and its targets in the recording.
    pub(crate) fn end_multirate(&mut self, mut p: PhysicsLoop) {
        for f in p.fault_log() {
            if self.fault_log.len() < FAULT_LOG {
                self.fault_log.push(f.clone());
            }
        }
        if let Some(r) = &mut self.recording {
            r.targets = std::mem::take(&mut p.targets);
        }
        self.physics = p.physics;
        self.tool_speed = f64::INFINITY;
    }

    fn record(&mut self, input: DeviceInput, has_input: bool, out: &TickOut) {
        if let Some(r) = &mut self.recording {
            // Within the buffer sized at start only (a push past it would allocate in the servo
            // thread); what does not fit is counted, so that a truncated recording is reported
            // rather than passed off as the whole run.
            if r.ticks.len() < r.ticks.capacity() {
                r.ticks.push(TickRecord { input, has_input, stalled: false, force: out.force, tool: out.tool, tissue: out.tissue });
            } else {
                self.recording_dropped += 1;
            }
        }
    }

    /// The rest of the tick, after its force was sent (step 6 of the module docs): the physics'
    /// [`Physics::finish`], then the checkpoint when due, on a tick without a fault. Returns
    /// `true` when the finish failed or the state was found non-finite, and the fault path was
    /// taken: `out` then says so (zero force), and the caller zeroes the device at once.
    /// Everything here depends on the tick count and the state only, so the real-time thread and
    /// [`HapticCore::run_offline`] stay the same.
    pub fn after_send(&mut self, out: &mut TickOut) -> bool {
        // The tick's own rest (the hybrid model's skin update, and its core's step when the
        // tool had nothing of the core within reach), before a checkpoint copies the state. A
        // failure there is a fault, as a failed tick's: zero now, the last good state back.
        if let Err(e) = self.physics.finish() {
            if !out.fault {
                self.fault(Fault::Step(e), out);
                self.retract(out);
                return true;
            }
        }
        if out.fault || self.input.is_none() || !self.tick.is_multiple_of(self.checkpoint_every) {
            return false;
        }
        // A state gone non-finite where the tick does not look (it returned a finite force) is
        // met here: a fault, not a skipped checkpoint (the last good state would grow stale
        // while the bad one ran on).
        if self.physics.is_finite() {
            self.physics.checkpoint();
            return false;
        }
        self.fault(Fault::NonFinite, out);
        self.retract(out);
        true
    }

    /// The tick's force was replaced by the fault path's zero after it was accounted and
    /// recorded: what the device got last is the zero (as [`HapticCore::stalled`]).
    fn retract(&mut self, out: &mut TickOut) {
        self.last_sent = Some((out.force, out.device));
        out.tool = self.coupling.proxy;
        out.tissue = Vec3::zeros();
        // This tick's record, if it has one: once the buffer is full the last record is an
        // older tick's, which must keep what was sent then.
        if self.recording_dropped == 0 {
            if let Some(last) = self.recording.as_mut().and_then(|r| r.ticks.last_mut()) {
                (last.force, last.tool, last.tissue) = (out.force, out.tool, out.tissue);
            }
        }
    }

    /// The fault path: zero now, back to the last good state, the proxy at its tool, the ramp
    /// again, logged.
    fn fault(&mut self, fault: Fault, out: &mut TickOut) {
        out.force = self.safety.zero();
        out.fault = true;
        self.physics.restore();
        let at = self.physics.tool().or(self.input.map(|i| i.position)).unwrap_or_else(Vec3::zeros);
        self.coupling.reset(at);
        self.tissue = Vec3::zeros();
        self.faults += 1;
        if let Some(r) = &mut self.recording {
            r.faults += 1;
        }
        if self.fault_log.len() < FAULT_LOG {
            self.fault_log.push(FaultRecord { tick: self.tick - 1, time: (self.tick - 1) as f64 * self.dt, fault, counted: true });
        }
    }

    fn account(&mut self, out: &TickOut) {
        if let Some((f, x)) = self.last_sent {
            self.energy += f.dot(&(out.device - x));
        }
        self.last_sent = Some((out.force, out.device));
        self.max_force = self.max_force.max(out.force.norm());
    }

    /// The watchdog tripped during the last tick: take the fault path for it, and mark its
    /// record (a replay cannot reproduce a stall: `devices::replay::divergence_reason`).
    fn stalled(&mut self, seconds: f64, out: &mut TickOut) {
        self.fault(Fault::Stall(seconds), out);
        self.retract(out);
        if self.recording_dropped == 0 {
            if let Some(last) = self.recording.as_mut().and_then(|r| r.ticks.last_mut()) {
                last.stalled = true;
            }
        }
    }

    /// Makes now what the physics' first tick at the servo's rate would make (its factorisation,
    /// [`Physics::prepare`]): [`Servo::start`] and [`HapticCore::run_offline`] call it before the
    /// first tick. Changes no result; `true` if it did work.
    pub fn prepare(&mut self) -> bool {
        self.physics.prepare(self.dt).unwrap_or(false)
    }

    /// Runs ticks without a clock (as fast as the physics goes) until the device is finished or
    /// `max_ticks`, sending each force to the device's sink: tests and replays.
    pub fn run_offline(&mut self, device: &mut dyn Device, max_ticks: u64) -> u64 {
        self.prepare();
        let sink = device.sink();
        let mut n = 0;
        while n < max_ticks && !device.finished(self.tick, self.dt) {
            let s = device.read(self.tick, self.dt);
            let mut out = self.tick_force(s);
            if out.fault {
                sink.zeroed();
            } else {
                sink.send(&out.force);
            }
            if self.after_send(&mut out) {
                sink.zeroed();
            }
            n += 1;
        }
        n
    }

    pub fn ticks(&self) -> u64 {
        self.tick
    }
    /// The largest force sent so far \[N\].
    pub fn max_force(&self) -> f64 {
        self.max_force
    }
    /// The energy the device has put into the user so far \[J\] (see the field).
    pub fn energy_into_user(&self) -> f64 {
        self.energy
    }
    pub fn dt(&self) -> f64 {
        self.dt
    }
    pub fn faults(&self) -> u64 {
        self.faults
    }
    pub fn fault_log(&self) -> &[FaultRecord] {
        &self.fault_log
    }
    /// Device samples that were not finite (held the last good one).
    pub fn bad_inputs(&self) -> u64 {
        self.bad_inputs
    }
    /// Device silences whose fade began (the force faded to zero unless the device came back
    /// within the fade), and multirate local models whose staleness fade began.
    pub fn silences(&self) -> u64 {
        self.silences
    }
    pub fn stalls(&self) -> u64 {
        self.stalls
    }
    pub fn coupling(&self) -> &VirtualCoupling {
        &self.coupling
    }
    pub fn safety(&self) -> &Safety {
        &self.safety
    }
    pub fn physics(&self) -> &dyn Physics {
        self.physics.as_ref()
    }
    pub fn physics_mut(&mut self) -> &mut dyn Physics {
        self.physics.as_mut()
    }
    /// The recording so far (`None` if not recording).
    pub fn recording(&self) -> Option<&Recording> {
        self.recording.as_ref()
    }
    pub fn take_recording(&mut self) -> Option<Recording> {
        self.recording.take()
    }
    /// Ticks that were not recorded because the recording's buffer (`record_ticks`) was full:
    /// nonzero means the recording holds only the run's beginning.
    pub fn recording_dropped(&self) -> u64 {
        self.recording_dropped
    }
}

/// Shared between the servo, the watchdog and the handle.
struct Shared {
    stop: AtomicBool,
    done: AtomicBool,
    /// Nanoseconds since `epoch` at the end of the servo's last tick.
    heartbeat: AtomicU64,
    /// Set by the watchdog when it zeroed the force; taken by the servo.
    tripped: AtomicBool,
    /// When the watchdog tripped (ns since `epoch`), and the stall it saw (ns).
    tripped_at: AtomicU64,
    stall_ns: AtomicU64,
    trips: AtomicU64,
    snapshot: SnapshotCell,
    surface: Mailbox,
    interior: Mailbox,
    epoch: Instant,
    /// Multirate: the physics' latest local model, the servo's proxy for the physics' next tick
    /// and the servo tick that set it (0: none yet), the physics' ticks so far.
    model: ModelCell,
    target: Vec3Cell,
    target_tick: AtomicU64,
    physics_ticks: AtomicU64,
}

impl Shared {
    fn now_ns(&self) -> u64 {
        self.epoch.elapsed().as_nanos() as u64
    }
}

/// The real-time servo (see the module).
pub struct Servo;

/// What a finished servo run gives back.
pub struct ServoReport {
    pub core: HapticCore,
    pub device: Box<dyn Device>,
    pub stats: Stats,
    /// Watchdog trips (each also a [`Fault::Stall`] in the core's log).
    pub watchdog_trips: u64,
    /// The servo thread's scheduling: [`Realtime::Off`] unless [`ServoConfig::realtime`].
    pub realtime: Realtime,
    /// An ordinary servo thread was granted Linux's short slice
    /// ([`crate::realtime::request_short_slice`]).
    pub short_slice: bool,
    /// The multirate loop's physics thread (`None`: single-rate).
    pub physics: Option<PhysicsStats>,
}

/// The running servo: snapshots, stop.
pub struct ServoHandle {
    shared: Arc<Shared>,
    servo: Option<JoinHandle<ServoReport>>,
    watchdog: Option<JoinHandle<()>>,
    physics: Option<JoinHandle<(PhysicsLoop, PhysicsStats)>>,
}

impl Servo {
    /// Starts the servo thread (and its watchdog) on `core` with `device`.
    pub fn start(mut core: HapticCore, device: Box<dyn Device>, config: &ServoConfig) -> Result<ServoHandle, String> {
        config.check()?;
        // The first tick's factorisation before the clock starts (the multirate loop's in
        // PhysicsLoop::new, at its own rate).
        if config.physics_rate_hz.is_none() {
            core.prepare();
        }
        let physics_loop = config.physics_rate_hz.map(|hz| core.begin_multirate(hz));
        let surface_len = physics_loop.as_ref().map_or_else(|| core.physics.surface_len(), |p| p.physics().surface_len());
        let interior_cap = physics_loop.as_ref().map_or_else(|| core.physics.interior_capacity(), |p| p.physics().interior_capacity());
        let stall = core.safety.params.stall_timeout;
        let shared = Arc::new(Shared {
            stop: AtomicBool::new(false),
            done: AtomicBool::new(false),
            heartbeat: AtomicU64::new(0),
            tripped: AtomicBool::new(false),
            tripped_at: AtomicU64::new(0),
            stall_ns: AtomicU64::new(0),
            trips: AtomicU64::new(0),
            snapshot: SnapshotCell::default(),
            surface: Mailbox::new(if config.surface_every > 0 { surface_len } else { 0 }),
            interior: Mailbox::up_to(if config.surface_every > 0 { interior_cap } else { 0 }),
            epoch: Instant::now(),
            model: ModelCell::default(),
            target: Vec3Cell::default(),
            target_tick: AtomicU64::new(0),
            physics_ticks: AtomicU64::new(0),
        });
        let sink = device.sink();
        let cfg = *config;
        let s = shared.clone();
        let multirate = physics_loop.is_some();
        let servo = std::thread::Builder::new()
            .name("palpate-servo".into())
            .spawn(move || if multirate { run_render(core, device, cfg, s) } else { run(core, device, cfg, s) })
            .map_err(|e| format!("cannot start the servo thread: {e}"))?;
        let physics = match physics_loop {
            Some(pl) => {
                let s = shared.clone();
                Some(
                    std::thread::Builder::new()
                        .name("palpate-physics".into())
                        .spawn(move || run_physics(pl, cfg, s))
                        .map_err(|e| format!("cannot start the physics thread: {e}"))?,
                )
            }
            None => None,
        };
        let s = shared.clone();
        let watchdog = std::thread::Builder::new()
            .name("palpate-watchdog".into())
            .spawn(move || {
                if cfg.realtime {
                    // Above the servo, so that a stuck servo cannot starve its own watchdog.
                    let _ = crate::realtime::make_current_thread_realtime(crate::realtime::SERVO_PRIORITY + 1);
                }
                // Every 0.5 ms for a servo that computes the physics in its period; every 2 ms
                // beside a physics thread, which then keeps the other core busy: each wake of the
                // watchdog takes a core from one of the two (at 4 kHz, 310 late periods a minute
                // against 8 in the idle loop, 2026-12-06), and 2 ms is still well inside the
                // 30 ms it guards.
                watch(s, sink, stall, if multirate { Duration::from_millis(2) } else { Duration::from_micros(500) })
            })
            .map_err(|e| format!("cannot start the watchdog thread: {e}"))?;
        Ok(ServoHandle { shared, servo: Some(servo), watchdog: Some(watchdog), physics })
    }
}

impl ServoHandle {
    /// The latest snapshot (never blocks the servo).
    pub fn snapshot(&self) -> Option<Snapshot> {
        self.shared.snapshot.latest()
    }
    /// The organ's surface as of the latest surface snapshot (\[m\], world frame; see
    /// [`Physics::surface`]) and its tick (0: none yet). Never blocks the servo.
    pub fn surface(&self) -> (u64, Vec<Vec3>) {
        self.shared.surface.latest()
    }
    /// The organ's core nodes then its active particles (\[m\], world frame; see
    /// [`Physics::interior`]) as of the latest surface snapshot, and its tick (0: none yet).
    /// Never blocks the servo.
    pub fn interior(&self) -> (u64, Vec<Vec3>) {
        self.shared.interior.latest()
    }
    /// Has the servo stopped (device finished, `max_ticks` reached, or stopped)?
    pub fn is_finished(&self) -> bool {
        self.shared.done.load(Ordering::Acquire)
    }
    /// Watchdog trips so far.
    pub fn watchdog_trips(&self) -> u64 {
        self.shared.trips.load(Ordering::Relaxed)
    }
    /// Asks the servo to stop and waits for it (its last act sends zero force).
    pub fn stop(self) -> ServoReport {
        self.shared.stop.store(true, Ordering::Release);
        self.join()
    }
    /// Waits for the servo to finish by itself (device finished or `max_ticks`).
    pub fn join(mut self) -> ServoReport {
        self.join_inner()
    }
    fn join_inner(&mut self) -> ServoReport {
        let r = self.servo.take().expect("joined once").join();
        self.shared.done.store(true, Ordering::Release);
        if let Some(w) = self.watchdog.take() {
            let _ = w.join();
        }
        let physics = self.physics.take().map(|p| p.join());
        let mut r = match r {
            Ok(r) => r,
            Err(p) => std::panic::resume_unwind(p),
        };
        match physics {
            Some(Ok((pl, stats))) => {
                r.core.end_multirate(pl);
                r.physics = Some(stats);
            }
            Some(Err(p)) => std::panic::resume_unwind(p),
            None => {}
        }
        r
    }
}

impl Drop for ServoHandle {
    fn drop(&mut self) {
        if self.servo.is_some() {
            self.shared.stop.store(true, Ordering::Release);
            let _ = self.join_inner();
        }
    }
}

fn watch(shared: Arc<Shared>, sink: Arc<dyn ForceSink>, stall: f64, poll: Duration) {
    let limit = (stall * 1e9) as u64;
    while !shared.done.load(Ordering::Acquire) {
        std::thread::sleep(poll);
        let beat = shared.heartbeat.load(Ordering::Acquire);
        if beat == 0 || shared.tripped.load(Ordering::Acquire) {
            continue; // not started, or already tripped and not yet taken by the servo
        }
        let now = shared.now_ns();
        if now.saturating_sub(beat) > limit {
            sink.zeroed();
            shared.stall_ns.store(now - beat, Ordering::Relaxed);
            shared.tripped_at.store(now, Ordering::Relaxed);
            shared.trips.fetch_add(1, Ordering::Relaxed);
            shared.tripped.store(true, Ordering::Release);
        }
    }
}

/// A servo thread's clock: absolute deadlines one period apart, each tick's period and compute
/// measured (wall and CPU time, so that an overrun is told apart: the physics' own or the
/// machine's), a tick more than a whole period late restarts the schedule from now (no burst of
/// catch-up ticks), and a real-time thread's least rest (below).
struct Pacer {
    period: Duration,
    spin: Duration,
    /// The least a real-time servo rests each tick: 6% of the period. A real-time servo that
    /// computes through its whole period (the physics slower than real time) would use the whole
    /// core, and the kernel's RT throttle would then take it off the CPU for ~50 ms (a watchdog
    /// trip, a zeroed force): it rests a little every tick instead, so that it stays under the
    /// throttle's 95% (crate::realtime).
    min_rest: Duration,
    realtime: Realtime,
    /// Whether the kernel granted the short slice.
    short_slice: bool,
    times: TickTimes,
    start: Instant,
    deadline: Instant,
    last_start: Option<Instant>,
    /// The current tick's start (wall, thread CPU).
    t0: Instant,
    c0: Option<f64>,
}

impl Pacer {
    /// On the calling thread (made real-time if the configuration asks).
    fn new(cfg: &ServoConfig) -> Pacer {
        let period = Duration::from_secs_f64(cfg.dt());
        let realtime = if cfg.realtime {
            crate::realtime::make_current_thread_realtime(crate::realtime::SERVO_PRIORITY)
        } else {
            Realtime::Off
        };
        // An ordinary servo thread asks for Linux's shortest slice and a 1 us timer slack (no
        // privilege needed; crate::realtime says why). Measured 2026-12-07 on Rodero with a
        // CPU-bound program beside the multirate loop (30 s): at 4 kHz 320 late periods without
        // the slice, 40-47 with it; the slack takes the sleep's wake-up from 50 us late to ~1 us.
        let short_slice = !realtime.granted() && crate::realtime::request_short_slice(crate::realtime::SERVO_SLICE_NS);
        crate::realtime::set_timer_slack(crate::realtime::SERVO_TIMER_SLACK_NS);
        let start = Instant::now();
        Pacer {
            period,
            spin: Duration::from_secs_f64(cfg.spin),
            min_rest: period.mul_f64(0.06),
            realtime,
            short_slice,
            times: TickTimes::new(cfg.stats_ticks, cfg.rate_hz),
            start,
            deadline: start,
            last_start: None,
            t0: start,
            c0: None,
        }
    }

    /// A tick starts.
    fn begin(&mut self) {
        self.t0 = Instant::now();
        self.c0 = crate::realtime::thread_cpu_time();
    }

    /// The tick's compute ends (with its send): its period and compute \[s\] are counted for
    /// the servo tick `tick`; returns them and the end.
    fn end(&mut self, tick: u64) -> (f64, f64, Instant) {
        let t1 = Instant::now();
        let c1 = crate::realtime::thread_cpu_time();
        let p = self.last_start.map_or(self.period.as_secs_f64(), |s| (self.t0 - s).as_secs_f64());
        self.last_start = Some(self.t0);
        let compute = (t1 - self.t0).as_secs_f64();
        let cpu = match (self.c0, c1) {
            (Some(a), Some(b)) => (b - a).clamp(0.0, compute),
            _ => compute,
        };
        self.deadline += self.period;
        let late = t1.saturating_duration_since(self.deadline);
        self.times.push(p, compute, cpu, t1 > self.deadline, (t1 - self.start).as_secs_f64(), tick);
        if late > self.period {
            self.deadline = t1;
        }
        (p, compute, t1)
    }

    fn overruns(&self) -> u64 {
        self.times.overruns()
    }

    /// Waits for the next tick's deadline (a tick that ended at `t1`).
    fn wait(&self, t1: Instant) {
        wait_until(self.deadline, self.spin);
        if self.realtime.granted() {
            let rested = Instant::now().saturating_duration_since(t1);
            if rested < self.min_rest {
                std::thread::sleep(self.min_rest - rested);
            }
        }
    }

    /// The run's statistics, `done` set first: sorting a long run's times (240,000 ticks at
    /// 4 kHz for a minute) takes tens of milliseconds, which the watchdog took for a stalled
    /// servo.
    fn finish(self, shared: &Shared) -> (Stats, Realtime, bool) {
        let elapsed = (Instant::now() - self.start).as_secs_f64();
        shared.done.store(true, Ordering::Release);
        (self.times.finish(elapsed), self.realtime, self.short_slice)
    }
}

/// The viewer's surface and interior snapshots, published every `every` ticks (0: never) while
/// someone reads them (a read in the last `idle` ticks), every `idle` ticks otherwise.
struct SurfacePublisher {
    every: u64,
    idle: u64,
    read_tick: u64,
    reads: u64,
    published: Option<u64>,
}

impl SurfacePublisher {
    fn new(every: u64, idle: u64) -> SurfacePublisher {
        SurfacePublisher { every, idle: idle.max(1), read_tick: 0, reads: 0, published: None }
    }

    fn tick(&mut self, tick: u64, physics: &dyn Physics, shared: &Shared) {
        if self.every == 0 || !tick.is_multiple_of(self.every) {
            return;
        }
        let r = shared.surface.reads() + shared.interior.reads();
        if r != self.reads {
            (self.reads, self.read_tick) = (r, tick);
        }
        let watched = tick.saturating_sub(self.read_tick) <= self.idle;
        if watched || self.published.is_none_or(|t| tick - t >= self.idle) {
            self.publish(tick, physics, shared);
        }
    }

    /// Publishes the surface and the interior now, as of `tick`.
    fn publish(&mut self, tick: u64, physics: &dyn Physics, shared: &Shared) {
        self.published = Some(tick);
        shared.surface.publish_with(tick, |out| {
            physics.surface(out);
            out.len()
        });
        shared.interior.publish_with(tick, |out| physics.interior(out));
    }
}

/// The viewer's snapshot of a servo tick.
fn snapshot(core: &HapticCore, out: &TickOut, period: f64, compute: f64, overruns: u64, physics_ticks: u64) -> Snapshot {
    Snapshot {
        tick: core.tick,
        time: core.tick as f64 * core.dt,
        device: out.device,
        tool: out.tool,
        force: out.force,
        raw_force: out.raw_force,
        tissue_force: out.tissue,
        period,
        compute,
        overruns,
        faults: core.faults,
        buttons: out.buttons,
        physics_ticks,
    }
}

/// The single-rate servo thread: every period, the device's sample in, a physics tick, the
/// force out; the tick's rest and the checkpoint after the send.
fn run(mut core: HapticCore, mut device: Box<dyn Device>, cfg: ServoConfig, shared: Arc<Shared>) -> ServoReport {
    let sink = device.sink();
    let mut surfaces = SurfacePublisher::new(cfg.surface_every, IDLE_SNAPSHOT_TICKS);
    let mut pacer = Pacer::new(&cfg);
    shared.heartbeat.store(shared.now_ns().max(1), Ordering::Release);
    let mut n: u64 = 0;
    loop {
        if shared.stop.load(Ordering::Acquire) || cfg.max_ticks.is_some_and(|m| n >= m) || device.finished(core.tick, core.dt) {
            break;
        }
        pacer.begin();
        let sample = device.read(core.tick, core.dt);
        let mut out = core.tick_force(sample);
        // The physics is back: beat before taking the watchdog's flag, or the watchdog would
        // see the stale beat again while the fault path restores the state, and trip twice.
        shared.heartbeat.store(shared.now_ns().max(1), Ordering::Release);
        if shared.tripped.swap(false, Ordering::AcqRel) {
            // The watchdog zeroed the force while this tick was stuck: the stale force is not sent.
            let stalled = shared.stall_ns.load(Ordering::Relaxed) as f64 * 1e-9;
            core.stalled(stalled, &mut out);
        }
        if out.fault {
            sink.zeroed();
        } else {
            sink.send(&out.force);
        }
        let (period, compute, t1) = pacer.end(core.tick);
        // The tick's rest and the checkpoint, in the tick's slack (the module docs say why): not
        // part of the tick's compute, which ends with the send; a late one shows as the next
        // tick's lateness.
        if core.after_send(&mut out) {
            sink.zeroed();
        }
        shared.heartbeat.store(shared.now_ns().max(1), Ordering::Release);
        n += 1;
        shared.snapshot.publish(&snapshot(&core, &out, period, compute, pacer.overruns(), core.tick));
        surfaces.tick(core.tick, core.physics.as_ref(), &shared);
        pacer.wait(t1);
    }
    sink.send(&Vec3::zeros());
    let (stats, realtime, short_slice) = pacer.finish(&shared);
    let trips = shared.trips.load(Ordering::Relaxed);
    ServoReport { core, device, stats, watchdog_trips: trips, realtime, short_slice, physics: None }
}

/// The multirate loop's servo thread: every period, the device's sample and the physics' newest
/// model in, the rendered force out ([`HapticCore::render`]), the proxy published for the
/// physics. It never waits for the physics (a seqlock read of the model, a seqlock write of the
/// proxy).
fn run_render(mut core: HapticCore, mut device: Box<dyn Device>, cfg: ServoConfig, shared: Arc<Shared>) -> ServoReport {
    let sink = device.sink();
    let mut pacer = Pacer::new(&cfg);
    let mut seen = (0u64, 0u64);
    shared.heartbeat.store(shared.now_ns().max(1), Ordering::Release);
    let mut n: u64 = 0;
    loop {
        if shared.stop.load(Ordering::Acquire) || cfg.max_ticks.is_some_and(|m| n >= m) || device.finished(core.tick, core.dt) {
            break;
        }
        pacer.begin();
        let sample = device.read(core.tick, core.dt);
        let m = shared.model.latest();
        // A new tick's model, or the same tick's replaced by a fault in its finish.
        let fresh = ((m.tick, m.faults) != seen).then_some(m);
        seen = (m.tick, m.faults);
        let mut out = core.render(sample, fresh);
        shared.heartbeat.store(shared.now_ns().max(1), Ordering::Release);
        if shared.tripped.swap(false, Ordering::AcqRel) {
            // The servo thread itself was kept off the CPU past the stall timeout (the watchdog
            // zeroed the device): zero this tick too, and ramp in again.
            let stalled = shared.stall_ns.load(Ordering::Relaxed) as f64 * 1e-9;
            out.force = core.safety.zero();
            out.fault = true;
            core.log(Fault::Stall(stalled), false);
        }
        if out.fault {
            sink.zeroed();
        } else {
            sink.send(&out.force);
        }
        if core.input.is_some() {
            shared.target.set(&core.coupling.proxy);
            shared.target_tick.store(core.tick, Ordering::Release);
        }
        let (period, compute, t1) = pacer.end(core.tick);
        n += 1;
        shared
            .snapshot
            .publish(&snapshot(&core, &out, period, compute, pacer.overruns(), shared.physics_ticks.load(Ordering::Relaxed)));
        pacer.wait(t1);
    }
    sink.send(&Vec3::zeros());
    let (stats, realtime, short_slice) = pacer.finish(&shared);
    let trips = shared.trips.load(Ordering::Relaxed);
    ServoReport { core, device, stats, watchdog_trips: trips, realtime, short_slice, physics: None }
}

/// The multirate loop's physics thread: on its own clock (absolute deadlines at the physics
/// rate; a tick that starts late runs at once, a whole period behind the schedule restarts from
/// now, counted as skipped), a tick with the servo's latest proxy, the model published, then the
/// tick's rest and the checkpoint, and the viewer's snapshots. It sleeps rather than spins (the
/// servo spins; two spinning threads would take both cores of a laptop).
fn run_physics(mut pl: PhysicsLoop, cfg: ServoConfig, shared: Arc<Shared>) -> (PhysicsLoop, PhysicsStats) {
    let rate = cfg.physics_rate_hz.unwrap_or(cfg.rate_hz);
    let period = Duration::from_secs_f64(1.0 / rate);
    // An ordinary thread, at the servo's nice value, even beside a real-time servo: a physics
    // slower than real time never sleeps, and under SCHED_FIFO it would hold its core against
    // everything else on it. Lowered (nice 5, measured 2026-12-06 on Rodero at 1 kHz with a
    // CPU-bound program beside it), it got a quarter of a core, 155 ticks a second, and the servo
    // gained nothing.
    let cap = cfg.stats_ticks.max(1);
    let (mut compute, mut lag) = (Vec::<f32>::with_capacity(cap), Vec::<f32>::with_capacity(cap));
    let (mut compute_max, mut lag_max, mut late, mut skipped) = (0.0f64, 0.0f64, 0u64, 0u64);
    // The viewer's snapshots every `surface_every` servo ticks' worth of time.
    let scaled = |ticks: u64| ((ticks as f64 * rate / cfg.rate_hz).round() as u64).max(1);
    let every = if cfg.surface_every > 0 { scaled(cfg.surface_every) } else { 0 };
    let mut surfaces = SurfacePublisher::new(every, scaled(IDLE_SNAPSHOT_TICKS));
    let mut started: Option<Instant> = None;
    let mut deadline = Instant::now();
    while !shared.done.load(Ordering::Acquire) {
        if shared.target_tick.load(Ordering::Acquire) == 0 {
            // No device sample yet: nothing to tick against. A viewer meanwhile draws the tissue
            // at rest (published once, as tick 1: tick 0 is "nothing yet"), as the single-rate
            // servo's snapshots show it before a bridge client connects.
            if surfaces.every > 0 && surfaces.published.is_none() {
                surfaces.publish(1, pl.physics(), &shared);
            }
            std::thread::sleep(period.min(Duration::from_millis(1)));
            deadline = Instant::now();
            continue;
        }
        let t0 = Instant::now();
        started.get_or_insert(t0);
        let behind = t0.saturating_duration_since(deadline).as_secs_f64();
        let target = shared.target.get();
        let m = pl.tick(&target);
        shared.model.publish(&m);
        if let Some(f) = pl.finish() {
            shared.model.publish(&f);
        }
        shared.physics_ticks.store(pl.ticks(), Ordering::Relaxed);
        let tick = pl.ticks();
        surfaces.tick(tick, pl.physics(), &shared);
        let t1 = Instant::now();
        let c = (t1 - t0).as_secs_f64();
        compute_max = compute_max.max(c);
        lag_max = lag_max.max(behind);
        if compute.len() < cap {
            compute.push(c as f32);
            lag.push(behind as f32);
        }
        if behind > 0.1 * period.as_secs_f64() {
            late += 1;
        }
        deadline += period;
        if t1 > deadline + period {
            // A whole period or more behind: restart the schedule from now (the rate lowered
            // for this while) rather than a burst of ticks with one proxy each.
            skipped += ((t1 - deadline).as_secs_f64() / period.as_secs_f64()) as u64;
            deadline = t1;
        }
        wait_until(deadline, Duration::ZERO);
    }
    let elapsed = started.map_or(0.0, |s| s.elapsed().as_secs_f64());
    let ticks = pl.ticks();
    let stats = PhysicsStats {
        rate_hz: rate,
        achieved_hz: if elapsed > 0.0 { ticks as f64 / elapsed } else { 0.0 },
        ticks,
        elapsed,
        compute_p50: crate::stats::percentile(&mut compute, 0.5),
        compute_p99: crate::stats::percentile(&mut compute, 0.99),
        compute_max,
        late,
        skipped,
        lag_p99: crate::stats::percentile(&mut lag, 0.99),
        lag_max,
    };
    (pl, stats)
}

/// Sleeps until `spin` before `deadline`, then spins to it.
fn wait_until(deadline: Instant, spin: Duration) {
    loop {
        let now = Instant::now();
        if now >= deadline {
            return;
        }
        let left = deadline - now;
        if left > spin {
            std::thread::sleep(left - spin);
        } else {
            break;
        }
    }
    while Instant::now() < deadline {
        std::hint::spin_loop();
    }
}
