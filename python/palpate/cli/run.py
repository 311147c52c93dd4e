"""``palpate run SCENE.toml [--out DIR] [--steps N] [--quiet]``: a scene file, headless, to a VTU
series, with a progress bar over the steps on a terminal."""
from __future__ import annotations

from ._common import Fail, RunFailed, add_quiet, fmt_mm


def add_parser(sub) -> None:
    r = sub.add_parser("run", help="run a scene file headless, writing a VTU time series")
    r.add_argument("scene", metavar="SCENE.toml")
    r.add_argument("--out", help="output folder (overrides [run] output)")
    r.add_argument("--steps", type=int, help="number of steps (overrides [run] steps)")
    add_quiet(r)
    r.set_defaults(func=cmd_run)


def cmd_run(a) -> int:
    from .. import _palpate as _p
    from ..scene import SceneError, load_scene, run_scene

    try:
        scene = load_scene(a.scene, output=a.out, steps=a.steps)
    except SceneError as e:
        raise Fail(str(e)) from None
    print(f"palpate run: {a.scene}: {scene.body.n_nodes} nodes, {scene.body.n_tets} tets, "
          f"{scene.steps} steps of {scene.dt:g} s, integrator {scene.description['integrator']}, "
          f"output {scene.output}", flush=True)
    from .. import _progress
    try:
        # A bar over the steps, advanced between the chunks of steps that end at a frame.
        with _progress.task("running the scene", total=scene.steps) as advance:   # a terminal only
            s = run_scene(scene, advance=advance)
    except _p.StepError as e:
        raise Fail(f"{a.scene}: simulation failed: {e}", cause=e) from None
    except OSError as e:
        raise RunFailed(f"{a.scene}: cannot write the output: {e}") from None
    print(f"  {s['steps']} steps in {s['wall_s']:.3f} s of stepping: {s['steps_per_s']:.1f} steps/s")
    print(f"  max |u| = {fmt_mm(s['max_disp_m'])} mm")
    print(f"  final energy: strain {s['strain_energy_J']:.6e} J, kinetic {s['kinetic_energy_J']:.6e} J")
    print(f"  wrote {s['frames']} frames: {s['pvd']}")
    return 0
