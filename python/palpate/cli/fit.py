"""``palpate fit SPEC.toml --measured CURVE.csv``: identify the material from a measured
force-depth curve (:mod:`palpate.sweep.fit`): a coarse sweep, then least squares, on the same
runner as ``palpate sweep``."""
from __future__ import annotations

import json

from ._common import Usage, require_extra
from .sweep import STUDY_MODULES


def add_parser(sub) -> None:
    s = sub.add_parser("fit", help="fit Young's modulus (and optionally Poisson's ratio, viscosity) to a measured curve",
                       description="Fit the material of SPEC's loading to a measured force-depth curve (CSV with "
                                   "depth_m and force_n columns): a coarse sweep, then a least-squares refinement; "
                                   "prints the values, their 95% confidence intervals and the residual, and plots "
                                   "measured against fitted.")
    s.add_argument("spec", metavar="SPEC.toml")
    s.add_argument("--measured", required=True, metavar="CURVE.csv", help="depth_m, force_n columns [m, N]")
    s.add_argument("--params", default="young", metavar="P[,P...]",
                   help="what to fit: young, poisson, phi, psi (default young)")
    s.add_argument("--plot", default="fit.png", metavar="PNG", help="measured against fitted (default fit.png; '' for none)")
    s.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: one per core; 0: in this process)")
    s.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler instead of a local cluster")
    s.add_argument("--json", action="store_true", help="the result as one JSON object")
    s.set_defaults(func=cmd_fit)


def cmd_fit(a) -> int:
    require_extra("fit", "study", STUDY_MODULES)
    from ..sweep.fit import fit

    if a.workers is not None and a.workers < 0:
        raise Usage("palpate fit: --workers must be 0 or more")
    params = [p.strip() for p in a.params.split(",") if p.strip()]
    r = fit(a.spec, a.measured, params, scheduler=a.scheduler, workers=a.workers, plot=a.plot or None,
            log=None if a.json else print)
    if a.json:
        print(json.dumps({"values": r.values, "ci95": {k: list(v) for k, v in r.ci95.items()}, "rms": r.rms,
                          "residual_unit": r.residual_unit, "scenarios": r.evaluations, "plot": r.plot, "status": r.status}))
    else:
        print(f"palpate fit: {a.spec} against {a.measured}:")
        print(r.summary())
        if r.plot:
            print(f"  plot: {r.plot}")
    return 0
