"""``palpate info MODEL|MESH``: load and validate a palpate model file or a tet mesh file, and
print its size and quality."""
from __future__ import annotations

from ._common import Fail, mb, model_lines


def add_parser(sub) -> None:
    i = sub.add_parser("info", help="load and validate a model or mesh file, print its size and quality",
                       description="MODEL: a palpate model file (palpate build): counts, core quality, volumes, "
                                   "size, build times. MESH: a tet mesh file: size and quality.")
    i.add_argument("mesh", metavar="MODEL|MESH")
    i.add_argument("--unit", default="m", choices=["m", "cm", "mm"], help="length unit of a mesh file (default m)")
    i.set_defaults(func=cmd_info)


def _looks_like_model(path: str) -> bool:
    """A palpate model file (or a damaged one): the magic number, a prefix of it, or the .palpate extension."""
    from ..hybrid import MODEL_MAGIC

    if path.lower().endswith(".palpate"):
        return True
    import os
    if not os.path.isfile(path):
        return False  # opening a FIFO would block; the loaders refuse it with a message
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(MODEL_MAGIC))
    except OSError:
        return False
    return len(head) >= 8 and MODEL_MAGIC.startswith(head)


def cmd_info_model(a) -> int:
    import os
    import time

    from .. import _palpate as _p

    t0 = time.perf_counter()
    try:
        model = _p.HybridModel.load(a.mesh)
    except (_p.ModelFileError, OSError) as e:
        raise Fail(str(e)) from None
    load_s = time.perf_counter() - t0
    i = model.info()
    size = os.path.getsize(a.mesh)
    print(f"{a.mesh}: palpate hybrid model, file {mb(size)} (loaded and checked in {load_s:.3f} s); "
          f"{i['projection']} projection, core fraction {i['core_fraction']:g}")
    for line in model_lines(i):
        print(line)
    return 0


def cmd_info(a) -> int:
    if _looks_like_model(a.mesh):
        return cmd_info_model(a)
    from ..io import MeshError, load_mesh

    try:
        m = load_mesh(a.mesh, unit=a.unit)
    except (MeshError, ValueError) as e:
        raise Fail(str(e)) from None
    p = m.points
    print(f"{a.mesh}: {m.n_nodes} nodes, {m.n_tets} tets, volume {m.volume:.6e} m^3, "
          f"min dihedral {m.min_dihedral_deg:.2f} deg")
    print(f"  bounding box [m]: {p.min(0).round(6).tolist()} .. {p.max(0).round(6).tolist()}")
    print(f"  boundary faces: {len(m.boundary_faces())}")
    return 0
