"""St. Venant-Kirchhoff vs Neo-Hookean: static solutions of the benchmark case at several probe forces.

The shared protocol case (python/palpate/bench/__init__.py: E = 30 kPa, nu = 0.4, base fixed, the outer-surface
nodes near the probe point share the total force along the inward normal) is solved to static
equilibrium (`Body.static_solve`, Newton with load increments) for both laws. Prints a markdown
table: per force, the loaded nodes' mean |u| and max |u| for each law, the relative L2 difference
of the displacement fields ||u_NH - u_SVK|| / ||u_SVK||, the smallest det F over the tets, and the
solve time. Used for VALIDATION.md ("Neo-Hookean and St. Venant-Kirchhoff").

Run from the repo root (after `make setup`):
    .venv/bin/python bench/law_compare.py                      # lv_1350 at 0.2 N and 2 N
    .venv/bin/python bench/law_compare.py --mesh 190 --forces 0.2 1 2 4
The shared folder is $PALPATE_SHARED (the folder holding bench/), else <repo>/../shared.
"""
import argparse
import os
import time
from pathlib import Path

import numpy as np

import palpate
from palpate import bench

REPO = Path(__file__).resolve().parents[1]


def min_det_f(mesh, x):
    """Smallest det F over the tets of `mesh` at positions `x` (n, 3) [m]."""
    p, t = mesh.points, mesh.tets
    dm = np.stack([p[t[:, k]] - p[t[:, 0]] for k in (1, 2, 3)], axis=-1)
    ds = np.stack([x[t[:, k]] - x[t[:, 0]] for k in (1, 2, 3)], axis=-1)
    return float((np.linalg.det(ds) / np.linalg.det(dm)).min())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="1350", help="shared bench mesh: 190, 1350, 10k, 50k (default 1350)")
    ap.add_argument("--forces", type=float, nargs="+", default=[0.2, 2.0], help="total probe forces [N]")
    ap.add_argument("--load-steps", type=int, default=4, help="initial load increments of the static solve")
    a = ap.parse_args()
    shared = Path(os.environ.get("PALPATE_SHARED") or REPO.parent / "shared")
    case = bench.load_case(str(shared / "bench" / "meshes" / f"lv_{a.mesh}.msh"))
    n = case.total_force / np.linalg.norm(case.total_force)
    print(f"lv_{a.mesh}: {case.mesh.n_tets} tets, {case.mesh.n_nodes} nodes, {len(case.loaded)} loaded nodes, "
          f"E = {bench.E} Pa, nu = {bench.NU}")
    print("| force [N] | law | loaded mean \\|u\\| [mm] | max \\|u\\| [mm] | min det F | rel. L2 NH vs SVK | solve [s] |")
    print("|---|---|---|---|---|---|---|")
    for force in a.forces:
        u = {}
        for law in (palpate.Law.ST_VENANT_KIRCHHOFF, palpate.Law.NEO_HOOKEAN):
            mat = palpate.Material(young=bench.E, poisson=bench.NU, density=bench.RHO, law=law)
            body = palpate.Body(case.mesh, mat, fixed=case.fixed)
            f = np.zeros((body.n_nodes, 3))
            f[case.loaded] = force * n / len(case.loaded)
            t0 = time.perf_counter()
            try:
                x = body.static_solve(f, load_steps=a.load_steps)
            except palpate.SolveError as e:
                name = "SVK" if law == palpate.Law.ST_VENANT_KIRCHHOFF else "NH"
                print(f"| {force} | {name} | no equilibrium found: {e} | | | | |")
                continue
            dt = time.perf_counter() - t0
            u[law] = x - case.mesh.points
            mag = np.linalg.norm(u[law], axis=1)
            rel = ""
            if law == palpate.Law.NEO_HOOKEAN and palpate.Law.ST_VENANT_KIRCHHOFF in u:
                us = u[palpate.Law.ST_VENANT_KIRCHHOFF]
                rel = f"{np.linalg.norm(u[law] - us) / np.linalg.norm(us):.3f}"
            name = "SVK" if law == palpate.Law.ST_VENANT_KIRCHHOFF else "NH"
            print(f"| {force} | {name} | {1e3 * mag[case.loaded].mean():.4f} | {1e3 * mag.max():.4f} | "
                  f"{min_det_f(case.mesh, x):.3f} | {rel} | {dt:.2f} |")


if __name__ == "__main__":
    main()
