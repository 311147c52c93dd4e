//! `palpate.HapticLoop`: the haptic loop (`palpate_haptics`) over a hybrid model or a full-FEM
//! body: a native servo thread that reads a device, ticks the simulation and sends the force, never waiting on Python.
//! Python only starts it, reads snapshots (a seqlock: never blocks the loop) and stops it;
//! waiting and the offline run release the GIL.
//!
//! The loop's stage sits behind a mutex, which no method holds while the GIL is released or
//! while it calls into Python: `stop` and `run` take what they need out of it first (leaving
//! [`Stage::Busy`]) and put it back after. Holding it across a GIL release deadlocked: another
//! thread's `snapshot()` took the GIL and waited on the mutex, and `stop()` waited for the GIL.

use std::net::{Ipv4Addr, SocketAddrV4};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use palpate_core::runtime::{scale, SimOptions};
use palpate_core::{ModelBuilder, Vec3};
use palpate_haptics::bridge::protocol::Reject;
use palpate_haptics::bridge::{BridgeError, BridgeStats, Key};
use palpate_haptics::devices::ReplayCheck;
use palpate_haptics::{
    BuiltLoop, CouplingSpec, Device, DeviceKind, DeviceSpec, FemOptions, HapticCore, LoopError, LoopSpec, PhysicsSpec, Realtime, Recording, SafetySpec, Servo,
    ServoConfig, ServoHandle, ServoReport, Snapshot, Stats, Vec3Cell,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::body::PyBody;
use crate::conv;
use crate::errors::{self, HapticsError};
use crate::hybrid::PyHybridModel;
use crate::material::PyMaterial;

// One per loop, moved rarely: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
enum Stage {
    Ready(HapticCore, Box<dyn Device>),
    Running(ServoHandle),
    Done(Box<ServoReport>),
    /// Taken out of the mutex by a call that releases the GIL (`stop`, `run`): what it is doing.
    Busy(&'static str),
    /// Consumed: stopped and reported, or a panic left the core unusable.
    Taken,
}

fn busy(what: &str) -> PyErr {
    haptics_error(format!("the loop is {what} in another thread"))
}

/// The haptic loop over a hybrid model (issue 13) or a full-FEM body (issue 14): a servo thread at ``rate_hz`` (250 to 4000 Hz)
/// that each tick reads ``device``, ticks the simulation (its tool driven through a virtual
/// coupling) and sends the force through the safety layer (force limit, rate limit, ramp); a
/// watchdog zeroes the force if the simulation misses ticks for ``stall_timeout``.
///
/// ``HapticLoop(model, material, device, *, rate_hz=1000.0, times=None, knots=None,
/// recording=None, port=None, host="127.0.0.1", kind=None, hand_start=None, idle=False,
/// tool_radius=None, core_contact_stiffness=None, tool_area_stiffness=None, hold=True, coupling_stiffness=None,
/// coupling_damping=None, proxy_mass=None, max_force=None, max_rate=None, ramp=None,
/// stall_timeout=None, silence=None, record_ticks=0, max_ticks=None, spin=None, realtime=False, threads=1,
/// physics_rate=None, single_rate=False, unsafe_limits=False, bridge_key=None, strict_units=False)``
///
/// Parameters
/// ----------
/// model : HybridModel or Body
///     A hybrid model (core, shell, skin), or a full-FEM :class:`Body`: its mesh, fixed nodes,
///     gravity and integrator with ``material``, at rest (the body's state is not used). The
///     tool meets a body's boundary surface (its triangles, not only its nodes), with a penalty
///     per unit of surface area (``tool_area_stiffness``) capped by what keeps the explicit
///     contact stable (``palpate_haptics::FemPhysics``).
/// material : Material
///     The tissue's (a body's own material is replaced by it: pass ``body.material`` to keep it).
/// device : str
///     ``"scripted"`` (needs ``times`` (k,) [s], strictly increasing, and ``knots`` (k, 3) [m]:
///     the tool-centre trajectory, e.g. a resolved ``palpate.touch`` script), ``"replay"``
///     (needs ``recording``, a file written by :meth:`save_recording`; the loop takes its rate,
///     coupling and safety parameters and refuses a recording of another model), ``"hand"`` (a
///     simulated hand at ``hand_start`` (3,) [m] following :meth:`set_hand_target`), or
///     ``"bridge"`` (UDP on ``host``:``port``, protocol in ``crates/palpate-haptics/PROTOCOL.md``;
///     ``port=0`` picks a free one, see :attr:`bridge_address`).
/// kind : str, optional
///     The device's make for the coupling and safety defaults: ``simulated``, ``bridge``,
///     ``touch``, ``forcedimension``, ``haply``, ``hapticmaster`` (default: ``bridge`` for a
///     bridge, else ``simulated``).
/// idle : bool
///     No simulation (zero force): the idle loop the benchmark compares with.
/// hold : bool
///     Hybrid models only: see :class:`HybridSim`.
/// tool_radius : float, optional
///     The tool sphere's radius [m] (default 0.005).
/// core_contact_stiffness : float, optional
///     Hybrid models only: the tool's wall against the core's surface [N/m] (default 2000): see
///     :class:`HybridSim`.
/// tool_area_stiffness : float, optional
///     The penalty per unit of surface area [N/m^3] (default ``12 E* / min(R, 4 h)``, ``h`` a
///     hybrid model's lattice spacing, ``12 E* / R`` on a full-FEM body: ten times the tissue's
///     Hertz stiffness per unit area under the smallest contact the model resolves; 8.6e7 for
///     myocardium and the 5 mm tool on the Rodero model). A hybrid model's skin vertices carry it by their areas (see
///     :class:`HybridSim`); a full-FEM body takes each tick the least of it and what keeps the
///     contact stable (at 1 kHz on the protocol meshes about 1.5e6 to 2.5e6: that bound sets it).
/// coupling_stiffness, coupling_damping, proxy_mass : float, optional
///     The virtual coupling [N/m], [N s/m], [kg] (defaults: the device kind's).
/// max_force, max_rate, ramp, stall_timeout, silence : float, optional
///     Safety: force limit [N] (default 3), force-rate limit [N/s] (1000), ramp-up [s] (0.5),
///     watchdog timeout [s] (0.03; with ``physics_rate``, a physics this late has faded to zero
///     force), device silence [s] (0.05: no new device sample for this long fades the force to
///     zero over 30 ms, logged; the device's return ramps it in again).
/// physics_rate : float, optional
///     The multirate loop: the physics runs on its own thread at this rate [Hz] (100 to
///     ``rate_hz``) and publishes after each tick a local model (the force at the tool and its
///     stiffness, 3x3 [N/m]) that the servo renders every period without ever waiting for the
///     physics (``palpate_haptics::multirate``). ``stop()``'s report then has ``physics``
///     (``rate_hz``, ``achieved_hz``, ``ticks``, ``compute_us_p50`` / ``_p99`` / ``_max``,
///     ``lag_us_p99`` / ``_max``, ``late``, ``skipped``); :meth:`run` runs it without a clock, a
///     multirate recording replaying bit for bit from its recorded schedule. None (default):
///     1000 Hz, or ``rate_hz`` if lower. A replay runs at its recording's rates.
/// single_rate : bool
///     One physics tick inside every servo period instead (no physics thread; the loop before
///     the multirate one, kept for comparison: a physics tick longer than the period is a period
///     the hand misses). Not with ``physics_rate``.
/// unsafe_limits : bool
///     Accept a ``max_force`` above the device class's rated force (``kind``: touch 3.3 N,
///     forcedimension 12 N, hapticmaster 250 N, haply and bridge 3.3 N until checked, simulated
///     10 N), a ``coupling_stiffness`` above its rated stiffness (1,020 / 14,500 / 50,000 /
///     1,020 / 3,000 N/m), or a ``stall_timeout`` or ``silence`` over 0.1 s. Without it those
///     raise ``ParameterError``; with it a ``UserWarning`` says which, and the reports'
///     ``unsafe_limits`` holds the reason (None otherwise). A replay keeps its recording's limits.
/// bridge_key : bytes, optional
///     Device ``"bridge"``: the shared key (at least 16 bytes) of an authenticated bridge: every
///     packet carries an HMAC-SHA256 tag made with it, and the loop drops any whose tag does not
///     verify (``palpate.devices.bridge.load_key`` reads one from a file). Required for a ``host``
///     other than a loopback address; without it only local processes can reach the bridge, and
///     the loop's session rules (PROTOCOL.md) decide which one moves the tool.
/// strict_units : bool
///     Values most likely in the wrong unit (a Young's modulus outside 100 Pa to 10 MPa, a tool
///     radius over 5 cm, a ``hand_start`` or :meth:`set_hand_target` more than 1 m from the
///     model's bounding box: positions in mm) warn with ``palpate.UnitWarning`` (a far target
///     once a loop); True makes each a ``ParameterError``.
/// record_ticks : int
///     Ticks to record for :meth:`save_recording` (0: none). The buffer is allocated at start
///     (144 bytes a tick; a replay's or a script's is at most its length); ticks past it are
///     not recorded but counted (the report's ``recording_dropped_ticks``).
/// max_ticks : int, optional
///     Stop after this many ticks (a scripted or replayed device also stops at its end).
/// spin : float, optional
///     The last part of each wait that the servo spins rather than sleeps [s], 0 to 1 (default
///     1 s, longer than any period: the servo never sleeps and keeps its core busy; 0 with
///     ``realtime``). A core that slept starts the next tick with cold caches and, on a virtual
///     machine, may be taken away meanwhile: on the Rodero palpation at 1 kHz the busy servo had
///     a compute p99 ~20% lower and 5-50 overruns a minute against 38-234 sleeping (2026-11-27,
///     docs/history/benchmarks-log.md#2026-11-27-tenth-session-the-checkpoint-after-the-send-a-first-tick-without-the-whole-skin-the-busy-servo-by-default).
///     ``200e-6`` (``palpate haptic --sleep``) sleeps through each wait but its
///     last 200 us, leaving the core to other work.
///     With ``physics_rate`` the default is 0: the servo's work is then ~10-20 us a period, it
///     sleeps to each deadline (an ordinary servo thread asks Linux for its shortest time slice
///     and a 1 us timer slack, so that it wakes on time and preempts a CPU-bound program), and
///     the core is left to the physics thread. Rodero at 1 kHz with a CPU-bound program beside
///     it, 30 s: 3,346 late periods spinning, 593 sleeping all but the last 200 us, 41-48
///     sleeping to the deadline; at 4 kHz 6,329 against 40-47 (BENCHMARKS.md).
/// realtime : bool
///     Run the servo thread under ``SCHED_FIFO`` (priority 80; the watchdog 81) so that the
///     machine's other work cannot preempt a tick. Needs root, ``CAP_SYS_NICE`` or an
///     ``rtprio`` limit; refused otherwise (the loop runs as an ordinary thread) and the
///     report's ``realtime`` says which (``"off"``, ``"SCHED_FIFO priority 80"`` or
///     ``"refused: ..."``). The wait then sleeps to the deadline (``spin`` defaults to 0: a
///     real-time thread wakes on time, and one that spins the rest of each tick uses the whole
///     core and meets the kernel's real-time throttling, 50 ms without the CPU every second).
/// threads : int
///     Hybrid models only: the threads a tick's particle passes run on, 1 to 8 (default 1): the
///     servo's and ``threads - 1`` helpers, which spin during a tick and park between ticks
///     (under ``SCHED_FIFO`` with ``realtime``). The forces and states are bitwise those of one
///     thread (a recording replays alike), only sooner: on a 2-core machine 2 threads take
///     about a fifth off a Rodero tick (2026-11-26,
///     docs/history/benchmarks-log.md#2026-11-26-fourth-session-the-particle-passes-on-two-threads-do-not-pay-on-this-machine-load-09-14-1100-1140-utc).
///     Give it cores that are otherwise idle.
///
/// Positions in metres, forces in newtons (on the user's hand), the model's world frame.
#[pyclass(module = "palpate", name = "HapticLoop")]
pub struct PyHapticLoop {
    stage: Mutex<Stage>,
    config: ServoConfig,
    hand: Option<Arc<Vec3Cell>>,
    bridge: Option<(String, Arc<BridgeStats>)>,
    identity: (u64, String),
    /// A multirate recording to replay (`run`: bit for bit, from its recorded schedule).
    replay: Option<Recording>,
    /// A single-rate replay's check of its forces against the recording's.
    replay_check: Option<Arc<ReplayCheck>>,
    /// The limit beyond the device class's rating that `unsafe_limits` let through.
    unsafe_note: Option<String>,
    /// The hand target's unit check (the model's bounding box at rest, `strict_units`).
    target_check: errors::TargetCheck,
}

fn kind_of(name: &str) -> PyResult<DeviceKind> {
    Ok(match name {
        "simulated" => DeviceKind::Simulated,
        "bridge" => DeviceKind::Bridge,
        // `touch`: the former name, still accepted.
        "geomagic" | "touch" => DeviceKind::Touch,
        "forcedimension" => DeviceKind::ForceDimension,
        "haply" => DeviceKind::Haply,
        "hapticmaster" => DeviceKind::HapticMaster,
        _ => return Err(errors::param_error_from(format!("kind = {name:?}: expected simulated, bridge, geomagic, forcedimension, haply or hapticmaster"))),
    })
}

fn positive(name: &str, v: Option<f64>, zero_ok: bool) -> PyResult<()> {
    palpate_haptics::spec::check_positive(name, v, zero_ok).map_err(errors::param_error_from)
}

fn haptics_error(msg: impl std::fmt::Display) -> PyErr {
    HapticsError::new_err(msg.to_string())
}

/// A recording that cannot be loaded: over the memory budget a `palpate.LimitError` (as every
/// size refused before allocation), anything else a `HapticsError`.
fn record_error(e: palpate_haptics::record::RecordError) -> PyErr {
    match e {
        palpate_haptics::record::RecordError::Limit { path, source } => errors::limit_error(&source, Some(&path)),
        other => haptics_error(other),
    }
}

fn snapshot_dict<'py>(py: Python<'py>, s: &Snapshot) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("tick", s.tick)?;
    d.set_item("time", s.time)?;
    d.set_item("device", conv::vec3_to_py(py, s.device))?;
    d.set_item("tool", conv::vec3_to_py(py, s.tool))?;
    d.set_item("force", conv::vec3_to_py(py, s.force))?;
    d.set_item("raw_force", conv::vec3_to_py(py, s.raw_force))?;
    d.set_item("tissue_force", conv::vec3_to_py(py, s.tissue_force))?;
    d.set_item("period_us", s.period * 1e6)?;
    d.set_item("compute_us", s.compute * 1e6)?;
    d.set_item("overruns", s.overruns)?;
    d.set_item("faults", s.faults)?;
    d.set_item("physics_ticks", s.physics_ticks)?;
    d.set_item("buttons", s.buttons)?;
    Ok(d)
}

