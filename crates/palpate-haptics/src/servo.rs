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
use crate::physics::Physics;
use crate::realtime::Realtime;
use crate::record::{Recording, TickRecord};
use crate::safety::{Safety, SafetyParams};
use crate::snapshot::{Mailbox, Snapshot, SnapshotCell};
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
    /// The simulation did not complete a tick for this long \[s\] (the watchdog).
    Stall(f64),
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fault::Step(e) => write!(f, "the simulation's tick failed: {e}"),
            Fault::NonFinite => write!(f, "non-finite force, tool position or state"),
            Fault::Stall(s) => write!(f, "the simulation missed ticks for {:.1} ms", s * 1e3),
        }
    }
}

/// A fault, when it happened (tick and simulated time \[s\]).
#[derive(Debug, Clone, PartialEq)]
pub struct FaultRecord {
    pub tick: u64,
    pub time: f64,
    pub fault: Fault,
}

/// At most this many faults are logged (later ones are counted only).
pub const FAULT_LOG: usize = 256;

/// The servo's configuration (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoConfig {
    /// Tick rate \[Hz\], 250 to 4000 (default 1000).
    pub rate_hz: f64,
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
    /// Rodero palpation at 1 kHz (BENCHMARKS.md): the compute p99 4-20% lower in every pair of
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
}

/// Without a reader, the surface and interior snapshots are refreshed about once every this many
/// ticks (0.5 s at 1 kHz: a reader's first read is at most about that old); a read makes them
/// follow [`ServoConfig::surface_every`] again for as many ticks.
pub const IDLE_SNAPSHOT_TICKS: u64 = 512;

impl Default for ServoConfig {
    fn default() -> Self {
        ServoConfig { rate_hz: 1000.0, coupling: None, safety: None, checkpoint_every: 250, record_ticks: 0, stats_ticks: 600_000, max_ticks: None, spin: 200e-6, surface_every: 32, realtime: false }
    }
}

