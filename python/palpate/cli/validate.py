"""``palpate validate indentation SHAPE``: the hybrid model's force and dent against the converged
FEM of the same wall and the coarse FEM (``palpate/validate.py``, issue 33)."""
from __future__ import annotations

from typing import List, Tuple

from ._common import Fail, RunFailed, Usage


def _level(text: str) -> Tuple[int, int]:
    try:
        s, l = (int(v) for v in text.split(":"))
    except ValueError:
        raise Usage(f"palpate validate: a mesh level is SUBDIVISIONS:LAYERS (e.g. 4:4), got {text!r}") from None
    if not (0 <= s <= 7 and 1 <= l <= 32):
        raise Usage(f"palpate validate: level {text}: subdivisions must be 0 to 7 and layers 1 to 32")
    return s, l


def add_parser(sub) -> None:
    from ..validate import REFERENCE_LEVELS

    v = sub.add_parser("validate", help="the hybrid model against references palpate computes itself",
                       description="Validation against references palpate computes itself.")
    vs = v.add_subparsers(dest="what", metavar="WHAT")
    vs.required = True
    i = vs.add_parser("indentation",
                      help="sphere indentation: the hybrid against the converged FEM of its wall and the coarse FEM",
                      description="Press a rigid sphere into the hybrid model of SHAPE (quasi-statically) and into "
                                  "full-FEM meshes of the same wall refined toward the tool (static equilibrium, "
                                  "Newton), print force and dent against indentation with the reference's mesh "
                                  "convergence, and write indentation.json and indentation.png. Only the "
                                  "'ellipsoids' wall can be meshed for the reference today.")
    i.add_argument("shape", choices=["ellipsoids", "ventricle", "rodero"], help="the wall")
    i.add_argument("--model", metavar="FILE", help="a hybrid model of that wall (palpate build --shape SHAPE ...), "
                   "instead of building one with the default options")
    i.add_argument("--tool-radius", type=float, default=0.005, metavar="M", help="sphere radius [m] (default 0.005)")
    i.add_argument("--depths", type=float, nargs="+", default=[0.002, 0.004, 0.006], metavar="M",
                   help="indentations of the table [m] (default 0.002 0.004 0.006)")
    i.add_argument("--levels", nargs="+", default=[f"{s}:{l}" for s, l in REFERENCE_LEVELS], metavar="S:L",
                   help="reference meshes, SUBDIVISIONS:LAYERS each, coarse to fine, each halving the last's "
                        "element size (default " + " ".join(f"{s}:{l}" for s, l in REFERENCE_LEVELS) + ")")
    i.add_argument("--coarse", default="2:2", metavar="S:L", help="the coarse full FEM, ungraded (default 2:2: "
                   "768 tets)")
    i.add_argument("--young", type=float, default=30e3, metavar="E", help="Young's modulus [Pa] (default 30e3)")
    i.add_argument("--poisson", type=float, default=0.4, metavar="NU", help="Poisson's ratio (default 0.4)")
    i.add_argument("--law", choices=["neo-hookean", "svk"], default="neo-hookean",
                   help="the references' law (default neo-hookean; St. Venant-Kirchhoff collapses under a deep "
                        "press, see palpate.validate.IndentCase)")
    i.add_argument("--out", default="out/validate", metavar="DIR", help="output folder (default out/validate)")
    i.add_argument("--quiet", action="store_true", help="print the table only")
    i.set_defaults(func=cmd_indentation)


def cmd_indentation(a) -> int:
    from .. import _palpate as _p
    from .. import validate

    if a.shape != "ellipsoids":
        raise Fail(f"palpate validate indentation: {a.shape}: the converged reference needs a tet mesh of the wall, "
                   "and palpate meshes only the 'ellipsoids' wall today (a wall mesher for surfaces such as "
                   "Rodero's is the next step of issue 33)")
    if not (a.tool_radius > 0 and all(d > 0 for d in a.depths)):
        raise Usage("palpate validate indentation: --tool-radius and --depths must be positive [m]")
    depths: List[float] = sorted(a.depths)
    levels = [_level(t) for t in a.levels]
    coarse = _level(a.coarse)
    model = None
    if a.model:
        try:
            model = _p.HybridModel.load(a.model)
        except (_p.ModelFileError, OSError) as e:
            raise Fail(str(e)) from None
    try:
        result = validate.run_indentation(a.shape, tool_radius=a.tool_radius, depths=depths, levels=levels,
                                          coarse=coarse, young=a.young, poisson=a.poisson, law=a.law,
                                          out_dir=a.out, model=model, verbose=not a.quiet)
    except _p.SolveError as e:
        raise RunFailed(f"palpate validate indentation: the reference did not reach equilibrium: {e}") from None
    except _p.MaterialError as e:
        raise Fail(f"palpate validate indentation: material: {e}") from None
    if a.quiet:
        print(validate.format_table(result))
    print(f"wrote {a.out}/indentation.json and {a.out}/indentation.png")
    return 0
