//! A haptic loop described as values and built by one constructor: [`LoopSpec`] (what to
//! simulate, which device, the servo's and the safety's settings) and [`LoopSpec::build`], which
//! checks it once and makes the [`HapticCore`], the [`Device`] and the [`ServoConfig`] that
//! [`crate::Servo::start`] runs (or [`HapticCore::run_offline`] steps).
//!
//! Why here: the loop used to be assembled in the Python binding, behind a 30-keyword signature,
//! so a Rust program could not build the loop the CLI builds. Now the binding converts keywords
//! into a `LoopSpec` and its errors into Python's, and nothing more; the defaults (the device
//! class's coupling and limits, the physics rate, the servo's spin) and the checks live with the
//! loop.
//!
//! Units: SI (Hz, s, m, N, kg); positions in the model's world frame.

use std::net::SocketAddrV4;
use std::sync::Arc;

use palpate_core::hybrid::HybridModel;
use palpate_core::runtime::SimOptions;
use palpate_core::{Material, Model, ModelError, Vec3};

use crate::bridge::{Bridge, BridgeError, BridgeOptions, BridgeStats, Key};
use crate::devices::{Hand, HandParams, Replay, ReplayCheck, Scripted};
use crate::physics::{FemOptions, FemPhysics, HybridPhysics, Identity, Idle, Physics};
use crate::safety::check_limits;
use crate::{CouplingParams, Device, DeviceKind, HapticCore, Recording, SafetyParams, ServoConfig, Vec3Cell};

/// The `spin` of a servo that is not real-time and has no physics thread beside it \[s\]:
/// longer than any period, so the servo never sleeps (the single-rate loop computes the tick in
/// its period; a sleep's wake-up would eat into it).
pub const BUSY_SPIN: f64 = 1.0;

/// The `spin` of the multirate loop's servo \[s\]: it sleeps to each deadline, leaving the cores to
/// the physics thread (BENCHMARKS.md, the multirate servo).
pub const MULTIRATE_SPIN: f64 = 0.0;

/// The multirate loop's physics rate when none is given \[Hz\] (at most the servo's).
pub const DEFAULT_PHYSICS_RATE_HZ: f64 = 1000.0;

/// What the servo's tool touches.
// Built once per loop: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum PhysicsSpec {
    /// The hybrid runtime of a built model, its particle passes on `threads` threads (1: the
    /// servo's or the physics thread alone).
    Hybrid { model: HybridModel, material: Material, options: SimOptions, threads: usize },
    /// A full-FEM body touched by a sphere ([`FemPhysics`]).
    Fem { model: Model, options: FemOptions },
    /// Nothing: the idle loop (the servo's own timing, no physics).
    Idle,
}

/// Where the tool's position comes from.
pub enum DeviceSpec {
    /// A path through `knots` \[m\] at `times` \[s\] (increasing), linear between them.
    Scripted { times: Vec<f64>, knots: Vec<Vec3> },
    /// A recording's device samples; the loop takes the recording's rates, coupling and limits,
    /// and refuses a recording of another simulation.
    Replay(Recording),
    /// The simulated hand ([`Hand`]), starting at `start` \[m\], moved by its target.
    Hand { start: Vec3 },
    /// A vendor device through the UDP bridge, listening at `address` (port 0: any free one),
    /// with an optional shared key (required off the loopback address).
    Bridge { address: SocketAddrV4, key: Option<Key> },
}

/// The virtual coupling's settings; `None`: the device class's default ([`DeviceKind::defaults`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CouplingSpec {
    /// \[N/m\]
    pub stiffness: Option<f64>,
    /// \[N s/m\]
    pub damping: Option<f64>,
    /// \[kg\]
    pub proxy_mass: Option<f64>,
}

/// The safety layer's settings; `None`: the device class's default. Limits beyond the class's
/// rating are refused unless `unsafe_limits`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SafetySpec {
    /// \[N\]
    pub max_force: Option<f64>,
    /// \[N/s\]
    pub max_rate: Option<f64>,
    /// The start-up ramp \[s\].
    pub ramp: Option<f64>,
    /// The physics' watchdog \[s\].
    pub stall_timeout: Option<f64>,
    /// No device sample for this long fades the force \[s\].
    pub silence: Option<f64>,
    /// Allow limits beyond the device class's rating (at the user's risk; reported by
    /// [`BuiltLoop::unsafe_note`]).
    pub unsafe_limits: bool,
}

