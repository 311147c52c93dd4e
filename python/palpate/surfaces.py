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

from . import _readers
from ._indices import whole_indices
from ._palpate import MeshWarning, ParameterError, SurfaceError, TriSurface
from .io import unit_scale
from .vtp import read_vtp

PathLike = Union[str, "os.PathLike[str]"]

#: File extensions :func:`load_surface` reads, with meshio's format name (``.vtp``: :mod:`palpate.vtp`).
SURFACE_FORMATS = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".off": "off", ".vtk": "vtk", ".vtu": "vtu",
                   ".vtp": "vtp"}

#: meshio cell types of dimension < 2, ignored beside triangles (points, polylines).
_LOWER_DIM = {"vertex", "line", "line3", "polyline"}


def read_surface_arrays(path: PathLike, unit: str = "m", repair: bool = False) -> Tuple[np.ndarray, np.ndarray]:
    """Read a triangle surface file without validating it in the core.

    Returns ``(points, triangles)``: points ``(n, 3)`` float64 in metres, triangles ``(m, 3)``
    int64 0-based. Vertex and line cells are ignored; any other non-triangle cell (quads,
    polygons, tetrahedra ...) is an error naming the file and the cell type (for ``.vtp``, the
    polygon index). ``repair=True`` passes them through :func:`repair_surface` (one
    :class:`palpate.MeshWarning` naming the file says what changed, if anything did).
    """
    points, triangles, _ = _read_surface(path, unit)
    if repair:
        points, triangles, _ = _repair_file(path, points, triangles, None)
    return points, triangles


def _repair_file(path: PathLike, points, triangles, part, stacklevel: int = 2):
    """:func:`repair_surface` on a file's arrays, with one MeshWarning naming the file if it changed anything."""
    points, triangles, part, report = repair_surface(points, triangles, part)
    summary = repair_summary(report)
    if summary is not None:
        warnings.warn(f"{os.path.basename(os.fspath(path))}: repaired the surface: {summary}", MeshWarning,
                      stacklevel=stacklevel + 1)
    return points, triangles, part


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
    size = _readers.check_input_file(path, SurfaceError)
    if size == 0:
        raise SurfaceError(f"{name}: empty file")
    _header_precheck(path, fmt, size)
    if fmt == "vtk":
        _readers.vtk_legacy_precheck(path, SurfaceError)
    if fmt == "vtu":
        _readers.vtk_xml_inflated_precheck(path, SurfaceError)
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
    except MemoryError:
        _readers.check_budget("reading the file (the reader ran out of memory)", float("inf"), name)
        raise
    except RecursionError:
        raise SurfaceError(f"{name}: cannot read as {fmt.upper()}: nested too deeply (corrupt or crafted file)") from None
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