impl ServoConfig {
    pub fn check(&self) -> Result<(), String> {
        if !(self.rate_hz >= MIN_RATE_HZ && self.rate_hz <= MAX_RATE_HZ) {
            return Err(format!("rate = {} Hz must be within {MIN_RATE_HZ} to {MAX_RATE_HZ} Hz", self.rate_hz));
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
}

impl HapticCore {
    /// A loop over `physics` at `rate_hz` with these coupling and safety parameters, recording
    /// up to `record_ticks` ticks.
    pub fn new(physics: Box<dyn Physics>, rate_hz: f64, coupling: CouplingParams, safety: SafetyParams, checkpoint_every: u64, record_ticks: usize) -> HapticCore {
        let recording = (record_ticks > 0).then(|| Recording { rate_hz, identity: physics.identity(), coupling, safety, faults: 0, ticks: Vec::with_capacity(record_ticks) });
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
        }
    }

    /// With a [`ServoConfig`] and the device's defaults for what it leaves `None`.
    pub fn with_config(physics: Box<dyn Physics>, config: &ServoConfig, device: &dyn Device) -> Result<HapticCore, String> {
        config.check()?;
        let (c, s) = device.kind().defaults();
        Ok(HapticCore::new(physics, config.rate_hz, config.coupling.unwrap_or(c), config.safety.unwrap_or(s), config.checkpoint_every, config.record_ticks))
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
        match sample {
            Some(s) if s.is_finite() => {
                if self.input.is_none() {
                    // First sample: the proxy starts at the device, at rest.
                    self.coupling.reset(s.position);
                }
                self.input = Some(s);
            }
            Some(_) => self.bad_inputs += 1,
            None => {}
        }
        self.tick += 1;
        let Some(input) = self.input else {
            // No sample yet: nothing to simulate against.
            let z = Vec3::zeros();
            return TickOut { force: self.safety.zero(), raw_force: z, tissue: z, tool: z, device: z, buttons: 0, fault: false };
        };
        let mut out = TickOut { force: Vec3::zeros(), raw_force: Vec3::zeros(), tissue: Vec3::zeros(), tool: self.coupling.proxy, device: input.position, buttons: input.buttons, fault: false };
        let fault = match self.physics.tick(&self.coupling.proxy, self.dt) {
            Err(e) => Some(Fault::Step(e)),
            Ok(f) if !f.iter().all(|c| c.is_finite()) => Some(Fault::NonFinite),
            Ok(f) => {
                self.tissue = f;
                let c = self.coupling.step(&input.position, &f, self.dt, self.physics.max_tool_step());
                if c.force.iter().all(|x| x.is_finite()) && self.coupling.proxy.iter().all(|x| x.is_finite()) {
                    out.raw_force = c.force;
                    out.force = self.safety.apply(&c.force, self.dt);
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
        if let Some(r) = &mut self.recording {
            // Within the buffer sized at start only (a push past it would allocate in the servo
            // thread); what does not fit is counted, so that a truncated recording is reported
            // rather than passed off as the whole run.
            if r.ticks.len() < r.ticks.capacity() {
                r.ticks.push(TickRecord { input, has_input: sample.is_some(), force: out.force, tool: out.tool, tissue: out.tissue });
            } else {
                self.recording_dropped += 1;
            }
        }
        out
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
            self.fault_log.push(FaultRecord { tick: self.tick - 1, time: (self.tick - 1) as f64 * self.dt, fault });
        }
    }

    fn account(&mut self, out: &TickOut) {
        if let Some((f, x)) = self.last_sent {
            self.energy += f.dot(&(out.device - x));
        }
        self.last_sent = Some((out.force, out.device));
        self.max_force = self.max_force.max(out.force.norm());
    }

    /// The watchdog tripped during the last tick: take the fault path for it.
    fn stalled(&mut self, seconds: f64, out: &mut TickOut) {
        self.fault(Fault::Stall(seconds), out);
        self.retract(out);
    }

    /// Runs ticks without a clock (as fast as the physics goes) until the device is finished or
    /// `max_ticks`, sending each force to the device's sink: tests and replays.
    pub fn run_offline(&mut self, device: &mut dyn Device, max_ticks: u64) -> u64 {
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
}

/// The running servo: snapshots, stop.
pub struct ServoHandle {
    shared: Arc<Shared>,
    servo: Option<JoinHandle<ServoReport>>,
    watchdog: Option<JoinHandle<()>>,
}

impl Servo {
    /// Starts the servo thread (and its watchdog) on `core` with `device`.
    pub fn start(core: HapticCore, device: Box<dyn Device>, config: &ServoConfig) -> Result<ServoHandle, String> {
        config.check()?;
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
            surface: Mailbox::new(if config.surface_every > 0 { core.physics.surface_len() } else { 0 }),
            interior: Mailbox::up_to(if config.surface_every > 0 { core.physics.interior_capacity() } else { 0 }),
            epoch: Instant::now(),
        });
        let sink = device.sink();
        let cfg = *config;
        let s = shared.clone();
        let servo = std::thread::Builder::new()
            .name("palpate-servo".into())
            .spawn(move || run(core, device, cfg, s))
            .map_err(|e| format!("cannot start the servo thread: {e}"))?;
        let s = shared.clone();
        let watchdog = std::thread::Builder::new()
            .name("palpate-watchdog".into())
            .spawn(move || {
                if cfg.realtime {
                    // Above the servo, so that a stuck servo cannot starve its own watchdog.
                    let _ = crate::realtime::make_current_thread_realtime(crate::realtime::SERVO_PRIORITY + 1);
                }
                watch(s, sink, stall)
            })
            .map_err(|e| format!("cannot start the watchdog thread: {e}"))?;
        Ok(ServoHandle { shared, servo: Some(servo), watchdog: Some(watchdog) })
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
        match r {
            Ok(r) => r,
            Err(p) => std::panic::resume_unwind(p),
        }
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

fn watch(shared: Arc<Shared>, sink: Arc<dyn ForceSink>, stall: f64) {
    let limit = (stall * 1e9) as u64;
    while !shared.done.load(Ordering::Acquire) {
        std::thread::sleep(Duration::from_micros(500));
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

fn run(mut core: HapticCore, mut device: Box<dyn Device>, cfg: ServoConfig, shared: Arc<Shared>) -> ServoReport {
    let sink = device.sink();
    let period = Duration::from_secs_f64(cfg.dt());
    let spin = Duration::from_secs_f64(cfg.spin);
    let mut times = TickTimes::new(cfg.stats_ticks, cfg.rate_hz);
    // Snapshots for readers: the tick of the last read seen and the reads counted then.
    let (mut read_tick, mut reads, mut published) = (0u64, 0u64, None::<u64>);
    let start = Instant::now();
    let mut deadline = start;
    let mut last_start: Option<Instant> = None;
    shared.heartbeat.store(shared.now_ns().max(1), Ordering::Release);
    let mut n: u64 = 0;
    // The least a real-time servo rests each tick: 6% of the period (see below).
    let min_rest = period.mul_f64(0.06);
    let realtime = if cfg.realtime { crate::realtime::make_current_thread_realtime(crate::realtime::SERVO_PRIORITY) } else { Realtime::Off };
    loop {
        if shared.stop.load(Ordering::Acquire) || cfg.max_ticks.is_some_and(|m| n >= m) || device.finished(core.tick, core.dt) {
            break;
        }
        let t0 = Instant::now();
        let c0 = crate::realtime::thread_cpu_time();
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
        let t1 = Instant::now();
        let c1 = crate::realtime::thread_cpu_time();
        // The tick's rest and the checkpoint, in the tick's slack (the module docs say why): not
        // part of the tick's compute, which ends with the send; a late one shows as the next
        // tick's lateness.
        if core.after_send(&mut out) {
            sink.zeroed();
        }
        shared.heartbeat.store(shared.now_ns().max(1), Ordering::Release);
        n += 1;
        let p = last_start.map_or(cfg.dt(), |s| (t0 - s).as_secs_f64());
        last_start = Some(t0);
        let compute = (t1 - t0).as_secs_f64();
        let cpu = match (c0, c1) {
            (Some(a), Some(b)) => (b - a).clamp(0.0, compute),
            _ => compute,
        };
        deadline += period;
        let late = t1.saturating_duration_since(deadline);
        let overrun = t1 > deadline;
        times.push(p, compute, cpu, overrun, (t1 - start).as_secs_f64(), core.tick);
        let snap = Snapshot {
            tick: core.tick,
            time: core.tick as f64 * core.dt,
            device: out.device,
            tool: out.tool,
            force: out.force,
            raw_force: out.raw_force,
            tissue_force: out.tissue,
            period: p,
            compute,
            overruns: times.overruns(),
            faults: core.faults,
            buttons: out.buttons,
        };
        shared.snapshot.publish(&snap);
        if cfg.surface_every > 0 && core.tick.is_multiple_of(cfg.surface_every) {
            let r = shared.surface.reads() + shared.interior.reads();
            if r != reads {
                (reads, read_tick) = (r, core.tick);
            }
            let watched = core.tick.saturating_sub(read_tick) <= IDLE_SNAPSHOT_TICKS;
            if watched || published.is_none_or(|t| core.tick - t >= IDLE_SNAPSHOT_TICKS) {
                published = Some(core.tick);
                let physics = &core.physics;
                shared.surface.publish_with(core.tick, |out| {
                    physics.surface(out);
                    out.len()
                });
                shared.interior.publish_with(core.tick, |out| physics.interior(out));
            }
        }
        if late > period {
            // More than a whole tick late: start again from now (no burst of catch-up ticks).
            deadline = t1;
        }
        wait_until(deadline, spin);
        if realtime.granted() {
            // A real-time servo that computes through its whole period (the physics slower than
            // real time) would use the whole core, and the kernel's RT throttle would then take
            // it off the CPU for ~50 ms (a watchdog trip, a zeroed force): it rests a little
            // every tick instead, so that it stays under the throttle's 95% (crate::realtime).
            let rested = Instant::now().saturating_duration_since(t1);
            if rested < min_rest {
                std::thread::sleep(min_rest - rested);
            }
        }
    }
    sink.send(&Vec3::zeros());
    let stats = times.finish((Instant::now() - start).as_secs_f64());
    shared.done.store(true, Ordering::Release);
    let trips = shared.trips.load(Ordering::Relaxed);
    ServoReport { core, device, stats, watchdog_trips: trips, realtime }
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