fn core_dict<'py>(py: Python<'py>, core: &HapticCore, d: &Bound<'py, PyDict>) -> PyResult<()> {
    d.set_item("ticks", core.ticks())?;
    d.set_item("max_force_n", core.max_force())?;
    d.set_item("energy_into_user_j", core.energy_into_user())?;
    d.set_item("bad_inputs", core.bad_inputs())?;
    d.set_item("device_silences", core.silences())?;
    d.set_item("model_stalls", core.stalls())?;
    d.set_item("recording_dropped_ticks", core.recording_dropped())?;
    let faults = PyList::empty(py);
    for f in core.fault_log() {
        let e = PyDict::new(py);
        e.set_item("tick", f.tick)?;
        e.set_item("time", f.time)?;
        e.set_item("reason", f.fault.to_string())?;
        e.set_item("fault", f.counted)?;
        faults.append(e)?;
    }
    d.set_item("n_faults", core.faults())?;
    d.set_item("faults", faults)?;
    Ok(())
}

fn stats_dict(d: &Bound<'_, PyDict>, s: &Stats) -> PyResult<()> {
    d.set_item("rate_hz", s.rate_hz)?;
    d.set_item("achieved_hz", s.achieved_hz)?;
    d.set_item("elapsed_s", s.elapsed)?;
    d.set_item("period_us_p50", s.period_p50 * 1e6)?;
    d.set_item("period_us_p99", s.period_p99 * 1e6)?;
    d.set_item("period_us_max", s.period_max * 1e6)?;
    d.set_item("compute_us_p50", s.compute_p50 * 1e6)?;
    d.set_item("compute_us_p99", s.compute_p99 * 1e6)?;
    d.set_item("compute_us_max", s.compute_max * 1e6)?;
    d.set_item("cpu_us_p50", s.cpu_p50 * 1e6)?;
    d.set_item("cpu_us_p99", s.cpu_p99 * 1e6)?;
    d.set_item("cpu_us_max", s.cpu_max * 1e6)?;
    d.set_item("overruns", s.overruns)?;
    d.set_item("overruns_own", s.own_overruns)?;
    d.set_item("overruns_machine", s.overruns - s.own_overruns)?;
    d.set_item("overrun_times_s", s.overrun_at.iter().map(|x| x.1).collect::<Vec<f64>>())?;
    Ok(())
}

