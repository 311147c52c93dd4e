"""``palpate validate indentation SHAPE``: the hybrid model's force and dent against the converged
FEM of the same wall and the coarse FEM (``palpate/validate.py``, issue 33)."""
from __future__ import annotations

from typing import List, Tuple

from .. import defaults as _defaults
from ._common import Fail, RunFailed, Usage, num

#: The material's defaults [Pa, -]: the default tissue (palpate.defaults.tissue).
YOUNG, POISSON = _defaults.tissue.young, _defaults.tissue.poisson


def _level(text: str, shape: str) -> Tuple[int, int]:
    from ..validate import GMSH_SHAPES

    if shape in GMSH_SHAPES:
        try:
            a = int(text.split(":")[0])
        except ValueError:
            raise Usage(f"palpate validate: a mesh level of {shape} is TRIANGLES (e.g. 6000), got {text!r}") from None
        if not 100 <= a <= 200_000:
            raise Usage(f"palpate validate: level {text}: {shape}'s surface triangles must be 100 to 200000")
        return a, 0
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise Usage(f"palpate validate: a mesh level is A:LAYERS (e.g. 4:4), got {text!r}") from None
    if shape == "ellipsoids" and not (0 <= a <= 7 and 1 <= b <= 32):
        raise Usage(f"palpate validate: level {text}: the ellipsoids' subdivisions must be 0 to 7 and layers 1 to 32")
    if shape != "ellipsoids" and not (4 <= a <= 200_000 and 1 <= b <= 16):
        raise Usage(f"palpate validate: level {text}: a built wall's triangles must be 4 to 200000 and layers 1 to 16")
    return a, b


def add_parser(sub) -> None:
    from ..validate import BUILT_LEVELS, GMSH_LEVELS, QUADRATIC_LEVELS, REFERENCE_LEVELS

    v = sub.add_parser("validate", help="the hybrid model against references palpate computes itself",
                       description="Validation against references palpate computes itself.")
    vs = v.add_subparsers(dest="what", metavar="WHAT")
    vs.required = True
    i = vs.add_parser("indentation",
                      help="sphere indentation: the hybrid against the converged FEM of its wall and the coarse FEM",
                      description="Press a rigid sphere into the hybrid model of SHAPE (quasi-statically) and into "
                                  "full-FEM meshes of the same wall refined toward the tool (static equilibrium, "
                                  "Newton), print force and dent against indentation with the reference's mesh "
                                  "convergence, and write indentation.json and indentation.png.")
    i.add_argument("shape", choices=["ellipsoids", "ventricle", "rodero"], help="the wall")
    i.add_argument("--model", metavar="FILE", help="a hybrid model of that wall (palpate build --shape SHAPE ...), "
                   "instead of building one with the default options")
    i.add_argument("--tool-radius", type=float, default=0.005, metavar="M", help="sphere radius [m] (default 0.005)")
    i.add_argument("--depths", type=float, nargs="+", default=[0.002, 0.004, 0.006], metavar="M",
                   help="indentations of the table [m] (default 0.002 0.004 0.006)")
    i.add_argument("--levels", nargs="+", metavar="A:L",
                   help="reference meshes, coarse to fine, each halving the last's element size: for the ellipsoids "
                        "SUBDIVISIONS:LAYERS of the graded wall (linear tets' default " + " ".join(f"{s}:{l}" for s, l in REFERENCE_LEVELS)
                        + "), for rodero TRIANGLES of its simplified surface filled by gmsh (default "
                        + " ".join(str(s) for s, _ in GMSH_LEVELS) + "), for the ventricle TRIANGLES:LAYERS of the "
                        "build's wall mesh (default " + " ".join(f"{s}:{l}" for s, l in BUILT_LEVELS) + ")")
    i.add_argument("--order", type=int, choices=[1, 2], default=2,
                   help="the references' elements: 2 quadratic tets (default; they converge where linear ones "
                        "lock, a level coarser: default levels " + ", ".join(
                            f"{k} " + " ".join(f"{s}:{l}" if k != "gmsh" else str(s) for s, l in v)
                            for k, v in QUADRATIC_LEVELS.items()) + "), 1 linear tets (the levels above)")
    i.add_argument("--coarse", metavar="A:L", help="the coarse full FEM, ungraded (default 2:2 for the ellipsoids: "
                   "768 tets; 600 for rodero: 880 tets; 300:1 for the ventricle: 900 tets)")
    i.add_argument("--young", type=float, default=YOUNG, metavar="E",
                   help=f"Young's modulus [Pa] (default {num(YOUNG)}, the default tissue's)")
    i.add_argument("--poisson", type=float, default=POISSON, metavar="NU",
                   help=f"Poisson's ratio (default {num(POISSON)})")
    i.add_argument("--law", choices=["neo-hookean", "svk"], default="neo-hookean",
                   help="the references' law (default neo-hookean; St. Venant-Kirchhoff collapses under a deep "
                        "press, see palpate.validate.IndentCase)")
    i.add_argument("--reference", metavar="JSON", help="reuse the reference and coarse curves of an earlier run's "
                   "indentation.json (the same wall, material, law, tool and held height; --levels and --coarse are "
                   "then its own): minutes instead of half an hour when only the hybrid changed")
    i.add_argument("--explicit-exchange", action="store_true",
                   help="the hybrid with the shell's springs capped by the explicit exchange's stability "
                        "(HybridSim(implicit_exchange=False), for comparison: softer, force not proportional to E; "
                        "VALIDATION.md)")
    i.add_argument("--out", default="out/validate", metavar="DIR", help="output folder (default out/validate)")
    i.add_argument("--quiet", action="store_true", help="print the table only")
    i.set_defaults(func=cmd_indentation)


def cmd_indentation(a) -> int:
    from .. import _palpate as _p
    from .. import validate

    if not (a.tool_radius > 0 and all(d > 0 for d in a.depths)):
        raise Usage("palpate validate indentation: --tool-radius and --depths must be positive [m]")
    depths: List[float] = sorted(a.depths)
    levels = [_level(t, a.shape) for t in a.levels] if a.levels else list(validate.default_levels(a.shape, a.order))
    coarse = _level(a.coarse, a.shape) if a.coarse else validate.default_coarse(a.shape)
    model = None
    if a.model:
        try:
            model = _p.HybridModel.load(a.model)
        except (_p.ModelFileError, OSError) as e:
            raise Fail(str(e)) from None
    try:
        result = validate.run_indentation(a.shape, tool_radius=a.tool_radius, depths=depths, levels=levels,
                                          coarse=coarse, young=a.young, poisson=a.poisson, law=a.law,
                                          out_dir=a.out, model=model, reference=a.reference, verbose=not a.quiet,
                                          implicit_exchange=not a.explicit_exchange, order=a.order)
    except validate.ReferenceMismatch as e:
        raise Fail(f"palpate validate indentation: --reference {e}") from None
    except _p.SolveError as e:
        raise RunFailed(f"palpate validate indentation: the reference did not reach equilibrium: {e}") from None
    except _p.ModelError as e:
        raise Fail(f"palpate validate indentation: the reference mesh: {e}") from None
    except _p.MaterialError as e:
        raise Fail(f"palpate validate indentation: material: {e}") from None
    if a.quiet:
        print(validate.format_table(result))
    plotted = f" and {a.out}/indentation.png" if result.get("plot") else ""
    print(f"wrote {a.out}/indentation.json{plotted}")
    return 0
