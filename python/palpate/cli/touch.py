"""``palpate touch MODEL --script SCRIPT [--out DIR]``: a scripted touch of a hybrid model (a press,
hold, slide, release in TOML, or tool positions over time in CSV), logged as force.csv,
force.png and a VTU series. The script format and the outputs: :mod:`palpate.touch`."""
from __future__ import annotations

import math

from .. import defaults as _defaults
from ..hybrid import SHAPES
from ._common import Fail, RunFailed, Usage, add_quiet, fmt_mm, num

#: Material defaults [Pa, -, kg/m^3]: the default tissue (palpate.defaults.tissue:
#: Material::myocardium in the core), whose density the builder's particles have too.
YOUNG, POISSON, DENSITY = _defaults.tissue.young, _defaults.tissue.poisson, _defaults.tissue.density


def add_parser(sub) -> None:
    t = sub.add_parser("touch", help="run a scripted touch (press, hold, slide, release) on a hybrid model",
                       description="Touch a hybrid model (a palpate model file, or --shape) with a spherical tool "
                                   "following SCRIPT (.toml segments or .csv t,x,y,z; see palpate/touch.py), "
                                   "writing force.csv, force.png and a VTU series (touch.pvd) to --out.")
    t.add_argument("model", nargs="?", metavar="MODEL", help="a palpate model file (palpate build)")
    t.add_argument("--shape", choices=SHAPES,
                   help="build a shipped geometry instead of loading MODEL (see palpate build --shape)")
    t.add_argument("--script", required=True, metavar="SCRIPT", help="touch script: .toml or .csv")
    t.add_argument("--out", default="out/touch", metavar="DIR", help="output folder (default out/touch)")
    t.add_argument("--young", type=float, default=YOUNG, metavar="E", help=f"Young's modulus [Pa] (default {num(YOUNG)})")
    t.add_argument("--poisson", type=float, default=POISSON, metavar="NU", help=f"Poisson's ratio (default {num(POISSON)})")
    t.add_argument("--density", type=float, default=DENSITY, metavar="RHO",
                   help=f"density [kg/m^3] (default {num(DENSITY)}; with --shape, also the shell's particle masses)")
    t.add_argument("--phi", type=float, default=0.0, help="damping phi [Pa s] (default 0)")
    t.add_argument("--psi", type=float, default=0.0, help="damping psi [Pa s] (default 0)")
    t.add_argument("--tool-radius", type=float, default=None, metavar="M", help="tool sphere radius [m] (default the core's, 5 mm)")
    t.add_argument("--tool-area-stiffness", type=float, default=None, metavar="K",
                   help="penalty stiffness per unit of skin area [N/m^3] (default 12 E*/min(R, 4h), h the lattice spacing: 8.6e7 for the default tissue and tool on Rodero)")
    t.add_argument("--free", action="store_true", help="do not hold the core at its base (or lower 30%%)")
    t.add_argument("--strict-units", action="store_true",
                   help="refuse (exit 1) a Young's modulus outside 100 Pa-10 MPa or a tool radius over 5 cm instead of "
                        "warning (most likely the wrong unit: palpate's are SI)")
    add_quiet(t)
    t.add_argument("--dt", type=float, default=1e-3, metavar="S", help="tick [s] (default 1e-3)")
    t.add_argument("--every", type=int, default=None, metavar="K",
                   help="write a VTU frame every K ticks (default: about 80 frames)")
    t.set_defaults(func=cmd_touch)


def _positive(flag: str, v, allow_zero: bool = False) -> None:
    if v is None:
        return
    ok = (v >= 0 if allow_zero else v > 0) and math.isfinite(v)
    if not ok:
        raise Usage(f"palpate touch: {flag} must be {'non-negative' if allow_zero else 'positive'} and finite, got {v}")


def _model(a):
    import warnings

    from .. import _palpate as _p
    from .. import hybrid
    from ..data import DataError

    if (a.model is None) == (a.shape is None):
        raise Usage("palpate touch: give a MODEL file or --shape NAME (exactly one)")
    if a.shape is not None:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", _p.MeshWarning)
                return hybrid.build_shape(a.shape, density=a.density), f"shape {a.shape}"
        except DataError as e:
            raise Fail(f"palpate touch: shape {a.shape}: {e}", cause=e) from None
        except _p.PalpateError as e:
            raise Fail(f"palpate touch: shape {a.shape}: the build failed: {e}", cause=e) from None
    try:
        return _p.HybridModel.load(a.model), a.model
    except (_p.ModelFileError, OSError) as e:
        raise Fail(f"palpate touch: {e}") from None


