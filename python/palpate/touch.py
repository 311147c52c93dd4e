"""Scripted touches of a :class:`palpate.HybridSim`: a tool trajectory from a small file, run tick
by tick, recorded as a force log, a plot and a VTU series (``palpate touch``, issue 12).

A *touch script* is a TOML file of segments relative to a contact point and normal, or a CSV file
of tool positions over time. All lengths in metres, times in seconds, forces in newtons.

TOML (``.toml``)::

    [probe]
    vertex = "probe"          # the default probe point (palpate.probe.probe_point); or point = [x, y, z]
    # normal = [1, 0, 0]      # optional: default the outward surface normal at the point
    # gap = 0.002             # optional: the tool starts this far clear of the surface (default 2 mm)

    [[segment]]
    kind = "press"            # to depth [m] past first contact, along the inward normal
    depth = 0.005
    duration = 0.5
    [[segment]]
    kind = "hold"             # stay where the last segment ended
    duration = 0.3
    [[segment]]
    kind = "slide"            # distance [m] along direction, projected onto the tangent plane
    direction = [0, 0, 1]
    distance = 0.01
    duration = 1.0
    [[segment]]
    kind = "release"          # back out along the normal to the probe's gap (or gap = ... [m])
    duration = 0.3

The tool sphere of radius ``r`` touches the surface at depth 0: its centre is
``point + normal * (r - depth)``. Depth is measured along the probe's normal from the tangent plane
at the point (a slide over a curved surface keeps it, not the local indentation). Every segment
moves linearly in time from where the previous one ended; ``duration`` > 0 is required.

CSV (``.csv``): a header ``t,x,y,z`` then one row per knot (``#`` starts a comment line), times
strictly increasing; the tool centre is linearly interpolated at each tick. The contact point for
the log's depth column is the outer-surface vertex nearest the trajectory, with its outward
normal.

Scripts are validated strictly: unknown tables and keys, wrong types, non-finite numbers,
non-positive durations, an empty script raise :class:`ScriptError` naming the file and the entry
(``press.toml: segment[2].duration: must be positive, got -0.5``).

The run (:func:`run_touch`) ticks the simulation at ``dt`` from ``t = dt`` to the script's end,
the tool at the script's position for the end of the tick, and writes to ``out_dir``:

- ``force.csv``: per tick ``t`` [s], tool ``x, y, z`` [m] (commanded), ``depth`` [m],
  ``fx, fy, fz, f`` [N] (force on the tool, its magnitude), ``fn`` [N] (its component along the
  outward normal: positive when the tissue pushes back), ``active`` (active particles),
  ``contacts`` (skin vertices in contact), ``core_contacts`` (1 when the tool touches the core's
  surface), ``substeps``, ``tick_ms`` (wall
  time of ``sim.step``);
- ``force.png``: normal force against depth, force against time;
- ``touch.pvd`` and ``surface_NNNNN.vtu`` (triangles; point data ``displacement`` [m]),
  ``core_NNNNN.vtu`` (tets), ``active_NNNNN.vtu`` (active particles, vertex cells),
  ``tool_NNNNN.vtu`` (the tool centre, point data ``radius`` [m]) every ``every`` ticks: one
  time step per frame, four parts (0 to 3), which ParaView opens as one multiblock series. A
  frame with no active particle has no ``active`` file (meshio cannot read a VTU without points).

The simulated tool follows the commanded one at most at 0.5 m/s (``HybridSim``'s
``max_tool_speed``): faster scripts are logged as commanded and noted in the summary.
"""
from __future__ import annotations

import csv
import math
import os
import time
try:
    import tomllib
except ImportError:  # Python < 3.11 (the tomli backport, a dependency there)
    import tomli as tomllib
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import numpy as np

