"""The hybrid tick under the worst a hand gives (issue 12): a fast slide, a device that stalls
then jumps, a jab, presses to 10 and 15 mm and a press toward 5 N, on a shipped model (default the synthetic ventricle;
undamped material, 5 mm tool, at palpate.touch.probe_point along the inward normal). Prints, per
scenario, whether every tick stayed finite, the largest force, how far the force along the press fell
below its running maximum on the ticks the tool went deeper ("gave way": the organ letting the tool through,
or a slope it slid down), the p99 tick time and how many ticks shed the shell (its step failed: HybridSim's ``shell_fallback``, the tick going on with the core
and the skin), or the tick where it stopped and why. ``FALLBACK=0`` turns the fallback off (a
failed shell step then stops the scenario, as before 2026-11-26).

    .venv/bin/python bench/hybrid_hand.py [ventricle|ellipsoids|rodero]
    PHI=0.5 .venv/bin/python bench/hybrid_hand.py   # with the paper's viscosity (phi = psi [Pa s])
"""
import os
import time

import sys

import numpy as np

import palpate
from palpate.bench import hybrid as bench_hybrid


def main():
    shape = sys.argv[1] if len(sys.argv) > 1 else "ventricle"
    m = palpate.build_shape(shape)
    _, p, n_in, t = bench_hybrid.probe(m)
    n = -n_in
    print(f"{shape}: probe {np.round(p * 1e3, 2)} mm, inward normal {np.round(n_in, 3)}")
    damp = float(os.environ.get("PHI", "0"))
    mat = palpate.Material(young=3e4, poisson=0.4, density=1000.0, phi=damp, psi=damp)

    def run(name, path, stop_force=None):
        """Step ``path`` (tool depth and slide [m] a tick); with ``stop_force`` [N], the depth stops
        growing once the force reaches it (a hand pressing toward that force)."""
        sim = palpate.HybridSim(m, mat, shell_fallback=os.environ.get("FALLBACK", "1") != "0")
        fmax, times, shed, off = 0.0, [], [], 0
        top, gave, held, last_depth = 0.0, 0.0, None, -1.0
        for k, (depth, slide) in enumerate(path):
            if held is not None:
                depth = held
            pressing = depth > last_depth
            last_depth = depth
            t0 = time.perf_counter()
            try:
                f = sim.step(p + n * (0.005 - depth) + t * slide)
            except palpate.StepError as e:
                print(f"{name}: stopped at tick {k}: {e}")
                return
            times.append(time.perf_counter() - t0)
            fmax = max(fmax, float(np.linalg.norm(f)))
            along = float(np.dot(f, n))
            top = max(top, along)
            if pressing:
                gave = max(gave, top - along)
            if stop_force is not None and held is None and np.linalg.norm(f) >= stop_force:
                held = depth
            if sim.last["shell_failed"]:
                shed.append(k)
            off += sim.last["shell_off"]
        print(f"{name}: {len(path)} ticks finite, max force {fmax:.3f} N, gave way by {gave:.3f} N, "
              f"tick p99 {np.percentile(times, 99) * 1e3:.2f} ms, shell shed at ticks {shed or 'none'} ({off} ticks off)")

    ramp = [(3e-3 * min(1, (k + 1) / 200), 0.0) for k in range(300)]
    run("fast slide 0.5 m/s at 3 mm", ramp + [(3e-3, 5e-4 * (k + 1)) for k in range(40)] + [(3e-3, 0.02)] * 100)
    run("stall 50 ticks then a 5 mm jump", ramp + [(3e-3, 0.0)] * 50 + [(8e-3, 0.0)] * 200)
    run("jab 10 mm in 10 ms", [(1e-3 * (k + 1), 0.0) for k in range(10)] + [(10e-3, 0.0)] * 300)
    for v in [0.2e-3, 0.05e-3]:
        run(f"press to 10 mm at {v * 1e3:.2f} m/s", [(v * (k + 1), 0.0) for k in range(int(10e-3 / v))] + [(10e-3, 0.0)] * 100)
    run("press to 15 mm at 0.05 m/s, hold, slide 10 mm", [(5e-5 * (k + 1), 0.0) for k in range(300)] + [(15e-3, 0.0)] * 100
        + [(15e-3, 1e-5 * (k + 1)) for k in range(1000)])
    run("press toward 5 N at 0.05 m/s (25 mm at most), hold", [(min(5e-5 * (k + 1), 25e-3), 0.0) for k in range(700)], stop_force=5.0)


if __name__ == "__main__":
    main()
