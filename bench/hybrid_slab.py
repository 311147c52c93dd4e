"""A sphere pressed into a hybrid slab, against Hertz (issue 33, item 3; VALIDATION.md).

The slab is a box ``--width`` x ``--width`` x ``--height`` [m] given to
:meth:`palpate.HybridModel.build_tagged` as one closed surface: the bottom is the inner part (the
core grows up from it to ``--core-fraction`` of the height), the top the outer part (the skin), the
four sides the base (the runtime holds the core's nodes there; the bottom is free). A sphere of
``--radius`` is pressed quasi-statically at the top's centre (:func:`palpate.validate.hybrid_curve`:
per depth a 0.5 s ramp and a 0.5 s hold at 1 kHz) and the force is printed beside Hertz's
``4/3 E/(1 - nu^2) sqrt(R) d^1.5`` with the contact radius ``sqrt(R d)`` in particle spacings.

    .venv/bin/python bench/hybrid_slab.py --core-fraction 0.85 --radius 0.005 --depths 0.001 0.002 0.004

``--fem N`` instead presses the slab's own full-FEM reference (Neo-Hookean, ``Body.indent``) on a
``box_mesh`` of N x N x (2/3 N) cells graded toward the contact, the side nodes held up to the
core's top as the runtime holds them (VALIDATION.md: 16, 24, 32 give 15k, 55k, 135k tets).

    .venv/bin/python bench/hybrid_slab.py --fem 24 --radius 0.015 --depths 0.0008 0.0017 0.0034 0.0045
"""
from __future__ import annotations

import argparse

import numpy as np

import palpate
from palpate import validate


def fem_reference(a: argparse.Namespace, grading: float = 1.4) -> None:
    """The slab's full-FEM reference at the travels ``a.depths``, printed against Hertz."""
    w, h = a.width, a.height
    box = palpate.box_mesh(size=(w, w, h), cells=(a.fem, a.fem, max(2, round(a.fem * 2 / 3))))
    p = np.array(box.points, dtype=float)
    # Centred, and graded toward (0, 0, h): s -> sign(s) |s|^g across, t -> 1 - (1 - t)^g down.
    s = (p[:, :2] - w / 2) / (w / 2)
    p[:, :2] = w / 2 * np.sign(s) * np.abs(s) ** grading
    p[:, 2] = h * (1 - (1 - p[:, 2] / h) ** grading)
    mesh = palpate.TetMesh(p, np.array(box.tets))
    side = (np.abs(np.abs(p[:, 0]) - w / 2) < 1e-9) | (np.abs(np.abs(p[:, 1]) - w / 2) < 1e-9)
    fixed = np.nonzero(side & (p[:, 2] <= a.core_fraction * h + 1e-9))[0]
    case = validate.IndentCase(shape="slab", tool_radius=a.radius, point=(0.0, 0.0, h), direction=(0.0, 0.0, -1.0))
    body = palpate.Body(mesh, case.material(case.reference_law), fixed=fixed)
    r = body.indent(case.start(), np.asarray(case.direction), a.radius, np.asarray(a.depths),
                    max_increment=a.radius / 10, sample_spacing=3e-4)
    hertz = validate.hertz_force(case.young, case.poisson, a.radius, r["indentation"])
    for d, f, hz in zip(r["indentation"], r["force_along"], hertz):
        print(f"FEM {mesh.n_tets} tets: indentation {d * 1e3:.3f} mm: {f:.4f} N, Hertz {hz:.4f} N ({100 * (f / hz - 1):+.1f}%)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=float, default=0.08, help="box width [m] (default 0.08)")
    ap.add_argument("--height", type=float, default=0.04, help="box height [m] (default 0.04)")
    ap.add_argument("--cells", type=int, default=50, help="quads along the width (default 50)")
    ap.add_argument("--core-fraction", type=float, default=0.85, help="the core's share of the height (default 0.85)")
    ap.add_argument("--radius", type=float, default=0.005, help="sphere radius [m] (default 0.005)")
    ap.add_argument("--depths", type=float, nargs="+", default=[0.001, 0.002, 0.004], help="travels [m]")
    ap.add_argument("--fem", type=int, default=None, help="press the slab's full-FEM reference of N x N x 2N/3 cells")
    a = ap.parse_args()
    if a.fem is not None:
        fem_reference(a)
        return
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
