"""Mesh files: the shared bench meshes in every format, units, TetGen, mixed cell types, VTU output."""
import struct
import warnings

import meshio
import numpy as np
import pytest

import palpate
from palpate.io import VtuSeries, read_pvd

from conftest import needs_shared

BENCH = {"190": (75, 190), "1350": (436, 1298), "10k": (2734, 9818), "50k": (11338, 48000)}


@needs_shared
@pytest.mark.parametrize("name", list(BENCH))
@pytest.mark.parametrize("ext", [".msh", ".vtu", ".npz"])
def test_shared_bench_meshes_load(shared, name, ext):
    path = shared / "bench" / "meshes" / f"lv_{name}{ext}"
    if not path.exists():
        pytest.skip(f"{path.name} not in the shared folder")
    with warnings.catch_warnings():
        warnings.simplefilter("error", palpate.MeshWarning)   # the bench meshes need no repair
        m = palpate.load_mesh(path, unit="cm")
    nodes, tets = BENCH[name]
    assert (m.n_nodes, m.n_tets) == (nodes, tets)
    p = m.points
    assert p[:, 2].min() == pytest.approx(0.0, abs=1e-9)
    assert p[:, 2].max() == pytest.approx(0.042, rel=1e-3)   # apex at 4.2 cm
    assert m.volume > 0


@needs_shared
def test_formats_agree_and_units_scale(shared):
    base = shared / "bench" / "meshes" / "lv_190"
    a = palpate.load_mesh(f"{base}.msh", unit="cm")
    b = palpate.load_mesh(f"{base}.vtu", unit="cm")
    c = palpate.load_mesh(f"{base}.npz", unit="cm")
    np.testing.assert_allclose(a.points, b.points)
    np.testing.assert_allclose(a.points, c.points)
    np.testing.assert_array_equal(a.tets, c.tets)
    mm = palpate.load_mesh(f"{base}.msh", unit="mm")
    m = palpate.load_mesh(f"{base}.msh")  # default: metres
    np.testing.assert_allclose(mm.points * 10, a.points)
    np.testing.assert_allclose(m.points / 100, a.points)


def test_bad_unit(tmp_path):
    with pytest.raises(ValueError, match="unit must be one of"):
        palpate.load_mesh(tmp_path / "x.msh", unit="inch")


def _two_tets():
    p = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    return p, np.array([[0, 1, 2, 3], [1, 2, 3, 4]])


@pytest.mark.parametrize("fmt, ext", [("gmsh22", ".msh"), ("gmsh", ".msh"), ("vtk", ".vtk"), ("vtu", ".vtu")])
@pytest.mark.parametrize("binary", [False, True])
def test_meshio_written_files_with_boundary_cells_load(tmp_path, fmt, ext, binary):
    """Tets plus lower-dimensional cells (gmsh boundary tags): the extra cells are ignored."""
    p, t = _two_tets()
    cells = [("triangle", np.array([[0, 1, 2]])), ("tetra", t), ("line", np.array([[0, 1]])),
             ("vertex", np.array([[4]]))]
    if fmt == "gmsh" and binary:
        cells = [("tetra", t)]  # meshio cannot read back its own binary MSH 4.1 with several cell types
    path = tmp_path / f"m{ext}"
    kw = {} if fmt == "vtu" else {"binary": binary}
    # gmsh 4 needs each node's entity (dim, tag) to write several cell types.
    pd, cd = {}, {}
    if fmt == "gmsh":
        pd = {"gmsh:dim_tags": np.tile([3, 1], (len(p), 1))}
        cd = {"gmsh:geometrical": [np.ones(len(c), int) for _, c in cells],
              "gmsh:physical": [np.ones(len(c), int) for _, c in cells]}
    meshio.write(path, meshio.Mesh(p, cells, point_data=pd, cell_data=cd), file_format=fmt, **kw)
    m = palpate.load_mesh(path, unit="mm")
    np.testing.assert_allclose(m.points, p * 1e-3)
    np.testing.assert_array_equal(m.tets, t)


