"""Mesh input through meshio (issue 16, item 9): gmsh physical groups, Medit references and
Abaqus sets come back as named node / tet sets matching load_mesh's numbering; .mesh and .inp load.

What a wrong implementation would do: drop the groups, number the sets in meshio's block order
instead of palpate's tet order, or leave out the nodes of a group's lower-dimensional elements (a
clamped face given as triangles): each is compared against the sets written here."""
import meshio
import numpy as np
import pytest

import palpate


@pytest.fixture
def bar():
    m = palpate.box_mesh(size=(0.1, 0.02, 0.02), cells=(4, 1, 1))
    pts, tets = m.points, m.tets
    faces = np.array([t[f] for t in tets for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3])
                      if np.all(pts[t[f], 0] == 0.0)])
    left = np.flatnonzero(pts[tets].mean(axis=1)[:, 0] < 0.05)
    return pts, tets, faces, left


def test_gmsh_physical_groups_round_trip(tmp_path, bar):
    pts, tets, faces, left = bar
    phys = np.where(np.isin(np.arange(len(tets)), left), 2, 3)
    mesh = meshio.Mesh(pts, [("triangle", faces), ("tetra", tets)],
                       cell_data={"gmsh:physical": [np.full(len(faces), 1), phys],
                                  "gmsh:geometrical": [np.full(len(faces), 1), np.full(len(tets), 1)]},
                       field_data={"clamp": np.array([1, 2]), "left": np.array([2, 3])})   # tag 3 unnamed
    path = tmp_path / "bar.msh"
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    loaded = palpate.load_mesh(path)
    np.testing.assert_array_equal(loaded.tets, tets)
    nodes, tet_sets = palpate.read_mesh_sets(path)
    np.testing.assert_array_equal(nodes["clamp"], np.flatnonzero(pts[:, 0] == 0.0))
    np.testing.assert_array_equal(tet_sets["left"], left)
    np.testing.assert_array_equal(tet_sets["physical 3"], np.setdiff1d(np.arange(len(tets)), left))
    np.testing.assert_array_equal(nodes["left"], np.unique(tets[left]))
    assert "clamp" not in tet_sets   # a face group has nodes, no tets
    # The sets drive a body: clamp the group, load the rest.
    body = palpate.Body(loaded, palpate.Material(young=3e4, poisson=0.4), fixed=nodes["clamp"])
    assert np.array_equal(body.fixed, nodes["clamp"])


def test_medit_and_abaqus_load_with_their_sets(tmp_path, bar):
    pts, tets, _, left = bar
    ref = np.where(np.isin(np.arange(len(tets)), left), 1, 2)
    meshio.write(tmp_path / "bar.mesh", meshio.Mesh(pts, [("tetra", tets)], cell_data={"medit:ref": [ref]}))
    m = palpate.load_mesh(tmp_path / "bar.mesh")
    np.testing.assert_allclose(m.points, pts)
    np.testing.assert_array_equal(m.tets, tets)
    _, tet_sets = palpate.read_mesh_sets(tmp_path / "bar.mesh")
    np.testing.assert_array_equal(tet_sets["ref 1"], left)
    clamp = np.flatnonzero(pts[:, 0] == 0.0)
    meshio.write(tmp_path / "bar.inp", meshio.Mesh(pts, [("tetra", tets)], point_sets={"CLAMP": clamp},
                                                   cell_sets={"LEFT": [left]}))
    m = palpate.load_mesh(tmp_path / "bar.inp")
    np.testing.assert_array_equal(m.tets, tets)
    nodes, tet_sets = palpate.read_mesh_sets(tmp_path / "bar.inp")
    np.testing.assert_array_equal(nodes["CLAMP"], clamp)
    np.testing.assert_array_equal(tet_sets["LEFT"], left)


def test_sets_of_an_unsupported_format(tmp_path):
    with pytest.raises(palpate.MeshError, match="named sets"):
        palpate.read_mesh_sets(tmp_path / "x.npz")


def test_scene_fixes_and_loads_named_sets(tmp_path, bar):
    from palpate.scene import load_scene, run_scene

    pts, tets, faces, _ = bar
    tip_faces = np.array([t[f] for t in tets for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3])
                          if np.all(pts[t[f], 0] == 0.1)])
    mesh = meshio.Mesh(pts, [("triangle", faces), ("triangle", tip_faces), ("tetra", tets)],
                       cell_data={"gmsh:physical": [np.full(len(faces), 1), np.full(len(tip_faces), 2),
                                                    np.full(len(tets), 3)],
                                  "gmsh:geometrical": [np.full(len(faces), 1), np.full(len(tip_faces), 2),
                                                       np.full(len(tets), 3)]},
                       field_data={"clamp": np.array([1, 2]), "tip": np.array([2, 2]), "bar": np.array([3, 3])})
    meshio.write(tmp_path / "bar.msh", mesh, file_format="gmsh22", binary=False)
    (tmp_path / "s.toml").write_text(
        '[mesh]\nfile = "bar.msh"\n[material]\nyoung = 3e4\npoisson = 0.4\n[fixed]\nset = "clamp"\n'
        '[[loads]]\nset = "tip"\nforce = [0.0, 0.0, -0.01]\n[run]\nsteps = 5\n')
    scene = load_scene(tmp_path / "s.toml")
    np.testing.assert_array_equal(scene.body.fixed, np.flatnonzero(pts[:, 0] == 0.0))
    np.testing.assert_array_equal(np.sort(scene.loads[0].nodes), np.flatnonzero(pts[:, 0] == 0.1))
    run_scene(scene, write=False, log=lambda *a: None)
    (tmp_path / "bad.toml").write_text(
        '[mesh]\nfile = "bar.msh"\n[material]\nyoung = 3e4\npoisson = 0.4\n[fixed]\nset = "nope"\n')
    with pytest.raises(Exception, match="no node set 'nope'"):
        load_scene(tmp_path / "bad.toml")
