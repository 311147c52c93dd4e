"""The haptic loop from Python (issue 13): :class:`palpate.HapticLoop` (a native servo thread over
a hybrid model, see ``crates/palpate-haptics``) and what the ``palpate haptic``, ``palpate soak``
and ``palpate bench haptic`` commands build on it.

Python never runs in the loop: it makes the device's trajectory (a ``palpate touch`` script,
resolved against the model's outer surface: one script format for both commands), starts the
loop, reads snapshots (which never block it) and stops it. Units SI, the model's world frame.
"""
from __future__ import annotations

import math
import os
import platform
import time
from datetime import datetime, timezone
from typing import Any, Callable, Dict, Optional, Tuple

import numpy as np

from . import _palpate as _p
from . import defaults as _defaults
from .devices import canonical as device_kind  # former device names (``touch``) to today's

#: The material of ``palpate haptic``, the haptic benchmark and the soak [Pa, -, kg/m^3, Pa s]:
#: the default tissue (:data:`palpate.defaults.tissue`) with the paper's damping.
YOUNG, POISSON, DENSITY = _defaults.tissue.young, _defaults.tissue.poisson, _defaults.tissue.density
PHI, PSI = 1.0, 1.0
#: The scripted palpation of the benchmark: press depth [m], slide [m], one cycle's length [s].
PRESS_DEPTH, PRESS_SLIDE, CYCLE_S = 0.004, 0.006, 2.0
#: JSON keys of ``palpate bench haptic`` (at least these).
BENCH_KEYS = ("rate_hz", "ticks", "period_us_p50", "period_us_p99", "period_us_max", "compute_us_p99",
              "overruns", "max_force_n")


def material() -> "_p.Material":
    return _p.Material(young=YOUNG, poisson=POISSON, density=DENSITY, phi=PHI, psi=PSI)


def script_trajectory(model: "_p.HybridModel", script_path: str, tool_radius: float = 0.005) -> Tuple[np.ndarray, np.ndarray]:
    """``(times (k,) [s], knots (k, 3) [m])`` of a ``palpate touch`` script (TOML segments or CSV,
    :mod:`palpate.touch`) resolved on ``model``'s outer surface for a tool of ``tool_radius`` [m].
    Raises :class:`palpate.touch.ScriptError` for a bad script."""
    from .touch import parse_script

    traj = parse_script(script_path).resolve(np.asarray(model.outer_points), np.asarray(model.outer_triangles), tool_radius)
    return np.asarray(traj.times, dtype=np.float64), np.asarray(traj.knots, dtype=np.float64)


def palpation_cycle(model: "_p.HybridModel", tool_radius: float = 0.005, depth: float = PRESS_DEPTH,
                    slide: float = PRESS_SLIDE, gap: float = 0.002) -> Tuple[np.ndarray, np.ndarray]:
    """One scripted palpation at the probe point (:func:`palpate.touch.probe_point`): from ``gap``
    [m] clear, a press to ``depth`` [m] in 0.5 s, a 0.2 s hold, a ``slide`` [m] along the surface
    in 0.6 s, a release in 0.5 s and 0.2 s clear: ``(times (k,) [s], knots (k, 3) [m])``."""
    from .touch import probe_point, vertex_normals

    s, tris = np.asarray(model.outer_points), np.asarray(model.outer_triangles)
    v = probe_point(s, tris)
    n = vertex_normals(s, tris)[v]
    tangent = np.cross(n, [0.0, 0.0, 1.0])
    if np.linalg.norm(tangent) < 1e-9:
        tangent = np.cross(n, [1.0, 0.0, 0.0])
    tangent /= np.linalg.norm(tangent)
    c = lambda d, sl: s[v] + n * (tool_radius - d) + tangent * sl  # noqa: E731
    times = np.array([0.0, 0.5, 0.7, 1.3, 1.8, 2.0])
    knots = np.array([c(-gap, 0), c(depth, 0), c(depth, 0), c(depth, slide), c(-gap, slide), c(-gap, 0)])
    return times, knots


def repeat(times: np.ndarray, knots: np.ndarray, seconds: float) -> Tuple[np.ndarray, np.ndarray]:
    """The trajectory repeated back to back until it lasts at least ``seconds`` [s] (it must end
    where it starts)."""
    d = float(times[-1] - times[0])
    n = max(1, int(math.ceil(seconds / d)))
    t = np.concatenate([times[:-1] + k * d for k in range(n)] + [[times[-1] + (n - 1) * d]])
    k = np.concatenate([knots[:-1]] * n + [knots[-1:]])
    return t - t[0], k


