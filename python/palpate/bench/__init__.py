"""palpate's benchmarks (``palpate bench ...``), and here the shared benchmark case
(``shared/bench/PROTOCOL.md``, defined in code in ``shared/bench/common.py``).

The other benchmarks are this package's modules, each imported only when used (they reach up into
the hybrid simulation, the haptic loop, the viewer and the sweep runner): :mod:`.hybrid` (a tick of
the hybrid simulation at a chosen active count), :mod:`.particles` (a meshfree particle body),
:mod:`.haptic` (the haptic loop's timing), :mod:`.view` (what the web viewer costs that loop) and
:mod:`.sweep` (the batch-study runner's overhead). The old modules ``palpate.bench_hybrid``,
``palpate.bench_particles``, ``palpate.viewer.bench`` and ``palpate.sweep.bench`` re-export them.

A left-ventricle-like wall (the region between the ellipsoids of semi-axes (2.0, 2.0, 3.5) and
(2.6, 2.6, 4.2) mesh units, truncated at z = 0), mesh units x 0.01 = m. E = 3e4 Pa, nu = 0.4,
density 1000 kg/m^3, no gravity. Nodes with z <= 1e-6 mesh units are fixed. The outer-surface
nodes within 0.5 mesh units of the probe point P = (2.28629, 0, 2.0) (the nearest one if none)
share 0.2 N along the inward normal n, ramped linearly over 0.1 s. 1000 steps of 1 ms, one thread.
Figures: steps/s over the step calls only, stability (finite and max |u| < 2 cm), max |u|, the
loaded nodes' mean |u| over the second half, and how far the second-half mean displacement field
is from palpate's own static solution under the full load (``rel_L2_vs_static``).

The generated mesh ``ellipsoid_192``: :func:`palpate.ellipsoid_wall` with the same semi-axes
(the paper's ~188-tet "Ellipsoids Model" size: 192 tets, 54 nodes), a *closed* shell. The load
definition is adapted as follows: the same probe point, normal, radius, force and ramp; every node
with z <= 1e-6 mesh units is fixed (the LV's base plane, here clamping the bottom half-shell and
the equator: 39 of the 54 nodes). Its coarse mesh has a single outer node within 0.5 mesh units
of P (0.22 units away), which carries the whole 0.2 N.
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from .. import _palpate as _p
from .. import defaults
from ..io import read_mesh_arrays

SCALE = 0.01          # mesh unit -> m
E = 3.0e4             # Young's modulus [Pa]
NU = 0.4              # Poisson ratio
RHO = 1000.0          # density [kg/m^3]
DT = 1e-3             # [s]
STEPS = 1000
BASE_TOL = 1e-6       # mesh units
OUTER = np.array([2.6, 2.6, 4.2])
INNER = np.array([2.0, 2.0, 3.5])
PROBE_Z = 2.0         # mesh units
PROBE_R = 0.5         # mesh units
FORCE = 0.2           # [N]
RAMP = 0.1            # [s]
STABLE_LIMIT = 0.02   # [m]
MESHES = ["190", "1350", "10k", "50k"]
GENERATED = "ellipsoid_192"

STABLE_LIMIT_ANY_FORCE = 0.06  # [m]: at forces other than the protocol's, max |u| under the object's size
NEWTON_REFERENCE_MAX_TETS = 10_000

#: CLI names of the integrators.
INTEGRATORS = {
    "backward-euler": lambda: _p.BackwardEuler(),
    "quasi-newton": lambda: _p.BackwardEuler(),
    "newton": lambda: _p.BackwardEuler(_p.Solver.NEWTON),
    "linearised": lambda: _p.BackwardEuler(_p.Solver.LINEARISED),
    "semi-implicit": lambda: _p.SemiImplicit(),
    "semi-implicit-stable": lambda: _p.SemiImplicit(filter=_p.Filter.STABLE),
}

#: Iteration cap of the Newton reference: above the solver's default
#: (``palpate.defaults.newton.max_iterations``), so that a hard step converges rather than stops.
NEWTON_REFERENCE_MAX_ITERATIONS = 50


def newton_reference():
    """The converged Newton run that ``rel_L2_vs_newton`` compares against: the core's Newton
    tolerance (``palpate.defaults.newton.tolerance``), :data:`NEWTON_REFERENCE_MAX_ITERATIONS`."""
    return _p.BackwardEuler(_p.Solver.NEWTON, max_iterations=NEWTON_REFERENCE_MAX_ITERATIONS,
                            tolerance=defaults.newton.tolerance)


def probe_on_ellipsoid(semi_axes, z: float):
    """The point of the ellipsoid of ``semi_axes`` (centred at the origin) at height ``z`` on its
    +x side (y = 0), and the inward unit normal there, in the unit of ``semi_axes``: the protocol's
    probe point on its outer ellipsoid (:func:`probe_point` in mesh units,
    :func:`palpate.bench.particles.probe_point` in metres). A model's probe *vertex* is
    :func:`palpate.probe.probe_point`."""
    a = np.asarray(semi_axes, dtype=np.float64)
    x = a[0] * np.sqrt(1 - (z / a[2]) ** 2)
    p = np.array([x, 0.0, z])
    n = p / a ** 2
    n /= np.linalg.norm(n)
    return p, -n


def probe_point(z: float = PROBE_Z):
    """Probe point P (mesh units) on the outer ellipsoid at height ``z`` (mesh units, on the +x
    side; the protocol's 2.0 by default) and the inward unit normal there."""
    if not 0.0 <= z < OUTER[2]:
        raise _p.ParameterError(f"probe height z = {z} mesh units must be within [0, {OUTER[2]})")
    return probe_on_ellipsoid(OUTER, z)


def material():
    return _p.Material(young=E, poisson=NU, density=RHO)


@dataclass
class Case:
    """One mesh set up for the protocol (SI units)."""
    name: str
    mesh: "_p.TetMesh"
    fixed: np.ndarray
    loaded: np.ndarray
    total_force: np.ndarray   # [N], (3,)


def setup(name: str, points_mu: np.ndarray, tets: np.ndarray, force: float = FORCE,
          probe_z: float = PROBE_Z, mesh: "Optional[_p.TetMesh]" = None) -> Case:
    """Fixed and loaded nodes from points in mesh units, as common.setup does; ``probe_z``: the
    probe's height (mesh units; :func:`probe_point`); ``mesh``: the already made
    :class:`palpate.TetMesh` of these points (x ``SCALE``) and tets, reused rather than rebuilt."""
    p = np.asarray(points_mu, dtype=np.float64)
    fixed = np.flatnonzero(p[:, 2] <= BASE_TOL)
    level = np.sqrt(((p / OUTER) ** 2).sum(1))
    outer = np.flatnonzero(np.abs(level - 1) < 1e-3)
    P, n = probe_point(probe_z)
    d = np.linalg.norm(p[outer] - P, axis=1)
    loaded = outer[d <= PROBE_R]
    if len(outer) == 0 or len(fixed) == 0:
        # Not the protocol's ventricle: no node on its outer ellipsoid or its base plane.
        raise _p.MeshError(f"{name}: not a benchmark-protocol ventricle mesh ({len(outer)} nodes on the protocol's "
                           f"outer ellipsoid, {len(fixed)} on its base plane z <= {BASE_TOL} mesh units): "
                           "palpate bench protocol needs the shared lv_* meshes or a mesh of the same geometry")
    if len(loaded) == 0:
        loaded = outer[[int(np.argmin(d))]]
    if mesh is None:
        mesh = _p.TetMesh(p * SCALE, tets, source=name)
    return Case(name, mesh, fixed, loaded, force * n)


def load_case(path: str, force: float = FORCE) -> Case:
    """A protocol mesh file (.msh, .vtu, .npz; coordinates in mesh units); ``force`` the total [N]."""
    points, tets, _, _ = read_mesh_arrays(path, unit="m")  # raw mesh units
    return setup(Path(path).stem, points, tets, force)


def generated_case(force: float = FORCE) -> Case:
    """The 192-tet closed ellipsoid wall with the adapted load (module docs)."""
    m = _p.ellipsoid_wall(inner=tuple(INNER * SCALE), outer=tuple(OUTER * SCALE), subdivisions=1, layers=2)
    return setup(GENERATED, m.points / SCALE, m.tets, force)


#: Steps timed on a copy of a big mesh's Newton reference body to estimate the whole run.
NEWTON_ESTIMATE_STEPS = 5


def _announce_newton(case: Case, ref_body, steps: int, dt: float, limit: float) -> None:
    """Print (stderr) how long the Newton reference run will take, timed on a copy of its body
    over its first steps: on a big mesh it runs for minutes, which a user should know first."""
    k = min(NEWTON_ESTIMATE_STEPS, steps)
    t = ref_body.copy().run_probe(case.loaded, case.total_force, RAMP, k, dt=dt, stable_limit=limit)
    per_step = t["wall_s"] / max(int(t["steps"]), 1)
    print(f"palpate bench: the Newton reference on {case.name} ({case.mesh.n_tets} tets) takes about "
          f"{per_step * steps:.0f} s or more ({steps} steps at {per_step * 1e3:.0f} ms, timed over the first {k}; "
          f"later steps of the ramp iterate more); --newton off skips it", file=sys.stderr, flush=True)


def run(case: Case, integrator: str = "backward-euler", steps: int = STEPS, dt: float = DT,
        max_wall_s: Optional[float] = None, newton: Optional[bool] = None) -> Dict:
    """Run the protocol on ``case``; returns the result dict (JSON keys of ``palpate bench``).

    ``stable``: finite throughout and max |u| under 2 cm at the protocol's 0.2 N, under 6 cm (the
    object's size) at any other force. ``rel_L2_vs_newton``: relative L2 distance of the
    second-half mean displacement field from that of the same run with converged Newton backward
    Euler (``newton_reference``), computed when ``newton`` is true (default: meshes up to
    ``NEWTON_REFERENCE_MAX_TETS`` tets), else None; None too when the Newton run fails.
    """
    force = float(np.linalg.norm(case.total_force))
    limit = STABLE_LIMIT if abs(force - FORCE) < 1e-12 else STABLE_LIMIT_ANY_FORCE
    body = _p.Body(case.mesh, material(), fixed=case.fixed, integrator=INTEGRATORS[integrator]())
    r = body.run_probe(case.loaded, case.total_force, RAMP, steps, dt=dt, stable_limit=limit,
                       max_wall_s=max_wall_s)
    # palpate's own static equilibrium under the full load (nonlinear, Newton).
    f = np.zeros((body.n_nodes, 3))
    f[case.loaded] = case.total_force / len(case.loaded)
    errors = [r["error"]] if r["error"] else []
    complete = r["steps"] > steps // 2
    static_probe = rel = None
    # Above the protocol's load on large meshes the static Newton solve is skipped: St.
    # Venant-Kirchhoff's tangent turns indefinite and the solve retries up to 256 load increments,
    # minutes of factorisations on lv_50k, for a reference that rel_L2_vs_newton replaces.
    skip_static = force > FORCE * (1 + 1e-9) and case.mesh.n_tets > NEWTON_REFERENCE_MAX_TETS
    if not skip_static:
        try:
            x_static = body.static_solve(f, load_steps=1 if force <= FORCE else 8)
            u_static = x_static - case.mesh.points
            static_probe = float(np.linalg.norm(u_static, axis=1)[case.loaded].mean())
            ref = float(np.linalg.norm(u_static))
            rel = float(np.linalg.norm(r["mean_disp"] - u_static) / ref) if ref > 0 and complete else None
        except _p.SolveError as e:
            errors.append(f"static solve: {e}")
    rel_newton = None
    if newton is None:
        newton = case.mesh.n_tets <= NEWTON_REFERENCE_MAX_TETS
    if newton and complete:
        ref_body = _p.Body(case.mesh, material(), fixed=case.fixed, integrator=newton_reference())
        if case.mesh.n_tets > NEWTON_REFERENCE_MAX_TETS:
            _announce_newton(case, ref_body, steps, dt, limit)
        rn = ref_body.run_probe(case.loaded, case.total_force, RAMP, steps, dt=dt, stable_limit=limit)
        if rn["error"] is None and np.isfinite(rn["mean_disp"]).all():
            den = float(np.linalg.norm(rn["mean_disp"]))
            rel_newton = float(np.linalg.norm(r["mean_disp"] - rn["mean_disp"]) / den) if den > 0 else 0.0
    wall = r["wall_s"]
    t = np.asarray(r["step_us"])
    pct = (lambda q: round(float(np.percentile(t, q)), 1)) if len(t) else (lambda q: None)
    out = dict(
        mesh=case.name, tets=case.mesh.n_tets, nodes=case.mesh.n_nodes, integrator=integrator,
        force_N=round(force, 9), steps=int(r["steps"]), wall_s=round(wall, 6),
        steps_per_s=round(r["steps"] / wall, 1) if wall > 0 else None,
        stable=bool(r["stable"]), stable_limit_m=limit, max_disp_m=r["max_disp_m"],
        probe_disp_avg_m=r["probe_disp_avg_m"],
        iterations_mean=round(float(r["iterations_mean"]), 3) if r["steps"] else None,
        iterations_max=int(r["iterations_max"]), evaluations=int(r["evaluations"]),
        factorizations=int(r["factorizations"]), inverted_max=int(r["inverted_max"]),
        step_us_p50=pct(50), step_us_p99=pct(99), step_us_max=round(float(t.max()), 1) if len(t) else None,
        static_probe_disp_m=static_probe, rel_L2_vs_static=rel, rel_L2_vs_newton=rel_newton,
        loaded_nodes=len(case.loaded), fixed_nodes=len(case.fixed),
    )
    if errors:
        out["error"] = "; ".join(errors)
    return out


def shared_dir() -> Optional[Path]:
    """The project's shared folder: $PALPATE_SHARED, else ``<repo>/../shared``, else ``./../shared``.

    Returns None if none of them holds ``bench/meshes``.
    """
    cands: List[Path] = []
    env = os.environ.get("PALPATE_SHARED")
    if env:
        cands.append(Path(env))
    here = Path(__file__).resolve()
    cands += [here.parents[3] / ".." / "shared", Path.cwd() / ".." / "shared", Path.cwd() / "shared"]
    for c in cands:
        if (c / "bench" / "meshes").is_dir():
            return c.resolve()
    return None


def bench_mesh_path(name: str) -> Optional[Path]:
    """Path of the shared bench mesh ``lv_<name>.msh`` (None if the shared folder is absent)."""
    s = shared_dir()
    if s is None:
        return None
    p = s / "bench" / "meshes" / f"lv_{name}.msh"
    return p if p.exists() else None
