"""``python -m palpate.demo`` (``make demo``): the paper's two bodies under a probe load.

Builds, with the core's generators,
  * the paper's closed ellipsoid wall ("Ellipsoids Model", about 188 tets: here 192 tets, 54 nodes),
  * a truncated-ellipsoid left-ventricle wall (1320 tets, the size of the paper's 1352-tet
    full-FEM ventricle),
both with the semi-axes of the shared benchmark (inner (2.0, 2.0, 3.5) cm, outer (2.6, 2.6, 4.2) cm),
and its material (:func:`palpate.bench.material`: E = 30 kPa, nu = 0.4, 1000 kg/m^3, the protocol's
density rather than the default tissue's). Nodes with z <= 0 are fixed (the ventricle's base; the
ellipsoid's lower half). A probe pushes 0.2 N along the inward normal at (2.29, 0, 2.0) cm on the
outer surface, shared by the outer nodes within 5 mm (the nearest one if none), ramped over 0.1 s.

Each integrator runs 1000 steps of 1 ms (timed in Rust, stepping only) and the steps/s are printed
beside the paper's Table 1 (Pentium IV, 2006): 980 frames/s for 188 tets, 35 frames/s for the
1352-tet full-FEM ventricle. A plot of the probe displacement against time is written to
``out/demo_probe.png``.

Table 1's hybrid rows (:func:`hybrid_rows`): the hybrid synthetic ventricle (FEM core + particle
shell, :class:`palpate.HybridSim`) pressed 3 mm, held, slid 10 mm and released
(:mod:`palpate.bench.hybrid`, ``--hybrid-ticks`` ticks of 1 ms, 1000 by default), with the tool
radius calibrated for about 200 (the paper's average) and 600 (its worst case) active particles;
ticks/s = 1 / mean tick beside the paper's 330-600 frames/s.

Then the hybrid models of the shipped walls are built, and the Rodero et al. ventricle (the
synthetic one offline) is touched by a scripted press, hold, slide and release
(:mod:`palpate.touch`), logged to ``out/touch_rodero/`` (force.csv, force.png, touch.pvd).
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import Optional

#: VTU frames of the demo's scripted touch.
DEMO_FRAMES = 20

import numpy as np

from . import _palpate as _p
from . import bench
from ._extras import install_hint

PAPER = {"ellipsoid": (188, 980.0), "ventricle": (1352, 35.0)}
#: The paper's hybrid ventricle: 330-600 frames/s, 200 active particles on average, 600 at worst.
PAPER_HYBRID_FPS = (330.0, 600.0)
#: Table 1's hybrid rows: (target active particles, what the paper calls it).
HYBRID_ROWS = ((200, "average"), (600, "worst case"))
HYBRID_TICKS = 1000
INTEGRATORS = [
    ("semi-implicit", _p.SemiImplicit),
    ("backward Euler (quasi-Newton, default)", lambda: _p.BackwardEuler()),
    ("backward Euler (rest-linearised)", lambda: _p.BackwardEuler(_p.Solver.LINEARISED)),
    ("backward Euler (Newton)", lambda: _p.BackwardEuler(_p.Solver.NEWTON)),
]


def bodies():
    s = bench.SCALE
    ell = _p.ellipsoid_wall(inner=tuple(bench.INNER * s), outer=tuple(bench.OUTER * s))
    lv = _p.truncated_ellipsoid_wall(inner=tuple(bench.INNER * s), outer=tuple(bench.OUTER * s))
    return [("ellipsoid", bench.setup("ellipsoid", ell.points / s, ell.tets)),
            ("ventricle", bench.setup("ventricle", lv.points / s, lv.tets))]


def _hybrid_summary() -> dict:
    """Build the hybrid models of the shipped walls (paper §4, §6), print what they hold and
    return them by shape name."""
    import warnings

    from . import hybrid, data

    print("\nhybrid models (FEM core + particle shell + skin + one activation region per outer vertex):")
    print(f"{'wall':<34}{'core tets':>10}{'particles':>10}{'spacing mm':>11}{'regions':>9}"
          f"{'core+shell/wall':>16}{'build s':>9}")
    shapes = ["ellipsoids", "ventricle"]
    try:
        data.rodero_lv_path()
        shapes.append("rodero")
    except Exception as e:  # no network and no cached file: say so, build the others
        print(f"  (Rodero et al. left ventricle not available: {e})")
    names = {"ellipsoids": "paper's ellipsoids", "ventricle": "synthetic truncated ventricle",
             "rodero": "Rodero et al. 2021 left ventricle"}
    models = {}
    for shape in shapes:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = models[shape] = hybrid.build_shape(shape)
        i = m.info()
        ratio = (i["core_volume_m3"] + i["shell_volume_m3"]) / i["wall_volume_m3"]
        print(f"{names[shape]:<34}{i['core_tets']:>10}{i['particles']:>10}{i['spacing_m'] * 1e3:>11.3f}"
              f"{i['regions']:>9}{ratio:>16.4f}{i['build_s']:>9.2f}", flush=True)
    return models


def _touch(models: dict, a) -> None:
    """A scripted touch of the Rodero et al. ventricle (else the synthetic one): press 4 mm, hold,
    slide 8 mm, release (:data:`palpate.touch.DEFAULT_SCRIPT`), logged to ``<out>/touch_<shape>/``."""
    from . import touch

    shape = "rodero" if "rodero" in models else "ventricle"
    from . import defaults

    sim = _p.HybridSim(models[shape], defaults.tissue_material())   # the default tissue, as palpate touch
    out = os.path.join(a.out, f"touch_{shape}")
    print(f"\nscripted touch of the {shape} model (palpate touch; examples/scripts/press_hold_slide.toml): "
          f"press 4 mm, hold, slide 8 mm, release, 1 ms ticks:")
    try:
        # 20 frames (about 35 MB of VTU on Rodero's skin; palpate touch's default of about 80 wrote 172 MB).
        script = touch.default_script()
        every = touch.default_every(int(round(script.duration / 1e-3)), frames=DEMO_FRAMES)
        s = touch.run_touch(sim, script, out, tool_radius=0.005, plot=not a.no_plot, every=every,
                            title=f"palpate demo: touch of the {shape} model")
    except touch.TouchFailed as e:
        print(f"  failed at {e} (the ticks before it are in {out})")
        return
    late = " (over the 1 ms tick: a 1 kHz servo would wait for those)" if s["tick_ms_p99"] > 1.0 else ""
    print(f"  {s['ticks']} ticks, {s['ticks_per_s']:.0f} ticks/s (tick median {s['tick_ms_median']:.2f} ms, "
          f"p99 {s['tick_ms_p99']:.2f} ms{late}); max |f| {s['max_force_N']:.3f} N, max normal force "
          f"{s['max_normal_force_N']:.3f} N, up to {s['max_active']} active particles")
    print(f"  wrote {s['csv']}, {s['frames']} frames: {s['pvd']}")


def _firm_press(a) -> None:
    """A clinician's press, 2 N on the ventricle wall: the default integrator stays finite, the
    rest-linearised one does not (BENCHMARKS.md, "Stable at any press")."""
    print("\nfirm press: 2 N on the ventricle wall (what a clinician's finger applies), same probe:")
    _, case = bodies()[1]
    force = case.total_force * (2.0 / bench.FORCE)
    for iname, make in [("backward Euler, quasi-Newton (default)", lambda: _p.BackwardEuler()),
                        ("backward Euler, rest-linearised", lambda: _p.BackwardEuler(_p.Solver.LINEARISED))]:
        body = _p.Body(case.mesh, bench.material(), fixed=case.fixed, integrator=make())
        r = body.run_probe(case.loaded, force, bench.RAMP, a.steps, dt=1e-3, stable_limit=0.06,
                           max_wall_s=a.max_wall)
        sps = r["steps"] / r["wall_s"] if r["wall_s"] > 0 else float("inf")
        if r["error"]:
            what = r["error"]
        else:
            what = (f"finite, max |u| {r['max_disp_m'] * 1e3:.1f} mm, {r['iterations_mean']:.2f} iterations a step, "
                    f"at most {r['inverted_max']} inverted tets")
        print(f"  {iname:<40}{sps:>9.1f} steps/s  {what}", flush=True)


def hybrid_rows(model=None, shape: str = "ventricle", ticks: int = HYBRID_TICKS, rows=HYBRID_ROWS,
                quiet: bool = False):
    """Table 1's hybrid rows: for each ``(target, label)`` of ``rows``, :func:`palpate.bench.hybrid.run`
    on ``model`` (built from ``shape`` if None) with ``ticks`` ticks; prints one line per row
    (unless ``quiet``) and returns the reports."""
    import warnings

    from . import hybrid
    from .bench import hybrid as bench_hybrid

    if model is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = hybrid.build_shape(shape)
    lo, hi = PAPER_HYBRID_FPS
    if not quiet:
        i = model.info()
        print(f"\nTable 1, hybrid rows: {shape} ({i['core_tets']} core tets, {i['particles']} particles), "
              f"press {bench_hybrid.DEPTH * 1e3:g} mm, hold, slide {bench_hybrid.SLIDE * 1e3:g} mm, release, "
              f"{ticks} ticks of 1 ms, tool radius calibrated per row (palpate bench hybrid):")
        print(f"{'active particles':<26}{'radius mm':>10}{'mean':>8}{'max':>6}{'ticks/s':>9}{'mean ms':>9}"
              f"{'p99 ms':>8}  {'paper (2006)':<28}note")
    out = []
    for target, label in rows:
        r = bench_hybrid.run(model, target, ticks, name=shape)
        out.append(r)
        if quiet:
            continue
        f = lambda v, fmt: "-" if v is None else format(v, fmt)  # noqa: E731
        note = "" if r["stable"] else f"failed at tick {r['failed_tick']} ({r['failed_phase']}): {r['error']}"
        if r["stable"] and r["tick_ms_p99"] is not None and r["tick_ms_p99"] > 1.0:
            note = "p99 over the 1 ms tick: a 1 kHz servo would wait (palpate haptic renders multirate)"
        print(f"{f'~{target} ({label})':<26}{r['tool_radius_m'] * 1e3:>10.3f}{f(r['active_particles_mean'], '.0f'):>8}"
              f"{f(r['active_particles_max'], 'd'):>6}{f(r['ticks_per_s'], '.1f'):>9}{f(r['tick_ms_mean'], '.3f'):>9}"
              f"{f(r['tick_ms_p99'], '.3f'):>8}  {f'{lo:g}-{hi:g} f/s ({label})':<28}{note}", flush=True)
    if not quiet:
        print("ticks/s: 1 / mean tick (HybridSim.step calls only, perf_counter); mean / max: active particles "
              "over the script.")
    return out


def bench_hybrid_min_ticks() -> int:
    from .bench.hybrid import MIN_TICKS
    return MIN_TICKS


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m palpate.demo", description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--max-wall", type=float, default=60.0, help="cap per run, seconds of stepping (default 60)")
    ap.add_argument("--out", default="out", help="folder for the plot (default out/)")
    ap.add_argument("--no-plot", action="store_true")
    ap.add_argument("--hybrid-ticks", type=int, default=HYBRID_TICKS,
                    help=f"ticks of the hybrid rows' script (default {HYBRID_TICKS}; 0: skip the hybrid rows)")
    a = ap.parse_args(argv)
    if 0 < a.hybrid_ticks < bench_hybrid_min_ticks() or a.hybrid_ticks < 0:
        ap.error(f"--hybrid-ticks must be 0 or at least {bench_hybrid_min_ticks()}")

    print(f"palpate {_p.__version__} demo: probe load of {bench.FORCE} N ramped over {bench.RAMP} s, "
          f"{a.steps} steps of 1 ms, single thread\n")
    print(f"{'body':<11}{'tets':>6}{'nodes':>7}  {'integrator':<34}{'steps/s':>9}  {'paper (2006)':<22}"
          f"{'probe |u| mm':>13}  note")
    curves = []
    for name, case in bodies():
        ptets, pfps = PAPER[name]
        for iname, make in INTEGRATORS:
            body = _p.Body(case.mesh, bench.material(), fixed=case.fixed, integrator=make())
            r = body.run_probe(case.loaded, case.total_force, bench.RAMP, a.steps, dt=1e-3,
                               max_wall_s=a.max_wall)
            sps = r["steps"] / r["wall_s"] if r["wall_s"] > 0 else float("inf")
            note = r["error"] or ("" if r["stable"] else "unstable")
            if note and iname == "semi-implicit":
                # Measured and explained in BENCHMARKS.md: the paper's per-node filter leaves the
                # coupling between nodes explicit, so it is not unconditionally stable.
                note = "diverged (" + note + "): eq. (34) is not unconditionally stable, see BENCHMARKS.md"
            probe = r["probe_disp"][-1] * 1e3 if len(r["probe_disp"]) else float("nan")
            print(f"{name:<11}{case.mesh.n_tets:>6}{case.mesh.n_nodes:>7}  {iname:<34}{sps:>9.1f}  "
                  f"{f'{pfps:g} f/s ({ptets} tets)':<22}{probe:>13.4f}  {note}", flush=True)
            curves.append((f"{name}, {iname}", np.arange(1, r["steps"] + 1) * 1e-3, r["probe_disp"] * 1e3))
    print("\nsteps/s: stepping calls only (no set-up, no read-back); paper: frames/s on a Pentium IV.")
    if a.hybrid_ticks:
        hybrid_rows(ticks=a.hybrid_ticks)
    _firm_press(a)
    models = _hybrid_summary()
    _touch(models, a)
    if not a.no_plot:
        path = plot_probe(curves, a.out)
        if path:
            print(f"plot: {path}")
    return 0


def plot_probe(curves, out: str) -> Optional[str]:
    """``out/demo_probe.png``: the loaded nodes' mean |u| [mm] against time [s], one curve per
    ``(label, t, u)``; its path, or None (said on stdout) without matplotlib."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # an extra (palpate[plot]): the table above holds the numbers
        print(f"(matplotlib not installed: no plot; {install_hint('plot')})")
        return None
    os.makedirs(out, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for label, t, u in curves:
        ax.plot(t, u, label=label, lw=1.2)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("loaded nodes' mean |u| [mm]")
    ax.set_title(f"palpate demo: {bench.FORCE} N probe ramped over {bench.RAMP} s")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    path = os.path.join(out, "demo_probe.png")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    sys.exit(main())
