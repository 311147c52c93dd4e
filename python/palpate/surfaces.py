"""Triangle surface files in: :func:`load_surface`.

Surfaces bound the solids that :func:`palpate.sample_inside` / :func:`palpate.sample_between`
fill with particles. Files are read with meshio (``.obj``, ``.stl``, ``.ply``, ``.off``, ``.vtk``,
``.vtu``) or :mod:`palpate.vtp` (``.vtp``), scaled to metres and validated in the Rust core (:class:`palpate.TriSurface`): every
defect is a :class:`palpate.SurfaceError` (a :class:`palpate.MeshError`) naming the file, the
triangle / vertex / edge and the reason.
"""
from __future__ import annotations

import os
import warnings
from typing import Dict, Iterable, Optional, Tuple, Union

import numpy as np

from ._palpate import SurfaceError, TriSurface
from .io import unit_scale
from .vtp import read_vtp

PathLike = Union[str, "os.PathLike[str]"]

#: File extensions :func:`load_surface` reads, with meshio's format name (``.vtp``: :mod:`palpate.vtp`).
SURFACE_FORMATS = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".off": "off", ".vtk": "vtk", ".vtu": "vtu",
                   ".vtp": "vtp"}

#: meshio cell types of dimension < 2, ignored beside triangles (points, polylines).
_LOWER_DIM = {"vertex", "line", "line3", "polyline"}


def read_surface_arrays(path: PathLike, unit: str = "m") -> Tuple[np.ndarray, np.ndarray]:
    """Read a triangle surface file without validating it in the core.

    Returns ``(points, triangles)``: points ``(n, 3)`` float64 in metres, triangles ``(m, 3)``
    int64 0-based. Vertex and line cells are ignored; any other non-triangle cell (quads,
    polygons, tetrahedra ...) is an error naming the file and the cell type (for ``.vtp``, the
    polygon index).
    """
    points, triangles, _ = _read_surface(path, unit)
    return points, triangles


def _read_surface(path: PathLike, unit: str) -> Tuple[np.ndarray, np.ndarray, Dict[str, np.ndarray]]:
    """(points [m], triangles, cell data with one row per triangle) of a surface file."""
    path = os.fspath(path)
    scale = unit_scale(unit)
    name = os.path.basename(path)
    ext = os.path.splitext(path)[1].lower()
    fmt = SURFACE_FORMATS.get(ext)
    if fmt is None:
        raise SurfaceError(f"{name}: unsupported surface format {ext or '(no extension)'!r}; palpate reads "
                           f"{', '.join(SURFACE_FORMATS)} triangle surfaces")
    if not os.path.exists(path):
        raise SurfaceError(f"{name}: no such file ({path})")
    if os.path.getsize(path) == 0:
        raise SurfaceError(f"{name}: empty file")
    if fmt == "vtp":
        d = read_vtp(path)
        return d.points * scale, d.triangles, d.cell_data
    import meshio

    # The format's own reader, not meshio.read (which prints and exits on a ReadError).
    reader = getattr(meshio, fmt).read
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = reader(path)
    except (Exception, SystemExit) as e:
        reason = str(e).strip() or "malformed or truncated file"
        raise SurfaceError(f"{name}: cannot read as {fmt.upper()} ({type(e).__name__}: {reason})") from None
    points = np.asarray(m.points, dtype=np.float64)
    if points.ndim != 2 or len(points) == 0:
        raise SurfaceError(f"{name}: no points (empty surface)")
    if points.shape[1] != 3:
        raise SurfaceError(f"{name}: points have shape {points.shape}, expected (n, 3): a 3D surface")
    tris, keep = [], []
    for k, cb in enumerate(m.cells):
        data = np.asarray(cb.data)
        if len(data) == 0 or cb.type in _LOWER_DIM:
            continue
        if cb.type != "triangle":
            hint = " (a volume mesh: load it with palpate.load_mesh)" if cb.type.startswith(("tetra", "hexa", "wedge", "pyramid")) else ""
            raise SurfaceError(f"{name}: cells of type '{cb.type}' ({len(data)} of them) are not triangles: "
                               f"palpate needs a closed triangle surface{hint}")
        tris.append(data.astype(np.int64))
        keep.append(k)
    if not tris:
        raise SurfaceError(f"{name}: no triangles (empty surface)")
    cell_data = {}
    for key, blocks in (m.cell_data or {}).items():
        try:
            arrs = [np.asarray(blocks[k]) for k in keep]
            arr = np.concatenate(arrs, axis=0)
        except (IndexError, ValueError):
            continue
        if arr.ndim == 2 and arr.shape[1] == 1:
            arr = arr[:, 0]
        cell_data[key] = arr
    return points * scale, np.concatenate(tris, axis=0), cell_data