from ._fields import FieldChecker
from ._palpate import PalpateError, ParameterError
from ._readers import read_text
from .io import remove_frames, write_pvd
# The probe point and the surface normals live in the library (palpate.probe); imported from here
# too, as before (palpate.touch.probe_point, palpate.touch.vertex_normals).
from .probe import PROBE_HEIGHT, probe_point, vertex_normals  # noqa: F401
from ._extras import install_hint

PathLike = Union[str, "os.PathLike[str]"]

#: The tool's default start clearance from the surface [m] (``[probe] gap``).
DEFAULT_GAP = 0.002
#: Frames a run writes by default (:func:`default_every`).
TARGET_FRAMES = 80

#: The columns of ``force.csv``.
COLUMNS = ("t", "x", "y", "z", "depth", "fx", "fy", "fz", "f", "fn", "active", "contacts", "core_contacts",
           "substeps", "tick_ms")

_SEGMENT_KEYS = {
    "press": {"kind", "depth", "duration"},
    "hold": {"kind", "duration"},
    "slide": {"kind", "direction", "distance", "duration"},
    "release": {"kind", "gap", "duration"},
}
_PROBE_KEYS = {"point", "vertex", "normal", "gap"}


class ScriptError(PalpateError, ValueError):
    """A touch script that cannot be used: one line naming the file and the entry. A
    :class:`palpate.PalpateError` (and a ``ValueError``, as before)."""


class TouchFailed(PalpateError, RuntimeError):
    """A tick failed during :func:`run_touch` (a :class:`palpate.StepError`); what was done so far
    is written. ``tick`` (1-based), ``reason`` and ``summary`` (as :func:`run_touch` returns)."""

    def __init__(self, tick: int, reason: str, summary: Dict[str, Any]):
        super().__init__(f"tick {tick} (t = {summary['t_failed_s']:.4f} s): {reason}")
        self.tick, self.reason, self.summary = tick, reason, summary


# ---------------------------------------------------------------------------------------- scripts

@dataclass
class Segment:
    """One TOML segment: ``kind`` (press, hold, slide, release), ``duration`` [s] and its
    parameters (``depth`` [m]; ``direction`` (3,) and ``distance`` [m]; ``gap`` [m])."""
    kind: str
    duration: float
    depth: Optional[float] = None
    direction: Optional[np.ndarray] = None
    distance: Optional[float] = None
    gap: Optional[float] = None


