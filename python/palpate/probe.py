"""Where a tool presses on a model: the outward vertex normals of its outer surface
(:func:`vertex_normals`), the default probe vertex (:func:`probe_point`) and the press frame there
(:func:`probe_frame`: the point, its outward normal and the direction of a slide).

One definition for everything that presses "at the probe point": touch scripts (``vertex =
"probe"``, :mod:`palpate.touch`), the haptic palpations (:mod:`palpate.haptics`), the viewer,
``palpate bench hybrid`` and ``palpate validate``. (The shared benchmark protocol's probe point, a
point of its analytic outer ellipsoid rather than a vertex of a model, is
:func:`palpate.bench.probe_point`.)

>>> import palpate
>>> from palpate.probe import probe_frame
>>> m = palpate.build_shape("ellipsoids", particles=2000)
>>> v, point, normal, tangent = probe_frame(m.outer_points, m.outer_triangles)
>>> bool(point[0] > 0.025 and abs(point[2]) < 3e-3)      # the +x side, near the equator [m]
True
"""
from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

from ._indices import whole_indices

#: The default probe height, as a fraction of the outer surface's z extent: on the synthetic
#: ventricle (z from 0 to 42 mm) the protocol's 20 mm.
PROBE_HEIGHT = 20.0 / 42.0


def vertex_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) of a triangle surface (points (n, 3) [m],
    triangles (m, 3)), oriented outward: flipped if the surface's signed volume about its centroid
    is negative (this holds for an open surface such as a truncated ventricle's epicardium).
    Vertices in no triangle get a zero normal."""
    p = np.asarray(points, dtype=np.float64)
    t = whole_indices(triangles, "triangles", 3)
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    fn = np.cross(b - a, c - a)                       # 2 x area x unit normal
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, t[:, k], fn)
    o = p.mean(axis=0)
    if np.einsum("ij,ij->i", a - o, fn).sum() < 0:    # 6 x signed volume about the centroid
        n = -n
    ln = np.linalg.norm(n, axis=1)
    return np.divide(n, ln[:, None], out=np.zeros_like(n), where=ln[:, None] > 0)


def probe_point(points: np.ndarray, triangles: Optional[np.ndarray] = None) -> int:
    """The default probe vertex (index into ``points``, the outer surface (n, 3) [m]): the one
    nearest ``(x_max, (y_min + y_max) / 2, z_min + PROBE_HEIGHT (z_max - z_min))`` of the surface's
    bounding box (of the vertices in ``triangles`` if given). On the synthetic ventricle (y
    symmetric, z from 0 to 42 mm) that is the benchmark protocol's probe, the vertex nearest
    ``(x_max, 0, 20 mm)``; on the paper's ellipsoids a point on the x side just below the equator
    (above the held lower 30 %); on any model, a point of the +x side at mid height."""
    p = np.asarray(points, dtype=np.float64)
    used = p if triangles is None else p[np.unique(np.asarray(triangles))]
    lo, hi = used.min(axis=0), used.max(axis=0)
    target = np.array([hi[0], 0.5 * (lo[1] + hi[1]), lo[2] + PROBE_HEIGHT * (hi[2] - lo[2])])
    d = np.linalg.norm(p - target, axis=1)
    if triangles is not None:
        mask = np.zeros(len(p), dtype=bool)
        mask[np.unique(np.asarray(triangles))] = True
        d[~mask] = np.inf
    return int(np.argmin(d))


def probe_frame(points: np.ndarray, triangles: np.ndarray) -> Tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """``(vertex, point (3,) [m], outward unit normal (3,), tangent (3,))`` at the default probe
    vertex (:func:`probe_point`) of an outer surface (points (n, 3) [m], triangles (m, 3)): the
    area-weighted normal there (:func:`vertex_normals`; a vertex whose normal is zero takes the
    direction from the surface's centroid), and the horizontal unit tangent ``normal x z``
    (``normal x x`` where the normal is vertical), the direction of a slide. Press along
    ``-normal``."""
    s = np.asarray(points)
    tris = np.asarray(triangles)
    v = probe_point(s, tris)
    n = vertex_normals(s, tris)[v]
    if np.linalg.norm(n) == 0:
        n = s[v] - s.mean(axis=0)
    n = n / np.linalg.norm(n)
    t = np.cross(n, [0.0, 0.0, 1.0])
    if np.linalg.norm(t) < 1e-6:
        t = np.cross(n, [1.0, 0.0, 0.0])
    return v, s[v].copy(), n, t / np.linalg.norm(t)


__all__ = ["PROBE_HEIGHT", "probe_frame", "probe_point", "vertex_normals"]