/// A haptic loop as values; [`LoopSpec::new`] gives the defaults, [`LoopSpec::build`] checks and
/// makes it.
pub struct LoopSpec {
    pub physics: PhysicsSpec,
    pub device: DeviceSpec,
    /// The device's class (its rated limits and default coupling); `None`: `Bridge` for the
    /// bridge, else `Simulated`.
    pub kind: Option<DeviceKind>,
    /// The servo's rate \[Hz\] (250 Hz to 4 kHz).
    pub rate_hz: f64,
    /// The multirate loop's physics rate \[Hz\]; `None`: [`DEFAULT_PHYSICS_RATE_HZ`], at most
    /// the servo's.
    pub physics_rate_hz: Option<f64>,
    /// The single-rate loop (the physics ticked inside the servo's period), for comparison.
    pub single_rate: bool,
    pub coupling: CouplingSpec,
    pub safety: SafetySpec,
    /// Ticks recorded at most (the buffer is allocated at start; a finite device's length caps
    /// it).
    pub record_ticks: usize,
    /// Stop after this many servo ticks.
    pub max_ticks: Option<u64>,
    /// How long before each deadline the servo busy-waits instead of sleeping \[s\]; `None`: 0
    /// for a real-time or multirate servo, [`BUSY_SPIN`] otherwise.
    pub spin: Option<f64>,
    /// Run the servo (and helper threads) under `SCHED_FIFO` where the system allows it.
    pub realtime: bool,
}

/// Why a [`LoopSpec`] was refused or could not be built.
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// A setting out of its range or inconsistent with another.
    #[error("{0}")]
    Parameter(String),
    /// The physics could not be compiled.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The bridge could not be opened.
    #[error(transparent)]
    Bridge(#[from] BridgeError),
    /// Anything else the loop could not set up (threads, the recording's identity).
    #[error("{0}")]
    Setup(String),
}

/// A built loop, ready to start: what [`crate::Servo::start`] takes, and what a caller keeps to
/// steer and watch it.
pub struct BuiltLoop {
    pub core: HapticCore,
    pub device: Box<dyn Device>,
    pub config: ServoConfig,
    /// The simulated hand's target (device `Hand`).
    pub hand: Option<Arc<Vec3Cell>>,
    /// The bridge's address and statistics (device `Bridge`).
    pub bridge: Option<(String, Arc<BridgeStats>)>,
    /// The simulation's identity (what a recording must match).
    pub identity: Identity,
    /// A multirate recording to replay from its own schedule (device `Replay`).
    pub replay: Option<Recording>,
    /// A single-rate replay's check of its forces against the recording's.
    pub replay_check: Option<Arc<ReplayCheck>>,
    /// The limit beyond the device class's rating that `unsafe_limits` let through.
    pub unsafe_note: Option<String>,
}

/// `v`, if given, positive (or, with `zero_ok`, non-negative) and finite; else why not, naming
/// `name`. Shared with the binding's checks of the physics' options.
pub fn check_positive(name: &str, v: Option<f64>, zero_ok: bool) -> Result<(), String> {
    match v {
        Some(x) if !(x.is_finite() && (x > 0.0 || (zero_ok && x == 0.0))) => {
            Err(format!("{name} = {x} must be {} and finite", if zero_ok { "non-negative" } else { "positive" }))
        }
        _ => Ok(()),
    }
}

fn positive(name: &str, v: Option<f64>, zero_ok: bool) -> Result<(), LoopError> {
    check_positive(name, v, zero_ok).map_err(LoopError::Parameter)
}

impl LoopSpec {
    /// A 1 kHz multirate loop of `physics` driven by `device`, the device class's coupling and
    /// limits, nothing recorded.
    pub fn new(physics: PhysicsSpec, device: DeviceSpec) -> LoopSpec {
        LoopSpec {
            physics,
            device,
            kind: None,
            rate_hz: 1000.0,
            physics_rate_hz: None,
            single_rate: false,
            coupling: CouplingSpec::default(),
            safety: SafetySpec::default(),
            record_ticks: 0,
            max_ticks: None,
            spin: None,
            realtime: false,
        }
    }

