"""The ``palpate`` command line (also ``python -m palpate``).

    palpate run SCENE.toml [--out DIR] [--steps N]
    palpate bench protocol MESH [--steps N] [--json] [--integrator NAME]
    palpate bench protocol --all [--steps N] [--json] [--integrator NAME]
    palpate bench particles N [--spacing S] [--kernel wendland|cubic|lj] [--ticks T] [--json]
    palpate bench particles --all [...]
    palpate info MESH [--unit m|cm|mm]

Exit codes: 0 success, 1 a simulation failed (e.g. a step diverged), 2 bad input (arguments,
scene file, mesh file), with one line on stderr and no traceback.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from typing import List, Optional

from . import __version__


class _Fail(Exception):
    def __init__(self, msg: str, code: int = 2):
        super().__init__(msg)
        self.code = code


def _fmt_mm(v) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{1e3 * v:.4f}"


def cmd_run(a) -> int:
    from . import _palpate as _p
    from .scene import SceneError, load_scene, run_scene

    try:
        scene = load_scene(a.scene, output=a.out, steps=a.steps)
    except SceneError as e:
        raise _Fail(str(e)) from None
    print(f"palpate run: {a.scene}: {scene.body.n_nodes} nodes, {scene.body.n_tets} tets, "
          f"{scene.steps} steps of {scene.dt:g} s, integrator {scene.description['integrator']}, "
          f"output {scene.output}", flush=True)
    try:
        s = run_scene(scene)
    except _p.StepError as e:
        raise _Fail(f"{a.scene}: simulation failed: {e}", 1) from None
    except OSError as e:
        raise _Fail(f"{a.scene}: cannot write the output: {e}", 1) from None
    print(f"  {s['steps']} steps in {s['wall_s']:.3f} s of stepping: {s['steps_per_s']:.1f} steps/s")
    print(f"  max |u| = {_fmt_mm(s['max_disp_m'])} mm")
    print(f"  final energy: strain {s['strain_energy_J']:.6e} J, kinetic {s['kinetic_energy_J']:.6e} J")
    print(f"  wrote {s['frames']} frames: {s['pvd']}")
    return 0


def _bench_cases(a):
    from . import bench
    from .io import MeshError

    if a.all:
        if a.mesh:
            raise _Fail("palpate bench protocol: give MESH or --all, not both")
        shared = bench.shared_dir()
        if shared is None:
            raise _Fail("palpate bench protocol --all: shared bench meshes not found "
                        "(set PALPATE_SHARED to the folder holding bench/meshes)")
        paths = [shared / "bench" / "meshes" / f"lv_{m}.msh" for m in bench.MESHES]
        yield bench.generated_case
        for p in paths:
            yield (lambda p=p: bench.load_case(str(p)))
        return
    if not a.mesh:
        raise _Fail("palpate bench protocol: give a MESH file (.msh, .vtu, .npz) or --all")
    if a.mesh == bench.GENERATED:
        yield bench.generated_case
        return

    def one():
        try:
            return bench.load_case(a.mesh)
        except MeshError as e:
            raise _Fail(f"palpate bench protocol: {e}") from None
    yield one


def cmd_bench_protocol(a) -> int:
    from . import bench

    rows = []
    if not a.json:
        print(f"palpate {__version__} bench protocol: {a.steps} steps of {bench.DT * 1e3:g} ms, "
              f"integrator {a.integrator}, single thread (shared/bench/PROTOCOL.md)")
        print(f"{'mesh':<16}{'tets':>7}{'nodes':>7}{'steps/s':>10}{'stable':>8}{'max|u| mm':>11}"
              f"{'probe mm':>10}{'static mm':>11}{'relL2':>8}")
    for make in _bench_cases(a):
        case = make()
        r = bench.run(case, a.integrator, steps=a.steps, max_wall_s=a.max_wall)
        rows.append(r)
        if a.json:
            print(json.dumps(r), flush=True)
        else:
            rel = "-" if r["rel_L2_vs_static"] is None else f"{r['rel_L2_vs_static']:.1e}"
            sps = "-" if r["steps_per_s"] is None else f"{r['steps_per_s']:.1f}"
            print(f"{r['mesh']:<16}{r['tets']:>7}{r['nodes']:>7}{sps:>10}{str(r['stable']):>8}"
                  f"{_fmt_mm(r['max_disp_m']):>11}{_fmt_mm(r['probe_disp_avg_m']):>10}"
                  f"{_fmt_mm(r['static_probe_disp_m']):>11}{rel:>8}", flush=True)
            if r.get("error"):
                print(f"  note: {r['error']}")
    return 0


def cmd_bench_particles(a) -> int:
    from . import bench_particles as bp

    if a.all == (a.n is not None):
        raise _Fail("palpate bench particles: give N or --all (not both)")
    if a.spacing <= 0 or a.spacing != a.spacing:
        raise _Fail(f"palpate bench particles: --spacing must be positive, got {a.spacing}")
    if a.ticks <= 0:
        raise _Fail("palpate bench particles: --ticks must be positive")
    if not (1.0 < a.support < 4.0):
        raise _Fail(f"palpate bench particles: --support must lie between 1 and 4 spacings, got {a.support}")
    sizes = bp.ALL if a.all else [a.n]
    if not a.json:
        mhz = bp.cpu_mhz()
        peak = "unknown" if mhz is None else f"{mhz * bp.FLOPS_PER_CYCLE / 1e3:.1f} GFlop/s"
        print(f"palpate {__version__} bench particles: LV-shell cluster at {a.spacing * 1e3:g} mm, kernel {a.kernel}, "
              f"support {a.support:g} spacings, "
              f"E = {bp.E:g} Pa, nu = {bp.NU}, rho = {bp.RHO:g} kg/m^3, {bp.PROBE_FORCE:g} N on {bp.N_PROBE} particles, "
              f"{a.ticks} ticks of {bp.DT * 1e3:g} ms, one thread")
        print(f"  flops per pair per sub-step {bp.FLOPS_PER_PAIR}, per particle {bp.FLOPS_PER_PARTICLE}; peak {peak} "
              f"(cpu MHz {mhz} x {bp.FLOPS_PER_CYCLE} flop/cycle: AVX2 FMA, 2 units x 4 doubles x 2); "
              f"hot loop: {bp._p.simd_path()}")
        print(f"{'N':>7}{'nbrs':>7}{'fixed':>7}{'sub/tick':>9}{'sub dt us':>10}{'tick ms':>9}{'ticks/s':>9}"
              f"{'GFlop/s':>9}{'%peak':>7}{'build s':>9}{'max|u| mm':>10}")
    failed = False
    for n in sizes:
        try:
            r = bp.run(n, a.spacing, a.kernel, a.ticks, a.max_wall, a.support)
        except ValueError as e:
            raise _Fail(f"palpate bench particles: {e}") from None
        except _p_errors() as e:
            raise _Fail(f"palpate bench particles: N = {n}: {type(e).__name__}: {e}", 1) from None
        failed |= r["error"] is not None and "wall-clock cap" not in r["error"]
        if a.json:
            print(json.dumps(r), flush=True)
            continue
        f = lambda v, fmt: "-" if v is None else format(v, fmt)  # noqa: E731
        print(f"{r['n']:>7}{r['mean_neighbours']:>7.1f}{r['fixed']:>7}{r['substeps']:>9}{r['substep_dt_s'] * 1e6:>10.1f}"
              f"{f(r['tick_median_s'] and r['tick_median_s'] * 1e3, '.3f'):>9}{f(r['ticks_per_s'], '.1f'):>9}"
              f"{f(r['gflops'], '.2f'):>9}{f(r['peak_fraction'] and 100 * r['peak_fraction'], '.1f'):>7}"
              f"{r['build_s']:>9.2f}{_fmt_mm(r['max_disp_m']):>10}", flush=True)
        if r["error"]:
            print(f"  note: {r['error']} (median over {r['ticks']} ticks)")
    return 1 if failed else 0


def _p_errors():
    from . import _palpate as _p
    return (_p.PalpateError,)


def cmd_info(a) -> int:
    from .io import MeshError, load_mesh

    try:
        m = load_mesh(a.mesh, unit=a.unit)
    except (MeshError, ValueError) as e:
        raise _Fail(str(e)) from None
    p = m.points
    print(f"{a.mesh}: {m.n_nodes} nodes, {m.n_tets} tets, volume {m.volume:.6e} m^3, "
          f"min dihedral {m.min_dihedral_deg:.2f} deg")
    print(f"  bounding box [m]: {p.min(0).round(6).tolist()} .. {p.max(0).round(6).tolist()}")
    print(f"  boundary faces: {len(m.boundary_faces())}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="palpate", description="Real-time soft-tissue FEM for haptic interaction (SI units).")
    ap.add_argument("--version", action="version", version=f"palpate {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    r = sub.add_parser("run", help="run a scene file headless, writing a VTU time series")
    r.add_argument("scene", metavar="SCENE.toml")
    r.add_argument("--out", help="output folder (overrides [run] output)")
    r.add_argument("--steps", type=int, help="number of steps (overrides [run] steps)")
    r.set_defaults(func=cmd_run)

    b = sub.add_parser("bench", help="benchmarks")
    bsub = b.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    p = bsub.add_parser("protocol", help="the shared LV probe case (shared/bench/PROTOCOL.md)",
                        description="Run the shared benchmark case on MESH (.msh, .vtu or .npz in mesh units; "
                                    "'ellipsoid_192' for the generated paper-size ellipsoid), or --all.")
    p.add_argument("mesh", nargs="?", metavar="MESH")
    p.add_argument("--all", action="store_true", help="the 4 shared meshes and the generated 192-tet closed ellipsoid "
                        "(same probe; its nodes with z <= 0, the lower half-shell, are fixed)")
    p.add_argument("--steps", type=int, default=1000, help="steps of 1 ms (default 1000)")
    p.add_argument("--json", action="store_true", help="one JSON object per mesh (JSON lines)")
    p.add_argument("--integrator", default="backward-euler", choices=["semi-implicit", "backward-euler", "newton"])
    p.add_argument("--max-wall", type=float, default=None, metavar="S",
                   help="stop a run after S seconds of stepping (default: no cap)")
    p.set_defaults(func=cmd_bench_protocol)

    q = bsub.add_parser("particles", help="per-tick cost of a meshfree particle body (an LV-shell cluster of N particles)",
                        description="Time 1 ms ticks of the N particles of the LV shell fill nearest the probe point "
                                    "(see palpate/bench_particles.py), or --all: N = " + ", ".join(map(str, [200, 600, 2000, 28000])) + ".")
    q.add_argument("n", nargs="?", type=int, metavar="N", help="number of (active) particles")
    q.add_argument("--all", action="store_true", help="N = 200, 600, 2000, 28000")
    q.add_argument("--spacing", type=float, default=9e-4, metavar="M", help="lattice spacing [m] (default 9e-4)")
    q.add_argument("--kernel", default="wendland", choices=["wendland", "cubic", "lj"])
    q.add_argument("--support", type=float, default=1.8, metavar="F",
                   help="kernel support radius in lattice spacings (default 1.8)")
    q.add_argument("--ticks", type=int, default=200, help="ticks of 1 ms to time (default 200)")
    q.add_argument("--json", action="store_true", help="one JSON object per N (JSON lines)")
    q.add_argument("--max-wall", type=float, default=None, metavar="S",
                   help="stop a case after S seconds of ticks (default: no cap)")
    q.set_defaults(func=cmd_bench_particles)

    i = sub.add_parser("info", help="load and validate a mesh file, print its size and quality")
    i.add_argument("mesh", metavar="MESH")
    i.add_argument("--unit", default="m", choices=["m", "cm", "mm"], help="length unit of the file (default m)")
    i.set_defaults(func=cmd_info)
    return ap


def main(argv: Optional[List[str]] = None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    if getattr(a, "steps", None) is not None and a.steps <= 0:
        ap.error("--steps must be positive")
    try:
        return a.func(a)
    except _Fail as e:
        print(f"palpate: error: {e}", file=sys.stderr)
        return e.code
    except KeyboardInterrupt:
        print("palpate: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
