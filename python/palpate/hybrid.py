"""Building :class:`palpate.HybridModel` from files and from the shipped geometries.

The compiled hybrid model (FEM core, particle shell, skin, activation regions) is built in the
Rust core from the surfaces of an organ wall; these helpers read the surfaces first:

- :func:`build_from_files`: two nested closed surfaces (inner, outer), any format
  :func:`palpate.load_surface` reads;
- :func:`build_tagged_file`: one closed surface with a part per triangle (inner / outer / base,
  a truncated ventricle), read by :func:`palpate.read_tagged_surface`;
- :func:`build_shape`: ``"ellipsoids"`` (the paper's concentric ellipsoids), ``"ventricle"``
  (the synthetic truncated ventricle of the benchmark protocol) or ``"rodero"`` (the real left
  ventricle of Rodero et al., :func:`palpate.data.rodero_lv_path`);
- :func:`load_model`: a model file or a shape name, the one place that resolves what a user
  names as a model (``palpate touch|haptic|view|soak|bench hybrid MODEL``, a study's ``hybrid``).

Keyword options (``**opts``) are those of :meth:`palpate.HybridModel.build_nested`:
``projection``, ``core_fraction``, ``core_triangles``, ``core_layers``, ``spacing`` [m] or
``particles``, ``density`` [kg/m^3], ``min_region_particles``, ``field_voxels``.

>>> import palpate
>>> m = palpate.build_shape("ellipsoids", particles=2000)
>>> m.info()["core_tets"]
900
>>> palpate.build_shape("ellipsoids", particles=2000, core_triangles=64).info()["core_tets"]  # the paper's
192
"""
from __future__ import annotations

import math
import os
import warnings
from typing import Any, Optional, Tuple, Union

import numpy as np

from ._palpate import HybridModel, MeshWarning, ParameterError
from ._palpate import ventricle_surface as _ventricle_surface
from .surfaces import load_surface, read_tagged_surface

PathLike = Union[str, "os.PathLike[str]"]

#: The first 16 bytes of a palpate model file (what :meth:`HybridModel.save` writes).
MODEL_MAGIC = b"PALPATE\0HYBRID\0\0"

#: The geometries :func:`build_shape` knows.
SHAPES = ("ellipsoids", "ventricle", "rodero")

#: The paper's "Ellipsoids Model": semi-axes [m] of the inner and outer ellipsoid, and the
#: refinement of each (an octahedron refined 5 times: 8192 triangles, 4098 vertices).
ELLIPSOIDS_INNER = (0.020, 0.020, 0.035)
ELLIPSOIDS_OUTER = (0.026, 0.026, 0.042)
ELLIPSOIDS_SUBDIVISIONS = 5

#: The synthetic truncated ventricle (shared/bench/PROTOCOL.md): the wall between the
#: ellipsoids above, cut at z = 0, at this surface resolution (points per ring x rings).
VENTRICLE_Z_CUT = 0.0
VENTRICLE_CIRCUMFERENTIAL = 96
VENTRICLE_LONGITUDINAL = 24

_Tags = Any


def is_model_file(path: PathLike) -> bool:
    """True if ``path`` is a readable file starting with :data:`MODEL_MAGIC` (it may still be
    truncated or corrupted: :meth:`HybridModel.load` checks the rest)."""
    try:
        with open(os.fspath(path), "rb") as fh:
            return fh.read(len(MODEL_MAGIC)) == MODEL_MAGIC
    except OSError:
        return False


#: The volume an organ encloses [m^3]: 1 mL to 1 L (a human heart's left ventricle with its
#: cavity is about 0.1-0.3 L). Outside it, a surface was most likely read in the wrong unit.
ORGAN_VOLUME_M3 = (1e-6, 1e-3)


def organ_scale_warning(volume: float, unit: str, what: str) -> Optional[str]:
    """A message when ``what``, read in length unit ``unit``, encloses ``volume`` [m^3] outside
    :data:`ORGAN_VOLUME_M3`, naming the unit that would put it inside (None when inside). A
    surface in millimetres read as metres makes a 119 mL ventricle 119,000 m^3: the build would
    fill it with particles metres apart and a 5 mm tool would never touch it (issue 37)."""
    from .io import UNITS

    lo, hi = ORGAN_VOLUME_M3
    if not (volume > 0 and math.isfinite(volume)) or lo <= volume <= hi:
        return None
    in_file = volume / UNITS[unit] ** 3
    fits = [u for u, s in UNITS.items() if lo <= in_file * s ** 3 <= hi]
    hint = f"; read in {fits[0]} it would be {in_file * UNITS[fits[0]] ** 3 * 1e3:.3g} L: pass unit='{fits[0]}' " \
           f"(palpate build --unit {fits[0]})" if fits else ""
    return (f"{what} encloses {volume:.3g} m^3 ({volume * 1e3:.3g} L) read in {unit}: an organ encloses "
            f"1 mL to 1 L{hint}")


def _check_scale(volume: float, unit: str, what: str, strict: bool) -> None:
    msg = organ_scale_warning(volume, unit, what)
    if msg is None:
        return
    if strict:
        raise ParameterError(msg)
    warnings.warn(msg, MeshWarning, stacklevel=3)