def load_surface(path: PathLike, unit: str = "m") -> TriSurface:
    """Load and validate a closed triangle surface.

    Parameters
    ----------
    path:
        ``.obj``, ``.stl`` (ASCII or binary; coincident vertices are merged by meshio), ``.ply``,
        ``.off``, ``.vtk``, ``.vtu`` or ``.vtp`` (VTK XML PolyData) holding triangles (vertex and
        line cells are ignored).
    unit:
        Length unit of the file's coordinates: ``"m"``, ``"cm"`` or ``"mm"``.

    Returns
    -------
    TriSurface
        In metres, outward oriented (an inward one is reversed with a :class:`palpate.MeshWarning`).

    Raises
    ------
    SurfaceError
        Missing, unreadable or empty file, non-triangle cells, or an invalid surface (open,
        non-manifold, degenerate ...); the message names the file and the culprit.
    ValueError
        ``unit`` is not one of the above.
    """
    path = os.fspath(path)
    points, triangles = read_surface_arrays(path, unit)
    return TriSurface(points, triangles, source=os.path.basename(path))


# --- tagged surfaces -----------------------------------------------------------------------------

#: Part codes of :func:`read_tagged_surface`.
INNER, OUTER, BASE = 0, 1, 2
PART_NAMES = ("inner", "outer", "base")

#: Default tag array and values when no part-definition JSON sits beside the file.
DEFAULT_TAG_ARRAY = "surface-id"

_Tags = Union[int, Iterable[int], None]


def part_definition_path(path: PathLike) -> Optional[str]:
    """The part-definition JSON beside a surface file, or None: ``<stem>_part_definition.json``,
    or for a file named ``<x>_surface.<ext>``, ``<x>_part_definition.json`` (Rodero et al.'s naming)."""
    path = os.fspath(path)
    base, _ = os.path.splitext(path)
    cands = [base + "_part_definition.json"]
    if base.endswith("_surface"):
        cands.append(base[: -len("_surface")] + "_part_definition.json")
    for c in cands:
        if os.path.isfile(c):
            return c
    return None


def read_part_definition(path: PathLike) -> Dict[str, int]:
    """Surface name -> tag value from a part-definition JSON.

    Reads every ``"enclosed_by_boundaries"`` mapping (the ansys-health-heart layout:
    ``{"Left ventricle": {"id": 1, "enclosed_by_boundaries": {"left-ventricle-endocardium": 1, ...}}}``),
    else a flat top-level ``{name: value}`` mapping.
    """
    import json

    path = os.fspath(path)
    name = os.path.basename(path)
    try:
        with open(path, encoding="utf-8") as fh:
            doc = json.load(fh)
    except (OSError, ValueError) as e:
        raise SurfaceError(f"{name}: cannot read the part definition ({type(e).__name__}: {e})") from None
    found: Dict[str, int] = {}

    def walk(node):
        if isinstance(node, dict):
            for k, v in node.items():
                if k == "enclosed_by_boundaries" and isinstance(v, dict):
                    found.update({str(n): t for n, t in v.items() if isinstance(t, int) and not isinstance(t, bool)})
                else:
                    walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(doc)
    if not found and isinstance(doc, dict):
        found = {str(n): t for n, t in doc.items() if isinstance(t, int) and not isinstance(t, bool)}
    if not found:
        raise SurfaceError(f"{name}: no surface names with integer tags in the part definition")
    return found