/// `stop()`'s dict of a finished run.
fn report_dict<'py>(py: Python<'py>, r: &ServoReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    stats_dict(&d, &r.stats)?;
    core_dict(py, &r.core, &d)?;
    d.set_item("watchdog_trips", r.watchdog_trips)?;
    match &r.physics {
        Some(p) => {
            let q = PyDict::new(py);
            q.set_item("rate_hz", p.rate_hz)?;
            q.set_item("achieved_hz", p.achieved_hz)?;
            q.set_item("ticks", p.ticks)?;
            q.set_item("elapsed_s", p.elapsed)?;
            q.set_item("compute_us_p50", p.compute_p50 * 1e6)?;
            q.set_item("compute_us_p99", p.compute_p99 * 1e6)?;
            q.set_item("compute_us_max", p.compute_max * 1e6)?;
            q.set_item("lag_us_p99", p.lag_p99 * 1e6)?;
            q.set_item("lag_us_max", p.lag_max * 1e6)?;
            q.set_item("late", p.late)?;
            q.set_item("skipped", p.skipped)?;
            d.set_item("physics", q)?;
        }
        None => d.set_item("physics", py.None())?,
    }
    d.set_item("short_slice", r.short_slice)?;
    d.set_item(
        "realtime",
        match &r.realtime {
            Realtime::Off => "off".to_string(),
            Realtime::Granted(p) => format!("SCHED_FIFO priority {p}"),
            Realtime::Refused(why) => format!("refused: {why}"),
        },
    )?;
    Ok(d)
}

