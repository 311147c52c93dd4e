"""``palpate bench hybrid``: the cost of one 1 ms haptic tick of the hybrid simulation
(:class:`palpate.HybridSim`) at a chosen number of active particles (issue 12).

The case. A built hybrid model (a model file, or a shape of :func:`palpate.build_shape`), the
default tissue (:data:`palpate.defaults.tissue`: E = 30 kPa, nu = 0.4, 1060 kg/m^3; 1000 kg/m^3
until 2026-12-07) with the paper's damping (0.5, 0.5), i.e. ``phi = psi = 1.0`` Pa s in palpate's
convention, the material of ``palpate haptic`` too, the core held (``hold=True``), the default
tool stiffness, activation margin (1 mm), linger (100 ticks) and tool
speed cap (0.5 mm a tick). One thread (the core spawns none).

The probe point (:func:`probe`): :func:`palpate.probe.probe_frame`, the library's one definition.
The outer (skin) vertex nearest ``(x_max, y_mid, z_min + 20/42 (z_max - z_min))`` of the outer
surface's bounding box: on the synthetic ``ventricle`` the outer vertex nearest (x_max, 0, 20 mm),
the issue's probe point, as ``tests/test_hybrid_sim.py`` and ``bench/hybrid_hand.py`` choose it;
on the ellipsoids the +x side just below the equator; on the Rodero ventricle or a model file its
+x side, in the frame of its file. The press direction is the inward surface normal there
(area-weighted normal of the outer triangles at the vertex, turned away from the outer surface's
centroid); the slide runs along ``normal x z``, horizontally.

The script (:func:`script`), ``ticks`` ticks of 1 ms: the sphere starts touching the skin at the
probe point (depth 0) and is pressed to :data:`DEPTH` (3 mm) over 25 % of the ticks, held 10 %,
slid :data:`SLIDE` (10 mm) along the surface's tangent over 50 % and lifted back to depth 0
over the last 15 % (2,000 ticks: the BENCHMARKS.md hybrid script's 0.5 / 0.2 / 1.0 / 0.3 s but
starting at the skin rather than 2 mm off it).

Calibration (:func:`calibrate`). The activation is the tool's reach (radius + margin), so the
tool radius sets the active count. ``count(R)``: a fresh ``HybridSim`` with tool radius ``R``,
pressed to :data:`DEPTH` at the probe point over :data:`CAL_PRESS_TICKS` ticks and held
:data:`CAL_HOLD_TICKS`, the most particles active (``sim.last["active"]``) over those ticks (the
count grows with depth: this is the count at the held press). ``R`` is bisected in log space
over :data:`RADIUS_RANGE` for :data:`CAL_EVALUATIONS` evaluations at most (fewer once a count
lies within :data:`CAL_TOLERANCE` of the target); the radius whose count is nearest the target
is taken (the smaller on a tie). The count is a step function of ``R``: a region (one per outer
vertex) brings its whole patch of particles (``model.info()["region_particles_*"]``; 141 for the
one region the smallest sphere touches on the synthetic ventricle), so a target below one patch,
or between two steps, is missed by up to a patch; ``active_particles_calibrated`` says what was
reached. The timed run's counts differ from it: its press is slower than the calibration's (the
skin has time to move with the tool), its ramp starts with fewer, and its slide adds the regions
it reaches while those behind linger (a short script's fast slide leaves a longer trail). On the
synthetic ventricle, 2,000 ticks: target 200 -> calibrated 201 (R = 1.65 mm), run mean 192,
max 326; target 600 -> calibrated 616 (R = 3.16 mm), run mean 409, max 584.

Small spheres: below about the skin's edge length (~1.7 mm on the synthetic ventricle) the
sphere can slip between skin vertices and particles; the run then measures the tick's cost at
that active count with little or no contact force (``max_force_n`` says so).

Timing: ``time.perf_counter`` around each tick's two calls only (the binding's conversion of
the tool position and the force included: a few microseconds): ``sim.step(c, finish=False)``,
which ends once the force is known, then ``sim.finish()``, the rest of the tick (the skin's
update, and the core's step when the tool has nothing of the core within reach), as a haptic
servo sends the force in between. ``tick_ms_*``: both calls, the whole tick (the issue's
targets); ``force_ms_*``: the first alone, the time from a device's position to its force.
``stable``: every tick returned a finite force, raised no ``StepError``, and the skin is finite
at the end.
"""
from __future__ import annotations

import datetime
import math
import os
import platform
import re
import time
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from .. import _palpate as _p
from .. import defaults as _defaults
# The model's name or file resolved in the library, kept importable from here (palpate.bench.hybrid.load_model).
from ..hybrid import load_model  # noqa: F401
from ..probe import probe_frame

