"""Bit-identity check of the hybrid tick: runs the script of ``palpate bench hybrid`` (press to
3 mm at the probe point, hold, 10 mm slide, release; :mod:`palpate.bench.hybrid`) with a fixed
tool radius and prints a hash of every tick's force and of the final (fresh) surface, with the
sub-step count and the tick's CPU time (``time.thread_time``, less sensitive to the machine's load
than wall time). A change meant to leave the physics as it is must leave the hash unchanged.

    .venv/bin/python bench/hybrid_hash.py MODEL RADIUS_M [TICKS]

e.g. ``ellipsoids 0.0015``, ``ventricle 0.0016``, ``rodero 0.002`` (about 200 active particles;
docs/history/benchmarks-log.md#before-mass-scaling-second-session). For CPU cycles per tick, run
it under ``perf record -e cycles:u -c 200000`` before and after a change (PYTHONPATH pointing at
the other build's package).
"""
import hashlib
import sys
import time

import numpy as np

import palpate as _p
from palpate.bench import hybrid as bh


def main() -> None:
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    name, radius = sys.argv[1], float(sys.argv[2])
    ticks = int(sys.argv[3]) if len(sys.argv) > 3 else 2000
    name, model = bh.load_model(name)
    _, p, n_in, tangent = bh.probe(model, name)
    depth, slide, _ = bh.script(ticks)
    sim = _p.HybridSim(model, bh.material(), tool_radius=radius)
    forces, cpu, substeps = [], [], []
    for k in range(ticks):
        c = p + n_in * (depth[k] - radius) + tangent * slide[k]
        t0 = time.thread_time()
        forces.append(sim.step(c, bh.DT))
        cpu.append(time.thread_time() - t0)
        substeps.append(sim.last["substeps"])
    f = np.array(forces)
    digest = hashlib.sha1(f.tobytes() + np.asarray(sim.surface).tobytes()).hexdigest()[:12]
    ms = np.array(cpu) * 1e3
    print(f"{name} R={radius}: hash {digest} maxF {np.abs(f).max():.5f} subs {np.mean(substeps):.1f} "
          f"cpu mean {ms.mean():.3f} ms p50 {np.median(ms):.3f} p99 {np.percentile(ms, 99):.3f}")


if __name__ == "__main__":
    main()