@dataclass
class Script:
    """A parsed touch script (:func:`parse_script`). ``kind`` is ``"toml"`` (``point`` (3,) [m] or
    None for the default probe vertex, ``normal`` (3,) or None for the surface's, ``gap`` [m],
    ``segments``) or ``"csv"`` (``times`` (k,) [s], ``knots`` (k, 3) [m]). Resolve it against a
    simulation's surface with :meth:`resolve`."""
    path: str
    kind: str
    point: Optional[np.ndarray] = None
    normal: Optional[np.ndarray] = None
    gap: float = DEFAULT_GAP
    segments: List[Segment] = field(default_factory=list)
    times: Optional[np.ndarray] = None
    knots: Optional[np.ndarray] = None

    @property
    def name(self) -> str:
        return os.path.basename(self.path)

    @property
    def duration(self) -> float:
        """The script's length [s]."""
        if self.kind == "csv":
            return float(self.times[-1] - self.times[0])
        return float(sum(s.duration for s in self.segments))

    def resolve(self, surface: np.ndarray, triangles: np.ndarray, tool_radius: float) -> "Trajectory":
        """The tool-centre trajectory on a surface (outer vertices (n, 3) [m], triangles (m, 3))
        for a tool of ``tool_radius`` [m]. Raises :class:`ScriptError` for a normal that is zero
        or a slide along it."""
        surface = np.asarray(surface, dtype=np.float64)
        normals = vertex_normals(surface, triangles)
        if self.kind == "csv":
            d = np.linalg.norm(surface[None, :, :] - self.knots[:, None, :], axis=2) if len(surface) * len(self.knots) <= 5e6 \
                else np.stack([np.linalg.norm(surface - k, axis=1) for k in self.knots])
            kk, vi = np.unravel_index(np.argmin(d), d.shape)
            point, normal = surface[vi], normals[vi]
            return Trajectory(self.times - self.times[0], self.knots.copy(), point, normal, tool_radius,
                              vertex=int(vi), t0=float(self.times[0]))
        vi = None
        if self.point is None:
            vi = probe_point(surface, triangles)
            point = surface[vi]
        else:
            point = self.point
        if self.normal is not None:
            normal = self.normal
        else:
            if vi is None:
                vi = int(np.argmin(np.linalg.norm(surface - point, axis=1)))
            normal = normals[vi]
        if not np.linalg.norm(normal) > 0:
            raise ScriptError(f"{self.name}: probe.normal: the surface normal at the point is zero; give probe.normal")
        normal = normal / np.linalg.norm(normal)
        r = tool_radius
        times, knots = [0.0], [point + normal * (r + self.gap)]
        for i, s in enumerate(self.segments):
            last = knots[-1]
            if s.kind == "press":
                depth_now = r - float((last - point) @ normal)
                nxt = last + normal * (depth_now - s.depth)
            elif s.kind == "hold":
                nxt = last
            elif s.kind == "slide":
                d = s.direction - (s.direction @ normal) * normal
                if np.linalg.norm(d) < 1e-6 * np.linalg.norm(s.direction):
                    raise ScriptError(f"{self.name}: segment[{i + 1}].direction: along the normal {normal.round(6).tolist()}; "
                                      "a slide moves in the tangent plane (use press or release)")
                nxt = last + d / np.linalg.norm(d) * s.distance
            else:  # release
                gap = self.gap if s.gap is None else s.gap
                depth_now = r - float((last - point) @ normal)
                nxt = last + normal * (depth_now + gap)
            times.append(times[-1] + s.duration)
            knots.append(nxt)
        return Trajectory(np.array(times), np.array(knots), np.asarray(point, dtype=np.float64), normal, r, vertex=vi)


@dataclass
class Trajectory:
    """Tool-centre knots over time, linearly interpolated: ``times`` (k,) [s] from 0, ``knots``
    (k, 3) [m]; the contact ``point`` (3,) [m], unit outward ``normal`` (3,) and ``radius`` [m]
    that define the depth; ``vertex`` (the outer vertex of the point, if one) and ``t0`` (the
    script's own start time [s], CSV)."""
    times: np.ndarray
    knots: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    radius: float
    vertex: Optional[int] = None
    t0: float = 0.0

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def at(self, t: Union[float, np.ndarray]) -> np.ndarray:
        """Tool centre(s) [m] at time(s) ``t`` [s] from the start: (3,) or (len(t), 3); held at
        the ends outside the script."""
        t = np.asarray(t, dtype=np.float64)
        out = np.stack([np.interp(t, self.times, self.knots[:, k]) for k in range(3)], axis=-1)
        return out

    def n_ticks(self, dt: float) -> int:
        """Ticks of ``dt`` [s] the script lasts (at least 1)."""
        return max(1, int(math.floor(self.duration / dt + 1e-9)))

    def positions(self, dt: float) -> Tuple[np.ndarray, np.ndarray]:
        """``(t (n,) [s], centres (n, 3) [m])``: the tool at the end of each tick of ``dt``."""
        t = dt * np.arange(1, self.n_ticks(dt) + 1)
        return t, self.at(t)

    def depth(self, centres: np.ndarray) -> np.ndarray:
        """Depth past first contact [m] of tool centre(s) (…, 3): ``r - (c - point) . normal``."""
        return self.radius - (np.asarray(centres) - self.point) @ self.normal

    def max_step(self, dt: float) -> float:
        """The largest commanded move in one tick [m]."""
        _, c = self.positions(dt)
        c = np.vstack([self.knots[:1], c])
        return float(np.linalg.norm(np.diff(c, axis=0), axis=1).max())


