"""A sphere pressed into a hybrid slab, against Hertz (issue 33, item 3; VALIDATION.md).

The slab is a box ``--width`` x ``--width`` x ``--height`` [m] given to
:meth:`palpate.HybridModel.build_tagged` as one closed surface: the bottom is the inner part (the
core grows up from it to ``--core-fraction`` of the height), the top the outer part (the skin), the
four sides the base (the runtime holds the core's nodes there; the bottom is free). A sphere of
``--radius`` is pressed quasi-statically at the top's centre (:func:`palpate.validate.hybrid_curve`:
per depth a 0.5 s ramp and a 0.5 s hold at 1 kHz) and the force is printed beside Hertz's
``4/3 E/(1 - nu^2) sqrt(R) d^1.5`` with the contact radius ``sqrt(R d)`` in particle spacings.

    .venv/bin/python bench/hybrid_slab.py --core-fraction 0.85 --radius 0.005 --depths 0.001 0.002 0.004
"""
from __future__ import annotations

import argparse

import numpy as np

import palpate
from palpate import validate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=float, default=0.08, help="box width [m] (default 0.08)")
    ap.add_argument("--height", type=float, default=0.04, help="box height [m] (default 0.04)")
    ap.add_argument("--cells", type=int, default=50, help="quads along the width (default 50)")
    ap.add_argument("--core-fraction", type=float, default=0.85, help="the core's share of the height (default 0.85)")
    ap.add_argument("--radius", type=float, default=0.005, help="sphere radius [m] (default 0.005)")
    ap.add_argument("--depths", type=float, nargs="+", default=[0.001, 0.002, 0.004], help="travels [m]")
    a = ap.parse_args()
    points, tris, parts = validate.slab_surface(a.width, a.height, a.cells)
    model = palpate.HybridModel.build_tagged(points, tris, parts, core_fraction=a.core_fraction)
    print(model)
    case = validate.IndentCase(shape="slab", tool_radius=a.radius, point=(0.0, 0.0, a.height),
                               direction=(0.0, 0.0, -1.0), depths=tuple(a.depths))
    hyb = validate.hybrid_curve(model, case, verbose=True)
    spacing = model.info()["spacing_m"]
    hertz = validate.hertz_force(case.young, case.poisson, a.radius, np.asarray(hyb["indentation"]))
    for t, d, f, h, pen, act in zip(hyb["travel"], hyb["indentation"], hyb["force"], hertz, hyb["penetration"],
                                    hyb["active"]):
        print(f"travel {t * 1e3:.2f} mm, indentation {d * 1e3:.2f} mm: {f:.4f} N, Hertz {h:.4f} N "
              f"({100 * (f / h - 1):+.0f}%), contact radius {np.sqrt(a.radius * d) / spacing:.1f} spacings, "
              f"tool {pen * 1e3:.2f} mm into the skin, {act} active")


if __name__ == "__main__":
    main()
