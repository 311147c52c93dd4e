"""``palpate bench sweep``: what the Dask runner costs and gains (issue 17's benchmark).

A study of ``n`` probe scenarios on one protocol mesh (default ``lv_1350``, 1000 steps each,
Young's modulus on an even grid of +-20% around the protocol's, so that every scenario does a
similar amount of work) is run three ways on this machine: a plain Python loop over the
scenarios in this process (no Dask, no files), the runner on a ``LocalCluster`` of 1 worker, and
of 2 workers (table, parts and manifest written, as ``palpate sweep`` does). Reported: the wall
time and scenarios per second of each; the runner's overhead per scenario
(``(t_1worker - t_loop) / n`` over ``t_loop / n``: start-up, the model's transfer, scheduling,
Parquet writes; target at most 5%); and the 2-worker speed-up over 1 worker (target at least
1.8x on 2 cores). The cluster's start-up is included, as a user waits for it too; it is also
timed on its own (``startup_s``: importing ``distributed``, starting a 1-worker ``LocalCluster``
and closing it, no scenario), and the overhead without it is ``overhead_per_scenario_steady``.
"""
from __future__ import annotations

import os
import tempfile
import time
from typing import Any, Dict

from .runner import model_payload, sweep
from .scenario import run_scenario
from .spec import spec_from_dict

#: Keys of the JSON report.
KEYS = ("mesh", "scenarios", "steps", "loop_s", "worker1_s", "worker2_s", "loop_per_s", "worker1_per_s",
        "worker2_per_s", "overhead_per_scenario", "startup_s", "overhead_per_scenario_steady", "speedup_2_over_1", "cores")


def study(mesh: str, n: int, steps: int) -> Dict[str, Any]:
    return {"study": {"name": f"bench-{mesh}"}, "model": {"mesh": mesh},
            "loading": {"kind": "probe", "steps": steps},
            "parameters": {"young": {"grid": [2.4e4, 3.6e4], "num": n}}, "outputs": {"curve": True}}


def run(mesh: str = "1350", n: int = 64, steps: int = 1000, log=None) -> Dict[str, Any]:
    say = log or (lambda s: None)
    sp = spec_from_dict(study(mesh, n, steps))
    payload = model_payload(sp)
    scen = sp.scenarios()
    t0 = time.perf_counter()
    rows = [run_scenario(payload, s, True, False) for s in scen]
    loop = time.perf_counter() - t0
    bad = [r["error"] for r in rows if r["status"] != "ok"]
    say(f"plain loop: {n} scenarios in {loop:.2f} s" + (f" ({len(bad)} not ok: {bad[0]})" if bad else ""))
    out: Dict[str, Any] = {"mesh": mesh, "scenarios": n, "steps": steps, "loop_s": loop, "cores": os.cpu_count()}
    from .runner import Runner
    t0 = time.perf_counter()
    import distributed  # noqa: F401 - its import is part of the start-up a user waits for
    Runner(payload, workers=1).close()
    out["startup_s"] = time.perf_counter() - t0
    for w in (1, 2):
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            r = sweep(sp, os.path.join(d, "out"), workers=w, quiet=True)
            out[f"worker{w}_s"] = time.perf_counter() - t0
            assert r.done == n
        say(f"{w} worker{'s' if w > 1 else ''}: {out[f'worker{w}_s']:.2f} s")
    for k in ("loop", "worker1", "worker2"):
        out[f"{k}_per_s"] = n / out[f"{k}_s"]
    out["overhead_per_scenario"] = (out["worker1_s"] - loop) / loop
    out["overhead_per_scenario_steady"] = (out["worker1_s"] - out["startup_s"] - loop) / loop
    out["speedup_2_over_1"] = out["worker1_s"] / out["worker2_s"]
    return out