def parse_script_text(text: str, name: str, fmt: str) -> Script:
    """Parse a touch script held in ``text`` (``fmt``: ``"toml"`` or ``"csv"``); ``name`` is the
    file name its errors carry. See :func:`parse_script`."""
    if fmt == "toml":
        return _parse_toml(text, name)
    if fmt == "csv":
        return _parse_csv(text, name)
    raise ScriptError(f"{name}: unknown script format {fmt!r} (expected a .toml or .csv file)")


def parse_script(path: PathLike) -> Script:
    """Read and validate a touch script (``.toml`` segments or ``.csv`` knots, see the module
    docstring). Raises :class:`ScriptError` naming the file and the entry."""
    path = os.fspath(path)
    name = os.path.basename(path)
    ext = os.path.splitext(name)[1].lower()
    if ext not in (".toml", ".csv"):
        raise ScriptError(f"{name}: a touch script is a .toml (segments) or .csv (t,x,y,z) file")
    text = read_text(path, error=ScriptError)
    s = parse_script_text(text, name, ext[1:])
    s.path = path
    return s


def _parse_toml(text: str, name: str) -> Script:
    c = FieldChecker(name, ScriptError)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScriptError(f"{name}: invalid TOML: {e}") from None
    c.known(doc, "", {"probe", "segment"})
    probe = c.table(doc, "probe")
    c.known(probe, "probe", _PROBE_KEYS)
    if ("point" in probe) == ("vertex" in probe):
        raise c.err("probe", 'give exactly one of point = [x, y, z] or vertex = "probe"')
    point = c.vec3(probe, "probe", "point")
    if "vertex" in probe and probe["vertex"] != "probe":
        raise c.err("probe.vertex", f'must be "probe" (the default probe point), got {probe["vertex"]!r}')
    normal = c.vec3(probe, "probe", "normal", nonzero=True)
    if normal is not None:
        normal = normal / np.linalg.norm(normal)
    gap = c.number(probe, "probe", "gap", nonneg=True)
    segs = doc.get("segment")
    if segs is None or (isinstance(segs, list) and not segs):
        raise c.err("segment", "the script has no [[segment]] (an empty script)")
    if not isinstance(segs, list) or not all(isinstance(s, dict) for s in segs):
        raise c.err("segment", "must be an array of tables ([[segment]])")
    out = []
    for i, s in enumerate(segs):
        where = f"segment[{i + 1}]"
        kind = s.get("kind")
        if kind not in _SEGMENT_KEYS:
            raise c.err(f"{where}.kind", f"must be one of {', '.join(sorted(_SEGMENT_KEYS))}, got {kind!r}")
        c.known(s, where, _SEGMENT_KEYS[kind])
        seg = Segment(kind, float(c.number(s, where, "duration", positive=True, required=True)))
        if kind == "press":
            seg.depth = float(c.number(s, where, "depth", required=True))
        elif kind == "slide":
            seg.direction = c.vec3(s, where, "direction", required=True, nonzero=True)
            seg.distance = float(c.number(s, where, "distance", nonneg=True, required=True))
        elif kind == "release":
            gap_r = c.number(s, where, "gap", nonneg=True)
            seg.gap = None if gap_r is None else float(gap_r)
        out.append(seg)
    return Script(path=name, kind="toml", point=point, normal=normal,
                  gap=DEFAULT_GAP if gap is None else float(gap), segments=out)


