"""The first step's cost on a large FEM body, with and without the factorisation made ahead
(issue 38, item 4): the protocol case on MESH (default lv_50k), a ``Body`` stepped once then
again, fresh, and after ``Body.prepare(dt)`` (what the haptic loop does before its clock starts).

    OMP_NUM_THREADS=1 .venv/bin/python bench/first_step.py ../shared/bench/meshes/lv_50k.npz
"""
import sys
import time

import numpy as np

import palpate
from palpate import bench as B


def main() -> None:
    case = B.load_case(sys.argv[1] if len(sys.argv) > 1 else str(B.shared_dir() / "bench/meshes/lv_50k.npz"), B.FORCE)
    for prepared in (False, True):
        body = palpate.Body(case.mesh, B.material(), fixed=case.fixed)
        tp = 0.0
        if prepared:
            t = time.perf_counter()
            body.prepare(B.DT)
            tp = time.perf_counter() - t
        f = np.zeros((body.n_nodes, 3))
        f[case.loaded] = case.total_force / len(case.loaded)
        body.set_forces(f)
        t = time.perf_counter()
        body.step(1, dt=B.DT)
        t1 = time.perf_counter() - t
        t = time.perf_counter()
        body.step(1, dt=B.DT)
        t2 = time.perf_counter() - t
        print(f"{case.name} ({case.mesh.n_tets} tets), prepared={prepared}: prepare {tp:.3f} s, "
              f"first step {t1 * 1e3:.1f} ms, second {t2 * 1e3:.1f} ms", flush=True)


if __name__ == "__main__":
    main()
