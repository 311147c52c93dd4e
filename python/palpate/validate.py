"""Sphere indentation of the hybrid model against references palpate computes itself (issue 33).

What the hand feels is the product, so the hybrid's force and dent are measured against:

- **the converged FEM of the same wall**: palpate's full-FEM body (:class:`palpate.Body`), the
  same law and constants, the same held region, pressed by the same rigid frictionless sphere
  to static equilibrium (:meth:`palpate.Body.indent`: Newton on the full Green-strain forces, a
  stiff penalty integrated over the surface), on meshes refined until the force changes by under
  3% over the last refinement (or extrapolated, with the evidence printed);
- **the coarse FEM** of about the hybrid core's size (the paper's alternative);
- **Hertz** on a thick slab (``python/tests/test_validate.py``, ``tests/indentation.rs``).

Every curve is reported against the **indentation**: the tool's travel beyond first contact minus
the deepest penetration of its contact law (how far the surface was pushed in), so that no
penalty enters a comparison. The dent is the outer surface's displacement along the press at
distances from the tool's axis.

The reference walls are the shipped shapes' exact walls: for ``"ellipsoids"`` the region between
the paper's two ellipsoids, meshed as a geodesic sphere extruded in layers
(:func:`palpate.ellipsoid_wall`) and graded toward the tool by a conformal map of the sphere
(:func:`graded_ellipsoid_wall`), so that the contact is resolved without a uniform mesh of
millions of tets. Other walls (the synthetic
ventricle, Rodero's) are meshed by the hybrid build itself with its core taken across the whole
wall (:func:`wall_mesh`): the inner surface simplified, prism layers along the transmural field to
the outer surface; that mesh is uniform, so its contact converges only as the whole mesh is
refined. On the synthetic ventricle it serves; on Rodero's ventricle its prisms are nearly flat at
500 triangles (min dihedral 0.02 deg, 137 of the wall's 163 mL) and twist from 2,000 on, so
Rodero's wall is meshed by gmsh (the ``validate`` extra) instead (:func:`gmsh_wall`): the data's
closed surface (endocardium, epicardium and valve caps in one piece; the two four-triangle specks
its repair leaves are dropped, they intersect it), simplified by palpate's own quadric-error
simplifier to the level's triangle count (:meth:`palpate.TriSurface.simplified`), then filled
with tets by gmsh's Delaunay mesher keeping that surface: uniform levels, each halving the
element size (:data:`GMSH_LEVELS`).

All lengths in metres, forces in newtons, world frame.
"""

from __future__ import annotations

import functools
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _palpate
from . import defaults as _defaults
from .hybrid import ELLIPSOIDS_INNER, ELLIPSOIDS_OUTER
from ._extras import install_hint

__all__ = [
    "IndentCase",
    "graded_ellipsoid_wall",
    "reference_curve",
    "hybrid_curve",
    "dent_profile",
    "hertz_force",
    "slab_surface",
    "run_indentation",
    "REFERENCE_LEVELS",
    "BUILT_LEVELS",
    "wall_mesh",
    "gmsh_wall",
    "GMSH_LEVELS",
    "QUADRATIC_LEVELS",
]

#: Mesh levels of the ellipsoid wall's reference: (subdivisions of the geodesic sphere, tet layers
#: across the wall); each level halves the element size. With :data:`GRADING` the elements under
#: the tool are 4x smaller than a uniform mesh's of the same level.
REFERENCE_LEVELS: Tuple[Tuple[int, int], ...] = ((3, 2), (4, 4), (5, 8))

#: Mesh levels of a wall palpate meshes through the hybrid build (every shipped wall but the
#: ellipsoids): (triangles of the simplified inner surface, prism layers to the outer surface).
BUILT_LEVELS: Tuple[Tuple[int, int], ...] = ((1000, 2), (4000, 4), (16000, 8))

#: Mesh levels of a wall meshed by gmsh (Rodero's): (triangles of the simplified closed surface,
#: 0); each level halves the element size (measured on Rodero: 2,241, 11,228 and 68,921 tets).
GMSH_LEVELS: Tuple[Tuple[int, int], ...] = ((1500, 0), (6000, 0), (24000, 0))

#: The references' mesh levels in quadratic tets (``order=2``, the default), per kind of wall:
#: the linear levels' a level coarser (a quadratic tet has a smaller error than the linear tets of
#: the same nodes: VALIDATION.md, "The reference in quadratic tets"). A wall meshed by gmsh keeps
#: its finest linear level's surface and refines by sqrt(2): its surface at 600 triangles is
#: another wall (Rodero's force 40% lower than at 1,500, where the linear levels fall steadily).
QUADRATIC_LEVELS: Dict[str, Tuple[Tuple[int, int], ...]] = {
    "ellipsoids": ((2, 1), (3, 2), (4, 4)),
    "gmsh": ((1500, 0), (3000, 0), (6000, 0)),
    "built": ((250, 1), (1000, 2), (4000, 4)),
}

#: The walls meshed by gmsh rather than by the hybrid build's prisms.
GMSH_SHAPES = ("rodero",)

#: The core fraction that makes the hybrid build's core span the wall (a full-FEM mesh of it).
WALL_FRACTION = 0.999

#: Grading of the reference wall: element size under the tool over the uniform mesh's.
GRADING = 4.0

#: The reference counts as converged when its force changes by less than this over the last
#: refinement (issue 33).
CONVERGED = 0.03

#: Distances of the dent profile from the tool's axis [m].
DENT_DISTANCES = (0.005, 0.010, 0.020)


def hertz_force(young: float, poisson: float, radius: float, depth: np.ndarray) -> np.ndarray:
    """Hertz's force [N] of a rigid sphere of ``radius`` [m] pressed ``depth`` [m] into an elastic
    half-space: ``4/3 E/(1 - nu^2) sqrt(R) d^(3/2)``."""
    d = np.asarray(depth, dtype=float)
    return 4.0 / 3.0 * young / (1.0 - poisson**2) * math.sqrt(radius) * np.clip(d, 0.0, None) ** 1.5


