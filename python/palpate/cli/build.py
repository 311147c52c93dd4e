"""``palpate build``: a hybrid model (FEM core, particle shell, skin) from wall surfaces, a tagged
surface or a shipped shape, summarised and saved. The build options' defaults are the core's
(``palpate.defaults.hybrid``)."""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from .. import _palpate as _p
from .. import _progress
from .. import defaults
from ..hybrid import SHAPES
from ._common import Fail, RunFailed, Usage, add_quiet, mb, model_lines, num

#: --projection: the Projection, a description and a note of each choice.
_PROJECTIONS = {
    "transmural": (_p.Projection.TRANSMURAL, "along the transmural field's streamlines", "any wall"),
    "radial": (_p.Projection.RADIAL, "the paper's, through the mass centre", "star-shaped walls"),
}


def add_parser(sub) -> None:
    d = defaults.hybrid
    h = sub.add_parser("build", help="build a hybrid model (FEM core, particle shell, skin) from wall surfaces",
                       description="Build a palpate hybrid model from two nested closed surfaces INNER OUTER, one "
                                   "tagged surface (--tagged) or a shipped geometry (--shape), print a summary and "
                                   "write MODEL (load it with palpate.HybridModel.load).")
    h.add_argument("files", nargs="*", metavar="INNER OUTER", help="two nested closed surface files (.obj, .stl, .ply, "
                   ".off, .vtk, .vtu, .vtp)")
    h.add_argument("--tagged", metavar="SURFACE", help="one closed surface with an inner / outer / base tag per "
                   "triangle (a truncated ventricle)")
    h.add_argument("--shape", choices=SHAPES,
                   help="ellipsoids: the paper's concentric ellipsoids; ventricle: the benchmark's truncated "
                        "ventricle; rodero: the real left ventricle of Rodero et al. (fetched on first use)")
    h.add_argument("-o", "--output", required=True, metavar="MODEL", help="model file to write")
    add_quiet(h)
    h.add_argument("--unit", choices=["m", "cm", "mm"], help="length unit of the surface files (default m)")
    h.add_argument("--strict-units", action="store_true",
                   help="refuse a surface enclosing under 1 mL or over 1 L (most likely the wrong --unit) "
                        "instead of noting it")
    h.add_argument("--tag-array", metavar="NAME", help="integer cell array holding the tags (default surface-id)")
    h.add_argument("--inner", metavar="T[,T...]", help="tag values of the inner surface")
    h.add_argument("--outer", metavar="T[,T...]", help="tag values of the outer surface")
    h.add_argument("--base", metavar="T[,T...]", help="tag values of the base (valve planes, cut)")
    proj = next(k for k, (p, _, _) in _PROJECTIONS.items() if p == d.projection)
    h.add_argument("--projection", choices=list(_PROJECTIONS), default=proj,
                   help="; ".join(f"{k}: {desc} ({note}{', default' if k == proj else ''})"
                                  for k, (_, desc, note) in _PROJECTIONS.items()))
    h.add_argument("--core-fraction", type=float, default=d.core_fraction, metavar="F",
                   help=f"fraction of the wall (from the inner surface) in the FEM core (default {num(d.core_fraction)})")
    h.add_argument("--core-triangles", type=int, default=d.core_triangles, metavar="N",
                   help="triangles of the simplified inner surface, 3 tets each per layer (default "
                        f"{d.core_triangles}{': automatic' if d.core_triangles == 0 else ''})")
    h.add_argument("--core-layers", type=int, default=d.core_layers, metavar="N",
                   help="prism layers of the core (default "
                        f"{d.core_layers}{': automatic, about as tall as wide' if d.core_layers == 0 else ''})")
    g = h.add_mutually_exclusive_group()
    g.add_argument("--spacing", type=float, default=d.spacing, metavar="M", help="particle lattice spacing [m]"
                   + ("" if d.spacing is None else f" (default {num(d.spacing)})"))
    g.add_argument("--particles", type=int, default=d.particles, metavar="N",
                   help=f"about N particles in the shell (default {d.particles}; ignored with --spacing)")
    h.add_argument("--density", type=float, default=d.density, metavar="RHO",
                   help=f"density [kg/m^3] (default {num(d.density)})")
    h.add_argument("--min-region-particles", type=int, default=d.min_region_particles, metavar="N",
                   help=f"particles an activation region grows to at least (default {d.min_region_particles})")
    h.add_argument("--field-voxels", type=int, default=d.field_voxels, metavar="N",
                   help=f"wall voxels of the transmural field solve (default {d.field_voxels})")
    h.add_argument("--no-homogenise", dest="homogenise", action="store_false",
                   help="keep the core as stiff as the tissue (the paper's core; by default the build computes "
                        "how much stiffer the core must be to bend as the whole wall does, VALIDATION.md)")
    h.set_defaults(func=cmd_build)


def input_extent_line(model, unit: str) -> str:
    """The outer surface's extent in the unit the input was read in, and in metres: a surface
    read in the wrong unit shows at once (issue 37: 52 x 52 x 84 mm, not 52 x 52 x 84 m)."""
    from ..io import UNITS

    p = np.asarray(model.outer_points, dtype=float)
    ext = p.max(axis=0) - p.min(axis=0)
    s = UNITS[unit]
    return (f"  input read in {unit}: the outer surface spans " + " x ".join(f"{v / s:.4g}" for v in ext)
            + f" {unit} (" + " x ".join(f"{v:.4g}" for v in ext) + " m)")


