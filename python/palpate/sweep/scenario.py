"""One scenario of a study, as a worker runs it: the model (sent to each worker once), the
scenario's parameters in, one row of the table out. :func:`run_scenario` never raises: a scenario
that fails (bad parameters, a diverged or failed step, anything else) is a row with ``status``
``"failed"`` and its ``error``, so that one bad corner of a study never stops the rest.

Row columns (SI units): ``scenario``, the parameters, ``status`` (``"ok"`` | ``"unstable"`` |
``"failed"``), ``error``, ``stable``, ``max_force_n``, ``final_depth_m``, ``max_disp_m``,
``strain_energy_j`` and ``kinetic_energy_j`` (probe: at the end), ``iterations_mean`` and
``iterations_max`` (probe: the core's nonlinear iterations a step; press: the shell's sub-steps a
tick), ``steps_done``, ``wall_s`` (stepping only: the one column that differs between two runs of the
same study) and, with ``outputs.curve``, ``curve_time_s``, ``curve_force_n`` and
``curve_depth_m`` (lists, one entry a step; probe: the ramped force and the loaded nodes' mean
displacement magnitude; press: the tool's normal force and its depth past first contact).
"""
from __future__ import annotations

import math
import os
import time
import traceback
from dataclasses import dataclass
from typing import Any, Dict, Optional

import numpy as np

from .. import _palpate as _p

#: Fault injection for the tests (a worker lost mid-task): if set to a path that does not exist
#: yet, the first scenario 0 to run creates it and kills its own process.
CRASH_ONCE_ENV = "PALPATE_SWEEP_CRASH_ONCE"


@dataclass
class Payload:
    """What every scenario of a study shares, sent to each worker once: the FEM mesh (probe
    loading; points in mesh units, as the protocol's meshes are given) or the hybrid model
    (press loading)."""
    kind: str
    name: str
    mesh: Optional[Any] = None          # palpate.TetMesh [m]
    points_mu: Optional[np.ndarray] = None
    tets: Optional[np.ndarray] = None
    hybrid: Optional[Any] = None        # palpate.HybridModel
    script: Optional[Any] = None        # palpate.touch.Script (press loading with loading.script)

    def __setstate__(self, state: Dict[str, Any]) -> None:
        # Counted: a worker should unpickle a study's model once, not once a task (tests).
        global UNPICKLED
        UNPICKLED += 1
        self.__dict__.update(state)


#: Payloads unpickled by this process (see ``Payload.__setstate__``).
UNPICKLED = 0


def material(s: Dict[str, Any]) -> "_p.Material":
    return _p.Material(young=float(s["young"]), poisson=float(s["poisson"]), density=float(s["density"]),
                       phi=float(s["phi"]), psi=float(s["psi"]))


def run_scenario(payload: Payload, s: Dict[str, Any], curve: bool = True, field: bool = False) -> Dict[str, Any]:
    """The row of scenario ``s`` (a dict of parameters with its index ``scenario``); never raises.
    ``field``: the final displacement field (n, 3) [m] rides along as ``row[FIELD]`` (the driver
    stores it: workers on other machines need no shared file system)."""
    crash = os.environ.get(CRASH_ONCE_ENV)
    if crash and s.get("scenario") == 0 and not os.path.exists(crash):
        open(crash, "w").close()
        os._exit(3)
    row: Dict[str, Any] = {"status": "ok", "error": None, "stable": None, "max_force_n": None, "final_depth_m": None,
                           "max_disp_m": None, "strain_energy_j": None, "kinetic_energy_j": None,
                           "iterations_mean": None, "iterations_max": None, "steps_done": 0, "wall_s": 0.0}
    if curve:
        row.update(curve_time_s=[], curve_force_n=[], curve_depth_m=[])
    try:
        if payload.kind == "probe":
            _probe(payload, s, row, curve, field)
        else:
            _press(payload, s, row, curve, field)
    except _p.PalpateError as e:
        row["status"], row["error"] = "failed", f"{type(e).__name__}: {e}"
    except Exception as e:  # noqa: BLE001 - a row with the error, never a crashed study
        tb = traceback.extract_tb(e.__traceback__)
        where = f" (at {tb[-1].filename}:{tb[-1].lineno})" if tb else ""
        row["status"], row["error"] = "failed", f"{type(e).__name__}: {e}{where}"
    return row


