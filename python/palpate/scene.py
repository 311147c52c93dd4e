"""Scene files for ``palpate run``: a TOML description of a body, its loads and a run.

Every length is in metres, force in newtons, time in seconds, modulus in pascals (SI), except a
mesh file's coordinates, which are scaled by its ``unit``. A mesh path is relative to the scene
file, and environment variables in it are expanded: ``$VAR``, ``${VAR}``, and ``${VAR:-default}``
(``default`` when VAR is unset or empty).

.. code-block:: toml

    gravity = [0.0, 0.0, 0.0]          # [m/s^2], optional

    [mesh]                             # either a file ...
    file = "../../shared/bench/meshes/lv_1350.msh"
    unit = "cm"                        # "m" (default), "cm" or "mm"
    # ... or a generator: "ellipsoid_wall", "truncated_ellipsoid_wall" or "box_mesh",
    # generator = "truncated_ellipsoid_wall"
    # [mesh.params]                    # keyword arguments of palpate.<generator>
    # circumferential = 20

    [material]                         # young + poisson, or lame_lambda + lame_mu, or a preset
    young = 3.0e4                      # [Pa]
    poisson = 0.4
    density = 1000.0                   # [kg/m^3], optional: default the default tissue's
                                       # (palpate.defaults.tissue.density, 1060); 1000: the protocol's
    # preset = "myocardium"            # or "paper_ellipsoids"; phi, psi [Pa s] optional
    # law = "neo-hookean"              # or "st-venant-kirchhoff" (default, the paper's law)

    [fixed]                            # optional: node indices and/or a plane
    z_below = 1e-8                     # fix every node with z <= this [m]
    # nodes = [0, 1, 2]
    # set = "clamp"                    # a named node set of the mesh file (gmsh physical group, ...)

    [[loads]]                          # any number of probe loads
    point = [0.0228629, 0.0, 0.02]     # [m]
    radius = 0.005                     # nodes within this distance of point [m]
    surface = true                     # only boundary-surface nodes (default true)
    force = [-0.1896, 0.0, -0.0636]    # total force shared by those nodes [N]
    ramp = 0.1                         # linear ramp from 0 over this time [s] (0: at once)
    # set = "tip"                      # instead of point + radius: a named node set of the mesh file

    [integrator]
    type = "backward_euler"            # "semi_implicit", "backward_euler" (default) or "newton"
    # solver = "quasi_newton"          # backward_euler: "quasi_newton" (default), "newton", "linearised"
    # max_iterations = 40              # quasi_newton / newton: iteration cap per step
    # tolerance = 1e-2                 # quasi_newton / newton: relative gradient tolerance
    # history = 8                      # quasi_newton: L-BFGS pairs
    #                                  # (left out: the solver's default, palpate.defaults.quasi_newton / .newton)
    # filter = "paper"                 # semi_implicit: "paper" (default) or "stable"

    [run]
    dt = 1e-3                          # [s]
    steps = 1000
    output_every = 10                  # write a frame every k steps (and the first and last)
    output = "out/lv_probe"            # output folder (relative to the current directory)

Errors are raised as :class:`SceneError`, whose message names the file and the key as a dotted
path (``material.young``, ``loads[0].radius``). Unknown keys are errors (a typo is not ignored).
"""
from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

import numpy as np

from . import _palpate as _p
from . import defaults as _defaults
from ._fields import FieldChecker
from ._readers import read_text
from .io import UNITS, VtuSeries, load_mesh, read_mesh_sets

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class SceneError(_p.PalpateError, ValueError):
    """An invalid scene file; the message names the file and the key. A :class:`palpate.PalpateError`
    (and a ``ValueError``, as before)."""


_GENERATORS = {
    "ellipsoid_wall": _p.ellipsoid_wall,
    "truncated_ellipsoid_wall": _p.truncated_ellipsoid_wall,
    "box_mesh": _p.box_mesh,
}
_TOP_KEYS = {"gravity", "mesh", "material", "fixed", "loads", "integrator", "run"}
_SECTION_KEYS = {
    "mesh": {"file", "unit", "generator", "params"},
    "material": {"young", "poisson", "lame_lambda", "lame_mu", "density", "phi", "psi", "preset", "law"},
    "fixed": {"z_below", "nodes", "set"},
    "load": {"point", "radius", "force", "ramp", "surface", "set"},
    "integrator": {"type", "solver", "filter", "max_iterations", "tolerance", "history"},
    "run": {"dt", "steps", "output_every", "output"},
}


