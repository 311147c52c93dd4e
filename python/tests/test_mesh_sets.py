"""Mesh input through meshio (issue 16, item 9): gmsh physical groups, Medit references and
Abaqus sets come back as named node / tet sets matching load_mesh's numbering; .mesh and .inp load.

What a wrong implementation would do: drop the groups, number the sets in meshio's block order
instead of palpate's tet order, or leave out the nodes of a group's lower-dimensional elements (a
clamped face given as triangles): each is compared against the sets written here."""
import warnings

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


# Medit sections meshio's reader does not keep (issue 35): it read past some of them with a line on
# stderr ("Meshio doesn't know keyword RequiredVertices. Skipping."), past others without a word,
# and skipped line by line where it should skip entry by entry. Vertices, cells and references
# must never go that way.
_MEDIT_HEAD = ("MeshVersionFormatted 2\nDimension 3\nVertices\n5\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n1 1 1 2\n")
_MEDIT_CELLS = "Triangles\n1\n1 2 3 4\nTetrahedra\n2\n1 2 3 4 7\n5 2 4 3 8\n"


def _medit(tmp_path, name, middle="", cells=_MEDIT_CELLS):
    path = tmp_path / name
    path.write_text(_MEDIT_HEAD + middle + cells + "End\n")
    return path


def test_medit_sections_without_geometry_are_named_in_a_warning(tmp_path, capfd):
    """Corners, Ridges, RequiredVertices, Normals, Tangents, TangentAtVertices, Identifier hold no
    vertex, cell or reference: the mesh and its sets are those of the file without them, and one
    MeshWarning names them with their lines; nothing is printed on stderr."""
    plain = _medit(tmp_path, "plain.mesh")
    extra = ("Corners\n2\n1 2\nRidges\n1\n1\nRequiredVertices\n2\n1\n2\nNormals\n1\n0 0 1\nTangents\n1\n1 0 0\n"
             "TangentAtVertices\n1\n1 1\nIdentifier\n\"bar\"\n")
    full = _medit(tmp_path, "full.mesh", extra)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m0 = palpate.load_mesh(plain)
        sets0 = palpate.read_mesh_sets(plain)
    with pytest.warns(palpate.MeshWarning) as rec:
        m1 = palpate.load_mesh(full)
    assert [str(w.message) for w in rec] == [
        "full.mesh: Medit sections read past, not kept: Corners (2 entries, line 10), Ridges (1 entry, line 13), "
        "RequiredVertices (2 entries, line 16), Normals (1 entry, line 20), Tangents (1 entry, line 23), "
        "TangentAtVertices (1 entry, line 26), Identifier (line 29); they hold no vertex, cell or reference "
        "(feature marks, normals, tangents, geometry links), so the mesh and its sets are read in full"]
    np.testing.assert_array_equal(m1.points, m0.points)
    np.testing.assert_array_equal(m1.tets, m0.tets)
    with pytest.warns(palpate.MeshWarning, match="Medit sections read past"):
        sets1 = palpate.read_mesh_sets(full)
    assert sets0[1].keys() == {"ref 7", "ref 8"}
    for a, b in zip(sets0, sets1):
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    np.testing.assert_array_equal(sets1[0]["ref 4"], [0, 1, 2])   # the triangle's reference
    assert "Skipping" not in capfd.readouterr().err


def test_medit_section_meshio_would_skip_into_the_next_is_refused(tmp_path, capfd):
    """RequiredVertices with its 4 entries on one line: meshio skips 4 *lines*, the Triangles
    section with them, and loaded the mesh without it (only "Skipping." on stderr)."""
    path = _medit(tmp_path, "req.mesh", "RequiredVertices\n4\n1 2 3 4\n")
    for call in (palpate.load_mesh, palpate.read_mesh_sets):
        with pytest.raises(palpate.MeshError, match=r"req.mesh: line 12: RequiredVertices entries must be one a line "
                           r"\(1 number\), got 4: meshio reads past RequiredVertices by skipping 4 lines, and would "
                           r"skip into the next section and drop it"):
            call(path)
    assert "Skipping" not in capfd.readouterr().err


@pytest.mark.parametrize("middle, cells, message", [
    # A keyword meshio does not know: its reader stops there (a solution field, a required edge).
    ("SolAtVertices\n1\n1 1\n0.5\n", _MEDIT_CELLS,
     r"bad.mesh: line 10: Medit keyword 'SolAtVertices' is not one palpate can read past \(meshio's Medit reader "
     r"stops at it\): palpate reads Vertices, Edges, .*; remove the SolAtVertices section to load the mesh"),
    # A count that does not match the data: meshio reads numbers by count across lines.
    ("", "Triangles\n1\n1 2 3 4\nTetrahedra\n3\n1 2 3 4 7\n5 2 4 3 8\n",
     r"bad.mesh: line 14: Tetrahedra announces 3 entries of 5 numbers \(15\), lines 15..16 hold 10"),
    ("", "Triangles\n1\n1 2 3\nTetrahedra\n2\n1 2 3 4 7\n5 2 4 3 8\n",
     r"bad.mesh: line 11: Triangles announces 1 entry of 4 numbers \(4\), lines 12..12 hold 3"),
    ("Corners\n3\n1 2\n", _MEDIT_CELLS, r"bad.mesh: line 11: Corners announces 3 entries of 1 number \(3\)"),
    # Identifier with its value on its own line: meshio skips the next line, here a keyword.
    ("Identifier \"bar\"\n", _MEDIT_CELLS,
     r"bad.mesh: line 11: Identifier at line 10 has no value line: meshio skips the line after it, here the "
     r"keyword 'Triangles'"),
])
def test_medit_keywords_and_counts_that_would_misread_are_refused(tmp_path, middle, cells, message):
    path = _medit(tmp_path, "bad.mesh", middle, cells)
    with pytest.raises(palpate.MeshError, match=message):
        palpate.load_mesh(path)


def test_gmsh22_partition_tags_warn_in_read_mesh_sets(tmp_path, capfd):
    """Element tags after the physical and the geometrical one (partitions): meshio drops them
    with a line on stderr; read_mesh_sets says so with a MeshWarning, and keeps the groups."""
    text = ("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"
            "$Elements\n1\n1 4 4 7 1 2 3 1 2 3 4\n$EndElements\n")
    (tmp_path / "part.msh").write_text(text)
    with pytest.warns(palpate.MeshWarning, match=r"part.msh: meshio: The file contains tag data that couldn't be processed"):
        nodes, tets = palpate.read_mesh_sets(tmp_path / "part.msh")
    np.testing.assert_array_equal(tets["physical 7"], [0])
    assert "tag data" not in capfd.readouterr().err