def _probe(payload: Payload, s: Dict[str, Any], row: Dict[str, Any], curve: bool, field: bool) -> None:
    from .. import bench
    case = bench.setup(payload.name, payload.points_mu, payload.tets, float(s["force"]),
                       probe_z=float(s["probe_z"]) / bench.SCALE, mesh=payload.mesh)
    body = _p.Body(case.mesh, material(s), fixed=case.fixed, integrator=bench.INTEGRATORS[s["integrator"]]())
    steps, dt, ramp = int(s["steps"]), float(s["dt"]), float(s["ramp"])
    r = body.run_probe(case.loaded, case.total_force, ramp, steps, dt=dt, stable_limit=bench.STABLE_LIMIT_ANY_FORCE)
    n = int(r["steps"])
    depth = np.asarray(r["probe_disp"], dtype=np.float64)[:n]
    t = dt * np.arange(1, n + 1)
    force = float(s["force"]) * np.minimum(t / ramp, 1.0)
    row.update(stable=bool(r["stable"]), steps_done=n, wall_s=float(r["wall_s"]), max_disp_m=float(r["max_disp_m"]),
               iterations_mean=float(r["iterations_mean"]) if n else None, iterations_max=int(r["iterations_max"]),
               max_force_n=float(force.max()) if n else 0.0, final_depth_m=float(depth[-1]) if n else None)
    if np.all(np.isfinite(body.positions)):
        row.update(strain_energy_j=float(body.strain_energy()), kinetic_energy_j=float(body.kinetic_energy()))
    if curve:
        row.update(curve_time_s=t.tolist(), curve_force_n=force.tolist(), curve_depth_m=depth.tolist())
    if r["error"]:
        row["status"], row["error"] = "failed", str(r["error"])
    elif not r["stable"]:
        row["status"], row["error"] = "unstable", f"max |u| {r['max_disp_m']:.3g} m over {bench.STABLE_LIMIT_ANY_FORCE} m"
    if field and row["status"] != "failed":
        row[FIELD] = np.asarray(body.displacements, dtype=np.float64)


def _press(payload: Payload, s: Dict[str, Any], row: Dict[str, Any], curve: bool, field: bool) -> None:
    from .. import touch
    radius, dt = float(s["tool_radius"]), float(s["dt"])
    sim = _p.HybridSim(payload.hybrid, material(s), tool_radius=radius)
    script = payload.script if payload.script is not None else touch.parse_script_text(
        f"[probe]\nvertex = \"probe\"\ngap = 0.001\n\n[[segment]]\nkind = \"press\"\ndepth = {float(s['depth'])!r}\n"
        f"duration = {float(s['duration'])!r}\n" + (f"\n[[segment]]\nkind = \"hold\"\nduration = {float(s['hold'])!r}\n"
                                                      if s["hold"] > 0 else ""), "press.toml", "toml")
    traj = script.resolve(sim.surface, sim.surface_triangles, radius)
    times, centres = traj.positions(dt)
    depths = traj.depth(centres)
    n = len(times)
    fn = np.zeros(n)
    subs = np.zeros(n)
    rest = np.asarray(sim.surface).copy()
    done = 0
    t0 = time.perf_counter()
    try:
        for k in range(n):
            f = np.asarray(sim.step(centres[k], dt))
            fn[k] = float(f @ traj.normal)
            subs[k] = sim.last["substeps"]
            done = k + 1
    except _p.StepError as e:
        row["status"], row["error"] = "failed", f"StepError at t = {times[done]:.4f} s: {e}"
    wall = time.perf_counter() - t0
    u = np.linalg.norm(np.asarray(sim.surface) - rest, axis=1)
    row.update(stable=row["status"] == "ok" and bool(np.all(np.isfinite(u))), steps_done=done, wall_s=wall,
               max_force_n=float(fn[:done].max()) if done else 0.0, final_depth_m=float(depths[done - 1]) if done else None,
               max_disp_m=float(u.max()) if done else None,
               iterations_mean=float(subs[:done].mean()) if done else None, iterations_max=int(subs[:done].max()) if done else None)
    if curve:
        row.update(curve_time_s=[float(x) for x in times[:done]], curve_force_n=fn[:done].tolist(),
                   curve_depth_m=depths[:done].tolist())
    if field and row["status"] != "failed":
        row[FIELD] = np.asarray(sim.surface, dtype=np.float64) - rest


#: The row key of a scenario's final field (not a table column: :func:`save_field` stores it).
FIELD = "_field"


def save_field(field_dir: str, scenario: int, u: np.ndarray) -> None:
    """Store a scenario's field as ``field_dir/NNNNNNN.npy`` (whole or not at all)."""
    os.makedirs(field_dir, exist_ok=True)
    path = os.path.join(field_dir, f"{int(scenario):07d}.npy")
    tmp = path + f".tmp{os.getpid()}"
    with open(tmp, "wb") as fh:
        np.save(fh, np.asarray(u, dtype=np.float64))
    os.replace(tmp, path)


def finite_or_none(v: Any) -> Any:
    """NaN and infinities as None (a table cell that is null, not a float that poisons means)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v