#: Values of ``material.law``.
LAWS = {"st-venant-kirchhoff": _p.Law.ST_VENANT_KIRCHHOFF, "neo-hookean": _p.Law.NEO_HOOKEAN}


@dataclass
class Load:
    nodes: np.ndarray       # node indices
    force: np.ndarray       # total [N], (3,)
    ramp: float             # [s]


@dataclass
class Scene:
    path: Path
    body: "_p.Body"
    loads: List[Load]
    dt: float
    steps: int
    output_every: int
    output: Optional[str]
    description: Dict[str, Any] = field(default_factory=dict)


class _Ctx(FieldChecker):
    """The scene file's field checks; a section's known keys default to :data:`_SECTION_KEYS`."""

    def __init__(self, path: Path):
        super().__init__(path.name, SceneError)
        self.path = path

    def known(self, table: Dict, section: str, allowed=None):
        super().known(table, section, allowed if allowed is not None else _SECTION_KEYS[section])


def _expand(text: str) -> str:
    """Expand ``$VAR``, ``${VAR}`` and ``${VAR:-default}`` (the default when VAR is unset or empty)."""
    def sub(m):
        name, default = m.group(1) or m.group(3), m.group(2)
        value = os.environ.get(name)
        if value:
            return value
        return default if default is not None else m.group(0)
    return re.sub(r"\$\{(\w+)(?::-([^}]*))?\}|\$(\w+)", sub, text)


def _material_key(msg: str, given: Dict[str, float]) -> str:
    """The [material] key a core MaterialError message is about."""
    for word, key in (("Young", "young"), ("Poisson", "poisson"), ("Lame lambda", "lame_lambda"),
                      ("shear modulus", "lame_mu"), ("density", "density"), ("phi", "phi"), ("psi", "psi")):
        if word in msg:
            return f"material.{key}"
    return "material"


def _check_output(path: Path, out: str) -> None:
    """Refuse an output folder that is empty, ends in ``.`` or ``..`` (the run would write frames
    into, and clear stale frames from, the current or the parent folder: almost never meant), is
    an existing file, or contains a NUL byte."""
    where = f"{path.name}: output folder {out!r}"
    if not out.strip() or "\0" in out:
        raise SceneError(f"{where}: give a folder name")
    if os.path.basename(os.path.normpath(out)) in (".", "..") or os.path.normpath(out) in (".", "..", os.sep):
        raise SceneError(f"{where}: would write into (and remove old frames from) an existing folder such as "
                         "'.' or '..'; give a subfolder, e.g. out/run1")
    if os.path.exists(out) and not os.path.isdir(out):
        raise SceneError(f"{where}: exists and is not a folder")


