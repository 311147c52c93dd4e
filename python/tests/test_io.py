"""Mesh files: the shared bench meshes in every format, units, TetGen, mixed cell types, VTU output."""
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
