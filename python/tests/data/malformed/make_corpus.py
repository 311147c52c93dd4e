"""Regenerate the malformed-mesh corpus beside this script, and its table EXPECTED.toml.

    python make_corpus.py

Each file holds exactly one defect in an otherwise valid two-tet mesh (five nodes, tets (0 1 2 3)
and (1 2 3 4), both positively oriented). The files are committed; this script documents how they
were made and lets them be rebuilt. The writers are deliberately hand-rolled (not meshio) so that
a file can hold things a careful writer would refuse to write.

EXPECTED.toml maps each file to the exception class :func:`palpate.load_mesh` must raise and
substrings its message must contain (the file name is checked for every case by the test itself).
A case with ``warning`` instead of ``error`` must load, with that warning class.
"""
import os
import random
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
from corpus import entry, write_case, write_expected  # noqa: E402

P = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 1.0, 1.0)]
T = [(0, 1, 2, 3), (1, 2, 3, 4)]

GMSH_CODE = {"tetra": 4, "triangle": 2, "hexahedron": 5, "tetra10": 11, "line": 1, "vertex": 15}
VTK_CODE = {"tetra": 10, "triangle": 5, "hexahedron": 12}

HEX_P = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]


def fmt(x):
    return repr(float(x)) if isinstance(x, float) else str(x)


def gmsh2(points, cells, node_tags=None):
    """cells: [(type, [0-based node indices or explicit tags via node_tags])]"""
    tags = node_tags or list(range(1, len(points) + 1))
    out = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", str(len(points))]
    out += [f"{t} {' '.join(fmt(c) for c in p)}" for t, p in zip(tags, points)]
    out += ["$EndNodes", "$Elements", str(len(cells))]
    for k, (ty, conn) in enumerate(cells):
        out.append(f"{k + 1} {GMSH_CODE[ty]} 2 0 1 " + " ".join(str(c) for c in conn))
    out += ["$EndElements"]
    return "\n".join(out) + "\n"


def gmsh4(points, cells):
    """cells: [(type, [gmsh node tags])]; one entity block per cell type."""
    n = len(points)
    out = ["$MeshFormat", "4.1 0 8", "$EndMeshFormat", "$Nodes", f"1 {n} 1 {n}", f"3 1 0 {n}"]
    out += [str(i + 1) for i in range(n)]
    out += [" ".join(fmt(c) for c in p) for p in points]
    out += ["$EndNodes", "$Elements"]
    types = []
    for ty, _ in cells:
        if ty not in types:
            types.append(ty)
    out.append(f"{len(types)} {len(cells)} 1 {len(cells)}")
    tag = 1
    for ty in types:
        block = [c for t, c in cells if t == ty]
        dim = {"tetra": 3, "hexahedron": 3, "tetra10": 3, "triangle": 2, "line": 1, "vertex": 0}[ty]
        out.append(f"{dim} 1 {GMSH_CODE[ty]} {len(block)}")
        for conn in block:
            out.append(f"{tag} " + " ".join(str(c) for c in conn))
            tag += 1
    out += ["$EndElements"]
    return "\n".join(out) + "\n"


def tags1(cells):
    """0-based connectivity -> gmsh 1-based tags."""
    return [(ty, [i + 1 for i in conn]) for ty, conn in cells]


def vtk_legacy(points, cells, header="# vtk DataFile Version 4.2"):
    out = [header, "palpate malformed-mesh corpus", "ASCII", "DATASET UNSTRUCTURED_GRID",
           f"POINTS {len(points)} double"]
    out += [" ".join(fmt(c) for c in p) for p in points]
    size = sum(1 + len(c) for _, c in cells)
    out.append(f"CELLS {len(cells)} {size}")
    out += [f"{len(c)} " + " ".join(str(i) for i in c) for _, c in cells]
    out.append(f"CELL_TYPES {len(cells)}")
    out += [str(VTK_CODE[ty]) for ty, _ in cells]
    return "\n".join(out) + "\n"


def vtu(points, cells):
    conn = " ".join(str(i) for _, c in cells for i in c)
    offs, o = [], 0
    for _, c in cells:
        o += len(c)
        offs.append(str(o))
    pts = " ".join(fmt(x) for p in points for x in p)
    return f"""<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian">
  <UnstructuredGrid>
    <Piece NumberOfPoints="{len(points)}" NumberOfCells="{len(cells)}">
      <Points>
        <DataArray type="Float64" NumberOfComponents="3" format="ascii">{pts}</DataArray>
      </Points>
      <Cells>
        <DataArray type="Int64" Name="connectivity" format="ascii">{conn}</DataArray>
        <DataArray type="Int64" Name="offsets" format="ascii">{' '.join(offs)}</DataArray>
        <DataArray type="UInt8" Name="types" format="ascii">{' '.join(str(VTK_CODE[t]) for t, _ in cells)}</DataArray>
      </Cells>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"""