def load_scene(path: os.PathLike | str, output: Optional[str] = None, steps: Optional[int] = None) -> Scene:
    """Parse and build a scene; raises :class:`SceneError` for any problem in the file."""
    path = Path(path)
    c = _Ctx(path)
    if not path.exists():
        raise SceneError(f"{path}: no such scene file")
    # read_text: a directory, a FIFO, a file over the budget, NUL bytes or invalid UTF-8 are a
    # SceneError naming the file (not IsADirectoryError / a hang / UnicodeDecodeError).
    text = read_text(str(path), SceneError)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path.name}: invalid TOML: {e}") from None
    except RecursionError:
        raise SceneError(f"{path.name}: invalid TOML: nested too deeply") from None
    c.known(doc, "", _TOP_KEYS)

    # --- mesh
    m = c.table(doc, "mesh", required=True)
    mesh_path: Optional[Path] = None
    c.known(m, "mesh")
    if ("file" in m) == ("generator" in m):
        raise c.err("mesh", "give exactly one of 'file' or 'generator'")
    if "file" in m:
        if not isinstance(m["file"], str):
            raise c.err("mesh.file", f"must be a path string, got {m['file']!r}")
        unit = m.get("unit", "m")
        if unit not in UNITS:
            raise c.err("mesh.unit", f"must be one of {sorted(UNITS)}, got {unit!r}")
        if "params" in m:
            raise c.err("mesh.params", "only used with 'generator'")
        fname = _expand(m["file"])
        if "$" in fname:
            raise c.err("mesh.file", f"unset environment variable in {m['file']!r} (use ${{VAR:-default}})")
        mesh_path = Path(fname) if os.path.isabs(fname) else (path.parent / fname).resolve()
        try:
            mesh = load_mesh(mesh_path, unit=unit)
        except _p.MeshError as e:
            raise c.err("mesh.file", str(e)) from None
    else:
        gen = m["generator"]
        if gen not in _GENERATORS:
            raise c.err("mesh.generator", f"must be one of {sorted(_GENERATORS)}, got {gen!r}")
        if "unit" in m:
            raise c.err("mesh.unit", "only used with 'file' (generators work in metres)")
        params = m.get("params", {})
        if not isinstance(params, dict):
            raise c.err("mesh.params", "must be a table")
        try:
            mesh = _GENERATORS[gen](**params)
        except (TypeError, ValueError) as e:
            msg = str(e)
            key = re.search(r"(?:keyword argument|argument) '(\w+)'", msg)
            name = key.group(1) if key else next((k for k in params if msg.startswith(k)), None)
            raise c.err(f"mesh.params.{name}" if name else "mesh.params", msg) from None

    # --- material
    mat = c.table(doc, "material", required=True)
    c.known(mat, "material")
    kw = {}
    for k in ("young", "poisson", "lame_lambda", "lame_mu", "density", "phi", "psi"):
        v = c.number(mat, "material", k)
        if v is not None:
            kw[k] = float(v)
    law = mat.get("law", "st-venant-kirchhoff")
    if not isinstance(law, str) or law not in LAWS:
        raise c.err("material.law", f"must be one of {sorted(LAWS)}, got {law!r}")
    if "preset" in mat:
        presets = {"myocardium": _p.Material.myocardium, "paper_ellipsoids": _p.Material.paper_ellipsoids}
        if mat["preset"] not in presets:
            raise c.err("material.preset", f"must be one of {sorted(presets)}, got {mat['preset']!r}")
        if kw:
            raise c.err("material.preset", f"cannot be combined with {', '.join(sorted(kw))}")
        pre = presets[mat["preset"]]()
        material = _p.Material(lame_lambda=pre.lame_lambda, lame_mu=pre.lame_mu, density=pre.density, phi=pre.phi,
                               psi=pre.psi, law=LAWS[law])
    else:
        kw.setdefault("density", _defaults.tissue.density)   # the default tissue's (Material::myocardium)
        try:
            material = _p.Material(**kw, law=LAWS[law])
        except _p.MaterialError as e:
            raise c.err(_material_key(str(e), kw), str(e)) from None

    sets_cache: Dict[str, np.ndarray] = {}

    def node_set(name: Any, key: str) -> np.ndarray:
        """A named node set of the mesh file (io.read_mesh_sets), for fixed or loaded nodes."""
        if mesh_path is None:
            raise c.err(key, "named sets come from a mesh file (mesh.file), not a generator")
        if not isinstance(name, str):
            raise c.err(key, f"must be the name of a node set, got {name!r}")
        if not sets_cache:
            try:
                sets_cache.update(read_mesh_sets(mesh_path)[0])
            except _p.MeshError as e:
                raise c.err(key, str(e)) from None
        if name not in sets_cache:
            raise c.err(key, f"no node set {name!r} in {mesh_path.name} (it has {sorted(sets_cache) or 'none'})")
        return sets_cache[name]

    # --- fixed nodes
    fx = c.table(doc, "fixed")
    c.known(fx, "fixed")
    fixed = set()
    pts = mesh.points
    if "z_below" in fx:
        z = c.number(fx, "fixed", "z_below")
        sel = np.flatnonzero(pts[:, 2] <= z)
        if len(sel) == 0:
            raise c.err("fixed.z_below", f"no node has z <= {z} m (the mesh spans z = {pts[:, 2].min():.4g} .. "
                                           f"{pts[:, 2].max():.4g} m)")
        fixed.update(int(i) for i in sel)
    if "nodes" in fx:
        nodes = fx["nodes"]
        if not isinstance(nodes, list) or not all(isinstance(i, int) and not isinstance(i, bool) for i in nodes):
            raise c.err("fixed.nodes", f"must be a list of node indices, got {nodes!r}")
        bad = [i for i in nodes if not 0 <= i < mesh.n_nodes]
        if bad:
            raise c.err("fixed.nodes", f"node index {bad[0]} out of range (the mesh has {mesh.n_nodes} nodes)")
        fixed.update(nodes)
    if "set" in fx:
        fixed.update(int(i) for i in node_set(fx["set"], "fixed.set"))

    gravity = c.vec3(doc, "", "gravity", default=np.zeros(3))

    # --- integrator
    it = c.table(doc, "integrator")
    c.known(it, "integrator")
    kind = it.get("type", "backward_euler")
    if kind not in ("semi_implicit", "backward_euler", "newton"):
        raise c.err("integrator.type", f"must be 'semi_implicit', 'backward_euler' or 'newton', got {kind!r}")
    if kind == "semi_implicit":
        for k in ("solver", "max_iterations", "tolerance", "history"):
            if k in it:
                raise c.err(f"integrator.{k}", "not used with type = 'semi_implicit'")
        filters = {"paper": _p.Filter.PAPER, "stable": _p.Filter.STABLE}
        f = it.get("filter", "paper")
        if f not in filters:
            raise c.err("integrator.filter", f"must be 'paper' or 'stable', got {f!r}")
        integrator = _p.SemiImplicit(filter=filters[f])
    else:
        if "filter" in it:
            raise c.err("integrator.filter", "only used with type = 'semi_implicit'")
        solvers = {"quasi_newton": _p.Solver.QUASI_NEWTON, "newton": _p.Solver.NEWTON,
                   "linearised": _p.Solver.LINEARISED}
        name = it.get("solver", "newton" if kind == "newton" else "quasi_newton")
        if name not in solvers:
            raise c.err("integrator.solver", f"must be 'quasi_newton', 'newton' or 'linearised', got {name!r}")
        if kind == "newton" and name != "newton":
            raise c.err("integrator.solver", "type = 'newton' is backward Euler with solver = 'newton'")
        kw = {}
        if "max_iterations" in it:
            kw["max_iterations"] = c.number(it, "integrator", "max_iterations", positive=True, integer=True)
        if "tolerance" in it:
            tol = c.number(it, "integrator", "tolerance", positive=True)
            if not tol < 1:
                raise c.err("integrator.tolerance", f"must lie in (0, 1), got {tol!r}")
            kw["tolerance"] = float(tol)
        if "history" in it:
            kw["history"] = c.number(it, "integrator", "history", nonneg=True, integer=True)
        try:
            integrator = _p.BackwardEuler(solvers[name], **kw)
        except ValueError as e:
            raise c.err("integrator", str(e)) from None

    try:
        body = _p.Body(mesh, material, fixed=sorted(fixed), gravity=gravity, integrator=integrator)
    except _p.PalpateError as e:
        raise c.err("fixed" if "fixed" in str(e) else "gravity" if "gravity" in str(e) else "scene", str(e)) from None

    # --- loads
    loads_doc = doc.get("loads", [])
    if not isinstance(loads_doc, list):
        raise c.err("loads", "must be an array of tables: write [[loads]]")
    surface_nodes = None
    loads = []
    for i, ld in enumerate(loads_doc):
        sec = f"loads[{i}]"
        if not isinstance(ld, dict):
            raise c.err(f"loads[{i}]", "must be a table")
        c.known(ld, sec, _SECTION_KEYS["load"])
        f = c.vec3(ld, sec, "force", required=True)
        if "set" in ld:
            if "point" in ld or "radius" in ld:
                raise c.err(f"{sec}.set", "give a node set or point + radius, not both")
            sel = node_set(ld["set"], f"{sec}.set")
            if len(np.setdiff1d(sel, sorted(fixed))) == 0:
                raise c.err(f"{sec}.set", "every node of this load is fixed: it would do nothing")
            loads.append(Load(sel, f, float(c.number(ld, sec, "ramp", 0.0, nonneg=True))))
            continue
        p = c.vec3(ld, sec, "point", required=True)
        r = c.number(ld, sec, "radius", required=True, positive=True)
        ramp = c.number(ld, sec, "ramp", 0.0, nonneg=True)
        surface = ld.get("surface", True)
        if not isinstance(surface, bool):
            raise c.err(f"{sec}.surface", f"must be true or false, got {surface!r}")
        if surface:
            if surface_nodes is None:
                surface_nodes = np.unique(mesh.boundary_faces())
            cand = surface_nodes
        else:
            cand = np.arange(mesh.n_nodes)
        d = np.linalg.norm(pts[cand] - p, axis=1)
        sel = cand[d <= r]
        if len(sel) == 0:
            raise c.err(f"{sec}.radius", f"no {'surface ' if surface else ''}node within {r} m of point "
                                           f"{p.tolist()} (the nearest is {d.min():.4g} m away)")
        free = np.setdiff1d(sel, sorted(fixed))
        if len(free) == 0:
            raise c.err(f"{sec}.point", "every node of this load is fixed: it would do nothing")
        loads.append(Load(sel, f, float(ramp)))

    # --- run
    run = c.table(doc, "run")
    c.known(run, "run")
    dt = c.number(run, "run", "dt", 1e-3, positive=True)
    nsteps = c.number(run, "run", "steps", 1000, positive=True, integer=True)
    every = c.number(run, "run", "output_every", 10, positive=True, integer=True)
    out = run.get("output")
    if out is not None and not isinstance(out, str):
        raise c.err("run.output", f"must be a folder path string, got {out!r}")
    if output is not None:
        out = output
    if out is None:
        out = os.path.join("out", path.stem)
    _check_output(path, out)
    if steps is not None:
        nsteps = steps
    return Scene(path, body, loads, float(dt), int(nsteps), int(every), out,
                 dict(mesh=m.get("file") or m.get("generator"), integrator=kind))


