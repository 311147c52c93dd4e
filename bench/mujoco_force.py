"""MuJoCo 4.0 flex peer on the shared protocol case (shared/bench/PROTOCOL.md) at a chosen total probe force.

Same model and loop as shared/bench/peers/mujoco_peer.py (its `build` is re-used as is), but:
- `--force` sets the total probe force in N (the protocol's 0.2 N is the default), applied through
  `common.FORCE` before `common.setup`, ramped over 0.1 s by `common.force_scale` as in the protocol;
- prints ONE JSON line to stdout instead of appending to shared/bench/results (nothing under shared/ is written);
- adds per-step mj_step times (p50/p99/max, microseconds), and `stable` = all positions finite throughout
  and max |u| < 0.06 m (6 cm, a looser bound than the protocol's 2 cm so that large forces can be judged);
- `--save-mean PATH` saves the second-half mean displacement field (n, 3) [m] as an .npz
  (keys mean_disp, loaded, fixed), e.g. to compare with palpate node by node.

Single thread: the peer's XML sets <compiler usethread="false"/>; OMP/BLAS threads are set to 1 below.
Only mj_step is timed (time.perf_counter); the run stops early if max |u| > 1 m or the timed wall > --max-wall.
MuJoCo's warnings go to stderr (not to a MUJOCO_LOG.TXT in the working directory); their counts during the
run are in the JSON line as `warnings` (e.g. mjWARN_INERTIA when the M+K solve under-converges).

Needs any Python venv with numpy==2.4.6 and mujoco==4.0.0 (not palpate dependencies), e.g.
    python3 -m venv /work/peers-venv && /work/peers-venv/bin/pip install numpy==2.4.6 mujoco==4.0.0
Run from the repo root:
    /work/peers-venv/bin/python bench/mujoco_force.py --mesh 1350 --force 2
The shared folder is $PALPATE_SHARED (the folder holding bench/), else <repo>/../shared.
"""
import os
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
import argparse, importlib.util, json, sys, time
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED_BENCH = os.path.join(os.environ.get("PALPATE_SHARED") or os.path.join(REPO, "..", "shared"), "bench")
sys.path.insert(0, SHARED_BENCH)
import common as C  # noqa: E402  (the same module object that mujoco_peer imports)
import mujoco  # noqa: E402
mujoco.set_mju_user_warning(lambda msg: print("MuJoCo warning:", msg, file=sys.stderr, flush=True))

_spec = importlib.util.spec_from_file_location("mujoco_peer", os.path.join(SHARED_BENCH, "peers", "mujoco_peer.py"))
peer = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(peer)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mesh", default="1350", choices=C.MESHES)
    ap.add_argument("--force", type=float, default=0.2, help="total probe force [N]")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--max-wall", type=float, default=60.0, help="stop when timed mj_step wall exceeds this [s]")
    ap.add_argument("--integrator", default="discrete", choices=["discrete", "Euler"])
    ap.add_argument("--save-mean", metavar="PATH", help="save second-half mean displacement field (.npz)")
    a = ap.parse_args()

    C.FORCE = a.force  # read by common.setup when it computes the per-node force
    p, t, fixed, loaded, f_node = C.setup(a.mesh)
    m, d, vb = peer.build(p, t, fixed, a.integrator)
    lb = vb[loaded]
    assert np.all(lb > 0)
    mujoco.mj_forward(m, d)
    x0 = d.flexvert_xpos.copy()
    tr, wall, steps, finite, step_s = C.Track(a.steps, loaded, a.mesh), 0.0, 0, True, []
    for k in range(a.steps):  # the loop of mujoco_peer.main, plus per-step times and a finiteness check
        d.xfrc_applied[lb, :3] = C.force_scale((k + 1) * C.DT) * f_node
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        dt = time.perf_counter() - t0
        wall += dt
        step_s.append(dt)
        steps += 1
        finite = finite and bool(np.isfinite(d.flexvert_xpos).all())
        if tr.add(k, d.flexvert_xpos - x0) or wall > a.max_wall:
            break

    umax = np.asarray(tr.umax)
    max_disp = float(np.nanmax(umax)) if np.isfinite(umax).any() else float("nan")
    us = np.asarray(step_s) * 1e6
    r = dict(peer=f"mujoco-{a.integrator}", mesh=a.mesh, tets=len(t), nodes=len(p), force_N=a.force,
             steps=steps, wall_s=round(wall, 4), steps_per_s=round(steps / wall, 1) if wall > 0 else None,
             finite=finite, max_disp_m=max_disp,
             probe_disp_avg_m=float(np.mean(tr.uprobe[len(tr.uprobe) // 2:])),
             step_us_p50=round(float(np.percentile(us, 50)), 1), step_us_p99=round(float(np.percentile(us, 99)), 1),
             step_us_max=round(float(us.max()), 1),
             stable=bool(finite and np.isfinite(max_disp) and max_disp < 0.06),
             warnings={k: int(d.warning[int(w)].number) for k, w in mujoco.mjtWarning.__members__.items()
                       if k != "mjNWARNING" and d.warning[int(w)].number},
             mujoco=mujoco.__version__)
    if a.save_mean:
        mean = tr.usum / tr.cnt if tr.cnt else np.full((len(p), 3), np.nan)
        np.savez(a.save_mean, mean_disp=np.asarray(mean, dtype=np.float64), loaded=loaded, fixed=fixed)
    print(json.dumps(r), flush=True)


if __name__ == "__main__":
    main()