#[pymethods]
impl PyHapticLoop {
    #[new]
    #[pyo3(signature = (model, material, device, *, rate_hz = 1000.0, times = None, knots = None, recording = None, port = None, host = String::from("127.0.0.1"), kind = None, hand_start = None, idle = false, tool_radius = None, core_contact_stiffness = None, tool_area_stiffness = None, hold = true, coupling_stiffness = None, coupling_damping = None, proxy_mass = None, max_force = None, max_rate = None, ramp = None, stall_timeout = None, silence = None, record_ticks = errors::Int::Fits(0), max_ticks = None, spin = None, realtime = false, threads = errors::Int::Fits(1), physics_rate = None, single_rate = false, unsafe_limits = false, bridge_key = None, strict_units = false), text_signature = "(model, material, device, *, rate_hz=1000.0, times=None, knots=None, recording=None, port=None, host=\"127.0.0.1\", kind=None, hand_start=None, idle=False, tool_radius=None, core_contact_stiffness=None, tool_area_stiffness=None, hold=True, coupling_stiffness=None, coupling_damping=None, proxy_mass=None, max_force=None, max_rate=None, ramp=None, stall_timeout=None, silence=None, record_ticks=0, max_ticks=None, spin=None, realtime=False, threads=1, physics_rate=None, single_rate=False, unsafe_limits=False, bridge_key=None, strict_units=False)")]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        model: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = conv::arg)] material: PyRef<'_, PyMaterial>,
        #[pyo3(from_py_with = conv::arg)] device: String,
        #[pyo3(from_py_with = conv::arg)] rate_hz: f64,
        times: Option<&Bound<'_, PyAny>>,
        knots: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = conv::arg)] recording: Option<std::path::PathBuf>,
        port: Option<errors::Int>,
        #[pyo3(from_py_with = conv::arg)] host: String,
        #[pyo3(from_py_with = conv::arg)] kind: Option<String>,
        hand_start: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = conv::arg)] idle: bool,
        #[pyo3(from_py_with = conv::arg)] tool_radius: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] core_contact_stiffness: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] tool_area_stiffness: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] hold: bool,
        #[pyo3(from_py_with = conv::arg)] coupling_stiffness: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] coupling_damping: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] proxy_mass: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] max_force: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] max_rate: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] ramp: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] stall_timeout: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] silence: Option<f64>,
        record_ticks: errors::Int,
        max_ticks: Option<errors::Int>,
        #[pyo3(from_py_with = conv::arg)] spin: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] realtime: bool,
        threads: errors::Int,
        #[pyo3(from_py_with = conv::arg)] physics_rate: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] single_rate: bool,
        #[pyo3(from_py_with = conv::arg)] unsafe_limits: bool,
        #[pyo3(from_py_with = conv::arg)] bridge_key: Option<Bound<'_, pyo3::types::PyBytes>>,
        #[pyo3(from_py_with = conv::arg)] strict_units: bool,
    ) -> PyResult<Self> {
        // Counts as errors::Int: a negative one, or one beyond 64 bits, is a ParameterError
        // (pyo3's usize / u16 conversions raised OverflowError). The rest runs under the panic guard: a panic while opening a recording,
        // a device or the physics is an InternalError, not pyo3's PanicException.
        let record_ticks = errors::count(record_ticks, "record_ticks")?;
        let max_ticks = errors::count_opt(max_ticks, "max_ticks")?.map(|n| n as u64);
        let threads = errors::count(threads, "threads")?;
        if !(1..=palpate_core::parallel::MAX_WAYS).contains(&threads) {
            return Err(errors::param_error_from(format!("threads = {threads}: must be 1 to {}", palpate_core::parallel::MAX_WAYS)));
        }
        let port = match port {
            Some(p) => Some(
                match p {
                    errors::Int::Fits(v) => u16::try_from(v).ok(),
                    errors::Int::Huge { .. } => None,
                }
                .ok_or_else(|| errors::param_error_from(format!("port = {p}: must be 0 to 65535")))?,
            ),
            None => None,
        };
        errors::guard("HapticLoop", || {
            // Python's values into the loop's description (palpate_haptics::LoopSpec), which
            // checks and builds it; here only what is Python's: conversions, the unit checks'
            // warnings, which model class was given. (Over 100 lines for that reason: one
            // conversion per keyword of the signature, in its order; no logic of the loop.)
            for (n, v) in [
                ("tool_radius", tool_radius),
                ("core_contact_stiffness", core_contact_stiffness),
                ("tool_area_stiffness", tool_area_stiffness),
            ] {
                positive(n, v, false)?;
            }
            let kind = kind.map(|k| kind_of(&k)).transpose()?;
            // Values most likely in the wrong unit (palpate_core::runtime::scale): warned, or
            // refused with strict_units; the model's box for the hand target's check.
            let tool_r = tool_radius.unwrap_or(palpate_core::runtime::tool::DEFAULT_RADIUS);
            for w in scale::parameter_warnings(&material.inner, tool_r) {
                errors::unit_check(py, format!("HapticLoop: {w}"), strict_units)?;
            }
            let target_check = errors::TargetCheck::new(
                if let Ok(hm) = model.cast::<PyHybridModel>() {
                    scale::bounding_box(&hm.borrow().model.outer_points)
                } else if let Ok(body) = model.cast::<PyBody>() {
                    scale::bounding_box(body.borrow().model().mesh().points())
                } else {
                    (Vec3::repeat(f64::NEG_INFINITY), Vec3::repeat(f64::INFINITY))
                    // refused below
                },
                strict_units,
            );
            let device_spec = match device.as_str() {
                "scripted" => {
                    let (Some(t), Some(k)) = (times, knots) else {
                        return Err(errors::param_error_from("device 'scripted' needs times=(k,) [s] and knots=(k, 3) [m]"));
                    };
                    let (t, _) = conv::reals_nd(t, "times")?;
                    let k = conv::vec3s(k, "knots", t.len(), true)?;
                    DeviceSpec::Scripted { times: t, knots: k }
                }
                "replay" => {
                    let path = recording.as_ref().ok_or_else(|| errors::param_error_from("device 'replay' needs recording=PATH"))?;
                    DeviceSpec::Replay(Recording::load(path).map_err(record_error)?)
                }
                "hand" => {
                    let at = match hand_start {
                        Some(p) => conv::vec3(p, "hand_start")?,
                        None => return Err(errors::param_error_from("device 'hand' needs hand_start=(3,) [m]")),
                    };
                    target_check.check(py, "HapticLoop: hand_start", &at)?;
                    DeviceSpec::Hand { start: at }
                }
                "bridge" => {
                    let ip: Ipv4Addr = host.parse().map_err(|_| errors::param_error_from(format!("host = {host:?} is not an IPv4 address")))?;
                    let port = port.ok_or_else(|| errors::param_error_from("device 'bridge' needs port=N (0: any free port)"))?;
                    let key = match &bridge_key {
                        Some(k) => Some(Key::new(k.as_bytes()).map_err(|e| errors::param_error_from(format!("bridge_key: {e}")))?),
                        None => None,
                    };
                    DeviceSpec::Bridge { address: SocketAddrV4::new(ip, port), key }
                }
                other => return Err(errors::param_error_from(format!("device = {other:?}: expected scripted, replay, hand or bridge"))),
            };
            let physics = if idle {
                PhysicsSpec::Idle
            } else if let Ok(hm) = model.cast::<PyHybridModel>() {
                let mut options = SimOptions { hold, ..SimOptions::default() };
                if let Some(r) = tool_radius {
                    options.tool.radius = r;
                }
                options.tool.area_stiffness = tool_area_stiffness;
                if let Some(k) = core_contact_stiffness {
                    options.core_contact_stiffness = k;
                }
                PhysicsSpec::Hybrid { model: hm.borrow().model.clone(), material: material.inner, options, threads }
            } else if let Ok(body) = model.cast::<PyBody>() {
                if threads > 1 {
                    return Err(errors::param_error_from(format!(
                        "threads = {threads}: for a hybrid model only (a full-FEM body's tick runs on the servo's thread)"
                    )));
                }
                if core_contact_stiffness.is_some() {
                    return Err(errors::param_error_from("core_contact_stiffness: for a hybrid model only (a full-FEM Body has no core under a shell)"));
                }
                let mut options = FemOptions { area_stiffness: tool_area_stiffness, ..FemOptions::default() };
                if let Some(r) = tool_radius {
                    options.radius = r;
                }
                // The body's model rebuilt with the loop's material (its mesh, fixed nodes,
                // gravity and integrator): the material is the loop's, as for a hybrid model.
                let m = body.borrow();
                let src = m.model();
                let fixed: Vec<usize> = src.fixed().iter().enumerate().filter(|(_, &f)| f).map(|(i, _)| i).collect();
                let builder = ModelBuilder::new(src.mesh().clone(), material.inner)
                    .fixed_nodes(fixed)
                    .gravity(src.gravity())
                    .integrator(src.integrator());
                drop(m);
                PhysicsSpec::Fem { model: py.detach(|| builder.build()).map_err(errors::model_error)?, options }
            } else {
                return Err(errors::type_error(format!("model: expected a HybridModel or a Body, got {}", model.get_type().name()?)));
            };
            let spec = LoopSpec {
                kind,
                rate_hz,
                physics_rate_hz: physics_rate,
                single_rate,
                coupling: CouplingSpec { stiffness: coupling_stiffness, damping: coupling_damping, proxy_mass },
                safety: SafetySpec { max_force, max_rate, ramp, stall_timeout, silence, unsafe_limits },
                record_ticks,
                max_ticks,
                spin,
                realtime,
                ..LoopSpec::new(physics, device_spec)
            };
            let built = py.detach(|| spec.build()).map_err(|e| match e {
                LoopError::Parameter(msg) if msg.contains("unsafe_limits allows it") => {
                    errors::param_error_from(msg.replace("unsafe_limits allows it", "unsafe_limits=True, or --unsafe-limits on the command line, allows it"))
                }
                LoopError::Parameter(msg) => errors::param_error_from(msg),
                LoopError::Model(e) => errors::model_error(e),
                LoopError::Bridge(e @ BridgeError::KeyRequired(_)) => {
                    errors::param_error_from(format!("{e} (bridge_key=..., or --key-file FILE on the command line)"))
                }
                other => haptics_error(other),
            })?;
            if let Some(why) = &built.unsafe_note {
                let msg = std::ffi::CString::new(format!("unsafe limits: {why}")).unwrap_or_default();
                PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &msg, 1)?;
            }
            let BuiltLoop { core, device, config, hand, bridge, identity, replay, replay_check, unsafe_note } = built;
            Ok(PyHapticLoop {
                stage: Mutex::new(Stage::Ready(core, device)),
                config,
                hand,
                bridge,
                identity: (identity.digest, identity.description),
                replay,
                unsafe_note,
                replay_check,
                target_check,
            })
        })
    }

    /// Starts the servo thread. Raises ``HapticsError`` if already started.
    fn start(&self) -> PyResult<()> {
        let mut st = self.stage.lock().unwrap();
        match std::mem::replace(&mut *st, Stage::Taken) {
            Stage::Ready(core, dev) => {
                let h = Servo::start(core, dev, &self.config).map_err(haptics_error)?;
                *st = Stage::Running(h);
                Ok(())
            }
            Stage::Busy(what) => {
                *st = Stage::Busy(what);
                Err(busy(what))
            }
            other => {
                *st = other;
                Err(haptics_error("the loop was already started"))
            }
        }
    }

    /// The latest snapshot (dict: ``tick``, ``time`` [s], ``device``, ``tool`` (3,) [m],
    /// ``force``, ``raw_force``, ``tissue_force`` (3,) [N], ``period_us``, ``compute_us``,
    /// ``physics_ticks`` (the multirate loop's physics ticks so far; else the ticks),
    /// ``overruns``, ``faults``, ``buttons``), or None before the first tick. Never blocks the
    /// loop.
    fn snapshot<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        // The snapshot is copied out and the mutex released before any Python object is made
        // (making one can run Python code, e.g. the garbage collector's, which can hand the GIL
        // to a thread that then waits on the mutex).
        let snap = match &*self.stage.lock().unwrap() {
            Stage::Running(h) => h.snapshot(),
            _ => None,
        };
        snap.map(|s| snapshot_dict(py, &s)).transpose()
    }

    /// The organ's surface (the skin's vertices, (n, 3) [m], world frame; fresh near the tool,
    /// elsewhere at most 32 ticks old) as of the latest surface snapshot, and its tick, or None
    /// before one. Never blocks the loop. Snapshots are taken every 32 ticks while someone reads
    /// them (a read within the last 512 ticks), else every 512: a reader's first read after a
    /// long pause may be up to 512 ticks old, the next ones are fresh (poll, as a viewer does).
    fn surface<'py>(&self, py: Python<'py>) -> Option<(u64, Bound<'py, numpy::PyArray2<f64>>)> {
        let got = match &*self.stage.lock().unwrap() {
            Stage::Running(h) => Some(h.surface()),
            _ => None,
        };
        got.and_then(|(tick, pts)| (tick > 0).then(|| (tick, conv::vec3s_to_py(py, &pts))))
    }

    /// The organ's interior as of the latest surface snapshot: ``(tick, points)``, points
    /// ``(n_core + k, 3)`` [m] (world frame): the core's nodes (all ``n_core``, the model's
    /// ``core_points`` order), then the ``k`` active particles as simulated; or None before one.
    /// Never blocks the loop.
    fn interior<'py>(&self, py: Python<'py>) -> Option<(u64, Bound<'py, numpy::PyArray2<f64>>)> {
        let got = match &*self.stage.lock().unwrap() {
            Stage::Running(h) => Some(h.interior()),
            _ => None,
        };
        got.and_then(|(tick, pts)| (tick > 0).then(|| (tick, conv::vec3s_to_py(py, &pts))))
    }

    /// Has the running loop stopped by itself (device finished or ``max_ticks``)?
    fn finished(&self) -> bool {
        let st = self.stage.lock().unwrap();
        match &*st {
            Stage::Running(h) => h.is_finished(),
            Stage::Done(_) => true,
            _ => false,
        }
    }

    /// Waits (GIL released) until the loop finishes by itself or ``timeout`` [s] passes;
    /// returns whether it finished.
    #[pyo3(signature = (timeout = None))]
    fn wait(&self, py: Python<'_>, #[pyo3(from_py_with = conv::arg)] timeout: Option<f64>) -> PyResult<bool> {
        let t0 = Instant::now();
        loop {
            if self.finished() {
                return Ok(true);
            }
            if timeout.is_some_and(|t| t0.elapsed().as_secs_f64() >= t) {
                return Ok(false);
            }
            py.detach(|| std::thread::sleep(Duration::from_millis(5)));
            py.check_signals()?;
        }
    }

    /// Stops the loop (its last act sends zero force) and returns its report: ``rate_hz``,
    /// ``achieved_hz``, ``ticks``, ``elapsed_s``, ``period_us_p50`` / ``_p99`` / ``_max``,
    /// ``compute_us_p50`` / ``_p99`` / ``_max`` (wall clock), ``cpu_us_p50`` / ``_p99`` / ``_max``
    /// (the servo thread's CPU time over the same compute: without the time the machine kept it
    /// off the CPU), ``overruns``, ``overruns_own`` (those whose CPU time alone passed the period,
    /// and the late ticks right after one: the physics' own), ``overruns_machine`` (the rest: the
    /// thread kept off the CPU, or woken late), ``overrun_times_s`` (wall time since the start of
    /// each logged overrun), ``max_force_n``, ``energy_into_user_j``,
    /// ``bad_inputs``, ``n_faults`` (the ticks whose force a failure zeroed), ``faults`` (the log:
    /// dicts ``tick``, ``time``, ``reason``, ``fault``: True for a counted fault, False for an
    /// event logged only, such as a device silence's fade or a watchdog trip), ``watchdog_trips``, ``recording_dropped_ticks`` (ticks past the recording buffer, not
    /// recorded: nonzero means the recording holds only the run's beginning), ``realtime`` (the
    /// servo's scheduling: ``"off"``, ``"SCHED_FIFO priority 80"`` or ``"refused: ..."``),
    /// ``short_slice`` (an ordinary servo thread was granted Linux's shortest time slice, which
    /// lets it preempt a CPU-bound program when it wakes; kernels before 6.12 refuse it).
    fn stop<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        // Out of the mutex before the GIL is released (see the module).
        let taken = std::mem::replace(&mut *self.stage.lock().unwrap(), Stage::Busy("stopping"));
        let report = match taken {
            Stage::Running(h) => py.detach(|| h.stop()),
            Stage::Done(r) => *r,
            other => {
                let err = match &other {
                    Stage::Busy(what) => busy(what),
                    _ => haptics_error("the loop was not started"),
                };
                *self.stage.lock().unwrap() = other;
                return Err(err);
            }
        };
        let d = report_dict(py, &report);
        *self.stage.lock().unwrap() = Stage::Done(Box::new(report));
        let d = d?;
        d.set_item("unsafe_limits", self.unsafe_note.clone())?;
        self.replay_report(&d)?;
        Ok(d)
    }

    /// Runs the loop without a clock in this thread (GIL released) for at most ``max_ticks``
    /// ticks or until the device ends, before or instead of :meth:`start`; returns ``ticks``,
    /// ``max_force_n``, ``energy_into_user_j``, ``bad_inputs``, ``n_faults``, ``faults``,
    /// ``recording_dropped_ticks``.
    /// Deterministic: a replay gives the recorded forces bit for bit.
    #[pyo3(signature = (max_ticks = None))]
    fn run<'py>(&self, py: Python<'py>, max_ticks: Option<errors::Int>) -> PyResult<Bound<'py, PyDict>> {
        let max_ticks = errors::count_opt(max_ticks, "max_ticks")?.map(|n| n as u64);
        // Out of the mutex before the GIL is released (see the module).
        let taken = std::mem::replace(&mut *self.stage.lock().unwrap(), Stage::Busy("running offline"));
        let (mut core, mut dev) = match taken {
            Stage::Ready(core, dev) => (core, dev),
            other => {
                let err = match &other {
                    Stage::Busy(what) => busy(what),
                    _ => haptics_error("run() is for a loop that was not started"),
                };
                *self.stage.lock().unwrap() = other;
                return Err(err);
            }
        };
        let n = max_ticks.or(self.config.max_ticks).unwrap_or(u64::MAX);
        let (replay, physics_rate) = (self.replay.as_ref(), self.config.physics_rate_hz);
        let ran = errors::guard("HapticLoop.run", || {
            py.detach(|| match (replay, physics_rate) {
                (Some(r), _) => core.replay_multirate(r).map_err(haptics_error),
                (None, Some(hz)) => Ok(core.run_offline_multirate(dev.as_mut(), n, hz)),
                (None, None) => Ok(core.run_offline(dev.as_mut(), n)),
            })
        });
        if let Err(e) = ran {
            // A panic mid-run leaves the core in an unknown state: the loop is not usable again.
            *self.stage.lock().unwrap() = Stage::Taken;
            return Err(e);
        }
        let d = PyDict::new(py);
        let filled = core_dict(py, &core, &d);
        *self.stage.lock().unwrap() = Stage::Ready(core, dev);
        filled?;
        d.set_item("unsafe_limits", self.unsafe_note.clone())?;
        self.replay_report(&d)?;
        Ok(d)
    }

    /// Writes the recording (``record_ticks`` > 0) to ``path``: the device inputs, forces and
    /// tool positions per tick, and the model's identity (format: ``palpate_haptics::record``).
    fn save_recording(&self, #[pyo3(from_py_with = conv::arg)] path: std::path::PathBuf) -> PyResult<usize> {
        let st = self.stage.lock().unwrap();
        let rec = match &*st {
            Stage::Ready(core, _) => core.recording(),
            Stage::Done(r) => r.core.recording(),
            Stage::Running(_) => return Err(haptics_error("stop the loop before saving its recording")),
            Stage::Busy(what) => return Err(busy(what)),
            Stage::Taken => None,
        };
        let rec = rec.ok_or_else(|| haptics_error("nothing recorded: make the loop with record_ticks > 0"))?;
        rec.save(&path).map_err(haptics_error)?;
        Ok(rec.ticks.len())
    }

    /// The recorded forces (n, 3) [N] and tool positions (n, 3) [m] and device positions
    /// (n, 3) [m], and the tissue's force on the tool (n, 3) [N], as a dict of arrays (``force``,
    /// ``tool``, ``device``, ``tissue``).
    fn recorded<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        // The columns are copied out under the mutex, the arrays made after (see `snapshot`).
        let cols = {
            let st = self.stage.lock().unwrap();
            let rec = match &*st {
                Stage::Ready(core, _) => core.recording(),
                Stage::Done(r) => r.core.recording(),
                _ => None,
            };
            let rec = rec.ok_or_else(|| haptics_error("nothing recorded (record_ticks = 0, or the loop is running)"))?;
            let col = |f: &dyn Fn(&palpate_haptics::TickRecord) -> Vec3| rec.ticks.iter().map(f).collect::<Vec<Vec3>>();
            [
                ("force", col(&|t| t.force)),
                ("tool", col(&|t| t.tool)),
                ("device", col(&|t| t.input.position)),
                ("tissue", col(&|t| t.tissue)),
            ]
        };
        let d = PyDict::new(py);
        for (k, v) in cols {
            d.set_item(k, conv::vec3s_to_py(py, &v))?;
        }
        Ok(d)
    }

    /// Moves the simulated hand's target to ``p`` (3,) [m] (device ``"hand"`` only); never
    /// blocks the loop.
    fn set_hand_target(&self, py: Python<'_>, p: &Bound<'_, PyAny>) -> PyResult<()> {
        let v = conv::vec3(p, "p (the hand's target)")?;
        let h = self.hand.as_ref().ok_or_else(|| haptics_error("set_hand_target needs device 'hand'"))?;
        self.target_check.check(py, "HapticLoop.set_hand_target", &v)?;
        h.set(&v);
        Ok(())
    }

    /// The bridge's ``host:port`` (device ``"bridge"``), else None.
    #[getter]
    fn bridge_address(&self) -> Option<String> {
        self.bridge.as_ref().map(|b| b.0.clone())
    }

    /// The bridge's counters (``received``, ``accepted``, ``sent``, ``send_errors``,
    /// ``welcomed`` (hellos answered), ``sessions`` (opened), ``dropped`` and one per reason:
    /// ``short``, ``long``, ``bad_magic``, ``bad_version``, ``old_version``, ``bad_kind``,
    /// ``non_finite``, ``out_of_range``, ``out_of_order``, ``bad_tag``, ``no_session``,
    /// ``wrong_peer``, ``busy``), ``holder`` (the ``host:port`` of the client holding the tool,
    /// or None) and ``old_client`` (the last ``host:port`` that spoke protocol version 1, or
    /// None), else None.
    fn bridge_stats<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        use std::sync::atomic::Ordering::Relaxed;
        let Some((_, s)) = &self.bridge else { return Ok(None) };
        let d = PyDict::new(py);
        d.set_item("received", s.received.load(Relaxed))?;
        d.set_item("accepted", s.accepted.load(Relaxed))?;
        d.set_item("sent", s.sent.load(Relaxed))?;
        d.set_item("send_errors", s.send_errors.load(Relaxed))?;
        d.set_item("welcomed", s.welcomed.load(Relaxed))?;
        d.set_item("sessions", s.sessions.load(Relaxed))?;
        d.set_item("dropped", s.dropped())?;
        for r in Reject::ALL {
            d.set_item(r.name(), s.rejected(r))?;
        }
        d.set_item("holder", s.holder().map(|a| a.to_string()))?;
        d.set_item("old_client", s.old_client().map(|a| a.to_string()))?;
        Ok(Some(d))
    }

    /// The simulation's identity: ``(digest, description)`` (a recording carries it).
    #[getter]
    fn identity(&self) -> (u64, String) {
        self.identity.clone()
    }

    /// The loop's rate [Hz].
    #[getter]
    fn rate_hz(&self) -> f64 {
        self.config.rate_hz
    }

    /// The physics thread's rate [Hz] of a multirate loop, or None (single-rate).
    #[getter]
    fn physics_rate_hz(&self) -> Option<f64> {
        self.config.physics_rate_hz
    }

    fn __repr__(&self) -> String {
        let st = match &*self.stage.lock().unwrap() {
            Stage::Ready(..) => "ready",
            Stage::Running(_) => "running",
            Stage::Done(_) => "stopped",
            Stage::Busy(what) => what,
            Stage::Taken => "failed",
        };
        format!("HapticLoop({} Hz, {st}; {})", self.config.rate_hz, self.identity.1)
    }
}

impl PyHapticLoop {
    /// A single-rate replay's ``replay_diverged_at`` (the first tick whose force differs from the
    /// recording's in any bit, or None) and ``replay_divergence`` (why, from the recording: a
    /// watchdog trip recorded there, or nothing that explains it; None if it did not diverge).
    fn replay_report(&self, d: &Bound<'_, PyDict>) -> PyResult<()> {
        if let Some(c) = &self.replay_check {
            let (at, why) = c.divergence().unzip();
            d.set_item("replay_diverged_at", at)?;
            d.set_item("replay_divergence", why)?;
        }
        Ok(())
    }
}