def run_scene(scene: Scene, write: bool = True, log=print,
              advance: Optional[Callable[[int], None]] = None) -> Dict[str, Any]:
    """Run a scene, writing a VTU series; returns a summary dict. ``advance(k)``, if given, is
    called after each chunk of ``k`` steps (a progress display: ``palpate run``).

    Frames (deformed positions, the fields of :meth:`VtuSeries.write_body`: displacement,
    velocity, fixed and loaded flags per node; von Mises stress, strain energy density, det F and
    inverted flags per tet) are written at step 0, every ``output_every`` steps and after the last step, into
    ``scene.output`` with ``frame.pvd`` as the ParaView collection. Raises ``StepError`` if a step
    fails (frames written so far are kept).
    """
    body = scene.body
    series = VtuSeries(scene.output, body.mesh.tets) if write and scene.output else None
    loaded = np.unique(np.concatenate([np.asarray(ld.nodes, dtype=np.int64).ravel() for ld in scene.loads]
                                      or [np.zeros(0, dtype=np.int64)]))

    def frame():
        if series is not None:
            series.write_body(body, loaded=loaded)

    frame()
    # One run loop for every caller (palpate_core::probe): the loads ramp from the scene's start
    # (t = 0), each step carrying its load at the step's end; frames between chunks of steps.
    loads = [(ld.nodes, ld.force, ld.ramp) for ld in scene.loads]
    wall, umax, done = 0.0, 0.0, 0
    while done < scene.steps:
        n = min(scene.output_every - done % scene.output_every, scene.steps - done)
        r = body.run_loads(loads, n, scene.dt, ramp_start=0.0)
        wall += r["wall_s"]
        umax = max(umax, r["max_disp_m"])
        done += r["steps"]
        if advance is not None:
            advance(r["steps"])
        if r["error"] is not None:
            raise _p.StepError(f"scene {scene.path}: {r['error']}")
        frame()
    return dict(
        scene=str(scene.path), nodes=body.n_nodes, tets=body.n_tets, steps=scene.steps, dt=scene.dt,
        wall_s=wall, steps_per_s=scene.steps / wall if wall > 0 else float("inf"), max_disp_m=umax,
        strain_energy_J=body.strain_energy(), kinetic_energy_J=body.kinetic_energy(),
        frames=len(series.entries) if series else 0, pvd=series.pvd_path if series else None,
    )