def _header_precheck(path: str, fmt: str, size: int) -> None:
    """What meshio's OFF, PLY and binary STL readers trust without checking, checked first: a
    header cut short (the OFF and PLY readers looped forever waiting for the rest of it) and
    counts the file cannot hold (a 100-byte file announcing 1e8 vertices made them allocate
    gigabytes). Errors name the file, the line or byte, and the reason."""
    import struct

    name = os.path.basename(path)
    if fmt not in ("off", "ply", "stl"):
        return
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if fmt == "stl":
        if head[:5].lower() == b"solid" and b"facet" in head[:4096].lower() or size < 84:
            return  # ASCII STL: read line by line, no count to trust
        (n,) = struct.unpack("<I", head[80:84])
        if 84 + 50 * n != size:
            raise SurfaceError(f"{name}: byte 80: binary STL announces {n} triangles, which take {84 + 50 * n} bytes; "
                               f"the file has {size} (truncated or not a binary STL)")
        return
    lines = head.decode("latin-1").splitlines()
    if fmt == "off":
        toks, lineno = [], 0
        for lineno, line in enumerate(lines, 1):
            line = line.split("#", 1)[0]
            toks += line.split()
            if len(toks) >= 4:
                break
        if not toks or not toks[0].upper().endswith("OFF"):
            raise SurfaceError(f"{name}: line 1: not an OFF file (expected 'OFF', got {(toks or [''])[0][:20]!r})")
        if len(toks) < 4:
            raise SurfaceError(f"{name}: line {lineno}: the OFF header ends before its counts "
                               "'vertices faces edges' (truncated file)")
        try:
            nv, nf = int(toks[1]), int(toks[2])
        except ValueError:
            raise SurfaceError(f"{name}: line {lineno}: OFF counts {' '.join(toks[1:4])!r} are not integers") from None
        if nv < 0 or nf < 0 or 6 * nv + 8 * nf > size:
            raise SurfaceError(f"{name}: line {lineno}: the OFF header announces {nv} vertices and {nf} faces, "
                               f"more than a file of {size} bytes can hold (truncated or corrupt header)")
        _readers.check_budget(f"{nv} vertices and {nf} faces", 64.0 * (nv + nf), name)
        return
    # PLY
    if not lines or lines[0].strip() != "ply":
        raise SurfaceError(f"{name}: line 1: not a PLY file (expected 'ply')")
    end = next((k for k, line in enumerate(lines) if line.strip() == "end_header"), None)
    if end is None:
        raise SurfaceError(f"{name}: no 'end_header' line in the first {len(head)} bytes: the PLY header is cut "
                           "short (truncated file)")
    binary = any(line.startswith("format binary") for line in lines[:end])
    count, props, elements = 0, 0, []
    for k, line in enumerate(lines[:end], 1):
        t = line.split()
        if t[:1] == ["element"] and len(t) == 3:
            try:
                count = int(t[2])
            except ValueError:
                raise SurfaceError(f"{name}: line {k}: element count {t[2]!r} is not an integer") from None
            if count < 0:
                raise SurfaceError(f"{name}: line {k}: negative element count {count}")
            elements.append([t[1], count, 0, k])
        elif t[:1] == ["property"] and elements:
            elements[-1][2] += 1
    need = sum(c * max(p, 1) * (1 if binary else 2) for _, c, p, _ in elements)
    if need > size:
        what = ", ".join(f"{c} {e}" for e, c, _, _ in elements)
        raise SurfaceError(f"{name}: line {elements[0][3] if elements else 1}: the PLY header announces {what}, "
                           f"more than a file of {size} bytes can hold (truncated or corrupt header)")
    _readers.check_budget("the PLY elements", 64.0 * sum(c * max(p, 1) for _, c, p, _ in elements), name)


def load_surface(path: PathLike, unit: str = "m", repair: bool = False) -> TriSurface:
    """Load and validate a closed triangle surface.

    Parameters
    ----------
    path:
        ``.obj``, ``.stl`` (ASCII or binary; coincident vertices are merged by meshio), ``.ply``,
        ``.off``, ``.vtk``, ``.vtu`` or ``.vtp`` (VTK XML PolyData) holding triangles (vertex and
        line cells are ignored).
    unit:
        Length unit of the file's coordinates: ``"m"``, ``"cm"`` or ``"mm"``.
    repair:
        Pass the triangles through :func:`repair_surface` first (duplicate / zero-area triangles
        removed, orientation made consistent, non-manifold edges and vertices split), with one
        :class:`palpate.MeshWarning` naming the file if anything changed.

    Returns
    -------
    TriSurface
        In metres, outward oriented (an inward one is reversed with a :class:`palpate.MeshWarning`).

    Raises
    ------
    SurfaceError
        Missing, unreadable or empty file, non-triangle cells, or an invalid surface (open,
        non-manifold, degenerate ...); the message names the file and the culprit.
    ParameterError
        ``unit`` is not one of the above (also a ``ValueError``).
    """
    path = os.fspath(path)
    points, triangles, _ = _read_surface(path, unit)
    if repair:
        points, triangles, _ = _repair_file(path, points, triangles, None)
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
        doc = json.loads(_readers.read_text(path, SurfaceError))
    except RecursionError:
        raise SurfaceError(f"{name}: cannot read the part definition: nested too deeply (corrupt or crafted file)") from None
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
        raise ParameterError(f"{what} must be an integer tag value or a sequence of them, got {v!r}") from None
    return out