def test_gmsh_node_tags_need_not_be_contiguous(tmp_path):
    text = "\n".join(["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Comments", "anything", "$EndComments",
                      "$Nodes", "4", "10 0 0 0", "20 1 0 0", "30 0 1 0", "40 0 0 1", "$EndNodes",
                      "$Elements", "2", "1 15 2 0 1 10", "7 4 2 0 1 10 20 30 40", "$EndElements", ""])
    (tmp_path / "tags.msh").write_text(text)
    m = palpate.load_mesh(tmp_path / "tags.msh")
    np.testing.assert_array_equal(m.tets, [[0, 1, 2, 3]])


# gmsh MSH 4.0 (issue 35): read by palpate, as 2.2 and 4.1 are. The same mesh written by hand in
# 2.2, 4.1 and 4.0 (gmsh 4.0 writes its version as "4"): node tags 10..50 in three entity blocks,
# one of them with parametric coordinates (u v after x y z in 4.0), a boundary triangle and two tets.
_XYZ = {10: (0, 0, 0), 20: (1, 0, 0), 30: (0, 1, 0), 40: (0, 0, 1), 50: (1, 1, 1)}
_ELEMS = [(1, 2, (10, 20, 30)), (11, 4, (10, 20, 30, 40)), (12, 4, (50, 20, 40, 30))]


def _xyz(t):
    return " ".join(str(float(v)) for v in _XYZ[t])


def _msh22():
    return ("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n5\n" + "".join(f"{t} {_xyz(t)}\n" for t in _XYZ)
            + "$EndNodes\n$Elements\n3\n" + "".join(f"{e} {ty} 2 0 1 {' '.join(map(str, n))}\n" for e, ty, n in _ELEMS)
            + "$EndElements\n")


def _msh41():
    return ("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n3 5 10 50\n"
            f"0 10 0 1\n10\n{_xyz(10)}\n2 1 1 2\n20\n30\n{_xyz(20)} 0.5 0.25\n{_xyz(30)} 0.75 0.5\n"
            f"3 1 0 2\n40\n50\n{_xyz(40)}\n{_xyz(50)}\n$EndNodes\n"
            "$Elements\n2 3 1 12\n2 1 2 1\n1 10 20 30\n3 1 4 2\n11 10 20 30 40\n12 50 20 40 30\n$EndElements\n")


def _msh40(version="4", tets=((10, 20, 30, 40), (50, 20, 40, 30))):
    return (f"$MeshFormat\n{version} 0 8\n$EndMeshFormat\n$Entities\n1 0 0 1\n10 0 0 0 0 0 0 0\n"
            "1 0 0 0 1 1 1 0 0\n$EndEntities\n$Nodes\n3 5\n"
            f"10 0 0 1\n10 {_xyz(10)}\n1 2 1 2\n20 {_xyz(20)} 0.5 0.25\n30 {_xyz(30)} 0.75 0.5\n"
            f"1 3 0 2\n40 {_xyz(40)}\n50 {_xyz(50)}\n$EndNodes\n"
            "$Elements\n2 3\n1 2 2 1\n1 10 20 30\n1 3 4 2\n"
            + "".join(f"{11 + k} {' '.join(map(str, t))}\n" for k, t in enumerate(tets)) + "$EndElements\n")


def _msh40_binary(tets=((10, 20, 30, 40), (50, 20, 40, 30))):
    """The same mesh in binary MSH 4.0: counts unsigned long (8 bytes), tags int, the parametric
    block's nodes with u v after x y z."""
    out = b"$MeshFormat\n4 1 8\n" + struct.pack("<i", 1) + b"\n$EndMeshFormat\n$Nodes\n" + struct.pack("<2Q", 3, 5)
    out += struct.pack("<3iQ", 10, 0, 0, 1) + struct.pack("<i3d", 10, *_XYZ[10])
    out += struct.pack("<3iQ", 1, 2, 1, 2) + struct.pack("<i5d", 20, *_XYZ[20], 0.5, 0.25) \
        + struct.pack("<i5d", 30, *_XYZ[30], 0.75, 0.5)
    out += struct.pack("<3iQ", 1, 3, 0, 2) + struct.pack("<i3d", 40, *_XYZ[40]) + struct.pack("<i3d", 50, *_XYZ[50])
    out += b"\n$EndNodes\n$Elements\n" + struct.pack("<2Q", 2, 3)
    out += struct.pack("<3iQ", 1, 2, 2, 1) + struct.pack("<4i", 1, 10, 20, 30)
    out += struct.pack("<3iQ", 1, 3, 4, len(tets)) + b"".join(struct.pack("<5i", 11 + k, *t) for k, t in enumerate(tets))
    return out + b"\n$EndElements\n"


