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
import sys
import tempfile
import time
from typing import Any, Dict

import numpy as np

from ..sweep.runner import model_payload, sweep
from ..sweep.scenario import run_scenario
from ..sweep.spec import spec_from_dict

#: Keys of the JSON report.
KEYS = ("mesh", "scenarios", "steps", "repeat", "loop_s", "worker1_s", "worker2_s", "loop_per_s", "worker1_per_s",
        "worker2_per_s", "overhead_per_scenario", "startup_s", "cluster_start_stop_s",
        "overhead_per_scenario_steady", "speedup_2_over_1", "speedup_2_over_1_steady", "bare2_s",
        "bare_speedup_2", "cores")


def study(mesh: str, n: int, steps: int) -> Dict[str, Any]:
    return {"study": {"name": f"bench-{mesh}"}, "model": {"mesh": mesh},
            "loading": {"kind": "probe", "steps": steps},
            "parameters": {"young": {"grid": [2.4e4, 3.6e4], "num": n}}, "outputs": {"curve": True}}


def run(mesh: str = "1350", n: int = 64, steps: int = 1000, repeat: int = 3, log=None) -> Dict[str, Any]:
    """The three ways ``repeat`` times, interleaved (loop, 1 worker, 2 workers, then again), so that
    a slow spell of a shared machine falls on all three; every time reported is the median."""
    say = log or (lambda s: None)
    sp = spec_from_dict(study(mesh, n, steps))
    payload = model_payload(sp)
    scen = sp.scenarios()
    from ..sweep.runner import Runner
    t0 = time.perf_counter()
    import distributed  # noqa: F401 - its import is part of the start-up a user waits for
    Runner(payload, workers=1).close()
    startup = [time.perf_counter() - t0]
    times: Dict[str, list] = {"loop": [], "worker1": [], "worker2": [], "bare2": []}
    for k in range(repeat):
        t0 = time.perf_counter()
        rows = [run_scenario(payload, s, True, False) for s in scen]
        times["loop"].append(time.perf_counter() - t0)
        bad = [r["error"] for r in rows if r["status"] != "ok"]
        if bad:
            say(f"plain loop: {len(bad)} scenarios not ok: {bad[0]}")
        times["bare2"].append(_bare_two(payload, scen))
        for w in (1, 2):
            with tempfile.TemporaryDirectory() as d:
                t0 = time.perf_counter()
                r = sweep(sp, os.path.join(d, "out"), workers=w, quiet=True)
                times[f"worker{w}"].append(time.perf_counter() - t0)
                assert r.done == n
        t0 = time.perf_counter()
        Runner(payload, workers=1).close()
        startup.append(time.perf_counter() - t0)
        say(f"round {k + 1}/{repeat}: loop {times['loop'][-1]:.2f} s, 1 worker {times['worker1'][-1]:.2f} s, "
            f"2 workers {times['worker2'][-1]:.2f} s, 2 bare processes {times['bare2'][-1]:.2f} s")
    med = {k: float(np.median(v)) for k, v in times.items()}
    out: Dict[str, Any] = {"mesh": mesh, "scenarios": n, "steps": steps, "repeat": repeat, "cores": os.cpu_count()}
    # The first start-up includes importing distributed (a user pays it once a process); the
    # median over the later ones is the cluster's own start and stop.
    out["startup_s"] = startup[0]
    out["cluster_start_stop_s"] = float(np.median(startup[1:])) if len(startup) > 1 else startup[0]
    for k in ("loop", "worker1", "worker2"):
        out[f"{k}_s"] = med[k]
        out[f"{k}_per_s"] = n / med[k]
    loop = med["loop"]
    out["overhead_per_scenario"] = (med["worker1"] - loop) / loop
    out["overhead_per_scenario_steady"] = (med["worker1"] - out["cluster_start_stop_s"] - loop) / loop
    out["speedup_2_over_1"] = med["worker1"] / med["worker2"]
    cs = out["cluster_start_stop_s"]
    out["speedup_2_over_1_steady"] = (med["worker1"] - cs) / (med["worker2"] - cs)
    out["bare2_s"] = med["bare2"]
    out["bare_speedup_2"] = loop / med["bare2"]
    return out


def _half(payload, scen) -> None:
    for s in scen:
        run_scenario(payload, s, True, False)


def _bare_two(payload, scen) -> float:
    """The machine's own ceiling, for reference (not a runner: no Dask, no files, no retries):
    the scenarios split in two halves run by two forked processes, timed from the forks to the
    joins. What two cores give two copies of this work, memory bandwidth and the rest of the
    machine included."""
    import multiprocessing as mp
    ctx = mp.get_context("fork" if sys.platform == "linux" else "spawn")
    t0 = time.perf_counter()
    procs = [ctx.Process(target=_half, args=(payload, scen[k::2])) for k in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join()
    return time.perf_counter() - t0