def build_from_files(inner: PathLike, outer: PathLike, unit: str = "m", repair: bool = False,
                     strict_units: bool = False, **opts) -> HybridModel:
    """Build from two nested closed surface files (the wall lies inside ``outer``, outside
    ``inner``), read by :func:`palpate.load_surface` in length unit ``unit``.

    An outer surface enclosing less than 1 mL or more than 1 L (:func:`organ_scale_warning`: most
    likely the wrong ``unit``) warns (``MeshWarning``) with the unit that fits, or, with
    ``strict_units``, raises :class:`palpate.ParameterError` before the build.

    Raises :class:`palpate.SurfaceError` naming the file for an unreadable or invalid surface
    and for a pair that is not nested; ``ValueError`` for a bad option.
    """
    si = load_surface(inner, unit=unit, repair=repair)
    so = load_surface(outer, unit=unit, repair=repair)
    _check_scale(so.volume, unit, f"{os.fspath(outer)}: the outer surface", strict_units)
    return HybridModel.build_nested(si, so, **opts)


def build_tagged_file(path: PathLike, unit: str = "m", *, tag_array: Optional[str] = None, inner: _Tags = None,
                      outer: _Tags = None, base: _Tags = None, repair: bool = True, strict_units: bool = False,
                      **opts) -> HybridModel:
    """Build from one closed surface file whose triangles are tagged inner / outer / base
    (:func:`palpate.read_tagged_surface` with ``tag_array``, ``inner``, ``outer``, ``base``,
    ``repair``; the surface is repaired by default). The wall's volume is checked as
    :func:`build_from_files` checks the outer surface's (``strict_units`` alike)."""
    points, triangles, part = read_tagged_surface(path, unit=unit, tag_array=tag_array, inner=inner, outer=outer,
                                                  base=base, repair=repair)
    p, t = np.asarray(points, dtype=float), np.asarray(triangles, dtype=np.int64)
    volume = abs(float(np.einsum("ij,ij->i", p[t[:, 0]], np.cross(p[t[:, 1]], p[t[:, 2]])).sum()) / 6.0)
    _check_scale(volume, unit, f"{os.fspath(path)}: the wall", strict_units)
    return HybridModel.build_tagged(points, triangles, part, **opts)


#: The synthetic truncated ventricle as one tagged closed surface: ``palpate-core``'s
#: ``hybrid::shapes::truncated_ventricle`` (the surface the Rust tests and examples build), see
#: :func:`palpate.ventricle_surface`; ``(points [m], triangles, part)`` as
#: :func:`palpate.read_tagged_surface` returns.
ventricle_surface = _ventricle_surface


def build_shape(name: str, **opts) -> HybridModel:
    """Build one of the shipped geometries (:data:`SHAPES`):

    - ``"ellipsoids"``: the paper's concentric ellipsoids, semi-axes (20, 20, 35) mm and
      (26, 26, 42) mm, ``ellipsoid_surface(..., 5)`` each (:meth:`HybridModel.build_nested`);
    - ``"ventricle"``: :func:`ventricle_surface` (:meth:`HybridModel.build_tagged`);
    - ``"rodero"``: the Rodero et al. left ventricle (millimetres, parts from its part
      definition, repaired), fetched on first use (:class:`palpate.data.DataError` if that fails).
    """
    if name == "ellipsoids":
        from ._palpate import ellipsoid_surface

        return HybridModel.build_nested(ellipsoid_surface(ELLIPSOIDS_INNER, ELLIPSOIDS_SUBDIVISIONS),
                                        ellipsoid_surface(ELLIPSOIDS_OUTER, ELLIPSOIDS_SUBDIVISIONS), **opts)
    if name == "ventricle":
        return HybridModel.build_tagged(*ventricle_surface(), **opts)
    if name == "rodero":
        import warnings

        from ._palpate import MeshWarning
        from .data import rodero_lv_path

        path = rodero_lv_path()
        with warnings.catch_warnings():
            # the known repair of the shipped file (re-orientation, two non-manifold edges split)
            # and the two four-triangle specks that split leaves, which the build drops: a new
            # user's first build should not show a warning about palpate's own data
            warnings.simplefilter("ignore", MeshWarning)
            points, triangles, part = read_tagged_surface(path, unit="mm")
            return HybridModel.build_tagged(points, triangles, part, **opts)
    raise ParameterError(f"unknown shape {name!r}; expected one of {', '.join(SHAPES)}")


def load_model(spec: str) -> Tuple[str, HybridModel]:
    """``(name, model)`` for a shape name (:data:`SHAPES`, built by :func:`build_shape` with its
    warnings silenced) or a model file path (:meth:`HybridModel.load`; ``name`` its base name).
    Raises :class:`palpate.ParameterError` (a ``ValueError``) for neither,
    :class:`palpate.ModelFileError` / ``OSError`` for a bad file and :class:`palpate.data.DataError`
    when the Rodero data cannot be fetched."""
    if spec in SHAPES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return spec, build_shape(spec)
    if os.path.isfile(spec):
        if not is_model_file(spec):
            raise ParameterError(f"{spec} is not a palpate model file (write one with palpate build)")
        return os.path.basename(spec), HybridModel.load(spec)
    raise ParameterError(f"{spec!r} is neither a model file nor a shape ({', '.join(SHAPES)})")