def _parse_csv(text: str, name: str) -> Script:
    rows = []
    header = None
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = [x.strip() for x in next(csv.reader([line]))]
        if header is None:
            header = cells
            if [h.lower() for h in cells] != ["t", "x", "y", "z"]:
                raise ScriptError(f"{name}: line {lineno}: the header must be t,x,y,z, got {line.strip()!r}")
            continue
        if len(cells) != 4:
            raise ScriptError(f"{name}: line {lineno}: expected 4 values t,x,y,z, got {len(cells)}")
        vals = []
        for col, v in zip("txyz", cells):
            try:
                f = float(v)
            except ValueError:
                raise ScriptError(f"{name}: line {lineno}: {col}: not a number: {v!r}") from None
            if not math.isfinite(f):
                raise ScriptError(f"{name}: line {lineno}: {col}: must be finite, got {v!r}")
            vals.append(f)
        if rows and not vals[0] > rows[-1][1][0]:
            raise ScriptError(f"{name}: line {lineno}: t: times must increase, got {vals[0]:g} after {rows[-1][1][0]:g}")
        rows.append((lineno, vals))
    if header is None or not rows:
        raise ScriptError(f"{name}: the script has no rows (an empty script: header t,x,y,z then one row per time)")
    if len(rows) < 2:
        raise ScriptError(f"{name}: line {rows[0][0]}: one row lasts no time; give at least two (t increasing)")
    a = np.array([v for _, v in rows], dtype=np.float64)
    return Script(path=name, kind="csv", times=a[:, 0], knots=a[:, 1:])


# -------------------------------------------------------------------------------------------- run

def default_every(n_ticks: int, frames: int = TARGET_FRAMES) -> int:
    """Ticks between VTU frames for about ``frames`` frames over ``n_ticks`` ticks."""
    return max(1, math.ceil(n_ticks / frames))


class _Series:
    """The VTU parts of each frame and the ``touch.pvd`` listing them (rewritten per frame)."""

    PARTS = ("surface", "core", "active", "tool")

    def __init__(self, out_dir: str, sim, radius: float):
        self.out_dir, self.sim, self.radius = out_dir, sim, radius
        self.frames: List[Tuple[float, List[str]]] = []
        self.tris = np.asarray(sim.surface_triangles, dtype=np.int64)
        self.tets = np.asarray(sim.core_tets, dtype=np.int64)
        self.rest_surface = np.array(sim.surface)
        self.rest_core = np.array(sim.core_positions)
        remove_frames(out_dir, self.PARTS)

    @property
    def pvd(self) -> str:
        return os.path.join(self.out_dir, "touch.pvd")

    def write(self, t: float, tool: np.ndarray) -> None:
        import meshio

        k = len(self.frames)
        s, c = np.array(self.sim.surface), np.array(self.sim.core_positions)
        active = np.asarray(self.sim.active, dtype=np.int64)
        pa = self.sim.particle_positions()[active] if active.size else np.zeros((0, 3))
        meshes = {
            "surface": meshio.Mesh(s, [("triangle", self.tris)], point_data={"displacement": s - self.rest_surface}),
            "core": meshio.Mesh(c, [("tetra", self.tets)], point_data={"displacement": c - self.rest_core}),
            "active": meshio.Mesh(pa, [("vertex", np.arange(len(pa), dtype=np.int64)[:, None])],
                                  point_data={"particle": active.astype(np.int64)}),
            "tool": meshio.Mesh(np.asarray(tool, dtype=np.float64)[None, :], [("vertex", np.array([[0]]))],
                                point_data={"radius": np.array([self.radius])}),
        }
        names = []
        for part in self.PARTS:
            if part == "active" and not active.size:
                # meshio cannot read back a VTU without points; ParaView shows the part as empty.
                continue
            fname = f"{part}_{k:05d}.vtu"
            meshio.write(os.path.join(self.out_dir, fname), meshes[part], file_format="vtu")
            names.append(fname)
        self.frames.append((float(t), names))
        self._write_pvd()

    def _write_pvd(self) -> None:
        write_pvd(self.pvd, [(t, f, self.PARTS.index(f.split("_")[0]), f.split("_")[0])
                             for t, names in self.frames for f in names])