    /// Checks the settings, opens the device and compiles the physics (seconds for a large
    /// model: the hybrid runtime's set-up).
    pub fn build(self) -> Result<BuiltLoop, LoopError> {
        self.check()?;
        let LoopSpec {
            physics,
            device,
            kind,
            mut rate_hz,
            physics_rate_hz,
            single_rate,
            coupling,
            safety,
            record_ticks,
            max_ticks,
            spin,
            realtime,
        } = self;
        // The multirate loop by default, its physics at 1 kHz (or the servo's rate, if lower);
        // the idle loop has no physics to run. A replay takes its recording's rates.
        let mut physics_rate = if single_rate || matches!(physics, PhysicsSpec::Idle) {
            None
        } else {
            Some(physics_rate_hz.unwrap_or(DEFAULT_PHYSICS_RATE_HZ.min(rate_hz)))
        };
        let replay = match &device {
            DeviceSpec::Replay(r) => Some(r),
            _ => None,
        };
        if let Some(r) = replay {
            (rate_hz, physics_rate) = (r.rate_hz, r.physics_rate_hz);
        }
        let kind = kind.unwrap_or(if matches!(device, DeviceSpec::Bridge { .. }) { DeviceKind::Bridge } else { DeviceKind::Simulated });
        let (coupling, safety, unsafe_note) = limits(kind, &coupling, &safety, replay)?;
        let mut config = ServoConfig {
            rate_hz,
            physics_rate_hz: physics_rate,
            coupling: Some(coupling),
            safety: Some(safety),
            record_ticks,
            max_ticks,
            spin: spin.unwrap_or(if realtime {
                0.0
            } else if physics_rate.is_some() {
                MULTIRATE_SPIN
            } else {
                BUSY_SPIN
            }),
            realtime,
            ..ServoConfig::default()
        };
        config.check().map_err(LoopError::Parameter)?;
        let replay_identity = replay.map(|r| r.identity.clone());
        let opened = open_device(device, kind, rate_hz)?;
        let physics = make_physics(physics, realtime)?;
        let identity = physics.identity();
        if let Some(recorded) = replay_identity {
            check_identity(&recorded, &identity)?;
        }
        // No recording needs more ticks than a finite device gives.
        config.record_ticks = opened.ticks.map_or(record_ticks, |n| record_ticks.min(n));
        let core = HapticCore::new(physics, rate_hz, coupling, safety, config.checkpoint_every, config.record_ticks);
        Ok(BuiltLoop {
            core,
            device: opened.device,
            config,
            hand: opened.hand,
            bridge: opened.bridge,
            identity,
            replay: opened.multirate_replay,
            replay_check: opened.replay_check,
            unsafe_note,
        })
    }

    /// The settings' ranges and combinations (what the servo's own check does not see).
    fn check(&self) -> Result<(), LoopError> {
        let (c, s) = (&self.coupling, &self.safety);
        for (n, v) in [
            ("coupling_stiffness", c.stiffness),
            ("proxy_mass", c.proxy_mass),
            ("max_force", s.max_force),
            ("max_rate", s.max_rate),
            ("stall_timeout", s.stall_timeout),
            ("silence", s.silence),
            ("physics_rate", self.physics_rate_hz),
        ] {
            positive(n, v, false)?;
        }
        for (n, v) in [("coupling_damping", c.damping), ("ramp", s.ramp), ("spin", self.spin)] {
            positive(n, v, true)?;
        }
        if let PhysicsSpec::Hybrid { threads, .. } = &self.physics {
            if !(1..=palpate_core::parallel::MAX_WAYS).contains(threads) {
                return Err(LoopError::Parameter(format!("threads = {threads}: must be 1 to {}", palpate_core::parallel::MAX_WAYS)));
            }
        }
        if self.single_rate && self.physics_rate_hz.is_some() {
            return Err(LoopError::Parameter("physics_rate and single_rate together: the single-rate loop has no physics thread".into()));
        }
        Ok(())
    }
}