def _part_of_name(surface_name: str) -> Optional[int]:
    n = surface_name.lower()
    if "endocardium" in n:
        return INNER
    if "epicardium" in n:
        return OUTER
    if "valve" in n or "base" in n:
        return BASE
    return None


def _as_tags(v: _Tags, what: str):
    if v is None:
        return None
    if isinstance(v, (int, np.integer)):
        return {int(v)}
    try:
        out = {int(x) for x in v}
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be an integer tag value or a sequence of them, got {v!r}") from None
    return out


def read_tagged_surface(path: PathLike, unit: str = "m", tag_array: Optional[str] = None, inner: _Tags = None,
                        outer: _Tags = None, base: _Tags = None,
                        part_definition: Union[PathLike, bool, None] = None,
                        ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read one surface whose triangles are tagged inner / outer / base (a truncated ventricle).

    The tag is an integer cell-data array (``.vtp`` through :func:`palpate.vtp.read_vtp`,
    ``.vtk`` / ``.vtu`` and the other meshio formats through meshio's cell data).

    Which tag values form which part:

    - a part-definition JSON beside the file (:func:`part_definition_path`; or ``part_definition``
      = its path; ``False`` ignores it): surface names containing ``endocardium`` -> inner,
      ``epicardium`` -> outer, ``valve`` or ``base`` -> base;
    - else inner = 1, outer = 2 and base = every other value present;
    - ``inner`` / ``outer`` / ``base`` (a value or a list of values) override either.

    ``tag_array`` defaults to ``"surface-id"``.

    Returns
    -------
    points: ``(n, 3)`` float64 in metres; triangles: ``(m, 3)`` int64; part: ``(m,)`` int8 with
    0 = inner, 1 = outer, 2 = base (:data:`INNER`, :data:`OUTER`, :data:`BASE`). The surface is
    not validated (see :class:`palpate.TriSurface`).

    Raises
    ------
    SurfaceError
        The file cannot be read (see :func:`load_surface`), the tag array is missing or not one
        integer per triangle, a tag value present is mapped to no part (or to two), or there are
        no inner or no outer triangles. The message names the file.
    """
    path = os.fspath(path)
    name = os.path.basename(path)
    points, triangles, cell_data = _read_surface(path, unit)
    tag_array = DEFAULT_TAG_ARRAY if tag_array is None else tag_array
    if tag_array not in cell_data:
        have = sorted(cell_data) or "none"
        raise SurfaceError(f"{name}: missing tag array '{tag_array}' (cell data arrays: {have}); "
                           "pass tag_array= the name of the integer cell array tagging inner / outer / base")
    tags = np.asarray(cell_data[tag_array])
    if tags.ndim != 1 or len(tags) != len(triangles):
        raise SurfaceError(f"{name}: tag array '{tag_array}' has shape {tags.shape}, expected one value per "
                           f"triangle ({len(triangles)},)")
    if tags.dtype.kind == "f":
        if not (np.isfinite(tags).all() and (tags == np.round(tags)).all()):
            raise SurfaceError(f"{name}: tag array '{tag_array}' holds non-integer values")
    elif tags.dtype.kind not in "iu":
        raise SurfaceError(f"{name}: tag array '{tag_array}' is of type {tags.dtype}, not integer")
    tags = tags.astype(np.int64)
    present = sorted(int(v) for v in np.unique(tags))

    # defaults: part definition, else 1 / 2 / rest
    jpath = None
    if part_definition is None:
        jpath = part_definition_path(path)
    elif part_definition is not False and part_definition is not True:
        jpath = os.fspath(part_definition)
    elif part_definition is True:
        jpath = part_definition_path(path)
        if jpath is None:
            raise SurfaceError(f"{name}: no part-definition JSON beside the file")
    names: Dict[int, str] = {}
    if jpath is not None:
        defs = read_part_definition(jpath)
        sets = [set(), set(), set()]
        for sname, value in defs.items():
            names[value] = sname
            p = _part_of_name(sname)
            if p is not None:
                sets[p].add(value)
        source = f"the part definition {os.path.basename(jpath)}"
    else:
        sets = [{1}, {2}, None]
        source = "the default tags (inner 1, outer 2, base the rest)"
    # explicit arguments override (and take their values away from the other parts)
    explicit = [_as_tags(arg, PART_NAMES[p]) for p, arg in enumerate((inner, outer, base))]
    for p, s in enumerate(explicit):
        if s is not None:
            sets[p] = s
            for q in range(3):
                if explicit[q] is None and sets[q] is not None:
                    sets[q] = sets[q] - s
    if sets[BASE] is None:
        sets[BASE] = set(present) - sets[INNER] - sets[OUTER]
    for p in range(3):
        for q in range(p + 1, 3):
            both = sets[p] & sets[q]
            if both:
                raise SurfaceError(f"{name}: tag value(s) {sorted(both)} assigned to both {PART_NAMES[p]} and "
                                   f"{PART_NAMES[q]}")
    part = np.full(len(tags), -1, dtype=np.int8)
    for p in range(3):
        part[np.isin(tags, sorted(sets[p]))] = p
    if (part < 0).any():
        k = int(np.flatnonzero(part < 0)[0])
        v = int(tags[k])
        label = f" ('{names[v]}')" if v in names else ""
        unmapped = sorted(set(int(x) for x in np.unique(tags[part < 0])))
        raise SurfaceError(f"{name}: triangle {k}: tag value {v}{label} of '{tag_array}' is not mapped to inner, "
                           f"outer or base by {source} (unmapped values {unmapped}; pass inner= / outer= / base=)")
    for p in (INNER, OUTER):
        if not (part == p).any():
            raise SurfaceError(f"{name}: no {PART_NAMES[p]} triangles: none carries the {PART_NAMES[p]} tag "
                               f"value(s) {sorted(sets[p]) or '(none)'} of '{tag_array}' given by {source} "
                               f"(values present: {present})")
    return points, triangles, part


def orient_consistently(points, triangles) -> Tuple[np.ndarray, int]:
    """Flip triangles so that neighbours across every manifold edge agree, each connected piece
    then facing outward (positive enclosed volume).

    For surfaces whose triangles are stored in arbitrary orientations (the Rodero et al. left
    ventricle is one). Edges shared by more than two triangles do not link pieces. Returns the
    new ``(m, 3)`` int64 triangles and the number of triangles flipped; topology defects (open or
    non-manifold edges) are left for :class:`palpate.TriSurface` to report.
    """
    from collections import deque

    pts = np.asarray(points, dtype=np.float64)
    tris = np.array(triangles, dtype=np.int64, copy=True)
    m = len(tris)
    if m == 0:
        return tris, 0
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    owner = np.tile(np.arange(m), 3)
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    order = np.argsort(inv, kind="stable")
    si = inv[order]
    pair = np.flatnonzero((si[:-1] == si[1:]) & (cnt[si[:-1]] == 2))
    a, b = order[pair], order[pair + 1]          # half-edge rows sharing an edge
    ta, tb = owner[a], owner[b]
    same = (e[a, 0] == e[b, 0])                  # traversed the same way: one of the two must flip
    nbrs = [[] for _ in range(m)]
    for x, y, s in zip(ta.tolist(), tb.tolist(), same.tolist()):
        nbrs[x].append((y, s))
        nbrs[y].append((x, s))
    flip = np.zeros(m, dtype=bool)
    seen = np.zeros(m, dtype=bool)
    comp = np.full(m, -1, dtype=np.int64)
    n_comp = 0
    for start in range(m):
        if seen[start]:
            continue
        seen[start] = True
        comp[start] = n_comp
        q = deque([start])
        while q:
            t = q.popleft()
            for u, s in nbrs[t]:
                if not seen[u]:
                    seen[u] = True
                    comp[u] = n_comp
                    flip[u] = flip[t] ^ s
                    q.append(u)
        n_comp += 1
    tris[flip] = tris[flip][:, ::-1]
    p0, p1, p2 = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    vol = np.einsum("ij,ij->i", p0, np.cross(p1, p2))
    comp_vol = np.bincount(comp, weights=vol, minlength=n_comp)
    inward = comp_vol[comp] < 0
    tris[inward] = tris[inward][:, ::-1]
    flipped = int((flip ^ inward).sum())
    return tris, flipped