def slab_surface(width: float, height: float, cells: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A box ``[-w/2, w/2]^2 x [0, h]`` [m] as one closed surface for
    :meth:`palpate.HybridModel.build_tagged`: ``cells x cells`` quads on top and bottom (and as
    many as fit on the sides), split into outward-facing triangles. Returns points (k, 3) [m],
    triangles (m, 3) and their parts (m,): 0 the bottom (inner: the core grows up from it), 1 the
    top (outer: the skin), 2 the sides (base: the runtime holds the core's nodes there; the bottom
    is free). The hybrid's Hertz slab (``bench/hybrid_slab.py``, ``tests/test_validate.py``)."""
    nz = max(2, round(cells * height / width))
    ids: Dict[Tuple[float, float, float], int] = {}

    def pid(p: Tuple[float, float, float]) -> int:
        return ids.setdefault(tuple(np.round(p, 12)), len(ids))

    tris: List[List[int]] = []
    parts: List[int] = []

    def quad(a, b, c, d, part: int) -> None:  # counter-clockwise seen from outside
        tris.extend([[pid(a), pid(b), pid(c)], [pid(a), pid(c), pid(d)]])
        parts.extend([part, part])

    xs, zs = np.linspace(-width / 2, width / 2, cells + 1), np.linspace(0.0, height, nz + 1)
    w2 = width / 2
    for i in range(cells):
        for j in range(cells):
            x0, x1, y0, y1 = xs[i], xs[i + 1], xs[j], xs[j + 1]
            quad((x0, y0, height), (x1, y0, height), (x1, y1, height), (x0, y1, height), 1)
            quad((x0, y0, 0.0), (x0, y1, 0.0), (x1, y1, 0.0), (x1, y0, 0.0), 0)
    for i in range(cells):
        a, b = xs[i], xs[i + 1]
        for k in range(nz):
            z0, z1 = zs[k], zs[k + 1]
            quad((a, -w2, z0), (b, -w2, z0), (b, -w2, z1), (a, -w2, z1), 2)
            quad((b, w2, z0), (a, w2, z0), (a, w2, z1), (b, w2, z1), 2)
            quad((w2, a, z0), (w2, b, z0), (w2, b, z1), (w2, a, z1), 2)
            quad((-w2, b, z0), (-w2, a, z0), (-w2, a, z1), (-w2, b, z1), 2)
    points = np.zeros((len(ids), 3))
    for q, k in ids.items():
        points[k] = q
    return points, np.array(tris, dtype=np.int64), np.array(parts, dtype=np.int64)


def _mobius(dirs: np.ndarray, focus: np.ndarray, k: float) -> np.ndarray:
    """Unit vectors ``dirs`` (m, 3) moved toward the unit ``focus`` by the conformal map of the
    sphere that scales the stereographic plane (projected from ``-focus``) by ``1/k``: spacing
    near ``focus`` shrinks ``k`` times, near ``-focus`` grows ``k`` times, angles are kept."""
    f = focus / np.linalg.norm(focus)
    # Frame (e1, e2, f); stereographic projection from -f onto the plane through the origin.
    a = np.array([1.0, 0.0, 0.0]) if abs(f[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(f, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(f, e1)
    z = dirs @ f
    x, y = dirs @ e1, dirs @ e2
    with np.errstate(divide="ignore", invalid="ignore"):
        u, v = x / (1.0 + z), y / (1.0 + z)
    u, v = u / k, v / k
    r2 = u * u + v * v
    out = (np.outer(2 * u / (1 + r2), e1) + np.outer(2 * v / (1 + r2), e2) + np.outer((1 - r2) / (1 + r2), f))
    far = ~np.isfinite(out).all(axis=1)
    out[far] = -f
    return out


def graded_ellipsoid_wall(inner: Sequence[float] = ELLIPSOIDS_INNER, outer: Sequence[float] = ELLIPSOIDS_OUTER,
                          subdivisions: int = 4, layers: int = 4, focus: Sequence[float] = (1.0, 0.0, 0.0),
                          grading: float = GRADING) -> _palpate.TetMesh:
    """The wall between two concentric ellipsoids (semi-axes [m]) as :func:`palpate.ellipsoid_wall`
    meshes it, with its directions moved toward ``focus`` by a conformal map of the sphere
    (:func:`_mobius`): elements ``grading`` times smaller around ``focus``, as many times larger
    opposite it, the same topology and no sliver (the map keeps angles)."""
    base = _palpate.ellipsoid_wall(tuple(inner), tuple(outer), subdivisions=subdivisions, layers=layers)
    pts = base.points
    nv = 4 * 4**subdivisions + 2
    dirs = pts[:nv] / np.linalg.norm(pts[:nv], axis=1)[:, None]
    if grading != 1.0:
        dirs = _mobius(dirs, np.asarray(focus, dtype=float), grading)

    def onto(axes):
        a = np.asarray(axes, dtype=float)
        s = np.sqrt(((dirs / a) ** 2).sum(axis=1))
        return dirs / s[:, None]

    p_in, p_out = onto(inner), onto(outer)
    new = np.concatenate([p_in + (p_out - p_in) * (l / layers) for l in range(layers + 1)])
    return _palpate.TetMesh(new, base.tets)


@dataclass
class IndentCase:
    """One indentation: the wall, where and how it is held, the tool and the press.

    ``point`` [m] is on the outer surface, ``direction`` the unit press direction (into the
    wall). Nodes below ``hold_z`` [m] are held (the hybrid runtime's rule for a closed wall: its
    core nodes within 30% of the core's height from its lowest point; the reference holds every
    node of the wall there).
    """

    shape: str = "ellipsoids"
    young: float = _defaults.tissue.young         # [Pa]: the default tissue (palpate.defaults.tissue)
    poisson: float = _defaults.tissue.poisson
    density: float = _defaults.tissue.density     # [kg/m^3]
    tool_radius: float = 0.005
    point: Tuple[float, float, float] = (ELLIPSOIDS_OUTER[0], 0.0, 0.0)
    direction: Tuple[float, float, float] = (-1.0, 0.0, 0.0)
    depths: Tuple[float, ...] = (0.002, 0.004, 0.006)
    hold_z: Optional[float] = None
    #: The reference's law: "neo-hookean" (default) or "svk". At small strain both are linear
    #: elasticity with the same Lame constants; under a sphere pressed several millimetres into
    #: a 6 mm wall St. Venant-Kirchhoff softens in compression until the wall under the sphere
    #: collapses (the paper's ellipsoids, 5 mm sphere, 5.5 mm of travel: at a fixed sphere the
    #: force falls from 0.12 N to 0.007 N as the elements under it invert), which no tissue does.
    reference_law: str = "neo-hookean"

    def material(self, law: str = "svk") -> _palpate.Material:
        lw = {"svk": _palpate.Law.ST_VENANT_KIRCHHOFF, "neo-hookean": _palpate.Law.NEO_HOOKEAN}[law]
        return _palpate.Material(young=self.young, poisson=self.poisson, density=self.density, law=lw)

    def start(self) -> np.ndarray:
        """The tool's centre 1 mm outside the surface along the axis."""
        return np.asarray(self.point) - (self.tool_radius + 1e-3) * np.asarray(self.direction)


def dent_probes(case: "IndentCase", surface: Tuple[np.ndarray, np.ndarray],
                distances: Sequence[float] = DENT_DISTANCES, azimuths: int = 4) -> np.ndarray:
    """Rest points of the outer ``surface`` (points [m], triangles) at each of ``distances`` [m]
    from the press axis, in ``azimuths`` directions around it: where the line through the offset
    point along the press meets the surface nearest the pressed side. (len(distances),
    azimuths, 3)."""
    p, n = np.asarray(case.point, dtype=float), np.asarray(case.direction, dtype=float)
    a = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    pts, tris = surface
    v0, v1, v2 = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    out = np.zeros((len(distances), azimuths, 3))
    for i, r in enumerate(distances):
        for j in range(azimuths):
            ang = 2 * math.pi * j / azimuths
            q = p + r * (math.cos(ang) * e1 + math.sin(ang) * e2)
            # Moller-Trumbore against every triangle: the hit with the smallest |t|.
            ea, eb = v1 - v0, v2 - v0
            h = np.cross(n, eb)
            det = (ea * h).sum(axis=1)
            ok = np.abs(det) > 1e-300
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            sv = q - v0
            u = (sv * h).sum(axis=1) * inv
            qv = np.cross(sv, ea)
            w = (qv @ n) * inv
            t = (qv * eb).sum(axis=1) * inv
            hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1)
            if not hit.any():
                out[i, j] = np.nan  # the surface ends before (a base, a valve ring)
                continue
            k = np.flatnonzero(hit)[np.argmin(np.abs(t[hit]))]
            out[i, j] = q + t[k] * n
    return out


def surface_weights(points: np.ndarray, tris: np.ndarray, probes: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """For each probe point (..., 3), the triangle of ``tris`` nearest to it at rest and the
    barycentric weights of the probe's projection onto it (clamped to the triangle)."""
    a, b, c = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    cen = (a + b + c) / 3
    idx, w = [], []
    for q in probes.reshape(-1, 3):
        if not np.isfinite(q).all():
            idx.append(0)
            w.append(np.full(3, np.nan))
            continue
        best: Optional[Tuple[float, int, np.ndarray]] = None
        for t in np.argsort(((cen - q) ** 2).sum(axis=1))[:8]:
            e0, e1 = b[t] - a[t], c[t] - a[t]
            m = np.array([[e0 @ e0, e0 @ e1], [e0 @ e1, e1 @ e1]])
            uv = np.linalg.solve(m, [e0 @ (q - a[t]), e1 @ (q - a[t])])
            bw = np.clip(np.array([1 - uv.sum(), uv[0], uv[1]]), 0, None)
            bw /= bw.sum()
            d = float(np.linalg.norm(bw @ np.array([a[t], b[t], c[t]]) - q))
            if best is None or d < best[0]:
                best = (d, int(t), bw)
        assert best is not None
        idx.append(best[1])
        w.append(best[2])
    return np.array(idx), np.array(w)


def dent_profile(rest: np.ndarray, moved: np.ndarray, tris: np.ndarray, where: Tuple[np.ndarray, np.ndarray],
                 direction: Sequence[float], shape: Tuple[int, ...]) -> np.ndarray:
    """The surface's displacement along ``direction`` [m] (into the wall: positive) at the probe
    points ``where`` (:func:`surface_weights`), averaged over the azimuths of each distance."""
    idx, w = where
    u = ((moved - rest)[tris[idx]] * w[:, :, None]).sum(axis=1) @ np.asarray(direction, dtype=float)
    u = u.reshape(shape)
    ok = np.isfinite(u)
    return np.where(ok.any(axis=1), np.where(ok, u, 0.0).sum(axis=1) / np.maximum(ok.sum(axis=1), 1), np.nan)


def held_below(points: np.ndarray, z: float) -> np.ndarray:
    return np.nonzero(points[:, 2] <= z)[0]


def _compact(points: np.ndarray, cells: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The points ``cells`` use, in order, and the cells renumbered onto them."""
    used = np.unique(cells)
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    return points[used], renumber[cells]


def gmsh_wall(surface: _palpate.TriSurface, triangles: Optional[int] = None) -> _palpate.TetMesh:
    """The solid inside a closed ``surface`` [m] as linear tets: the surface simplified to at most
    ``triangles`` triangles (:meth:`palpate.TriSurface.simplified`; ``None``: as given), then
    filled by gmsh's Delaunay mesher, which keeps that surface as the mesh's boundary and sizes
    the inside from it. Needs gmsh (the ``validate`` extra); a surface that crosses
    itself is refused by gmsh ("PLC Error: a segment and a facet intersect"), raised as a
    ``ModelError``."""
    try:
        import gmsh
    except (ImportError, OSError) as e:
        raise _palpate.ModelError(f"meshing a wall needs gmsh, which could not be imported ({e}): "
                                  f"{install_hint('validate')}") from None
    if triangles is not None and triangles < surface.n_triangles:
        surface = surface.simplified(int(triangles))
    pts, tris = np.asarray(surface.points), np.asarray(surface.triangles)
    # gmsh's initialize sets SIGPIPE's disposition back to the default in the whole process, where
    # Python ignores it: a later write to a closed socket or pipe (the viewer's, the bridge's)
    # then kills the process instead of raising BrokenPipeError. Found by the test suite's
    # sigaction check (python/tests/conftest.py), which two CI runs killed by SIGPIPE led to.
    import signal
    import threading

    main_thread = threading.current_thread() is threading.main_thread()
    sigpipe = signal.getsignal(signal.SIGPIPE) if main_thread else None
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    if sigpipe is not None:
        signal.signal(signal.SIGPIPE, sigpipe)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay: keeps the given surface
        gmsh.model.add("wall")
        s = gmsh.model.addDiscreteEntity(2)
        gmsh.model.mesh.addNodes(2, s, np.arange(1, len(pts) + 1), pts.ravel())
        gmsh.model.mesh.addElementsByType(s, 2, [], (tris + 1).ravel())
        gmsh.model.geo.addVolume([gmsh.model.geo.addSurfaceLoop([s])])
        gmsh.model.geo.synchronize()
        try:
            gmsh.model.mesh.generate(3)
        except Exception as e:  # gmsh raises a bare Exception with its last error
            raise _palpate.ModelError(f"gmsh could not mesh the wall ({surface.n_triangles} triangles): {e}") from None
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, nodes = gmsh.model.mesh.getElementsByType(4)
    finally:
        gmsh.finalize()
        if sigpipe is not None:
            signal.signal(signal.SIGPIPE, sigpipe)
    index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    tets = index[np.asarray(nodes, dtype=np.int64).reshape(-1, 4)]
    return _palpate.TetMesh(*_compact(np.asarray(coords, dtype=float).reshape(-1, 3), tets))


@functools.lru_cache(maxsize=1)
def rodero_surface() -> Tuple[_palpate.TriSurface, np.ndarray]:
    """Rodero's left ventricle [m] as one closed surface (without its two specks,
    :meth:`palpate.TriSurface.without_specks`)
    and the points of its base (the valve caps: where the hybrid holds it) [m], (k, 3), read-only.
    Read once per process (every reference level of a run meshes the same surface)."""
    import warnings

    from .data import rodero_lv_path
    from .hybrid import read_tagged_surface
    from .surfaces import BASE

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", _palpate.MeshWarning)  # the known repair of the shipped file
        points, triangles, part = read_tagged_surface(rodero_lv_path(), unit="mm")
    base = np.asarray(points)[np.unique(np.asarray(triangles)[np.asarray(part) == BASE])]
    base.setflags(write=False)
    surface, _ = _palpate.TriSurface(points, triangles, source="Rodero left ventricle").without_specks()
    return surface, base


def held_at_base(mesh: _palpate.TetMesh, surface: _palpate.TriSurface, base: np.ndarray) -> np.ndarray:
    """The boundary nodes of ``mesh`` (a wall meshed inside ``surface``, maybe simplified) that
    lie on the base: those whose nearest vertex of ``surface`` is one of the ``base`` points [m]
    (the hybrid runtime holds a ventricle's core at its base nodes, so its reference holds the
    wall's base)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(surface.points))
    is_base = np.zeros(surface.n_vertices, dtype=bool)
    is_base[tree.query(base)[1]] = True
    on_surface = np.unique(mesh.boundary_faces())
    return on_surface[is_base[tree.query(np.asarray(mesh.points)[on_surface])[1]]]


def wall_mesh(shape: str, a: int, b: int, case: IndentCase, graded: bool = True
              ) -> Tuple[_palpate.TetMesh, Optional[np.ndarray]]:
    """A full-FEM mesh of the shipped wall ``shape`` and its held nodes (None: below the case's
    ``hold_z``).

    ``"ellipsoids"``: ``a`` subdivisions of the geodesic sphere, ``b`` layers, graded toward the
    tool (:func:`graded_ellipsoid_wall`) unless ``graded`` is false. ``"rodero"``: its closed
    surface simplified to ``a`` triangles and filled with tets by gmsh (:func:`gmsh_wall`; ``b``
    unused, 0), held at its base (:func:`held_at_base`), as the hybrid is. Other walls: the hybrid
    build's own core, taken across the whole wall (core fraction :data:`WALL_FRACTION`): the inner
    surface simplified to ``a`` triangles, ``b`` prism layers along the transmural field to the
    outer surface, held at its base nodes (a closed wall: below ``hold_z``).
    """
    if shape == "ellipsoids":
        if graded:
            return graded_ellipsoid_wall(subdivisions=a, layers=b, focus=-np.asarray(case.direction)), None
        return _palpate.ellipsoid_wall(ELLIPSOIDS_INNER, ELLIPSOIDS_OUTER, subdivisions=a, layers=b), None
    if shape in GMSH_SHAPES:
        surface, base = rodero_surface()
        mesh = gmsh_wall(surface, a)
        return mesh, held_at_base(mesh, surface, base)
    from .hybrid import build_shape

    try:
        m = build_shape(shape, core_fraction=WALL_FRACTION, core_triangles=a, core_layers=b, particles=2000)
    except _palpate.ModelError as e:
        raise _palpate.ModelError(f"the reference mesh of {shape!r} (the build's core across the wall, {a} "
                                  f"triangles, {b} layers) could not be built: {e}. The prism layers of the build "
                                  f"twist on a wall as irregular as Rodero's at fine levels; such a wall needs a "
                                  f"tet mesher (VALIDATION.md)") from None
    base = np.asarray(m.core_base_nodes)
    return _palpate.TetMesh(m.core_points, m.core_tets), (base if len(base) else None)


def reference_curve(mesh: _palpate.TetMesh, case: IndentCase, probes: np.ndarray, *,
                    fixed: Optional[np.ndarray] = None, max_increment: Optional[float] = None,
                    verbose: bool = False, order: int = 1) -> Dict[str, Any]:
    """The static indentation of the full-FEM wall ``mesh`` (:meth:`palpate.Body.indent`) at the
    case's depths of *travel* (the indentation, travel minus the penalty's penetration, is
    reported beside it): force along the press [N] and the dent profile. ``order``: the
    elements' degree (1: linear tets, 2: quadratic; ``fixed`` indexes the mesh's vertices, and
    the dent is read at them)."""
    if fixed is None:
        if case.hold_z is None:
            raise ValueError("the case needs hold_z (from the hybrid model's core: see hybrid_hold_z) or fixed nodes")
        fixed = held_below(mesh.points, case.hold_z)
    body = _palpate.Body(mesh, case.material(case.reference_law), fixed=fixed, order=order)
    t = time.perf_counter()
    r = body.indent(case.start(), case.direction, case.tool_radius, _travels(case.depths, 0.2),
                    max_increment=max_increment or case.tool_radius / 10)
    wall = time.perf_counter() - t
    faces = mesh.boundary_faces()
    # The probes lie on the outer surface: their nearest boundary triangles are outer ones.
    where = surface_weights(mesh.points, faces, probes)
    nv = mesh.n_nodes
    dents = np.array([dent_profile(mesh.points, x[:nv], faces, where, case.direction, probes.shape[:2])
                      for x in r["positions"]])
    out = dict(tets=mesh.n_tets, nodes=body.n_nodes, order=order, travel=r["travel"], force=r["force_along"],
               indentation=r["indentation"], penetration=r["penetration"], dent=dents,
               iterations=r["iterations"], factorisations=r["factorisations"], wall_s=wall)
    if verbose:
        print(f"  FEM {mesh.n_tets} {'quadratic ' if order == 2 else ''}tets: " + ", ".join(f"{f:.4f} N" for f in out["force"]) + f" ({wall:.1f} s)",
              flush=True)
    return out


def _travels(depths: Sequence[float], extra: float) -> np.ndarray:
    """The travels of a press whose indentations should span ``depths``: the depths and one more
    ``extra`` of the deepest beyond (the contact's penetration is not indentation)."""
    d = np.asarray(depths, dtype=float)
    return np.r_[d, d[-1] * (1 + extra)]


def hybrid_hold_z(sim: _palpate.HybridSim) -> float:
    """The height below which a closed wall's hybrid runtime holds its core nodes (30% of the
    core's height above its lowest point, ``runtime::Sim::new``), from the core's positions now:
    call it on a fresh sim (at rest)."""
    z = sim.core_positions[:, 2]
    return float(z.min() + 0.3 * (z.max() - z.min()))


def hybrid_curve(model: _palpate.HybridModel, case: IndentCase, *, ramp_s: float = 0.5, hold_s: float = 0.5,
                 dt: float = 1e-3, verbose: bool = False, implicit_exchange: bool = True) -> Dict[str, Any]:
    """The hybrid model pressed quasi-statically to the case's travels: per depth a ramp of
    ``ramp_s`` then a hold of ``hold_s`` at ``1/dt`` Hz, force and penetration averaged over the
    hold's second half (settled: its standard deviation is reported). ``implicit_exchange``: the
    ``HybridSim`` option (the shell's springs at the tissue's stiffness; False: capped, for
    comparison)."""
    sim = _palpate.HybridSim(model, case.material(), tool_radius=case.tool_radius, implicit_exchange=implicit_exchange)
    hold_z = hybrid_hold_z(sim)  # at rest, where the runtime chose its held nodes
    p, n = np.asarray(case.point, dtype=float), np.asarray(case.direction, dtype=float)
    s0 = sim.surface.copy()
    # First contact with the skin at rest: the travel at which the sphere meets a skin vertex.
    start = case.start()
    q = s0 - start
    b = q @ n
    disc = b * b - ((q * q).sum(axis=1) - case.tool_radius**2)
    ok = disc >= 0
    t0 = float((b[ok] - np.sqrt(disc[ok])).min())
    tris = sim.surface_triangles
    probes = dent_probes(case, (s0, tris))
    where = surface_weights(s0, tris, probes)
    rows: List[Dict[str, Any]] = []
    prev = 0.0
    # Approach from 1 mm outside.
    for j in range(200):
        sim.step(start + n * (t0 - 1e-3 + 1e-3 * (j + 1) / 200), dt)
    t_start = time.perf_counter()
    for d in _travels(case.depths, 0.3):
        n_ramp, n_hold = int(round(ramp_s / dt)), int(round(hold_s / dt))
        acc = []
        for j in range(n_ramp + n_hold):
            depth = prev + (d - prev) * min(1.0, (j + 1) / n_ramp)
            f = sim.step(start + n * (t0 + depth), dt)
            if j >= n_ramp + n_hold // 2:
                pen = sim.last["max_depth_m"]
                acc.append((float(f @ (-n)), pen))
        a = np.array(acc)
        rows.append(dict(travel=d, force=a[:, 0].mean(), force_sd=a[:, 0].std(), penetration=a[:, 1].mean(),
                         indentation=d - a[:, 1].mean(), active=sim.last["active"],
                         dent=dent_profile(s0, sim.surface, tris, where, n, probes.shape[:2])))
        prev = d
    out = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    out["wall_s"] = time.perf_counter() - t_start
    out["hold_z"] = hold_z
    out["core_tets"] = len(sim.core_tets)
    out["core_stiffening"] = sim.options["core_stiffening"]
    out["core_active_stiffening"] = sim.options["core_active_stiffening"]
    out["probes"] = probes
    if verbose:
        print("  hybrid: " + ", ".join(f"{f:.4f} N" for f in out["force"]) + f" ({out['wall_s']:.1f} s; "
              f"{out['core_tets']}-tet core stiffened {out['core_stiffening']:.2f}x away from the active shell, "
              f"{out['core_active_stiffening']:.2f}x under it)",
              flush=True)
    return out


def _interp(curve: Dict[str, Any], at: np.ndarray, key: str = "force") -> np.ndarray:
    """``curve[key]`` at indentations ``at`` (linear through the origin and the curve's points,
    per column for a 2-d value; nan beyond its deepest)."""
    x = np.concatenate([[0.0], curve["indentation"]])
    y = np.asarray(curve[key], dtype=float)
    if y.ndim == 2:
        return np.stack([_interp(dict(indentation=curve["indentation"], v=y[:, j]), at, "v")
                         for j in range(y.shape[1])], axis=1)
    y = np.concatenate([[0.0], y])
    v = np.interp(at, x, y)
    v[at > x[-1] * (1 + 1e-9)] = np.nan
    return v


def _richardson(h: np.ndarray, f: np.ndarray) -> Tuple[float, float]:
    """The h -> 0 limit of ``f = f0 + C h^p`` through three values ``f`` at element sizes ``h``
    (decreasing), and the order ``p`` (nan, nan if the differences do not shrink monotonically)."""
    d1, d2 = f[1] - f[0], f[2] - f[1]
    if d1 == 0 or d2 / d1 <= 0 or abs(d2) >= abs(d1):
        return float("nan"), float("nan")
    target = d2 / d1  # = (h2^p - h1^p) / (h1^p - h0^p), falls from ~1 toward 0 as p grows

    def ratio(p: float) -> float:
        return (h[2] ** p - h[1] ** p) / (h[1] ** p - h[0] ** p)

    lo, hi = 1e-3, 20.0
    if not (ratio(hi) < target < ratio(lo)):
        return float("nan"), float("nan")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ratio(mid) > target else (lo, mid)
    p = 0.5 * (lo + hi)
    c = d2 / (h[2] ** p - h[1] ** p)
    return float(f[2] - c * h[2] ** p), p


def default_levels(shape: str, order: int = 1) -> Tuple[Tuple[int, int], ...]:
    """The reference's mesh levels of a shipped wall in elements of ``order``: linear,
    :data:`REFERENCE_LEVELS` (ellipsoids), :data:`GMSH_LEVELS` (Rodero) or :data:`BUILT_LEVELS`
    (the others); quadratic, :data:`QUADRATIC_LEVELS`."""
    kind = "ellipsoids" if shape == "ellipsoids" else "gmsh" if shape in GMSH_SHAPES else "built"
    if order == 2:
        return QUADRATIC_LEVELS[kind]
    return {"ellipsoids": REFERENCE_LEVELS, "gmsh": GMSH_LEVELS, "built": BUILT_LEVELS}[kind]


def default_coarse(shape: str) -> Tuple[int, int]:
    """The coarse full FEM of about the hybrid core's 900 tets: the ellipsoids' (2, 2) (768 tets),
    Rodero's surface at 600 triangles (880 tets), the build's (300, 1) (900 tets)."""
    return (2, 2) if shape == "ellipsoids" else (600, 0) if shape in GMSH_SHAPES else (300, 1)


def level_size(shape: str, level: Tuple[int, int]) -> float:
    """A mesh level's element size, relative: the ellipsoids' halves with each subdivision (the
    layers double with it); a built wall's goes as one over the square root of its triangles."""
    a, _ = level
    return 2.0 ** -a if shape == "ellipsoids" else a ** -0.5


def run_indentation(shape: str = "ellipsoids", *, tool_radius: float = 0.005,
                    depths: Sequence[float] = (0.002, 0.004, 0.006), levels: Optional[Sequence[Tuple[int, int]]] = None,
                    coarse: Optional[Tuple[int, int]] = None, young: float = _defaults.tissue.young,
                    poisson: float = _defaults.tissue.poisson,
                    law: str = "neo-hookean", out_dir: Optional[str] = None, model: Optional[_palpate.HybridModel] = None,
                    reference: Optional[str] = None, verbose: bool = True,
                    implicit_exchange: bool = True, order: int = 2) -> Dict[str, Any]:
    """The hybrid's force and dent against the converged FEM of its wall, and the coarse FEM.

    ``levels``: the reference meshes (default :func:`default_levels`); ``coarse``: the level of
    the ungraded full FEM of about the hybrid core's size (default :func:`default_coarse`). Writes
    ``indentation.json`` and ``indentation.png`` into ``out_dir`` when given. Returns the curves,
    the table rows and the convergence evidence.

    ``reference``: an ``indentation.json`` of an earlier run whose reference and coarse curves
    are reused instead of computed (they take most of the run's time; the hybrid is what one
    iterates on): its wall, material, law, tool, press and held height must be this run's
    (:func:`load_reference`), and ``levels`` and ``coarse`` are then its own.

    ``implicit_exchange``: the hybrid with the shell's springs at the tissue's stiffness (the
    ``HybridSim`` option, default True; False: the springs capped as the explicit exchange's
    stability asks; recorded in the result).

    ``order``: the references' elements, 2 (default: quadratic tets, which converge where linear
    ones lock) or 1 (linear tets, as the hybrid's core). The coarse FEM is always linear: it is
    the full FEM of the hybrid core's size and element, the paper's comparison.
    """
    from .hybrid import SHAPES, build_shape

    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {SHAPES}, got {shape!r}")
    if law not in ("neo-hookean", "svk"):
        raise ValueError(f"law must be 'neo-hookean' or 'svk', got {law!r}")
    if order not in (1, 2):
        raise ValueError(f"order must be 1 (linear tets) or 2 (quadratic), got {order!r}")
    levels = default_levels(shape, order) if levels is None else levels
    coarse = default_coarse(shape) if coarse is None else coarse
    case = IndentCase(shape=shape, young=young, poisson=poisson, tool_radius=tool_radius, depths=tuple(depths),
                      reference_law=law)
    if model is None:
        if verbose:
            print(f"building the hybrid model of {shape!r} ...", flush=True)
        model = build_shape(shape)
    if shape != "ellipsoids":
        from .probe import probe_frame

        _, point, normal, _ = probe_frame(model.outer_points, model.outer_triangles)
        case.point, case.direction = tuple(float(v) for v in point), tuple(float(-v) for v in normal)
    if reference is not None:
        load_reference(reference, case)  # refuse a misfit before the hybrid's minute
    hyb = hybrid_curve(model, case, verbose=verbose, implicit_exchange=implicit_exchange)
    case.hold_z = hyb["hold_z"]
    if reference is not None:
        refs, coarse_curve = load_reference(reference, case, hyb["probes"])
        levels = [tuple(r["level"]) for r in refs]
        if verbose:
            print(f"  reference and coarse curves from {reference}", flush=True)
    else:
        refs = []
        for a, b in levels:
            mesh, fixed = wall_mesh(shape, a, b, case)
            refs.append(reference_curve(mesh, case, hyb["probes"], fixed=fixed, verbose=verbose, order=order))
            refs[-1]["level"] = (a, b)
        cmesh, cfixed = wall_mesh(shape, coarse[0], coarse[1], case, graded=False)
        coarse_curve = reference_curve(cmesh, case, hyb["probes"], fixed=cfixed, verbose=verbose)

    at = np.asarray(depths, dtype=float)
    ref_f = np.array([_interp(r, at) for r in refs])
    h = np.array([level_size(shape, lv) for lv in levels])
    conv = []
    for j, d in enumerate(at):
        change = abs(ref_f[-1, j] - ref_f[-2, j]) / abs(ref_f[-1, j]) if len(refs) > 1 else float("nan")
        lim, order = _richardson(h[-3:], ref_f[-3:, j]) if len(refs) >= 3 else (float("nan"), float("nan"))
        conv.append(dict(indentation=d, last_change=change, extrapolated=lim, order=order))
    reference = ref_f[-1]
    extrapolated = np.array([cv["extrapolated"] for cv in conv])
    hyb_f, coarse_f = _interp(hyb, at), _interp(coarse_curve, at)
    dents = {k: _interp(c, at, "dent") for k, c in (("reference", refs[-1]), ("hybrid", hyb), ("coarse", coarse_curve))}
    rows = []
    for j, d in enumerate(at):
        rows.append(dict(indentation=d, reference=reference[j], hybrid=hyb_f[j], coarse=coarse_f[j],
                         hybrid_error=hyb_f[j] / reference[j] - 1, coarse_error=coarse_f[j] / reference[j] - 1,
                         extrapolated=extrapolated[j], hybrid_error_extrapolated=hyb_f[j] / extrapolated[j] - 1,
                         dent_reference=dents["reference"][j], dent_hybrid=dents["hybrid"][j],
                         dent_coarse=dents["coarse"][j]))
    result = dict(case=asdict(case), hybrid=hyb, references=refs, coarse=coarse_curve, rows=rows, convergence=conv,
                  implicit_exchange=implicit_exchange)
    if verbose:
        print(format_table(result))
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        with open(os.path.join(out_dir, "indentation.json"), "w") as fh:
            json.dump(_jsonable(result), fh, indent=1)
        result["plot"] = plot(result, os.path.join(out_dir, "indentation.png"))
    return result


class ReferenceMismatch(ValueError):
    """An earlier run's reference that does not fit this run (:func:`load_reference`)."""


#: How far a reused reference's held height and dent probes may lie from this run's [m]: holding
#: the wall 0.9 mm higher changed the reference's force by 3% (VALIDATION.md).
REUSE_TOLERANCE = 1e-4


def load_reference(path: str, case: IndentCase, probes: Optional[np.ndarray] = None
                   ) -> Tuple[List[Dict[str, Any]], Dict[str, Any]]:
    """The reference curves (finest last) and the coarse curve of an earlier run's
    ``indentation.json``, refused with the reason unless it pressed the same wall with the same
    material, law, sphere and direction, held below the same height (when ``case.hold_z`` is
    set) and probed the dent at the same ``probes`` (when given), within :data:`REUSE_TOLERANCE`."""
    try:
        with open(path) as fh:
            data = json.load(fh)
        old, refs, coarse = data["case"], data["references"], data["coarse"]
        old_probes = np.asarray(data["hybrid"]["probes"], dtype=float)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ReferenceMismatch(f"{path}: not an indentation.json of palpate validate ({e})") from None
    new = asdict(case)
    for key in ("shape", "reference_law"):
        if old.get(key) != new[key]:
            raise ReferenceMismatch(f"{path}: its reference has {key} {old.get(key)!r}, this run {new[key]!r}")
    for key in ("young", "poisson", "tool_radius", "point", "direction", "hold_z"):
        if new[key] is None:
            continue
        a, b = np.asarray(old.get(key, np.nan), dtype=float), np.asarray(new[key], dtype=float)
        tol = REUSE_TOLERANCE if key in ("point", "hold_z") else 1e-9 * max(1.0, float(np.abs(b).max()))
        if a.shape != b.shape or not np.all(np.abs(a - b) <= tol):
            raise ReferenceMismatch(f"{path}: its reference has {key} {old.get(key)}, this run {new[key]}: compute "
                                    f"the reference anew (without --reference)")
    if probes is not None and (old_probes.shape != probes.shape or np.abs(old_probes - probes).max() > REUSE_TOLERANCE):
        raise ReferenceMismatch(f"{path}: its dent probes are not this run's (another skin): compute the reference anew")

    def arrays(c: Dict[str, Any]) -> Dict[str, Any]:
        return {k: (np.asarray(v) if isinstance(v, list) and k != "level" else v) for k, v in c.items()}

    return [arrays(r) for r in refs], arrays(coarse)


def format_table(result: Dict[str, Any]) -> str:
    c = result["case"]
    lines = [f"sphere R = {c['tool_radius'] * 1e3:g} mm into {c['shape']}, E = {c['young'] / 1e3:g} kPa, "
             f"nu = {c['poisson']:g}",
             "indentation | finest FEM | FEM extrapolated | hybrid (vs finest, vs extrapolated) | coarse FEM (vs finest)",
             "---|---|---|---|---"]
    for r in result["rows"]:
        ex = r.get("extrapolated", float("nan"))
        hx = r.get("hybrid_error_extrapolated", float("nan"))
        lines.append(f"{r['indentation'] * 1e3:.1f} mm | {r['reference']:.4f} N | {ex:.4f} N | {r['hybrid']:.4f} N "
                     f"({100 * r['hybrid_error']:+.0f}%, {100 * hx:+.0f}%) | {r['coarse']:.4f} N "
                     f"({100 * r['coarse_error']:+.0f}%)")
    orders = {int(r.get("order", 1)) for r in result["references"]}
    kind = "quadratic" if orders == {2} else "linear" if orders == {1} else "mixed"
    lines.append(f"reference convergence ({kind} tets; force at indentation over the levels; last change; "
                 "extrapolation):")
    for j, cv in enumerate(result["convergence"]):
        fs = ", ".join(f"{_interp(r, np.array([cv['indentation']]))[0]:.4f}" for r in result["references"])
        verdict = "converged" if cv["last_change"] < CONVERGED else "NOT converged"
        lines.append(f"  {cv['indentation'] * 1e3:.1f} mm: {fs} N; last change {100 * cv['last_change']:.1f}% "
                     f"({verdict}); extrapolated {cv['extrapolated']:.4f} N (order {cv['order']:.2f})")
    lines.append("dent: outer surface displacement along the press at "
                 + ", ".join(f"{d * 1e3:g}" for d in DENT_DISTANCES) + " mm from the axis [mm]")
    for r in result["rows"]:
        fmt = lambda v: " ".join(f"{x * 1e3:.2f}" for x in v)  # noqa: E731
        lines.append(f"  indentation {r['indentation'] * 1e3:.1f} mm: FEM {fmt(r['dent_reference'])} | hybrid "
                     f"{fmt(r['dent_hybrid'])} | coarse {fmt(r['dent_coarse'])}")
    return "\n".join(lines)


def plot(result: Dict[str, Any], path: str) -> Optional[str]:
    """Force against indentation (hybrid, coarse, each reference level) and the dent profiles,
    written to ``path``; returns ``path``, or None (and says so) without matplotlib, which the
    ``validate`` extra does not install (the ``plot`` extra does): the table and
    ``indentation.json`` are the result, the plot a view of it."""
    try:
        import matplotlib
    except ImportError:
        print(f"(matplotlib not installed: no {os.path.basename(path)}; {install_hint('plot')})")
        return None

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    for r in result["references"]:
        graded = " (graded)" if result["case"]["shape"] == "ellipsoids" else ""
        kind = "quadratic " if r.get("order", 1) == 2 else ""
        a.plot(np.r_[0, r["indentation"]] * 1e3, np.r_[0, r["force"]], "o-", lw=1,
               label=f"FEM {r['tets']} {kind}tets{graded}")
    for key, style, name in (("coarse", "s--", "coarse FEM"), ("hybrid", "^-", "hybrid")):
        r = result[key]
        label = f"{name} ({r['tets']} linear tets)" if key == "coarse" else f"hybrid ({r['core_tets']}-tet core)"
        a.plot(np.r_[0, r["indentation"]] * 1e3, np.r_[0, r["force"]], style, lw=1.5, label=label)
    conv = result.get("convergence", [])
    ex = [(cv["indentation"], cv["extrapolated"]) for cv in conv if np.isfinite(cv["extrapolated"])]
    if ex:
        a.plot([e[0] * 1e3 for e in ex], [e[1] for e in ex], "kx", ms=8, label="FEM extrapolated to h -> 0")
    c = result["case"]
    a.set_xlabel("indentation [mm]")
    a.set_ylabel("force [N]")
    a.set_title(f"sphere R = {c['tool_radius'] * 1e3:g} mm, {c['shape']}")
    a.legend(fontsize=8)
    dist = np.array(DENT_DISTANCES) * 1e3
    for k, r in enumerate(result["rows"]):
        col = f"C{k}"
        b.plot(dist, np.asarray(r["dent_reference"]) * 1e3, "o-", color=col,
               label=f"FEM, indentation {r['indentation'] * 1e3:g} mm")
        b.plot(dist, np.asarray(r["dent_hybrid"]) * 1e3, "^--", color=col, label="hybrid")
        b.plot(dist, np.asarray(r["dent_coarse"]) * 1e3, "s:", color=col, label="coarse FEM")
    b.set_xlabel("distance from the tool's axis [mm]")
    b.set_ylabel("surface displacement along the press [mm]")
    b.set_title("dent profile")
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _jsonable(o: Any) -> Any:
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items() if k != "positions"}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return o