/// The coupling and safety limits: the given ones over the device class's defaults, or a
/// replay's recorded ones; beyond the class's rating only with `unsafe_limits`, and then said
/// (the third value). A replay drives no device: its recorded limits stand.
fn limits(kind: DeviceKind, c: &CouplingSpec, s: &SafetySpec, replay: Option<&Recording>) -> Result<(CouplingParams, SafetyParams, Option<String>), LoopError> {
    if let Some(r) = replay {
        return Ok((r.coupling, r.safety, None));
    }
    let (dc, ds) = kind.defaults();
    let coupling = CouplingParams {
        stiffness: c.stiffness.unwrap_or(dc.stiffness),
        damping: c.damping.unwrap_or(dc.damping),
        proxy_mass: c.proxy_mass.unwrap_or(dc.proxy_mass),
    };
    let safety = SafetyParams {
        max_force: s.max_force.unwrap_or(ds.max_force),
        max_rate: s.max_rate.unwrap_or(ds.max_rate),
        ramp: s.ramp.unwrap_or(ds.ramp),
        stall_timeout: s.stall_timeout.unwrap_or(ds.stall_timeout),
        silence: s.silence.unwrap_or(ds.silence),
    };
    match check_limits(kind, &coupling, &safety) {
        Err(why) if !s.unsafe_limits => Err(LoopError::Parameter(format!("{why}: refused (unsafe_limits allows it, at the user's risk)"))),
        result => Ok((coupling, safety, result.err())),
    }
}

/// An opened device and what the loop keeps of it.
struct Opened {
    device: Box<dyn Device>,
    /// Ticks a finite device gives (a script's, a replay's).
    ticks: Option<usize>,
    hand: Option<Arc<Vec3Cell>>,
    bridge: Option<(String, Arc<BridgeStats>)>,
    replay_check: Option<Arc<ReplayCheck>>,
    /// A multirate recording, replayed from its own schedule rather than the device's samples.
    multirate_replay: Option<Recording>,
}

fn open_device(device: DeviceSpec, kind: DeviceKind, rate_hz: f64) -> Result<Opened, LoopError> {
    let (mut ticks, mut hand, mut bridge, mut replay_check, mut multirate_replay) = (None, None, None, None, None);
    let device: Box<dyn Device> = match device {
        DeviceSpec::Scripted { times, knots } => {
            let s = Scripted::new(times, knots).map_err(LoopError::Parameter)?;
            ticks = Some((s.duration() * rate_hz).ceil() as usize + 1);
            Box::new(s)
        }
        DeviceSpec::Replay(r) => {
            ticks = Some(r.ticks.len());
            let dev = Replay::new(&r);
            replay_check = Some(dev.check());
            if r.physics_rate_hz.is_some() {
                multirate_replay = Some(r);
            }
            Box::new(dev)
        }
        DeviceSpec::Hand { start } => {
            let h = Hand::new(HandParams::default(), start);
            hand = Some(h.target());
            Box::new(h)
        }
        DeviceSpec::Bridge { address, key } => {
            let b = Bridge::open(address, kind, BridgeOptions { key, ..Default::default() })?;
            let addr = b.local_addr().map_err(|e| LoopError::Setup(format!("the bridge's address: {e}")))?.to_string();
            bridge = Some((addr, b.stats()));
            Box::new(b)
        }
    };
    Ok(Opened { device, ticks, hand, bridge, replay_check, multirate_replay })
}

fn make_physics(physics: PhysicsSpec, realtime: bool) -> Result<Box<dyn Physics>, LoopError> {
    Ok(match physics {
        PhysicsSpec::Idle => Box::new(Idle::default()),
        PhysicsSpec::Hybrid { model, material, options, threads } => Box::new(
            HybridPhysics::new(model, material, options)?
                .with_threads(threads, realtime)
                .map_err(|e| LoopError::Setup(format!("cannot start {} helper threads: {e}", threads - 1)))?,
        ),
        PhysicsSpec::Fem { model, options } => Box::new(FemPhysics::new(model, options)?),
    })
}

/// A recording replays only on the simulation it was made with.
fn check_identity(recorded: &Identity, id: &Identity) -> Result<(), LoopError> {
    if recorded.digest != id.digest {
        return Err(LoopError::Setup(format!(
            "the recording is of another simulation (digest {:016x}: {}), this loop's is {:016x} ({}): a replay would not give the recorded forces",
            recorded.digest, recorded.description, id.digest, id.description
        )));
    }
    Ok(())
}