def test_gmsh40_reads_as_22_and_41(tmp_path):
    """MSH 4.0, ASCII (version "4" and "4.0") and binary, gives the mesh that 2.2 and 4.1 give:
    same points, tets and node names. meshio read 4.0 before (and took "4" for 4.1)."""
    files = {"m22.msh": _msh22(), "m41.msh": _msh41(), "m40.msh": _msh40(), "m400.msh": _msh40("4.0"),
             "m40b.msh": _msh40_binary()}
    got = {}
    for name, data in files.items():
        (tmp_path / name).write_bytes(data if isinstance(data, bytes) else data.encode())
        with warnings.catch_warnings():
            warnings.simplefilter("error")   # no repair, no warning
            got[name] = palpate.io.read_mesh_arrays(tmp_path / name)
            mesh = palpate.load_mesh(tmp_path / name)
        assert mesh.n_tets == 2 and mesh.volume == pytest.approx(0.5)
    points, tets, _, node_labels = got["m22.msh"]
    np.testing.assert_array_equal(points, [_XYZ[t] for t in _XYZ])
    np.testing.assert_array_equal(tets, [[0, 1, 2, 3], [4, 1, 3, 2]])
    for name, (p, t, labels, nl) in got.items():
        np.testing.assert_array_equal(p, points, err_msg=name)
        np.testing.assert_array_equal(t, tets, err_msg=name)
        assert nl == node_labels == ["gmsh node 10", "gmsh node 20", "gmsh node 30", "gmsh node 40", "gmsh node 50"]
        assert labels[1].startswith("gmsh element 12, "), (name, labels)
    assert got["m40.msh"][2] == ["gmsh element 11, line 25", "gmsh element 12, line 26"]


def test_gmsh40_written_by_meshio_loads(tmp_path):
    p, t = _two_tets()
    for binary in (False, True):
        path = tmp_path / f"m{int(binary)}.msh"
        meshio.gmsh.write(path, meshio.Mesh(p, [("tetra", t)]), fmt_version="4.0", binary=binary)
        m = palpate.load_mesh(path)
        np.testing.assert_allclose(m.points, p)
        np.testing.assert_array_equal(m.tets, t)
    # Under gmsh 4.0's own "4" header, the named sets are read by meshio's 4.0 reader too
    # (meshio.gmsh.read takes "4" for 4.1, and failed on the file).
    path = tmp_path / "v4.msh"
    path.write_bytes((tmp_path / "m0.msh").read_bytes().replace(b"4.0 0 8", b"4 0 8"))
    np.testing.assert_array_equal(palpate.load_mesh(path).tets, t)
    assert palpate.read_mesh_sets(path) == ({}, {})


@pytest.mark.parametrize("binary", [False, True])
def test_gmsh40_undefined_node_tag_is_an_error(tmp_path, binary):
    """An element's node tag that $Nodes does not define (0): meshio's 4.0 reader mapped it by
    index arithmetic (tag 0 -> -1, the last node) and loaded another tet."""
    tets = ((10, 20, 30, 40), (0, 20, 40, 30))
    path = tmp_path / "tag0.msh"
    path.write_bytes(_msh40_binary(tets) if binary else _msh40(tets=tets).encode())
    where = "byte 406" if binary else "line 26"   # where element 12 starts
    with pytest.raises(palpate.MeshError, match=rf"tag0.msh: {where}: gmsh element 12 \(tetra\) references node tag 0, "
                       r"which is not defined in \$Nodes \(5 nodes, tags 10..50\)"):
        palpate.load_mesh(path)


