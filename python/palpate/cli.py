"""The ``palpate`` command line (also ``python -m palpate``).

    palpate run SCENE.toml [--out DIR] [--steps N]
    palpate bench protocol MESH [--force F] [--steps N] [--json] [--integrator NAME] [--newton auto|on|off]
    palpate bench protocol --all [--force F] [--steps N] [--json] [--integrator NAME]
    palpate bench particles N [--spacing S] [--kernel wendland|cubic|lj] [--ticks T] [--json]
    palpate bench particles --all [...]
    palpate build INNER OUTER -o MODEL [--unit m|cm|mm] [build options]
    palpate build --tagged SURFACE -o MODEL [--unit m|cm|mm] [--tag-array NAME] [--inner 1,2] [--outer 3]
                  [--base 4,5] [build options]
    palpate build --shape ellipsoids|ventricle|rodero -o MODEL [build options]
        build options: [--projection transmural|radial] [--core-fraction F] [--core-triangles N]
                       [--core-layers N] [--spacing M | --particles N] [--density RHO]
                       [--min-region-particles N] [--field-voxels N]
    palpate info MODEL                  (a palpate model file, written by palpate build)
    palpate info MESH [--unit m|cm|mm]  (a tet mesh file)

Exit codes: 0 success, 1 a simulation failed (e.g. a step diverged), a hybrid build failed on
valid surfaces or an output could not be written, 2 bad input (arguments, scene file, mesh,
surface or model file), with one line on stderr and no traceback.
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
        yield (lambda: bench.generated_case(a.force))
        for p in paths:
            yield (lambda p=p: bench.load_case(str(p), a.force))
        return
    if not a.mesh:
        raise _Fail("palpate bench protocol: give a MESH file (.msh, .vtu, .npz) or --all")
    if a.mesh == bench.GENERATED:
        yield (lambda: bench.generated_case(a.force))
        return

    def one():
        try:
            return bench.load_case(a.mesh, a.force)
        except MeshError as e:
            raise _Fail(f"palpate bench protocol: {e}") from None
    yield one


def cmd_bench_protocol(a) -> int:
    from . import bench

    if not (math.isfinite(a.force) and a.force > 0):
        raise _Fail(f"palpate bench protocol: --force must be a positive number of newtons, got {a.force}")
    if a.steps < 1:
        raise _Fail("palpate bench protocol: --steps must be at least 1")
    newton = {"auto": None, "on": True, "off": False}[a.newton]
    rows = []
    if not a.json:
        print(f"palpate {__version__} bench protocol: {a.force:g} N, {a.steps} steps of {bench.DT * 1e3:g} ms, "
              f"integrator {a.integrator}, single thread (shared/bench/PROTOCOL.md)")
        print(f"{'mesh':<16}{'tets':>7}{'steps/s':>10}{'stable':>8}{'max|u| mm':>11}{'probe mm':>10}"
              f"{'iter':>6}{'inv':>5}{'p50 us':>8}{'p99 us':>8}{'max us':>8}{'vsStatic':>10}{'vsNewton':>10}")
    for make in _bench_cases(a):
        case = make()
        r = bench.run(case, a.integrator, steps=a.steps, max_wall_s=a.max_wall, newton=newton)
        rows.append(r)
        if a.json:
            print(json.dumps(r), flush=True)
        else:
            def rel(k):
                return "-" if r[k] is None else f"{100 * r[k]:.3f}%"
            sps = "-" if r["steps_per_s"] is None else f"{r['steps_per_s']:.1f}"
            us = lambda k: "-" if r[k] is None else f"{r[k]:.0f}"  # noqa: E731
            it = "-" if r["iterations_mean"] is None else f"{r['iterations_mean']:.2f}"
            print(f"{r['mesh']:<16}{r['tets']:>7}{sps:>10}{str(r['stable']):>8}"
                  f"{_fmt_mm(r['max_disp_m']):>11}{_fmt_mm(r['probe_disp_avg_m']):>10}{it:>6}"
                  f"{r['inverted_max']:>5}{us('step_us_p50'):>8}{us('step_us_p99'):>8}{us('step_us_max'):>8}"
                  f"{rel('rel_L2_vs_static'):>10}{rel('rel_L2_vs_newton'):>10}", flush=True)
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
        print(f"{'N':>7}{'in h':>6}{'nbrs':>7}{'fixed':>7}{'sub/tick':>9}{'sub dt us':>10}{'tick ms':>9}{'ticks/s':>9}"
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
        print(f"{r['n']:>7}{r['mean_neighbours_in_support']:>6.1f}{r['mean_neighbours']:>7.1f}{r['fixed']:>7}{r['substeps']:>9}{r['substep_dt_s'] * 1e6:>10.1f}"
              f"{f(r['tick_median_s'] and r['tick_median_s'] * 1e3, '.3f'):>9}{f(r['ticks_per_s'], '.1f'):>9}"
              f"{f(r['gflops'], '.2f'):>9}{f(r['peak_fraction'] and 100 * r['peak_fraction'], '.1f'):>7}"
              f"{r['build_s']:>9.2f}{_fmt_mm(r['max_disp_m']):>10}", flush=True)
        if r["error"]:
            print(f"  note: {r['error']} (median over {r['ticks']} ticks)")
    return 1 if failed else 0


def _p_errors():
    from . import _palpate as _p
    return (_p.PalpateError,)


def _int_list(text: Optional[str], flag: str):
    if text is None:
        return None
    try:
        vals = [int(v) for v in text.split(",") if v.strip() != ""]
    except ValueError:
        raise _Fail(f"palpate build: {flag} takes comma-separated integer tag values, got {text!r}") from None
    if not vals:
        raise _Fail(f"palpate build: {flag} takes comma-separated integer tag values, got {text!r}")
    return vals


def _mb(nbytes: int) -> str:
    return f"{nbytes / 1e6:.2f} MB"


def _ml(m3: float) -> str:
    return f"{m3 * 1e6:.3f} mL"


def _model_lines(info: dict) -> List[str]:
    """The description of a hybrid model's info() dict, shared by build and info."""
    i = info
    closure = (i["core_volume_m3"] + i["shell_volume_m3"]) / i["wall_volume_m3"] if i["wall_volume_m3"] > 0 else math.nan
    lines = [
        f"  core: {i['core_tets']} tets, {i['core_nodes']} nodes, {i['core_faces']} faces towards the shell, "
        f"{i['core_base_nodes']} base nodes; min dihedral {i['core_min_dihedral_deg']:.2f} deg, "
        f"tet volume ratio min/max {i['core_volume_ratio']:.3g}",
        f"  shell: {i['particles']} particles at {i['spacing_m'] * 1e3:.3f} mm spacing",
        f"  regions: {i['regions']} (one per outer vertex; {i['outer_triangles']} outer triangles), "
        f"particles per region min {i['region_particles_min']}, median {i['region_particles_median']}, "
        f"max {i['region_particles_max']}",
        f"  volumes: wall {_ml(i['wall_volume_m3'])}, core {_ml(i['core_volume_m3'])}, "
        f"shell {_ml(i['shell_volume_m3'])} (core + shell = {100 * closure:.2f} % of the wall)",
        f"  transmural field: {i['voxels']} voxels of {i['voxel_m'] * 1e3:.3f} mm, {i['field_cg_iterations']} CG iterations",
        f"  build time: {i['build_s']:.3f} s (field {i['build_field_s']:.3f}, core {i['build_core_s']:.3f}, "
        f"particles {i['build_particles_s']:.3f}, regions {i['build_regions_s']:.3f})",
    ]
    fb = {k: i[k] for k in ("fallback_particle_outer", "fallback_particle_core", "fallback_skin") if i.get(k)}
    if fb:
        lines.append("  fallbacks: " + ", ".join(f"{k[len('fallback_'):]} {v}" for k, v in fb.items()))
    return lines