def cmd_touch(a) -> int:
    from .. import _palpate as _p
    from ..touch import ScriptError, TouchFailed, parse_script, run_touch

    _positive("--dt", a.dt)
    for flag, v in (("--young", a.young), ("--density", a.density), ("--tool-radius", a.tool_radius),
                    ("--tool-area-stiffness", a.tool_area_stiffness)):
        _positive(flag, v)
    for flag, v in (("--phi", a.phi), ("--psi", a.psi)):
        _positive(flag, v, allow_zero=True)
    if a.every is not None and a.every < 1:
        raise Usage(f"palpate touch: --every must be at least 1, got {a.every}")
    try:
        script = parse_script(a.script)
    except ScriptError as e:
        raise Fail(f"palpate touch: {e}") from None
    try:
        material = _p.Material(young=a.young, poisson=a.poisson, density=a.density, phi=a.phi, psi=a.psi)
    except (_p.MaterialError, ValueError) as e:
        raise Fail(f"palpate touch: material: {e}") from None
    model, what = _model(a)
    try:
        sim = _p.HybridSim(model, material, tool_radius=a.tool_radius, tool_area_stiffness=a.tool_area_stiffness,
                           hold=not a.free, strict_units=a.strict_units)
    except ValueError as e:
        raise Fail(f"palpate touch: {e}") from None
    except _p.PalpateError as e:
        raise Fail(f"palpate touch: {what}: cannot simulate the model: {e}", cause=e) from None
    radius = sim.tool_radius if a.tool_radius is None else a.tool_radius
    try:
        traj = script.resolve(sim.surface, sim.surface_triangles, radius)
    except ScriptError as e:
        raise Fail(f"palpate touch: {e}") from None
    n = traj.n_ticks(a.dt)
    print(f"palpate touch: {what}: {a.script} ({script.kind}), {n} ticks of {a.dt:g} s; tool radius "
          f"{fmt_mm(radius)} mm at point {[round(1e3 * float(v), 3) for v in traj.point]} mm, normal "
          f"{[round(float(v), 4) for v in traj.normal]}; E = {a.young:g} Pa, nu = {a.poisson:g}; output {a.out}", flush=True)
    try:
        from .. import _progress
        with _progress.task(f"palpate touch: {what}"):
            s = run_touch(sim, traj, a.out, dt=a.dt, every=a.every, title=f"palpate touch: {what}, {a.script}")
    except TouchFailed as e:
        _report(e.summary, sim.options["max_tool_speed"] * a.dt)
        raise Fail(f"{a.script}: simulation failed at tick {e.tick} (t = {e.summary['t_failed_s']:.4f} s): "
                   f"{e.reason}; wrote the {e.summary['ticks']} ticks before it", cause=e) from None
    except OSError as e:
        raise RunFailed(f"palpate touch: cannot write the output: {e}") from None
    _report(s, sim.options["max_tool_speed"] * a.dt)
    return 0


def _report(s, max_step: float) -> None:
    if s["ticks"]:
        print(f"  {s['ticks']} ticks in {s['wall_s']:.3f} s of stepping: {s['ticks_per_s']:.1f} ticks/s; tick median "
              f"{s['tick_ms_median']:.3f} ms, p99 {s['tick_ms_p99']:.3f} ms, max {s['tick_ms_max']:.3f} ms")
        print(f"  max |f| {s['max_force_N']:.4f} N, max normal force {s['max_normal_force_N']:.4f} N, max depth "
              f"{fmt_mm(s['max_depth_m'])} mm, max active particles {s['max_active']}")
    if s.get("shell_shed"):
        print(f"  note: the shell's step failed {s['shell_shed']} time(s) and was shed (the core and the skin answered "
              f"for {s['shell_off_ticks']} ticks while it was off): a press the particles could not follow")
    if s["max_step_m"] > max_step * (1 + 1e-9):
        print(f"  note: the script moves the tool up to {fmt_mm(s['max_step_m'])} mm a tick; the simulated tool follows "
              f"at most {fmt_mm(max_step)} mm a tick (its top speed, max_tool_speed; force.csv logs the commanded "
              f"position)")
    print(f"  wrote {s['csv']}" + (f", {s['png']}" if s["png"] else "") + f", {s['frames']} frames: {s['pvd']}")