def test_gmsh40_refusals_name_the_file_and_the_fix(tmp_path):
    # A 4.1 layout under a "4" header: gmsh reads "4" as 4.0, and so does palpate.
    path = tmp_path / "mixed.msh"
    path.write_text(_msh41().replace("4.1 0 8", "4 0 8"))
    with pytest.raises(palpate.MeshError, match=r"mixed.msh: line 5: expected 'numEntityBlocks numNodes' \(MSH 4.0\), "
                       r"got 4 numbers \(4 numbers are an MSH 4.1 header, but \$MeshFormat says 4.0\)"):
        palpate.load_mesh(path)
    # Parametric node without its u v.
    path = tmp_path / "param.msh"
    path.write_text(_msh40().replace(" 0.5 0.25\n", "\n"))
    with pytest.raises(palpate.MeshError, match=r"param.msh: line 14: expected 'tag x y z u v' \(MSH 4.0, entity "
                       r"dimension 2, parametric 1\)"):
        palpate.load_mesh(path)
    # Binary 4.0 with 4-byte unsigned long counts (gmsh 4.0 on Windows or a 32-bit system).
    import corpus_cases

    path = tmp_path / "win.msh"
    path.write_bytes(corpus_cases._gmsh40_binary(corpus_cases._TWO_TETS, [(1, 2, 3, 4)], ulong="I"))
    with pytest.raises(palpate.MeshError, match=r"win.msh: byte 45: the \$Nodes header announces .* 4-byte unsigned "
                       r"long counts, as gmsh 4.0 on Windows or a 32-bit system does: palpate reads 8-byte ones; "
                       r"convert with gmsh IN.msh -format msh41 -save -o OUT.msh \(or -format msh22\)"):
        palpate.load_mesh(path)
    # A version palpate does not know.
    path = tmp_path / "v42.msh"
    path.write_text(_msh41().replace("4.1 0 8", "4.2 0 8"))
    with pytest.raises(palpate.MeshError, match=r"v42.msh: line 2: unsupported gmsh MSH version '4.2': palpate reads "
                       r"MSH 2.2, 4.0 and 4.1; convert with gmsh IN.msh -format msh41 -save -o OUT.msh"):
        palpate.load_mesh(path)


def test_tetgen_round_trip(tmp_path):
    p, t = _two_tets()
    (tmp_path / "m.node").write_text("# comment\n5  3  0  0\n" + "".join(
        f"{i + 1}\t{x} {y} {z}  # node\n" for i, (x, y, z) in enumerate(p)))
    (tmp_path / "m.ele").write_text("2 4 1\n" + "".join(
        f"{k + 1} {' '.join(str(i + 1) for i in tet)} 7\n" for k, tet in enumerate(t)))
    for name in ("m.node", "m.ele"):
        m = palpate.load_mesh(tmp_path / name)
        np.testing.assert_array_equal(m.tets, t)
        np.testing.assert_allclose(m.points, p)


def test_error_attributes_name_the_tet(tmp_path):
    p, t = _two_tets()
    p[4] = p[1]
    meshio.write(tmp_path / "flat.vtu", meshio.Mesh(p, [("tetra", t)]))
    with pytest.raises(palpate.MeshError) as e:
        palpate.load_mesh(tmp_path / "flat.vtu")
    assert e.value.tet == 1 and e.value.node is None
    assert "flat.vtu: tet 1 (VTU cell 1): degenerate" in str(e.value)


def test_vtu_series(tmp_path):
    p, t = _two_tets()
    s = VtuSeries(tmp_path / "o", t)
    for k in range(3):
        s.write(0.1 * k, p + k, np.full_like(p, k), np.zeros_like(p))
    frames = read_pvd(s.pvd_path)
    assert [round(tt, 6) for tt, _ in frames] == [0.0, 0.1, 0.2]
    m = meshio.read(frames[-1][1])
    np.testing.assert_allclose(m.points, p + 2)
    np.testing.assert_allclose(m.point_data["displacement"], 2.0)
    assert m.point_data["velocity"].shape == (5, 3)
    # A new series in the same folder replaces the old frames.
    s2 = VtuSeries(tmp_path / "o", t)
    s2.write(0.0, p, p * 0, p * 0)
    assert len(list((tmp_path / "o").glob("frame_*.vtu"))) == 1