def read_tagged_surface(path: PathLike, unit: str = "m", tag_array: Optional[str] = None, inner: _Tags = None,
                        outer: _Tags = None, base: _Tags = None,
                        part_definition: Union[PathLike, bool, None] = None, repair: bool = True,
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

    With ``repair`` (the default) the surface goes through :func:`repair_surface`: duplicate and
    zero-area triangles removed, triangles oriented consistently and outward, non-manifold edges
    and vertices split (new vertices appended), the parts following their triangles; one
    :class:`palpate.MeshWarning` naming the file says what changed, if anything did. The Rodero
    et al. left ventricle needs it (7,040 triangles re-oriented, two edges shared by four
    triangles split). ``repair=False`` returns the file's triangles as stored.

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
    if repair:
        points, triangles, part = _repair_file(path, points, triangles, part)
    return points, triangles, part


def _edge_keys(triangles: np.ndarray, n: int):
    """Half-edges of ``(m, 3)`` triangles: row ``3 t + k`` runs ``tri[t, k] -> tri[t, (k + 1) % 3]``.

    Returns ``(start, end, order, run_start, run_count)``: half-edges sorted by undirected edge
    (``order``), and per undirected edge the first position in ``order`` and the number of
    half-edges (triangles) on it.
    """
    start = triangles.ravel()
    end = triangles[:, [1, 2, 0]].ravel()
    key = np.minimum(start, end) * np.int64(max(n, 1)) + np.maximum(start, end)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    run_start = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]]) if len(sk) else np.zeros(0, np.int64)
    run_count = np.diff(np.r_[run_start, len(sk)])
    return start, end, order, run_start, run_count


