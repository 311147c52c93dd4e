"""Long computations end on Ctrl-C (issue 35 item 5): ``Body.static_solve`` with 10**9 load
steps, ``Body.indent`` over many travels, ``Body.step(10**9)`` and ``ParticleBody.step(10**9)``
would each run for hours; a SIGINT half a second in raises ``KeyboardInterrupt`` within the
binding's 50 ms poll, with the GIL released meanwhile (another thread keeps running).

Each runs in a child process: a signal to pytest's own process that arrived after the call had
finished would interrupt the test session instead.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SETUP = textwrap.dedent("""
    import os, signal, threading, time
    import numpy as np
    import palpate
    mesh = palpate.box_mesh((0.1, 0.02, 0.02), (10, 2, 2))
    body = palpate.Body(mesh, palpate.Material(young=3e4, poisson=0.4, density=1000.0),
                        fixed=np.flatnonzero(mesh.points[:, 0] == 0))
    f = np.zeros((body.n_nodes, 3)); f[mesh.points[:, 0] == 0.1, 2] = -1e-4
    ticks = [0]
    def other():                                  # runs while the call holds no GIL
        while True:
            ticks[0] += 1
            time.sleep(0.01)
    threading.Thread(target=other, daemon=True).start()
    threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
    t0 = time.monotonic()
""")

CALLS = {
    "static_solve": "body.static_solve(f, load_steps=10**9)",
    "indent": ("body.indent(radius=0.005, start=(0.05, 0.01, 0.03), direction=(0, 0, -1), "
               "travels=np.linspace(1e-5, 2e-3, 20000))"),
    "body_step": "body.set_forces(f); body.step(10**9, dt=1e-3)",
    "particles_step": ("pb = palpate.ParticleBody(mesh.points, np.full(len(mesh.points), 1e-4), palpate.Material(young=3e4, poisson=0.4, density=1000.0), 0.012, "
                       "fixed=np.flatnonzero(mesh.points[:, 0] == 0)); pb.step(10**9, dt=1e-3)"),
}


@pytest.mark.parametrize("name", sorted(CALLS))
def test_ctrl_c_ends_a_long_computation(name):
    code = SETUP + textwrap.dedent(f"""
        try:
            {CALLS[name]}
            print("FINISHED")
        except KeyboardInterrupt:
            print(f"INTERRUPTED {{time.monotonic() - t0:.3f}} {{ticks[0]}}")
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": ROOT})
    assert out.returncode == 0, out.stderr[-2000:]
    words = out.stdout.split()
    assert words and words[0] == "INTERRUPTED", out.stdout + out.stderr[-2000:]
    elapsed, ticks = float(words[1]), int(words[2])
    # The signal at 0.5 s; the poll every 50 ms; a loaded machine's scheduling on top.
    assert 0.45 < elapsed < 3.0, f"interrupted after {elapsed} s"
    assert ticks >= 5, f"another Python thread ran only {ticks} times: the GIL was held"
