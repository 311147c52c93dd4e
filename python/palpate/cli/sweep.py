"""``palpate sweep SPEC.toml``: a batch study on Dask (:mod:`palpate.sweep`): the scenarios of the
spec as tasks on a ``LocalCluster`` of this machine's cores or on an existing scheduler, their
outcomes one Parquet table."""
from __future__ import annotations

import json

from ._common import Usage, add_quiet, require_extra


def add_parser(sub) -> None:
    s = sub.add_parser("sweep", help="run a batch study (a spec of parameters to vary) on Dask: one Parquet table",
                       description="Run the study SPEC (TOML: palpate.sweep.spec) as Dask tasks and write its table "
                                   "(results.parquet, a row per scenario; results.csv without the curves), its plot (results.png: "
                                   "the force-depth curves; needs matplotlib), its parts as they finish and a manifest to --out.")
    s.add_argument("spec", metavar="SPEC.toml")
    s.add_argument("--out", metavar="DIR", help="output folder (default: sweep-<study name>)")
    s.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: one per core; 0: in this process, no Dask)")
    s.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (tcp://host:8786) instead of a local cluster")
    s.add_argument("--resume", action="store_true", help="continue the study in --out, running only scenarios without a row")
    s.add_argument("--no-plot", action="store_true", help="write no results.png")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_quiet(s)
    s.set_defaults(func=cmd_sweep)


#: The study extra's packages (pyproject's ``study``): Dask's scheduler, Parquet results, the fit.
STUDY_MODULES = ("dask", "distributed", "pyarrow", "scipy")


def cmd_sweep(a) -> int:
    require_extra("sweep", "study", STUDY_MODULES)
    from ..sweep import sweep

    if a.workers is not None and a.workers < 0:
        raise Usage("palpate sweep: --workers must be 0 or more")
    if a.scheduler is not None and a.workers is not None:
        raise Usage("palpate sweep: --workers is for the local cluster; a --scheduler has its own workers")
    r = sweep(a.spec, a.out, scheduler=a.scheduler, workers=a.workers, resume=a.resume, quiet=a.quiet or a.json,
              log=None if a.json else print, plot=not a.no_plot)
    if a.json:
        print(json.dumps({"study": r.manifest["study"], "scenarios": r.done, "failed": r.failed, "ran": r.ran,
                          "table": str(r.path), "plot": None if r.plot is None else str(r.plot), "model_hash": r.manifest["model_hash"]}))
    elif not a.quiet:
        for line in table_lines(r.rows(), list(r.manifest.get("varied") or [])):
            print(line)
        plot = f"; the plot: {r.plot}" if r.plot is not None else ""
        print(f"  the table: {r.path} (all columns, curves included) and {r.path.with_suffix('.csv')} (no curves){plot}")
    return 0


#: Outcome columns of the printed table.
SHOWN = ("status", "max_force_n", "final_depth_m", "max_disp_m", "steps_done")


def table_lines(rows, varied, most: int = 12):
    """The study's rows as text: scenario, the varied parameters and :data:`SHOWN` (the first and
    last ``most // 2`` rows of a longer study)."""
    cols = ["scenario"] + varied + [c for c in SHOWN if rows and c in rows[0]]
    cell = lambda v: "-" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)  # noqa: E731
    shown = rows if len(rows) <= most else rows[: most // 2] + [None] + rows[-(most // 2):]
    text = [[c for c in cols]] + [["..."] * len(cols) if r is None else [cell(r.get(c)) for c in cols] for r in shown]
    w = [max(len(t[j]) for t in text) for j in range(len(cols))]
    return ["  " + "  ".join(t[j].rjust(w[j]) for j in range(len(cols))) for t in text]