def _components(n: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Connected components of the graph with ``n`` nodes and edges ``(u[i], v[i])``: each node's
    label is the smallest node of its component (hook the larger root to the smaller, compress)."""
    lab = np.arange(n, dtype=np.int64)
    u = np.asarray(u, dtype=np.int64)
    v = np.asarray(v, dtype=np.int64)
    while len(u):
        lu, lv = lab[u], lab[v]
        live = lu != lv
        if not live.any():
            break
        u, v, lu, lv = u[live], v[live], lu[live], lv[live]
        np.minimum.at(lab, np.maximum(lu, lv), np.minimum(lu, lv))
        while True:
            nxt = lab[lab]
            if np.array_equal(nxt, lab):
                break
            lab = nxt
    return lab


def _orient(points: np.ndarray, tris: np.ndarray):
    """Consistent, outward orientation of each piece linked by edges shared by two triangles.

    Returns ``(triangles, flipped mask, piece label per triangle)``; the piece label is the
    smallest triangle index of the piece. Within a piece the smallest triangle keeps its
    orientation, then whole pieces with negative enclosed volume are reversed.
    """
    m = len(tris)
    start, end, order, rs, rc = _edge_keys(tris, len(points))
    s2 = rs[rc == 2]
    h1, h2 = order[s2], order[s2 + 1]
    t1, t2 = h1 // 3, h2 // 3
    same = start[h1] == start[h2]                # traversed the same way: one of the two must flip
    # double cover: node t = triangle t as stored, node m + t = triangle t reversed
    u = np.concatenate([t1, t1 + m])
    v = np.concatenate([np.where(same, t2 + m, t2), np.where(same, t2, t2 + m)])
    lab = _components(2 * m, u, v)
    l0, l1 = lab[:m], lab[m:]
    flip = l1 < l0                                # the reversed copy lies in the piece's first sheet
    piece = np.minimum(l0, l1)
    out = tris.copy()
    out[flip] = out[flip][:, ::-1]
    p0, p1, p2 = points[out[:, 0]], points[out[:, 1]], points[out[:, 2]]
    vol = np.einsum("ij,ij->i", p0, np.cross(p1, p2))
    piece_vol = np.bincount(piece, weights=vol, minlength=m)
    inward = piece_vol[piece] < 0
    out[inward] = out[inward][:, ::-1]
    return out, flip ^ inward, piece


def orient_consistently(points, triangles) -> Tuple[np.ndarray, int]:
    """Flip triangles so that neighbours across every manifold edge agree, each connected piece
    then facing outward (positive enclosed volume).

    For surfaces whose triangles are stored in arbitrary orientations (the Rodero et al. left
    ventricle is one). Edges shared by more than two triangles do not link pieces. Returns the
    new ``(m, 3)`` int64 triangles and the number of triangles flipped; topology defects (open or
    non-manifold edges) are left for :class:`palpate.TriSurface` to report (or
    :func:`repair_surface` to split).
    """
    pts = np.asarray(points, dtype=np.float64)
    tris = whole_indices(triangles, "triangles", 3)
    if len(tris) == 0:
        return tris, 0
    out, flipped, _ = _orient(pts, tris)
    return out, int(flipped.sum())


def repair_surface(points, triangles, part=None):
    """Repair a closed triangle surface so that :class:`palpate.TriSurface` can accept it.

    In order:

    1. removes exact duplicate triangles (same three vertices, in any order; the first is kept)
       and zero-area triangles (a repeated vertex or collinear corners), if any;
    2. orients every connected piece (triangles linked through edges shared by two triangles)
       consistently and outward, positive enclosed volume (as :func:`orient_consistently`);
    3. splits non-manifold edges and vertices: around every vertex, its triangles are grouped
       into fans linked through manifold edges only (shared by exactly two triangles traversed in
       opposite directions); every fan beyond the first (the one holding the vertex's lowest
       triangle corner) gets its own copy of the vertex, same coordinates, appended after the
       existing points. An edge shared by four triangles (two sheets touching) becomes two
       coincident manifold edges.

    Parameters
    ----------
    points: ``(n, 3)`` float array; triangles: ``(m, 3)`` integer array, 0-based;
    part: optional per-triangle array (e.g. the part codes of :func:`read_tagged_surface`),
    filtered alongside the triangles.

    Returns
    -------
    ``(points, triangles, part, report)``: points ``(n + k, 3)`` float64 (the input ones first,
    unchanged); triangles ``(m', 3)`` int64 in the input order (less any removed); part aligned
    with them (None if not given); report a dict with

    - ``"flipped"``: triangles reversed,
    - ``"components"``: connected pieces,
    - ``"split_vertices"``: input vertices that were split, ``"added_vertices"``: copies added,
    - ``"nonmanifold_edges"``: ``[(a, b, count), ...]``, the edges (input vertex indices, a < b)
      not shared by exactly two opposite triangles nor open, with their number of triangles,
    - ``"removed_triangles"``: duplicates plus zero-area triangles removed, also given apart as
      ``"duplicate_triangles"`` and ``"zero_area_triangles"``.

    Open edges are left alone (:class:`palpate.TriSurface` reports them); a removed zero-area
    sliver leaves its edges open.
    """
    pts = np.asarray(points, dtype=np.float64)
    tris = whole_indices(triangles, "triangles")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ParameterError(f"points must have shape (n, 3), got {pts.shape}")
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ParameterError(f"triangles must have shape (m, 3), got {tris.shape}")
    n, m = len(pts), len(tris)
    if m and (tris.min() < 0 or tris.max() >= n):
        raise ParameterError(f"triangle vertex indices must lie in [0, {n}), got [{tris.min()}, {tris.max()}]")
    if part is not None:
        part = np.asarray(part)
        if len(part) != m:
            raise ParameterError(f"part has {len(part)} entries, expected one per triangle ({m})")
    report = {"flipped": 0, "components": 0, "split_vertices": 0, "added_vertices": 0,
              "nonmanifold_edges": [], "removed_triangles": 0, "duplicate_triangles": 0,
              "zero_area_triangles": 0}
    if m == 0:
        return pts.copy(), tris, part, report

    # 1. duplicates and zero-area triangles
    s = np.sort(tris, axis=1)
    cr = np.cross(pts[tris[:, 1]] - pts[tris[:, 0]], pts[tris[:, 2]] - pts[tris[:, 0]])
    zero = (s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2]) | ~(cr != 0).any(axis=1)
    o = np.lexsort((s[:, 2], s[:, 1], s[:, 0]))
    dup = np.zeros(m, dtype=bool)
    dup[o[1:][(s[o[1:]] == s[o[:-1]]).all(axis=1)]] = True
    dup &= ~zero
    drop = zero | dup
    if drop.any():
        keep = ~drop
        tris = tris[keep]
        if part is not None:
            part = part[keep]
        m = len(tris)
        report.update(removed_triangles=int(drop.sum()), duplicate_triangles=int(dup.sum()),
                      zero_area_triangles=int(zero.sum()))
        if m == 0:
            return pts.copy(), tris, part, report

    # 2. orientation
    tris, flipped, piece = _orient(pts, tris)
    report["flipped"] = int(flipped.sum())
    report["components"] = int(np.count_nonzero(np.bincount(piece, minlength=m)))

    # 3. fans: triangle corners (row 3 t + k = vertex tri[t, k]) linked across manifold edges
    start, end, order, rs, rc = _edge_keys(tris, n)
    s2 = rs[rc == 2]
    h1, h2 = order[s2], order[s2 + 1]
    opposite = start[h1] == end[h2]
    bad = np.ones(len(rs), dtype=bool)
    bad[rc == 1] = False
    bad[np.flatnonzero(rc == 2)[opposite]] = False
    if bad.any():
        hb = order[rs[bad]]
        a, b = np.minimum(start[hb], end[hb]), np.maximum(start[hb], end[hb])
        report["nonmanifold_edges"] = [(int(x), int(y), int(c)) for x, y, c in zip(a, b, rc[bad])]
    # (a vertex can be non-manifold with all its edges manifold: two pieces touching at a point)
    h1, h2 = h1[opposite], h2[opposite]
    nxt1 = h1 - h1 % 3 + (h1 % 3 + 1) % 3          # corner at the end of half-edge h1
    nxt2 = h2 - h2 % 3 + (h2 % 3 + 1) % 3
    fan = _components(3 * m, np.concatenate([h1, nxt1]), np.concatenate([nxt2, h2]))
    cv = tris.ravel()
    roots = np.flatnonzero(fan == np.arange(3 * m))   # a fan's label: its lowest corner
    first = np.full(n, -1, dtype=np.int64)
    used, first_corner = np.unique(cv, return_index=True)
    first[used] = first_corner
    extra = roots[roots != first[cv[roots]]]
    if len(extra):
        extra = extra[np.argsort(cv[extra], kind="stable")]
        new_id = np.full(3 * m, -1, dtype=np.int64)
        new_id[extra] = n + np.arange(len(extra))
        corner = new_id[fan]
        tris = np.where(corner >= 0, corner, cv).reshape(m, 3)
        pts = np.concatenate([pts, pts[cv[extra]]])
        report["split_vertices"] = int(len(np.unique(cv[extra])))
        report["added_vertices"] = int(len(extra))
    return (pts if pts is not points else pts.copy()), tris, part, report


def repair_summary(report: dict, limit: int = 3) -> Optional[str]:
    """One sentence on what :func:`repair_surface` changed, or None if nothing."""
    bits = []
    if report["removed_triangles"]:
        bits.append(f"removed {report['duplicate_triangles']} duplicate and {report['zero_area_triangles']} "
                    "zero-area triangle(s)")
    if report["flipped"]:
        bits.append(f"re-oriented {report['flipped']} triangle(s) ({report['components']} piece(s), "
                    "consistent and outward)")
    if report["added_vertices"] and not report["nonmanifold_edges"]:
        bits.append(f"split {report['split_vertices']} non-manifold vertex(es) (pieces touching at a point) "
                    f"into {report['added_vertices']} new one(s)")
    elif report["added_vertices"]:
        edges = report["nonmanifold_edges"]
        shown = ", ".join(f"({a}, {b}) shared by {c} triangles" for a, b, c in edges[:limit])
        more = f" and {len(edges) - limit} more" if len(edges) > limit else ""
        bits.append(f"split {len(edges)} non-manifold edge(s) [{shown}{more}] by duplicating "
                    f"{report['split_vertices']} vertex(es) into {report['added_vertices']} new one(s)")
    return "; ".join(bits) if bits else None