def tetgen_node(points, base=0, count=None):
    out = ["# palpate malformed-mesh corpus", f"{count if count is not None else len(points)} 3 0 0"]
    out += [f"{base + i} " + " ".join(fmt(c) for c in p) for i, p in enumerate(points)]
    return "\n".join(out) + "\n"


def tetgen_ele(tets, base=0):
    out = [f"{len(tets)} 4 0"]
    out += [f"{base + k} " + " ".join(str(i) for i in t) for k, t in enumerate(tets)]
    return "\n".join(out) + "\n"


def cells_of(tets):
    return [("tetra", list(t)) for t in tets]


def moved(i, xyz):
    p = list(P)
    p[i] = xyz
    return p


CASES = []  # (file name, content (str or bytes or None for no file), expectation dict)


def case(name, content, error=None, contains=(), warning=None, note=""):
    CASES.append((name, content, dict(error=error, contains=list(contains), warning=warning, note=note)))


def build():
    nan, inf = float("nan"), float("inf")
    # --- gmsh MSH 2.2
    case("gmsh2_index_out_of_range.msh", gmsh2(P, tags1([("tetra", T[0]), ("tetra", (1, 2, 3, 8))])),
         "MeshError", ["gmsh element 2", "node tag 9", "not defined"], note="node tag 9 of 5")
    case("gmsh2_negative_index.msh", gmsh2(P, [("tetra", (1, 2, 3, 4)), ("tetra", (2, 3, -4, 5))]),
         "MeshError", ["gmsh element 2", "node tag -4"], note="negative node tag")
    case("gmsh2_zero_volume.msh", gmsh2(moved(4, P[1]), tags1(cells_of(T))),
         "MeshError", ["tet 1", "gmsh element 2", "degenerate"], note="node 4 sits on node 1: volume 0")
    case("gmsh2_only_triangles.msh", gmsh2(P, tags1([("triangle", (0, 1, 2)), ("triangle", (1, 2, 3))])),
         "MeshError", ["no tetrahedra", "'triangle'"])
    case("gmsh2_quadratic_tets.msh",
         gmsh2(P + [(0.5, 0, 0), (0.5, 0.5, 0), (0, 0.5, 0), (0, 0, 0.5), (0.5, 0, 0.5), (0, 0.5, 0.5)],
               tags1([("tetra10", (0, 1, 2, 3, 5, 6, 7, 8, 9, 10))])),
         "MeshError", ["tetra10", "quadratic"])
    full = gmsh2(P, tags1(cells_of(T)))
    case("gmsh2_truncated.msh", full[: full.index("$Elements") + len("$Elements\n2\n") + 10],
         "MeshError", ["end of file", "truncated"])
    case("gmsh2_inverted_tet.msh", gmsh2(P, tags1([("tetra", (0, 2, 1, 3)), ("tetra", T[1])])),
         warning="MeshWarning", contains=["inverted", "reoriented"], note="loads, with a warning")
    case("gmsh2_wrong_count.msh", full.replace("$Nodes\n5\n", "$Nodes\n4\n"),
         "MeshError", ["line", "expected '$EndNodes'"], note="$Nodes says 4, holds 5")
    # --- gmsh MSH 4.1
    p_cop = moved(4, (1.0, 1.0, -1.0))  # on the plane x + y + z = 1 of nodes 1, 2, 3
    case("gmsh4_coplanar_tet.msh", gmsh4(p_cop, tags1(cells_of(T))),
         "MeshError", ["tet 1", "gmsh element 2", "degenerate"], note="four coplanar nodes")
    case("gmsh4_duplicate_tet.msh", gmsh4(P, tags1(cells_of(T) + [("tetra", (1, 0, 3, 2))])),
         "MeshError", ["tet 2", "duplicate of tet 0"])
    case("gmsh4_repeated_node.msh", gmsh4(P, tags1([("tetra", T[0]), ("tetra", (1, 2, 2, 4))])),
         "MeshError", ["tet 1", "appears twice"])
    case("gmsh4_nan_coordinate.msh", gmsh4(moved(2, (0.0, nan, 0.0)), tags1(cells_of(T))),
         "MeshError", ["node 2", "gmsh node 3", "non-finite"])
    case("gmsh4_index_out_of_range.msh", gmsh4(P, tags1([("tetra", T[0]), ("tetra", (1, 2, 3, 5))])),
         "MeshError", ["gmsh element 2", "node tag 6"])
    case("gmsh4_only_hexahedra.msh", gmsh4(HEX_P, tags1([("hexahedron", list(range(8)))])),
         "MeshError", ["'hexahedron'", "not tetrahedra"])
    f4 = gmsh4(P, tags1(cells_of(T)))
    case("gmsh4_truncated.msh", f4[: f4.index("$Nodes") + 30], "MeshError", ["end of file"])
    case("gmsh_wrong_header.msh", f4.replace("$MeshFormat", "$MeshFromat", 1),
         "MeshError", ["line 1", "expected '$MeshFormat'"])
    case("gmsh_bad_version.msh", f4.replace("4.1 0 8", "9.1 0 8"), "MeshError", ["unsupported gmsh MSH version"])
    rnd = random.Random(1234)
    case("gmsh_garbage.msh", bytes(rnd.randrange(256) for _ in range(600)), "MeshError", ["not a gmsh MSH file"])
    case("empty_file.msh", b"", "MeshError", ["empty file"])
    # --- VTK legacy
    case("vtk_negative_index.vtk", vtk_legacy(P, [("tetra", T[0]), ("tetra", (1, 2, -1, 4))]),
         "MeshError", ["tet 1", "VTK cell 1", "index -1"])
    case("vtk_inf_coordinate.vtk", vtk_legacy(moved(4, (1.0, inf, 1.0)), cells_of(T)),
         "MeshError", ["node 4", "non-finite"])
    case("vtk_empty_no_cells.vtk", vtk_legacy(P, []), "MeshError", ["no cells"])
    case("vtk_tets_and_hexahedra.vtk",
         vtk_legacy(HEX_P + [(0.5, 0.5, 2.0)], [("hexahedron", list(range(8))), ("tetra", (4, 5, 6, 8))]),
         "MeshError", ["'hexahedron'", "not tetrahedra"])
    case("vtk_garbage.vtk", bytes(rnd.randrange(256) for _ in range(800)), "MeshError", ["cannot read as VTK"])
    case("vtk_wrong_header.vtk", vtk_legacy(P, cells_of(T), header="# vtk DataFile Version 4.2").replace(
        "DATASET UNSTRUCTURED_GRID", "DATASET STRUCTURED_POINTS"), "MeshError", ["cannot read as VTK"],
        note="declares a structured dataset")
    # --- VTK XML
    case("vtu_unused_node.vtu", vtu(P + [(5.0, 5.0, 5.0)], cells_of(T)),
         "MeshError", ["node 5", "used by no tetrahedron"])
    case("vtu_index_out_of_range.vtu", vtu(P, [("tetra", T[0]), ("tetra", (1, 2, 3, 5))]),
         "MeshError", ["tet 1", "VTU cell 1", "index 5", "out of range"])
    case("vtu_no_points.vtu", vtu([], []), "MeshError", ["no points"])
    case("vtu_only_hexahedra.vtu", vtu(HEX_P, [("hexahedron", list(range(8)))]),
         "MeshError", ["'hexahedron'"])
    fv = vtu(P, cells_of(T))
    case("vtu_truncated.vtu", fv[: fv.index("<Cells>") + 40], "MeshError", ["cannot read as VTU"])
    # --- TetGen
    case("tetgen_missing_node.ele", tetgen_ele(T), "MeshError", ["tetgen_missing_node.node", "missing"])
    case("tetgen_index_out_of_range.ele", tetgen_ele([T[0], (1, 2, 3, 7)]),
         "MeshError", ["TetGen element 1", "node index 7", "out of range"])
    case("tetgen_index_out_of_range.node", tetgen_node(P), None, note="companion of the .ele above")
    case("tetgen_negative_index.ele", tetgen_ele([(1, 2, 3, 4), (2, 3, -1, 5)], base=1),
         "MeshError", ["TetGen element 2", "node index -1"])
    case("tetgen_negative_index.node", tetgen_node(P, base=1), None, note="companion (numbered from 1)")
    case("tetgen_truncated.node", tetgen_node(P[:3], count=5), "MeshError", ["end of file", "5 points"])
    case("tetgen_truncated.ele", tetgen_ele(T), None, note="companion of the .node above")
    case("tetgen_nan_coordinate.node", tetgen_node(moved(3, (0.0, 0.0, nan))),
         "MeshError", ["node 3", "TetGen point 3", "non-finite"])
    case("tetgen_nan_coordinate.ele", tetgen_ele(T), None, note="companion of the .node above")
    # --- other
    case("unknown_format.stl", "solid x\nendsolid x\n", "MeshError", ["unsupported mesh format"])


def write_npz():
    import numpy as np
    path = os.path.join(HERE, "npz_missing_tets.npz")
    np.savez(path, points=np.array(P))
    return "npz_missing_tets.npz"


def main():
    build()
    lines = ["# Expected outcome of palpate.load_mesh for each file of this folder (made by make_corpus.py).",
             "# error: exception class name in palpate; warning: the file must load with this warning class;",
             "# contains: substrings of the message (the file's own name is always required too).", ""]
    for name, content, exp in CASES:
        if content is not None:
            write_case(HERE, name, content)
        if exp["error"] is None and exp["warning"] is None:
            continue
        lines += entry(name, exp)
    npz = write_npz()
    lines += [f'["{npz}"]', 'error = "MeshError"', 'contains = ["missing array", "tets"]', ""]
    write_expected(HERE, lines)

if __name__ == "__main__":
    main()
