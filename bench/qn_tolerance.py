"""The default integrator's distance from converged Newton under a firm press, by tolerance
(issue 38, item 1): the protocol case on MESH with its probe force scaled to each F, the
quasi-Newton backward Euler at each relative gradient tolerance, against Newton backward Euler
converged (``palpate.bench.newton_reference``): rel L2 of the second-half mean displacement field
(``palpate bench protocol``'s ``rel_L2_vs_newton``), steps/s, iterations, factorisations.

    OMP_NUM_THREADS=1 .venv/bin/python bench/qn_tolerance.py ../shared/bench/meshes/lv_1350.npz 1,2,5 2e-2,5e-3,1e-3,2e-4
"""
import sys

import numpy as np

import palpate as _p
from palpate import bench as B


def main() -> None:
    mesh = sys.argv[1]
    forces = [float(f) for f in sys.argv[2].split(",")]
    tols = [float(t) for t in sys.argv[3].split(",")]
    for force in forces:
        case = B.load_case(mesh, force)
        limit = B.STABLE_LIMIT_ANY_FORCE
        ref = _p.Body(case.mesh, B.material(), fixed=case.fixed, integrator=B.newton_reference())
        rn = ref.run_probe(case.loaded, case.total_force, B.RAMP, B.STEPS, dt=B.DT, stable_limit=limit)
        den = np.linalg.norm(rn["mean_disp"])
        print(f"{case.name} {force:g} N: Newton {rn['steps'] / rn['wall_s']:.0f} steps/s, "
              f"{rn['iterations_mean']:.2f} iterations a step", flush=True)
        for tol in tols:
            body = _p.Body(case.mesh, B.material(), fixed=case.fixed,
                           integrator=_p.BackwardEuler(tolerance=tol, max_iterations=200))
            r = body.run_probe(case.loaded, case.total_force, B.RAMP, B.STEPS, dt=B.DT, stable_limit=limit)
            rel = np.linalg.norm(r["mean_disp"] - rn["mean_disp"]) / den
            print(f"  tolerance {tol:g}: rel L2 {100 * rel:.2f}%, {r['steps'] / r['wall_s']:.0f} steps/s, "
                  f"iterations {r['iterations_mean']:.2f} (max {r['iterations_max']}), "
                  f"factorisations {r['factorizations']}, inverted max {r['inverted_max']}", flush=True)


if __name__ == "__main__":
    main()