E = _defaults.tissue.young     # [Pa]
NU = _defaults.tissue.poisson
RHO = _defaults.tissue.density  # [kg/m^3]
PHI = PSI = 1.0                # [Pa s]: the paper's (0.5, 0.5) (palpate stores them doubled)
DT = 1e-3                      # one haptic tick [s]
DEPTH = 3e-3                   # press depth [m]
SLIDE = 10e-3                  # slide length [m]
TICKS = 2000                   # default script length
MIN_TICKS = 40                 # the slide then moves 0.5 mm a tick, the runtime's speed cap
PHASES = (("press", 0.25), ("hold", 0.10), ("slide", 0.50), ("release", 0.15))
RADIUS_RANGE = (5e-4, 2e-2)    # [m], calibration bounds of the tool radius
CAL_PRESS_TICKS = 10
CAL_HOLD_TICKS = 5
CAL_EVALUATIONS = 8
CAL_TOLERANCE = 0.05           # stop the search once |count - target| <= 5 % of the target


def material() -> "_p.Material":
    return _p.Material(young=E, poisson=NU, density=RHO, phi=PHI, psi=PSI)


def probe(model: "_p.HybridModel", name: str = "") -> Tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """``(vertex, point, inward normal, slide direction)`` of the probe: the press frame of
    :func:`palpate.probe.probe_frame` (the vertex of :func:`palpate.probe.probe_point`, the
    protocol's probe on the synthetic ventricle; its area-weighted normal, turned inward; the
    horizontal tangent there). ``name`` is accepted for compatibility and not used."""
    v, point, normal, tangent = probe_frame(model.outer_points, model.outer_triangles)
    return v, point, -normal, tangent