def random_palpation(model: "_p.HybridModel", seconds: float, seed: int = 0, tool_radius: float = 0.005,
                     clear: float = 0.010) -> Tuple[np.ndarray, np.ndarray]:
    """A random scripted palpation lasting ``seconds`` [s]: presses at random outer vertices in
    the upper 60 % of the model's height (above the held base) facing sideways, each from
    ``clear`` [m] out along the normal: approach in 0.3 s, press 2-6 mm in 0.3-0.8 s, hold
    0-0.3 s, slide 0-8 mm in 0.4 s, release in 0.3 s; ``(times, knots)`` [s], [m]."""
    from .touch import vertex_normals

    rng = np.random.default_rng(seed)
    s, tris = np.asarray(model.outer_points), np.asarray(model.outer_triangles)
    normals = vertex_normals(s, tris)
    z = s[:, 2]
    ok = (z > z.min() + 0.4 * (z.max() - z.min())) & (np.abs(normals[:, 2]) < 0.7)
    ok[np.setdiff1d(np.arange(len(s)), np.unique(tris))] = False
    cand = np.flatnonzero(ok)
    if len(cand) == 0:
        raise _p.ParameterError("no outer vertex suits a palpation (upper 60 %, facing sideways)")
    times, knots = [0.0], []
    t = 0.0

    def add(dt: float, p: np.ndarray) -> None:
        nonlocal t
        t += dt
        times.append(t)
        knots.append(p)

    first = True
    while t < seconds:
        v = int(rng.choice(cand))
        n = normals[v]
        tan = np.cross(n, rng.normal(size=3))
        tan /= np.linalg.norm(tan)
        depth = rng.uniform(0.002, 0.006)
        slide = rng.uniform(0.0, 0.008)
        out = s[v] + n * (tool_radius + clear)
        at = lambda d, sl: s[v] + n * (tool_radius - d) + tan * sl  # noqa: E731
        if first:
            knots.append(out)
            first = False
        else:
            add(0.3, out)
        add(0.3, at(-0.001, 0.0))
        add(rng.uniform(0.3, 0.8), at(depth, 0.0))
        add(max(1e-3, rng.uniform(0.0, 0.3)), at(depth, 0.0))
        add(0.4, at(depth, slide))
        add(0.3, s[v] + n * (tool_radius + clear) + tan * slide)
    return np.asarray(times), np.asarray(knots)


def status_line(s: Optional[Dict[str, Any]], rate_hz: float) -> str:
    """One line of a running loop's snapshot: time, rate, period, compute, force, overruns."""
    if s is None:
        return "waiting for the first tick"
    hz = 1e6 / s["period_us"] if s["period_us"] > 0 else float("nan")
    f = float(np.linalg.norm(s["force"]))
    return (f"t {s['time']:8.3f} s | {hz:7.1f} Hz (of {rate_hz:g}) | period {s['period_us']:7.1f} us | compute "
            f"{s['compute_us']:7.1f} us | force {f:6.3f} N | overruns {s['overruns']} | faults {s['faults']}")


#: The device makes :class:`palpate.HapticLoop` knows (its ``kind``): each sets the coupling's and
#: the safety's defaults and the limits a user may ask without ``unsafe_limits``. ``geomagic`` is the
#: 3D Systems / Geomagic Touch (formerly ``touch``, still accepted: ``device_kind``,
#: the adapters' :data:`palpate.devices.ALIASES`).
DEVICE_KINDS = ("simulated", "bridge", "geomagic", "forcedimension", "haply", "hapticmaster")


def loop_rates(physics_rate: Optional[float]) -> Dict[str, Any]:
    """The :class:`palpate.HapticLoop` keywords for a physics rate [Hz], None meaning the
    single-rate loop (the commands' ``--single-rate``): ``physics_rate`` and ``single_rate``."""
    return {"physics_rate": physics_rate, "single_rate": physics_rate is None}


