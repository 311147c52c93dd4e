"""Triangle surface files in: :func:`load_surface`.

Surfaces bound the solids that :func:`palpate.sample_inside` / :func:`palpate.sample_between`
fill with particles. Files are read with meshio (``.obj``, ``.stl``, ``.ply``, ``.off``, ``.vtk``,
``.vtu``), scaled to metres and validated in the Rust core (:class:`palpate.TriSurface`): every
defect is a :class:`palpate.SurfaceError` (a :class:`palpate.MeshError`) naming the file, the
triangle / vertex / edge and the reason.
"""
from __future__ import annotations

import os
import warnings
from typing import Tuple, Union

import numpy as np

from ._palpate import SurfaceError, TriSurface
from .io import unit_scale

PathLike = Union[str, "os.PathLike[str]"]

#: File extensions :func:`load_surface` reads, with meshio's format name.
SURFACE_FORMATS = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".off": "off", ".vtk": "vtk", ".vtu": "vtu"}

#: meshio cell types of dimension < 2, ignored beside triangles (points, polylines).
_LOWER_DIM = {"vertex", "line", "line3", "polyline"}


def read_surface_arrays(path: PathLike, unit: str = "m") -> Tuple[np.ndarray, np.ndarray]:
    """Read a triangle surface file without validating it in the core.

    Returns ``(points, triangles)``: points ``(n, 3)`` float64 in metres, triangles ``(m, 3)``
    int64 0-based. Vertex and line cells are ignored; any other non-triangle cell (quads,
    polygons, tetrahedra ...) is an error naming the file and the cell type.
    """
    import meshio

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
    tris = []
    for cb in m.cells:
        data = np.asarray(cb.data)
        if len(data) == 0 or cb.type in _LOWER_DIM:
            continue
        if cb.type != "triangle":
            hint = " (a volume mesh: load it with palpate.load_mesh)" if cb.type.startswith(("tetra", "hexa", "wedge", "pyramid")) else ""
            raise SurfaceError(f"{name}: cells of type '{cb.type}' ({len(data)} of them) are not triangles: "
                               f"palpate needs a closed triangle surface{hint}")
        tris.append(data.astype(np.int64))
    if not tris:
        raise SurfaceError(f"{name}: no triangles (empty surface)")
    return points * scale, np.concatenate(tris, axis=0)


def load_surface(path: PathLike, unit: str = "m") -> TriSurface:
    """Load and validate a closed triangle surface.

    Parameters
    ----------
    path:
        ``.obj``, ``.stl`` (ASCII or binary; coincident vertices are merged by meshio), ``.ply``,
        ``.off``, ``.vtk`` or ``.vtu`` holding triangles (vertex and line cells are ignored).
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
