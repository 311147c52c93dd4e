"""The haptic loop from Python (issue 13): :class:`palpate.HapticLoop` (a native servo thread over
a hybrid model, see ``crates/palpate-haptics``) and what the ``palpate haptic``, ``palpate soak``
and ``palpate bench haptic`` commands build on it (the benchmark itself: :mod:`palpate.bench.haptic`).

Python never runs in the loop: it makes the device's trajectory (a ``palpate touch`` script,
resolved against the model's outer surface: one script format for both commands), starts the
loop, reads snapshots (which never block it) and stops it. Units SI, the model's world frame.
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable, Dict, Optional, Tuple

import numpy as np

from . import _palpate as _p
from . import defaults as _defaults
from .devices import canonical as device_kind  # former device names (``touch``) to today's
from .probe import probe_frame, vertex_normals

#: The material of ``palpate haptic``, the haptic benchmark and the soak [Pa, -, kg/m^3, Pa s]:
#: the default tissue (:data:`palpate.defaults.tissue`) with the paper's damping.
YOUNG, POISSON, DENSITY = _defaults.tissue.young, _defaults.tissue.poisson, _defaults.tissue.density
PHI, PSI = 1.0, 1.0
#: The scripted palpation of the benchmark: press depth [m], slide [m], one cycle's length [s].
PRESS_DEPTH, PRESS_SLIDE, CYCLE_S = 0.004, 0.006, 2.0


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
    """One scripted palpation at the probe point (:func:`palpate.probe.probe_frame`): from ``gap``
    [m] clear, a press to ``depth`` [m] in 0.5 s, a 0.2 s hold, a ``slide`` [m] along the surface
    in 0.6 s, a release in 0.5 s and 0.2 s clear: ``(times (k,) [s], knots (k, 3) [m])``."""
    _, p, n, tangent = probe_frame(model.outer_points, model.outer_triangles)
    c = lambda d, sl: p + n * (tool_radius - d) + tangent * sl  # noqa: E731
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


#: The ``spin`` [s] of :class:`palpate.HapticLoop` that never sleeps: longer than any period
#: (``spin`` takes 0 to 1 s), its default without ``realtime``. The servo then keeps a core busy,
#: its compute tail is shorter and it overruns less (on the Rodero palpation at 1 kHz, 2026-11-27:
#: compute p99 ~700-750 us against ~900 us, 5-50 overruns a minute against 38-234;
#: docs/history/benchmarks-log.md#2026-11-27-tenth-session-the-checkpoint-after-the-send-a-first-tick-without-the-whole-skin-the-busy-servo-by-default).
BUSY_SPIN = 1.0

#: The ``spin`` [s] of a servo that sleeps through each wait but its last 200 us (``palpate haptic
#: --sleep``): the core is left to other work between ticks.
SLEEP_SPIN = 200e-6


#: The haptic benchmark's names, moved to :mod:`palpate.bench.haptic` (issue 36) and kept here for
#: old imports (``palpate.haptics.bench``); resolved on first use, as that module imports this one.
_MOVED_TO_BENCH = ("bench", "BENCH_KEYS", "steal_seconds", "per_second")


def __getattr__(name: str) -> Any:
    if name in _MOVED_TO_BENCH:
        from .bench import haptic

        return getattr(haptic, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