def _int_list(text: Optional[str], flag: str):
    if text is None:
        return None
    try:
        vals = [int(v) for v in text.split(",") if v.strip() != ""]
    except ValueError:
        raise Usage(f"palpate build: {flag} takes comma-separated integer tag values, got {text!r}") from None
    if not vals:
        raise Usage(f"palpate build: {flag} takes comma-separated integer tag values, got {text!r}")
    return vals


def cmd_build(a) -> int:
    import os
    import time
    import warnings

    from .. import hybrid
    from ..data import DataError

    files = a.files or []
    modes = [bool(files), a.tagged is not None, a.shape is not None]
    if sum(modes) != 1:
        raise Usage("palpate build: give INNER OUTER (two nested surfaces), --tagged SURFACE or --shape NAME "
                   "(exactly one)")
    if files and len(files) != 2:
        raise Usage(f"palpate build: give two surface files INNER OUTER, got {len(files)}")
    if a.tagged is None and any(v is not None for v in (a.tag_array, a.inner, a.outer, a.base)):
        raise Usage("palpate build: --tag-array, --inner, --outer and --base go with --tagged SURFACE")
    if a.shape is not None and a.unit is not None:
        raise Usage("palpate build: --unit is for surface files, not --shape (the shapes are in metres)")
    unit = a.unit or "m"
    # Where the model goes, checked before the build's seconds are spent (it is written again at
    # the end, which reports any other failure to write).
    parent = os.path.dirname(os.path.abspath(a.output))
    if os.path.isdir(a.output):
        raise RunFailed(f"palpate build: cannot write the model: {a.output} is a directory (give a file name, "
                        f"e.g. {os.path.join(a.output, 'model.palpate')})")
    if not os.path.isdir(parent):
        raise RunFailed(f"palpate build: cannot write the model: {parent} is not a directory")
    opts = {"projection": _PROJECTIONS[a.projection][0],
            "core_fraction": a.core_fraction, "core_triangles": a.core_triangles, "core_layers": a.core_layers,
            "spacing": a.spacing, "particles": a.particles, "density": a.density,
            "min_region_particles": a.min_region_particles, "field_voxels": a.field_voxels,
            "homogenise": a.homogenise}
    opts = {k: v for k, v in opts.items() if v is not None}   # None: the core's default
    for flag, v in (("--core-triangles", a.core_triangles), ("--core-layers", a.core_layers),
                    ("--particles", a.particles), ("--min-region-particles", a.min_region_particles),
                    ("--field-voxels", a.field_voxels)):
        if v is not None and v < 0:
            raise Usage(f"palpate build: {flag} must not be negative, got {v}")
    for flag, v in (("--spacing", a.spacing), ("--density", a.density)):
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise Usage(f"palpate build: {flag} must be positive, got {v}")
    if files:
        what = f"inner {files[0]}, outer {files[1]}"
        build = lambda: hybrid.build_from_files(files[0], files[1], unit=unit, strict_units=a.strict_units, **opts)  # noqa: E731
    elif a.tagged is not None:
        what = f"{a.tagged} (tagged)"
        tags = dict(tag_array=a.tag_array, inner=_int_list(a.inner, "--inner"), outer=_int_list(a.outer, "--outer"),
                    base=_int_list(a.base, "--base"))
        build = lambda: hybrid.build_tagged_file(a.tagged, unit=unit, strict_units=a.strict_units, **tags, **opts)  # noqa: E731
    else:
        what = f"shape {a.shape}"
        build = lambda: hybrid.build_shape(a.shape, **opts)  # noqa: E731
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with _progress.task(f"building the hybrid model ({what})"):   # a terminal only
                model = build()
    except (_p.SurfaceError, _p.MeshError, ValueError, DataError) as e:
        msg = str(e)
        if not any(os.path.basename(f) in msg for f in files + [a.tagged or ""] if f):
            msg = f"{what}: {msg}"
        raise Fail(f"palpate build: {msg}", cause=e) from None
    except OSError as e:
        raise Fail(f"palpate build: cannot read the input: {e}") from None
    except _p.PalpateError as e:
        raise Fail(f"palpate build: {what}: the build failed: {e}", cause=e) from None
    wall = time.perf_counter() - t0
    info = model.info()
    # The model first, the summary after: the command's work is the file, and stdout may be a
    # pipe whose reader has gone (`palpate build ... | true` wrote no model; issue 35 item 7).
    try:
        model.save(a.output)
    except (OSError, _p.ModelFileError) as e:
        raise RunFailed(f"palpate build: cannot write the model: {e}") from None
    print(f"palpate build: {what}: {info['projection']} projection, core fraction {info['core_fraction']:g}; "
          f"{wall:.2f} s including reading the input")
    for w in caught:
        print(f"  note: {w.message}")
    if files or a.tagged is not None:
        print(input_extent_line(model, unit))
    for line in model_lines(info):
        print(line)
    print(f"  wrote {a.output} ({mb(info['file_bytes'])})")
    return 0