def cmd_build(a) -> int:
    import os
    import time
    import warnings

    from . import _palpate as _p
    from . import hybrid
    from .data import DataError

    files = a.files or []
    modes = [bool(files), a.tagged is not None, a.shape is not None]
    if sum(modes) != 1:
        raise _Fail("palpate build: give INNER OUTER (two nested surfaces), --tagged SURFACE or --shape NAME "
                    "(exactly one)")
    if files and len(files) != 2:
        raise _Fail(f"palpate build: give two surface files INNER OUTER, got {len(files)}")
    if a.tagged is None and any(v is not None for v in (a.tag_array, a.inner, a.outer, a.base)):
        raise _Fail("palpate build: --tag-array, --inner, --outer and --base go with --tagged SURFACE")
    if a.shape is not None and a.unit is not None:
        raise _Fail("palpate build: --unit is for surface files, not --shape (the shapes are in metres)")
    unit = a.unit or "m"
    opts = {"projection": _p.Projection.RADIAL if a.projection == "radial" else _p.Projection.TRANSMURAL,
            "core_fraction": a.core_fraction, "core_triangles": a.core_triangles, "core_layers": a.core_layers,
            "spacing": a.spacing, "particles": a.particles, "density": a.density,
            "min_region_particles": a.min_region_particles, "field_voxels": a.field_voxels}
    for flag, v in (("--core-triangles", a.core_triangles), ("--core-layers", a.core_layers),
                    ("--particles", a.particles), ("--min-region-particles", a.min_region_particles),
                    ("--field-voxels", a.field_voxels)):
        if v < 0:
            raise _Fail(f"palpate build: {flag} must not be negative, got {v}")
    for flag, v in (("--spacing", a.spacing), ("--density", a.density)):
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise _Fail(f"palpate build: {flag} must be positive, got {v}")
    if files:
        what = f"inner {files[0]}, outer {files[1]}"
        build = lambda: hybrid.build_from_files(files[0], files[1], unit=unit, **opts)  # noqa: E731
    elif a.tagged is not None:
        what = f"{a.tagged} (tagged)"
        tags = dict(tag_array=a.tag_array, inner=_int_list(a.inner, "--inner"), outer=_int_list(a.outer, "--outer"),
                    base=_int_list(a.base, "--base"))
        build = lambda: hybrid.build_tagged_file(a.tagged, unit=unit, **tags, **opts)  # noqa: E731
    else:
        what = f"shape {a.shape}"
        build = lambda: hybrid.build_shape(a.shape, **opts)  # noqa: E731
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = build()
    except (_p.SurfaceError, _p.MeshError, ValueError, DataError) as e:
        msg = str(e)
        if not any(os.path.basename(f) in msg for f in files + [a.tagged or ""] if f):
            msg = f"{what}: {msg}"
        raise _Fail(f"palpate build: {msg}") from None
    except OSError as e:
        raise _Fail(f"palpate build: cannot read the input: {e}") from None
    except _p.PalpateError as e:
        raise _Fail(f"palpate build: {what}: the build failed: {e}", 1) from None
    wall = time.perf_counter() - t0
    info = model.info()
    print(f"palpate build: {what}: {info['projection']} projection, core fraction {info['core_fraction']:g}; "
          f"{wall:.2f} s including reading the input")
    for w in caught:
        print(f"  note: {w.message}")
    for line in _model_lines(info):
        print(line)
    try:
        model.save(a.output)
    except (OSError, _p.ModelFileError) as e:
        raise _Fail(f"palpate build: cannot write the model: {e}", 1) from None
    print(f"  wrote {a.output} ({_mb(info['file_bytes'])})")
    return 0


