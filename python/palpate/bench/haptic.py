"""``palpate bench haptic``: the haptic loop's period, compute time and overruns on a repeated
scripted palpation, and the idle loop's (no simulation) on the same clock, for comparison.

The loop itself (:class:`palpate.HapticLoop`), its material, the scripted palpation and the
helpers that run it live in :mod:`palpate.haptics`; this module is the benchmark built on them
(moved here from ``palpate.haptics``, whose ``bench`` and ``BENCH_KEYS`` still resolve to these).
"""
from __future__ import annotations

import math
import os
import platform
from datetime import datetime, timezone
from typing import Any, Callable, Dict, Optional

import numpy as np

from .. import _palpate as _p
from ..haptics import BUSY_SPIN, SLEEP_SPIN, loop_rates, material, palpation_cycle, repeat, run_live

#: JSON keys of ``palpate bench haptic`` (at least these).
BENCH_KEYS = ("rate_hz", "ticks", "period_us_p50", "period_us_p99", "period_us_max", "compute_us_p99",
              "overruns", "max_force_n")


def steal_seconds() -> Optional[float]:
    """The machine's steal time so far [s] (all CPUs, ``/proc/stat``), or None off Linux."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK") if fields[0] == "cpu" and len(fields) > 8 else None
    except (OSError, ValueError, IndexError):
        return None


def per_second(times_s, elapsed_s: float) -> list:
    """Counts of events per whole second of wall time since the start (``times_s`` [s])."""
    n = max(1, int(math.ceil(elapsed_s)))
    return np.bincount(np.minimum(np.asarray(times_s, dtype=np.float64).astype(np.int64), n - 1), minlength=n).tolist() \
        if len(times_s) else [0] * n



def bench(model: "_p.HybridModel", seconds: float, rate_hz: float = 1000.0, idle: bool = True,
          name: str = "", on_status: Optional[Callable[[str], None]] = None, realtime: bool = False,
          threads: int = 1, busy_wait: Optional[bool] = None, physics_rate: Optional[float] = None) -> Dict[str, Any]:
    """``palpate bench haptic``: the loop at ``rate_hz`` on ``model`` for ``seconds`` [s] with a
    repeated scripted palpation (:func:`palpate.haptics.palpation_cycle`), then (``idle``) the idle loop (no
    simulation, same device, same length) on the same clock. Returns the loop's report
    (:data:`BENCH_KEYS` and more; ``overruns_per_s``: the overruns in each second of wall time,
    from the first 100,000 logged; ``overruns_own`` / ``overruns_machine``: the overruns whose
    compute alone passed the period on the CPU, and the rest, see :meth:`palpate.HapticLoop.stop`;
    ``steal_s``: the hypervisor's steal time over the run, all CPUs), with ``idle`` the idle run's and the machine's description;
    ``realtime``: both loops' servo under ``SCHED_FIFO`` (see :class:`palpate.HapticLoop`; the
    report's ``realtime`` says whether it was granted); ``threads``: the loop's particle passes on
    that many threads (:class:`palpate.HapticLoop`; the idle loop has no physics to split);
    ``busy_wait``: both loops' servo spins through each whole period (:data:`palpate.haptics.BUSY_SPIN`) or, False,
    sleeps through each wait but its last 200 us (:data:`palpate.haptics.SLEEP_SPIN`); None: :class:`palpate.HapticLoop`'s
    default, busy unless ``realtime`` (the report's ``busy_wait`` says which ran); ``physics_rate``
    [Hz]: the multirate loop, None the single-rate one (:class:`palpate.HapticLoop`; the report's ``physics`` holds the
    physics thread's figures). ``max_force_step_n``: the largest change of the sent force in one
    servo period [N], from the run's recording, and ``max_force_step_contact_n`` the same over the
    periods in contact (the tissue's force nonzero at either end)."""
    t, k = repeat(*palpation_cycle(model), seconds + 1.0)
    mat = material()
    spin = None if busy_wait is None else BUSY_SPIN if busy_wait else SLEEP_SPIN
    # HapticLoop's default: busy unless real-time or multirate (whose servo sleeps: the physics
    # thread needs the core).
    busy_wait = (not realtime and physics_rate is None) if busy_wait is None else busy_wait
    ticks = int(round(seconds * rate_hz))
    loop = _p.HapticLoop(model, mat, "scripted", times=t, knots=k, rate_hz=rate_hz, max_ticks=ticks,
                         realtime=realtime, threads=threads, spin=spin, record_ticks=ticks, **loop_rates(physics_rate))
    steal0 = steal_seconds()
    r = run_live(loop, None, on_status)
    steal1 = steal_seconds()
    # The hypervisor's share: time this VM's CPUs were ready but ran another guest (None where
    # /proc/stat is not there). The servo cannot see it as time off the CPU.
    r["steal_s"] = None if steal0 is None or steal1 is None else steal1 - steal0
    r["threads"] = threads
    r["busy_wait"] = busy_wait
    rec = loop.recorded()
    step = np.linalg.norm(np.diff(rec["force"], axis=0), axis=1)
    touching = np.linalg.norm(rec["tissue"], axis=1) > 0
    r["max_force_step_n"] = float(step.max()) if len(step) else 0.0
    # In contact (the tissue pushing the tool at either end of the period): the hand's palpation,
    # without the free-space coupling damper's steps at the script's corners.
    both = touching[1:] | touching[:-1]
    r["max_force_step_contact_n"] = float(step[both].max()) if both.any() else 0.0
    r["model"] = name
    r["seconds"] = seconds
    r["overruns_per_s"] = per_second(r.pop("overrun_times_s"), r["elapsed_s"])
    if idle:
        il = _p.HapticLoop(model, mat, "scripted", times=t, knots=k, rate_hz=rate_hz, idle=True,
                           max_ticks=int(round(seconds * rate_hz)), realtime=realtime, spin=spin)
        ir = run_live(il, None, None)
        r["idle"] = {key: ir[key] for key in ("ticks", "achieved_hz", "elapsed_s", "period_us_p50", "period_us_p99",
                                              "period_us_max", "compute_us_p99", "cpu_us_p99", "overruns",
                                              "overruns_own", "overruns_machine", "realtime",
                                              "short_slice")}
        r["idle"]["overruns_per_s"] = per_second(ir["overrun_times_s"], ir["elapsed_s"])
    r["cpu_count"] = os.cpu_count()
    r["machine"] = platform.processor() or platform.machine()
    r["load_avg"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    r["date"] = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return r