def bridge_events(stats: Optional[Dict[str, Any]], seen: Dict[str, Any]) -> list:
    """What changed at the bridge since ``seen`` (updated in place), as log lines: who holds the
    tool (each new session), protocol-1 clients refused, hellos refused while busy, packets with a
    bad tag and packets from outside the session (``HapticLoop.bridge_stats``)."""
    if stats is None:
        return []
    lines = []
    if stats["sessions"] != seen.get("sessions", 0) and stats["holder"]:
        lines.append(f"bridge: {stats['holder']} holds the tool (session {stats['sessions']})")
    if stats["old_version"] and stats["old_client"] != seen.get("old_client"):
        lines.append(f"bridge: a protocol-1 client at {stats['old_client']} was refused: update it to protocol "
                     "version 2 (palpate device, or crates/palpate-haptics/PROTOCOL.md)")
    for key, what in (("busy", "hellos refused while another client holds the tool"),
                      ("bad_tag", "packets dropped for a tag that does not verify with the key"),
                      ("no_session", "state packets dropped for naming no open session"),
                      ("wrong_peer", "state packets dropped for coming from another address than the session's")):
        if stats[key] > seen.get(key, 0):
            lines.append(f"bridge: {stats[key]} {what}")
    seen.update({k: stats[k] for k in ("sessions", "old_client", "busy", "bad_tag", "no_session", "wrong_peer")})
    return lines


def run_live(loop: "_p.HapticLoop", seconds: Optional[float], on_status: Optional[Callable[[str], None]] = None,
             every: float = 0.2, on_event: Optional[Callable[[str], None]] = None,
             until: Optional[Callable[[], bool]] = None) -> Dict[str, Any]:
    """Starts ``loop``, calls ``on_status(line)`` every ``every`` [s] until it finishes,
    ``seconds`` [s] pass or ``until()`` is true (checked as often), stops it and returns its
    report (:meth:`palpate.HapticLoop.stop`).
    ``on_event(line)`` gets the bridge's events (:func:`bridge_events`) as they happen. Ctrl-C
    (``KeyboardInterrupt``) stops the loop the same way: the report then has ``interrupted``
    True (a session is often ended so; its summary and recording are still wanted)."""
    loop.start()
    t0 = time.monotonic()
    seen: Dict[str, Any] = {}
    interrupted = False
    try:
        while True:
            done = loop.wait(every)
            if on_event is not None:
                for line in bridge_events(loop.bridge_stats(), seen):
                    on_event(line)
            if on_status is not None:
                on_status(status_line(loop.snapshot(), loop.rate_hz))
            if done or (seconds is not None and time.monotonic() - t0 >= seconds) or (until is not None and until()):
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        report = loop.stop()
    report["interrupted"] = interrupted
    return report