def plot_force(rows: np.ndarray, path: str, title: str = "") -> bool:
    """``force.png``: normal force [N] against depth [mm], and |f| and the normal force against
    time [s]; ``rows`` (n, len(COLUMNS)) as in ``force.csv``. False (and nothing written) without
    matplotlib."""
    try:
        import matplotlib
    except ImportError:  # an extra (palpate[plot]): the CSV holds the same data
        print(f"(matplotlib not installed: no {os.path.basename(path)}; {install_hint('plot')})")
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    col = {k: i for i, k in enumerate(COLUMNS)}
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    if len(rows):
        a1.plot(rows[:, col["depth"]] * 1e3, rows[:, col["fn"]], lw=1.0)
        a2.plot(rows[:, col["t"]], rows[:, col["f"]], lw=1.0, label="|f|")
        a2.plot(rows[:, col["t"]], rows[:, col["fn"]], lw=1.0, label="normal")
        a2.legend(fontsize=8)
    a1.axvline(0.0, color="0.6", lw=0.8, ls="--")
    a1.set_xlabel("depth past first contact [mm]")
    a1.set_ylabel("normal force on the tool [N]")
    a2.set_xlabel("time [s]")
    a2.set_ylabel("force on the tool [N]")
    for a in (a1, a2):
        a.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def run_touch(sim, script: Union[Script, "Trajectory"], out_dir: PathLike, *, dt: float = 1e-3,
              every: Optional[int] = None, on_tick: Optional[Callable[[int, float, np.ndarray, np.ndarray], None]] = None,
              tool_radius: Optional[float] = None, title: str = "", plot: bool = True) -> Dict[str, Any]:
    """Run ``script`` on ``sim`` (a :class:`palpate.HybridSim`, at rest) with ticks of ``dt`` [s],
    writing ``force.csv``, ``force.png`` and the VTU series (a frame at t = 0 and every ``every``
    ticks, default :func:`default_every`; the last tick's too) to ``out_dir``.

    ``tool_radius`` [m] is the radius ``sim`` was made with (default: ``sim.tool_radius``; the
    binding has no getter) and defines the depth. ``on_tick(k, t, tool (3,), force (3,))`` is called after each tick ``k`` (1-based). Returns a
    summary: ``ticks``, ``duration_s``, ``wall_s`` (stepping only), ``ticks_per_s``,
    ``tick_ms_median``, ``tick_ms_p99``, ``tick_ms_max``, ``max_force_N``, ``max_normal_force_N``,
    ``max_depth_m``, ``max_active``, ``frames``, ``every``, ``max_step_m`` (largest commanded move
    a tick), ``point``, ``normal``, ``vertex``, and the paths ``csv``, ``png``, ``pvd``.

    Raises :class:`TouchFailed` (with the summary so far, outputs written) when a tick raises
    :class:`palpate.StepError`.
    """
    from ._palpate import StepError

    if not (dt > 0 and math.isfinite(dt)):
        raise ParameterError(f"dt = {dt} s must be positive and finite")
    out_dir = os.fspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    traj = script if isinstance(script, Trajectory) else script.resolve(
        sim.surface, sim.surface_triangles, sim.tool_radius if tool_radius is None else tool_radius)
    times, centres = traj.positions(dt)
    n = len(times)
    every = default_every(n) if every is None else int(every)
    if every < 1:
        raise ParameterError(f"every = {every} must be at least 1")
    depths = traj.depth(centres)
    series = _Series(out_dir, sim, traj.radius)
    series.write(0.0, traj.knots[0])
    csv_path, png_path = os.path.join(out_dir, "force.csv"), os.path.join(out_dir, "force.png")
    rows: List[List[float]] = []
    tick_s = np.zeros(n)
    failed: Optional[Tuple[int, str]] = None
    shed = off = 0
    with open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for k in range(n):
            c = centres[k]
            t0 = time.perf_counter()
            try:
                f = np.asarray(sim.step(c, dt))
            except StepError as e:
                failed = (k + 1, str(e))
                break
            tick_s[k] = time.perf_counter() - t0
            last = sim.last
            # A failed shell step is shed and the tick goes on (HybridSim's shell_fallback).
            shed += bool(last.get("shell_failed", False))
            off += bool(last.get("shell_off", False))
            row = [times[k], c[0], c[1], c[2], depths[k], f[0], f[1], f[2], float(np.linalg.norm(f)),
                   float(f @ traj.normal), last["active"], last["particle_contacts"] + last["skin_contacts"],
                   last["core_contacts"], last["substeps"], 1e3 * tick_s[k]]
            rows.append(row)
            w.writerow([_fmt(v) for v in row])
            if (k + 1) % every == 0 or k + 1 == n:
                fh.flush()
                series.write(times[k], c)
            if on_tick is not None:
                on_tick(k + 1, float(times[k]), c, f)
    a = np.array(rows, dtype=np.float64).reshape(-1, len(COLUMNS))
    plotted = plot and plot_force(a, png_path, title)
    done = len(rows)
    ts = tick_s[:done]
    col = {k: i for i, k in enumerate(COLUMNS)}
    summary: Dict[str, Any] = {
        "ticks": done, "ticks_planned": n, "dt_s": dt, "duration_s": done * dt,
        "wall_s": float(ts.sum()), "ticks_per_s": float(done / ts.sum()) if done and ts.sum() > 0 else None,
        "tick_ms_median": float(1e3 * np.median(ts)) if done else None,
        "tick_ms_p99": float(1e3 * np.percentile(ts, 99)) if done else None,
        "tick_ms_max": float(1e3 * ts.max()) if done else None,
        "max_force_N": float(a[:, col["f"]].max()) if done else 0.0,
        "max_normal_force_N": float(a[:, col["fn"]].max()) if done else 0.0,
        "max_depth_m": float(a[:, col["depth"]].max()) if done else None,
        "max_active": int(a[:, col["active"]].max()) if done else 0,
        "frames": len(series.frames), "every": every, "max_step_m": traj.max_step(dt),
        "point": traj.point.tolist(), "normal": traj.normal.tolist(), "vertex": traj.vertex,
        "csv": csv_path, "png": png_path if plotted else None, "pvd": series.pvd,
        "error": None, "t_failed_s": None,
        "shell_shed": shed, "shell_off_ticks": off,
    }
    if failed is not None:
        tick, reason = failed
        summary["error"], summary["t_failed_s"] = reason, float(times[tick - 1])
        raise TouchFailed(tick, reason, summary)
    return summary