def _looks_like_model(path: str) -> bool:
    """A palpate model file (or a damaged one): the magic number, a prefix of it, or the .palpate extension."""
    from .hybrid import MODEL_MAGIC

    if path.lower().endswith(".palpate"):
        return True
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(MODEL_MAGIC))
    except OSError:
        return False
    return len(head) >= 8 and MODEL_MAGIC.startswith(head)


def cmd_info_model(a) -> int:
    import os
    import time

    from . import _palpate as _p

    t0 = time.perf_counter()
    try:
        model = _p.HybridModel.load(a.mesh)
    except _p.ModelFileError as e:
        raise _Fail(str(e)) from None
    except OSError as e:
        raise _Fail(str(e)) from None
    load_s = time.perf_counter() - t0
    i = model.info()
    size = os.path.getsize(a.mesh)
    print(f"{a.mesh}: palpate hybrid model, file {_mb(size)} (loaded and checked in {load_s:.3f} s); "
          f"{i['projection']} projection, core fraction {i['core_fraction']:g}")
    for line in _model_lines(i):
        print(line)
    return 0


def cmd_info(a) -> int:
    if _looks_like_model(a.mesh):
        return cmd_info_model(a)
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
    p.add_argument("--integrator", default="backward-euler", choices=list(__import__("palpate.bench").bench.INTEGRATORS),
                   help="backward-euler (the default: quasi-Newton), newton, linearised, semi-implicit, "
                        "semi-implicit-stable")
    p.add_argument("--force", type=float, default=0.2, metavar="F",
                   help="total probe force [N] (default 0.2, the protocol's; same loaded nodes)")
    p.add_argument("--newton", choices=["auto", "on", "off"], default="auto",
                   help="also run converged Newton for rel_L2_vs_newton (auto: meshes up to 10k tets)")
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

    h = sub.add_parser("build", help="build a hybrid model (FEM core, particle shell, skin) from wall surfaces",
                       description="Build a palpate hybrid model from two nested closed surfaces INNER OUTER, one "
                                   "tagged surface (--tagged) or a shipped geometry (--shape), print a summary and "
                                   "write MODEL (load it with palpate.HybridModel.load).")
    h.add_argument("files", nargs="*", metavar="INNER OUTER", help="two nested closed surface files (.obj, .stl, .ply, "
                   ".off, .vtk, .vtu, .vtp)")
    h.add_argument("--tagged", metavar="SURFACE", help="one closed surface with an inner / outer / base tag per "
                   "triangle (a truncated ventricle)")
    h.add_argument("--shape", choices=["ellipsoids", "ventricle", "rodero"],
                   help="ellipsoids: the paper's concentric ellipsoids; ventricle: the benchmark's truncated "
                        "ventricle; rodero: the real left ventricle of Rodero et al. (fetched on first use)")
    h.add_argument("-o", "--output", required=True, metavar="MODEL", help="model file to write")
    h.add_argument("--unit", choices=["m", "cm", "mm"], help="length unit of the surface files (default m)")
    h.add_argument("--tag-array", metavar="NAME", help="integer cell array holding the tags (default surface-id)")
    h.add_argument("--inner", metavar="T[,T...]", help="tag values of the inner surface")
    h.add_argument("--outer", metavar="T[,T...]", help="tag values of the outer surface")
    h.add_argument("--base", metavar="T[,T...]", help="tag values of the base (valve planes, cut)")
    h.add_argument("--projection", choices=["transmural", "radial"], default="transmural",
                   help="transmural: along the transmural field's streamlines (any wall, default); radial: the "
                        "paper's, through the mass centre (star-shaped walls)")
    h.add_argument("--core-fraction", type=float, default=0.5, metavar="F",
                   help="fraction of the wall (from the inner surface) in the FEM core (default 0.5)")
    h.add_argument("--core-triangles", type=int, default=0, metavar="N",
                   help="triangles of the simplified inner surface, 3 tets each per layer (default 0: automatic)")
    h.add_argument("--core-layers", type=int, default=1, metavar="N", help="tet layers of the core (default 1)")
    g = h.add_mutually_exclusive_group()
    g.add_argument("--spacing", type=float, metavar="M", help="particle lattice spacing [m]")
    g.add_argument("--particles", type=int, default=28000, metavar="N",
                   help="about N particles in the shell (default 28000; ignored with --spacing)")
    h.add_argument("--density", type=float, default=1000.0, metavar="RHO", help="density [kg/m^3] (default 1000)")
    h.add_argument("--min-region-particles", type=int, default=50, metavar="N",
                   help="particles an activation region grows to at least (default 50)")
    h.add_argument("--field-voxels", type=int, default=120000, metavar="N",
                   help="wall voxels of the transmural field solve (default 120000)")
    h.set_defaults(func=cmd_build)

    i = sub.add_parser("info", help="load and validate a model or mesh file, print its size and quality",
                       description="MODEL: a palpate model file (palpate build): counts, core quality, volumes, "
                                   "size, build times. MESH: a tet mesh file: size and quality.")
    i.add_argument("mesh", metavar="MODEL|MESH")
    i.add_argument("--unit", default="m", choices=["m", "cm", "mm"], help="length unit of a mesh file (default m)")
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