def script(ticks: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per tick: the tool's depth [m] below the skin, its slide [m] along the tangent, and the
    phase index into :data:`PHASES`."""
    if ticks < MIN_TICKS:
        raise _p.ParameterError(f"ticks must be at least {MIN_TICKS}, got {ticks}")
    counts = [max(1, int(round(f * ticks))) for _, f in PHASES[:-1]]
    counts.append(ticks - sum(counts))
    depth, slide, phase = [], [], []
    for ph, n in enumerate(counts):
        for k in range(n):
            u = (k + 1) / n
            d, s = [(DEPTH * u, 0.0), (DEPTH, 0.0), (DEPTH, SLIDE * u), (DEPTH * (1 - u), SLIDE)][ph]
            depth.append(d)
            slide.append(s)
            phase.append(ph)
    return np.array(depth), np.array(slide), np.array(phase)


def active_at_press(model, mat, radius: float, p, n_in, ticks: Tuple[int, int] = (CAL_PRESS_TICKS, CAL_HOLD_TICKS)) -> int:
    """The most particles active over a quick press to :data:`DEPTH` with tool radius ``radius``
    (a fresh simulation; a failed tick ends the press with the count so far)."""
    sim = _p.HybridSim(model, mat, tool_radius=radius)
    press, hold = ticks
    most = 0
    for k in range(press + hold):
        d = DEPTH * min(1.0, (k + 1) / press)
        try:
            sim.step(p + n_in * (d - radius), DT)
        except _p.StepError:
            break
        most = max(most, int(sim.last["active"]))
    return most


def calibrate(model, mat, target: int, p, n_in, evaluations: int = CAL_EVALUATIONS,
              bounds: Tuple[float, float] = RADIUS_RANGE) -> Tuple[float, int, List[Tuple[float, int]]]:
    """The tool radius [m] whose held-press active count is nearest ``target``, that count, and
    every ``(radius, count)`` tried (see the module docs)."""
    lo, hi = math.log(bounds[0]), math.log(bounds[1])
    tried: List[Tuple[float, int]] = []
    for _ in range(evaluations):
        r = math.exp(0.5 * (lo + hi))
        c = active_at_press(model, mat, r, p, n_in)
        tried.append((r, c))
        if abs(c - target) <= CAL_TOLERANCE * target:
            break
        if c < target:
            lo = math.log(r)
        else:
            hi = math.log(r)
    r, c = min(tried, key=lambda rc: (abs(rc[1] - target), rc[0]))
    return r, c, tried


def machine() -> Dict[str, Any]:
    """CPU count and model, Python and palpate versions, platform, date (UTC)."""
    model = None
    try:
        with open("/proc/cpuinfo") as fh:
            m = re.search(r"^model name\s*:\s*(.+)$", fh.read(), re.M)
            model = m.group(1).strip() if m else None
    except OSError:
        pass
    return {"cpu_count": os.cpu_count(), "cpu_model": model or platform.processor() or None,
            "python_version": platform.python_version(), "palpate_version": _p.__version__,
            "platform": platform.platform(),
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def _stats_ms(times: List[float], what: str = "tick") -> Dict[str, Optional[float]]:
    keys = [f"{what}_ms_{s}" for s in ("mean", "p50", "p99", "max")] + (["ticks_per_s"] if what == "tick" else [])
    if not times:
        return {k: None for k in keys}
    t = np.asarray(times) * 1e3
    mean = float(t.mean())
    out = {keys[0]: mean, keys[1]: float(np.percentile(t, 50)), keys[2]: float(np.percentile(t, 99)),
           keys[3]: float(t.max())}
    if what == "tick":
        out["ticks_per_s"] = 1e3 / mean if mean > 0 else None
    return out


def run(model_spec, active: int, ticks: int = TICKS, *, radius: Optional[float] = None,
        name: Optional[str] = None, mass_scaling: Optional[float] = None,
        tool_area_stiffness: Optional[float] = None, implicit_exchange: bool = True) -> Dict[str, Any]:
    """Calibrate the tool radius for about ``active`` particles (unless ``radius`` [m] is given),
    then time the scripted press and slide; returns the report (see ``palpate bench hybrid
    --help`` and the module docs). ``model_spec``: a shape name, a model file path or a
    :class:`palpate.HybridModel` (named ``name``); ``mass_scaling``: the shell's mass-scaling
    quantile (``HybridSim``'s default if ``None``; 1.0 scales nothing); ``tool_area_stiffness``:
    the contact's penalty per unit of skin area [N/m^3] (``HybridSim``'s default, ``12 E*/min(R, 4h)``,
    if ``None``); ``implicit_exchange``: ``HybridSim``'s option (False: the shell's springs
    capped, for comparison; the calibration runs with the default either way, so both time the
    same tool). Raises :class:`palpate.ParameterError` (a ``ValueError``) for bad arguments."""
    if isinstance(active, bool) or not isinstance(active, (int, np.integer)) or active <= 0:
        raise _p.ParameterError(f"active must be a positive number of particles, got {active}")
    if radius is not None and not (radius > 0 and math.isfinite(radius)):
        raise _p.ParameterError(f"radius must be positive and finite, got {radius}")
    depth, slide, phase = script(ticks)
    if isinstance(model_spec, _p.HybridModel):
        name, model = name or "model", model_spec
    else:
        name, model = load_model(str(model_spec))
    info = model.info()
    if active > info["particles"]:
        raise _p.ParameterError(f"active = {active} exceeds the model's {info['particles']} particles")
    mat = material()
    v, p, n_in, tangent = probe(model, name)

    t0 = time.perf_counter()
    if radius is None:
        radius, calibrated, tried = calibrate(model, mat, int(active), p, n_in)
    else:
        calibrated, tried = active_at_press(model, mat, radius, p, n_in), []
        tried = [(radius, calibrated)]
    cal_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    sim = _p.HybridSim(model, mat, tool_radius=radius, mass_scaling=mass_scaling, tool_area_stiffness=tool_area_stiffness,
                       implicit_exchange=implicit_exchange)
    setup_s = time.perf_counter() - t0
    times: List[float] = []
    to_force: List[float] = []
    act: List[int] = []
    subs: List[int] = []
    fmax = 0.0
    error = failed_tick = None
    perf = time.perf_counter
    for k in range(ticks):
        c = p + n_in * (depth[k] - radius) + tangent * slide[k]
        try:
            t1 = perf()
            f = sim.step(c, DT, finish=False)
            t2 = perf()
            sim.finish()
            t3 = perf()
        except _p.StepError as e:
            error, failed_tick = f"StepError: {e}", k
            break
        times.append(t3 - t1)
        to_force.append(t2 - t1)
        if not np.all(np.isfinite(f)):
            error, failed_tick = f"non-finite force {f.tolist()} N", k
            break
        fmax = max(fmax, float(np.linalg.norm(f)))
        act.append(int(sim.last["active"]))
        subs.append(int(sim.last["substeps"]))
    if error is None and not np.all(np.isfinite(sim.surface)):
        error, failed_tick = "non-finite skin after the script", ticks - 1

    r: Dict[str, Any] = {
        "model": name, "core_tets": info["core_tets"], "particles": info["particles"], "regions": info["regions"],
        "active_target": int(active), "tool_radius_m": radius, "activation_margin_m": sim.options["activation_margin"],
        "tool_area_stiffness": sim.options["tool_area_stiffness"],
        "implicit_exchange": sim.options["implicit_exchange"], "coupling_stiffness": sim.options["coupling_stiffness"],
        "active_particles_calibrated": calibrated,
        "active_particles_mean": float(np.mean(act)) if act else None,
        "active_particles_max": max(act) if act else None,
        "ticks": len(times), "ticks_planned": ticks, "dt_s": DT,
    }
    r.update(_stats_ms(times))
    r.update(_stats_ms(to_force, "force"))
    r.update({
        "stable": error is None, "error": error, "failed_tick": failed_tick,
        "failed_phase": None if failed_tick is None else PHASES[int(phase[failed_tick])][0],
        "max_force_n": fmax,
        "substeps_mean": float(np.mean([k for k in subs if k > 0])) if any(subs) else None,
        "mass_scaling": sim.options["mass_scaling"], "mass_scaling_applied": sim.options["mass_scaling_applied"],
        "added_mass_fraction": sim.options["added_mass_fraction"],
        "probe_vertex": v, "probe_point_m": p.tolist(), "press_direction": n_in.tolist(),
        "slide_direction": tangent.tolist(), "depth_m": DEPTH, "slide_m": SLIDE,
        "calibration": [[rr, cc] for rr, cc in tried], "calibration_s": cal_s, "setup_s": setup_s,
        "threads": 1,
    })
    r.update(machine())
    return r