def _fmt(v: float) -> str:
    return repr(v) if isinstance(v, int) else f"{v:.9g}"




#: A press, hold, slide and release at the default probe point (``examples/scripts/press_hold_slide.toml``):
#: what ``make demo`` runs on the Rodero et al. ventricle.
DEFAULT_SCRIPT = """\
# palpate touch: press 4 mm at the default probe point, hold, slide 8 mm towards +z, hold, release.
[probe]
vertex = "probe"     # the outer vertex nearest (x_max, y_mid, z at 20/42 of the height): see palpate.touch
gap = 0.002          # start 2 mm clear of the surface [m]

[[segment]]
kind = "press"       # approach (2 mm) and press 4 mm past first contact, along the inward normal
depth = 0.004
duration = 0.6

[[segment]]
kind = "hold"
duration = 0.3

[[segment]]
kind = "slide"       # in the tangent plane at the probe point
direction = [0.0, 0.0, 1.0]
distance = 0.008
duration = 0.8

[[segment]]
kind = "hold"
duration = 0.2

[[segment]]
kind = "release"     # back out to the probe's gap
duration = 0.4
"""


def default_script() -> Script:
    """:data:`DEFAULT_SCRIPT`, parsed."""
    return parse_script_text(DEFAULT_SCRIPT, "press_hold_slide.toml", "toml")