def steal_seconds() -> Optional[float]:
    """The machine's steal time so far [s] (all CPUs, ``/proc/stat``), or None off Linux."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK") if fields[0] == "cpu" and len(fields) > 8 else None
    except (OSError, ValueError, IndexError):
        return None


def per_second(times_s, elapsed_s: float) -> list:
    """Counts of events per whole second of wall time since the start (``times_s`` [s])."""
    n = max(1, int(math.ceil(elapsed_s)))
    return np.bincount(np.minimum(np.asarray(times_s, dtype=np.float64).astype(np.int64), n - 1), minlength=n).tolist() \
        if len(times_s) else [0] * n


#: The ``spin`` [s] of :class:`palpate.HapticLoop` that never sleeps: longer than any period
#: (``spin`` takes 0 to 1 s), its default without ``realtime``. The servo then keeps a core busy,
#: its compute tail is shorter and it overruns less (on the Rodero palpation at 1 kHz, 2026-11-27:
#: compute p99 ~700-750 us against ~900 us, 5-50 overruns a minute against 38-234;
#: docs/history/benchmarks-log.md#2026-11-27-tenth-session-the-checkpoint-after-the-send-a-first-tick-without-the-whole-skin-the-busy-servo-by-default).
BUSY_SPIN = 1.0

#: The ``spin`` [s] of a servo that sleeps through each wait but its last 200 us (``palpate haptic
#: --sleep``): the core is left to other work between ticks.
SLEEP_SPIN = 200e-6


def bench(model: "_p.HybridModel", seconds: float, rate_hz: float = 1000.0, idle: bool = True,
          name: str = "", on_status: Optional[Callable[[str], None]] = None, realtime: bool = False,
          threads: int = 1, busy_wait: Optional[bool] = None, physics_rate: Optional[float] = None) -> Dict[str, Any]:
    """``palpate bench haptic``: the loop at ``rate_hz`` on ``model`` for ``seconds`` [s] with a
    repeated scripted palpation (:func:`palpation_cycle`), then (``idle``) the idle loop (no
    simulation, same device, same length) on the same clock. Returns the loop's report
    (:data:`BENCH_KEYS` and more; ``overruns_per_s``: the overruns in each second of wall time,
    from the first 100,000 logged; ``overruns_own`` / ``overruns_machine``: the overruns whose
    compute alone passed the period on the CPU, and the rest, see :meth:`palpate.HapticLoop.stop`;
    ``steal_s``: the hypervisor's steal time over the run, all CPUs), with ``idle`` the idle run's and the machine's description;
    ``realtime``: both loops' servo under ``SCHED_FIFO`` (see :class:`palpate.HapticLoop`; the
    report's ``realtime`` says whether it was granted); ``threads``: the loop's particle passes on
    that many threads (:class:`palpate.HapticLoop`; the idle loop has no physics to split);
    ``busy_wait``: both loops' servo spins through each whole period (:data:`BUSY_SPIN`) or, False,
    sleeps through each wait but its last 200 us (:data:`SLEEP_SPIN`); None: :class:`palpate.HapticLoop`'s
    default, busy unless ``realtime`` (the report's ``busy_wait`` says which ran); ``physics_rate``
    [Hz]: the multirate loop, None the single-rate one (:class:`palpate.HapticLoop`; the report's ``physics`` holds the
    physics thread's figures). ``max_force_step_n``: the largest change of the sent force in one
    servo period [N], from the run's recording, and ``max_force_step_contact_n`` the same over the
    periods in contact (the tissue's force nonzero at either end)."""
    t, k = repeat(*palpation_cycle(model), seconds + 1.0)
    mat = material()
    spin = None if busy_wait is None else BUSY_SPIN if busy_wait else SLEEP_SPIN
    # HapticLoop's default: busy unless real-time or multirate (whose servo sleeps: the physics
    # thread needs the core).
    busy_wait = (not realtime and physics_rate is None) if busy_wait is None else busy_wait
    ticks = int(round(seconds * rate_hz))
    loop = _p.HapticLoop(model, mat, "scripted", times=t, knots=k, rate_hz=rate_hz, max_ticks=ticks,
                         realtime=realtime, threads=threads, spin=spin, record_ticks=ticks, **loop_rates(physics_rate))
    steal0 = steal_seconds()
    r = run_live(loop, None, on_status)
    steal1 = steal_seconds()
    # The hypervisor's share: time this VM's CPUs were ready but ran another guest (None where
    # /proc/stat is not there). The servo cannot see it as time off the CPU.
    r["steal_s"] = None if steal0 is None or steal1 is None else steal1 - steal0
    r["threads"] = threads
    r["busy_wait"] = busy_wait
    rec = loop.recorded()
    step = np.linalg.norm(np.diff(rec["force"], axis=0), axis=1)
    touching = np.linalg.norm(rec["tissue"], axis=1) > 0
    r["max_force_step_n"] = float(step.max()) if len(step) else 0.0
    # In contact (the tissue pushing the tool at either end of the period): the hand's palpation,
    # without the free-space coupling damper's steps at the script's corners.
    both = touching[1:] | touching[:-1]
    r["max_force_step_contact_n"] = float(step[both].max()) if both.any() else 0.0
    r["model"] = name
    r["seconds"] = seconds
    r["overruns_per_s"] = per_second(r.pop("overrun_times_s"), r["elapsed_s"])
    if idle:
        il = _p.HapticLoop(model, mat, "scripted", times=t, knots=k, rate_hz=rate_hz, idle=True,
                           max_ticks=int(round(seconds * rate_hz)), realtime=realtime, spin=spin)
        ir = run_live(il, None, None)
        r["idle"] = {key: ir[key] for key in ("ticks", "achieved_hz", "elapsed_s", "period_us_p50", "period_us_p99",
                                              "period_us_max", "compute_us_p99", "cpu_us_p99", "overruns",
                                              "overruns_own", "overruns_machine", "realtime",
                                              "short_slice")}
        r["idle"]["overruns_per_s"] = per_second(ir["overrun_times_s"], ir["elapsed_s"])
    r["cpu_count"] = os.cpu_count()
    r["machine"] = platform.processor() or platform.machine()
    r["load_avg"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    r["date"] = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return r
