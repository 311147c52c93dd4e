"""Mesh input through meshio (issue 16, item 9): gmsh physical groups, Medit references and
Abaqus sets come back as named node / tet sets matching load_mesh's numbering; .mesh and .inp load.

What a wrong implementation would do: drop the groups, number the sets in meshio's block order
instead of palpate's tet order, or leave out the nodes of a group's lower-dimensional elements (a
clamped face given as triangles): each is compared against the sets written here."""
import struct
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



# The reader leftovers of issue 35: Medit vertices in double precision and their references as node
# sets, the physical groups of an MSH 4.0 file with parametric nodes, and the Abaqus keywords
# meshio skips without a word.

def test_medit_version_1_vertices_keep_double_precision(tmp_path):
    """MeshVersionFormatted 1 (as mmg and TetGen write): meshio reads the vertex lines as float32,
    0.1234567891 came back as 0.12345679104328156 (7 digits) and a reference 16777217 as
    16777216. palpate parses them from the text in double precision, whatever the version."""
    xyz = ["0.1234567891 0.0000000001 0", "1.0000000003 0 0", "0 0.9876543219 0", "0 0 1.2345678912345"]
    text = ("MeshVersionFormatted 1\nDimension 3\nVertices\n4\n" + "".join(f"{v} {r}\n" for v, r in zip(
        xyz, (0, 16777217, 0, 0))) + "Tetrahedra\n1\n1 2 3 4 1\nEnd\n")
    want = np.array([[float(t) for t in v.split()] for v in xyz])
    for version in ("1", "2"):
        path = tmp_path / f"v{version}.mesh"
        path.write_text(text.replace("MeshVersionFormatted 1", f"MeshVersionFormatted {version}"))
        np.testing.assert_array_equal(palpate.load_mesh(path).points, want, err_msg=version)
        np.testing.assert_array_equal(palpate.io.read_mesh_arrays(path)[0], want)
        nodes, _ = palpate.read_mesh_sets(path)
        np.testing.assert_array_equal(nodes["vertex ref 16777217"], [1])


def test_medit_vertex_references_make_node_sets(tmp_path):
    """The Vertices section's references (its last column) are node sets "vertex ref <k>", apart
    from the element references' "ref <k>" (Medit numbers the two independently); 0 is no
    reference. They made no set before."""
    path = _medit(tmp_path, "v.mesh")   # vertex references 1 1 1 1 2; triangle ref 4, tets 7 and 8
    nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"vertex ref 1", "vertex ref 2", "ref 4", "ref 7", "ref 8"}
    np.testing.assert_array_equal(nodes["vertex ref 1"], [0, 1, 2, 3])
    np.testing.assert_array_equal(nodes["vertex ref 2"], [4])
    np.testing.assert_array_equal(nodes["ref 4"], [0, 1, 2])   # the triangle's, as before
    assert set(tets) == {"ref 7", "ref 8"}
    zero = tmp_path / "zero.mesh"
    zero.write_text(path.read_text().replace("0 0 0 1\n", "0 0 0 0\n"))
    np.testing.assert_array_equal(palpate.read_mesh_sets(zero)[0]["vertex ref 1"], [1, 2, 3])
    bad = tmp_path / "frac.mesh"
    bad.write_text(path.read_text().replace("1 1 1 2\n", "1 1 1 2.5\n"))
    with pytest.raises(palpate.MeshError, match=r"frac.mesh: Vertices: vertex 5 \(as Medit numbers them, from 1\) has "
                       r"reference '2.5': a reference is a whole number"):
        palpate.load_mesh(bad)


# An MSH 4.0 mesh (gmsh 4.0 writes its version "4") whose boundary triangle's nodes lie on a
# parametric surface (u v after x y z), with its physical groups: "clamp" (the triangle, on
# surface 5) and "body" (the two tets, in volume 1).
_MSH40_PARAMETRIC = """$MeshFormat
4 0 8
$EndMeshFormat
$PhysicalNames
2
2 1 "clamp"
3 2 "body"
$EndPhysicalNames
$Entities
0 0 1 1
5 0 0 0 1 1 0 1 1 0
1 0 0 0 1 1 1 1 2 1 5
$EndEntities
$Nodes
2 5
5 2 1 3
10 0 0 0 0 0
20 1 0 0 1 0
30 0 1 0 0 1
1 3 0 2
40 0 0 1
50 1 1 1
$EndNodes
$Elements
2 3
5 2 2 1
1 10 20 30
1 3 4 2
11 10 20 30 40
12 50 20 40 30
$EndElements
"""


def _msh40_parametric_binary(node_surface=5, element_surface=5):
    """The same file in binary MSH 4.0 (counts unsigned long, tags int, the surface's nodes with u v);
    ``node_surface``, ``element_surface``: the entity tag of the surface's node and element blocks."""
    out = b"$MeshFormat\n4 1 8\n" + struct.pack("<i", 1) + b"\n$EndMeshFormat\n"
    out += b'$PhysicalNames\n2\n2 1 "clamp"\n3 2 "body"\n$EndPhysicalNames\n'
    out += b"$Entities\n" + struct.pack("<4Q", 0, 0, 1, 1)
    out += struct.pack("<i6dQiQ", 5, 0, 0, 0, 1, 1, 0, 1, 1, 0)
    out += struct.pack("<i6dQiQi", 1, 0, 0, 0, 1, 1, 1, 1, 2, 1, 5)
    out += b"\n$EndEntities\n$Nodes\n" + struct.pack("<2Q", 2, 5) + struct.pack("<3iQ", node_surface, 2, 1, 3)
    for tag, xyz, uv in ((10, (0, 0, 0), (0, 0)), (20, (1, 0, 0), (1, 0)), (30, (0, 1, 0), (0, 1))):
        out += struct.pack("<i5d", tag, *xyz, *uv)
    out += struct.pack("<3iQ", 1, 3, 0, 2) + struct.pack("<i3d", 40, 0, 0, 1) + struct.pack("<i3d", 50, 1, 1, 1)
    out += b"\n$EndNodes\n$Elements\n" + struct.pack("<2Q", 2, 3)
    out += struct.pack("<3iQ", element_surface, 2, 2, 1) + struct.pack("<4i", 1, 10, 20, 30)
    out += struct.pack("<3iQ", 1, 3, 4, 2) + struct.pack("<5i", 11, 10, 20, 30, 40)
    out += struct.pack("<5i", 12, 50, 20, 40, 30)
    return out + b"\n$EndElements\n"


@pytest.mark.parametrize("binary", [False, True])
def test_gmsh40_parametric_nodes_sets_are_read(tmp_path, binary):
    """load_mesh read such a file; its sets were a MeshError (meshio's 4.0 node reader expects
    'tag x y z' and failed on the u v)."""
    path = tmp_path / "param.msh"
    path.write_bytes(_msh40_parametric_binary() if binary else _MSH40_PARAMETRIC.encode())
    np.testing.assert_array_equal(palpate.load_mesh(path).tets, [[0, 1, 2, 3], [4, 1, 3, 2]])
    nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"clamp", "body"} and set(tets) == {"body"}
    np.testing.assert_array_equal(nodes["clamp"], [0, 1, 2])
    np.testing.assert_array_equal(nodes["body"], [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(tets["body"], [0, 1])


# Abaqus: meshio's reader takes *NODE, *ELEMENT, *NSET and *ELSET and skips every other line
# without a word, whatever it does to the mesh.
_INP_NODES = "".join(f"{i + 1}, {x}, {y}, {z}\n" for i, (x, y, z) in enumerate(
    [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)]))
_INP_MESH = "*NODE\n" + _INP_NODES + "*ELEMENT, TYPE=C3D4, ELSET=ALL\n1, 1, 2, 3, 4\n2, 5, 2, 4, 3\n"


def _inp(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_abaqus_model_definitions_are_read_past_quietly(tmp_path):
    """What an exported model holds besides its mesh (heading, parts and one unplaced instance,
    materials, sections, steps, boundary conditions, loads, output, comments): no error, no
    warning, the mesh and its sets as written."""
    text = ("*HEADING\nA bar\n** exported\n*PART, NAME=P\n" + _INP_MESH + "*NSET, NSET=BASE\n1, 2, 3\n"
            "*SOLID SECTION, ELSET=ALL, MATERIAL=M\n,\n*END PART\n*ASSEMBLY, NAME=A\n*INSTANCE, NAME=I, PART=P\n"
            "*END INSTANCE\n*END ASSEMBLY\n*MATERIAL, NAME=M\n*DENSITY\n1000.\n*ELASTIC\n3e4, 0.4\n"
            "*TRANSFORM, NSET=BASE\n1., 0., 0., 0., 1., 0.\n*STEP\n*STATIC\n*BOUNDARY\nBASE, 1, 3\n"
            "*CLOAD\n5, 3, -0.1\n*OUTPUT, FIELD\n*NODE OUTPUT\nU\n*END STEP\n")
    path = _inp(tmp_path, "model.inp", text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = palpate.load_mesh(path)
        nodes, tets = palpate.read_mesh_sets(path)
    np.testing.assert_array_equal(m.tets, [[0, 1, 2, 3], [4, 1, 3, 2]])
    np.testing.assert_array_equal(nodes["BASE"], [0, 1, 2])
    np.testing.assert_array_equal(tets["ALL"], [0, 1])


def test_abaqus_comment_inside_a_block_keeps_the_rest(tmp_path, bar):
    """meshio's reader ended an *ELEMENT block at a comment line and skipped the lines after it as
    unknown keywords: the tets after the comment were lost (the mesh loaded smaller, or failed on
    a node no tet used). Comment lines are blanked before meshio reads."""
    pts, tets, _, _ = bar
    lines = [f"{k + 1}, " + ", ".join(str(i + 1) for i in t) for k, t in enumerate(tets)]
    lines.insert(len(lines) - 3, "** the last three")
    text = ("*NODE\n" + "".join(f"{i + 1}, {x!r}, {y!r}, {z!r}\n" for i, (x, y, z) in enumerate(pts.tolist()))
            + "*ELEMENT, TYPE=C3D4\n" + "\n".join(lines) + "\n")
    m = palpate.load_mesh(_inp(tmp_path, "c.inp", text))
    np.testing.assert_array_equal(m.tets, tets)


@pytest.mark.parametrize("text, message", [
    (_INP_MESH + "*ELGEN, ELSET=ALL\n1, 3, 1, 1\n",
     r"g.inp: line 10: Abaqus keyword \*ELGEN generates elements from a master element, which meshio's reader skips "
     r"without a word \(the mesh read would not be the model's\): palpate refuses it; write the elements it makes"),
    ("*NODE\n" + _INP_NODES + "*NGEN\n1, 5, 1\n*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n2, 5, 2, 4, 3\n",
     r"g.inp: line 7: Abaqus keyword \*NGEN generates nodes along a line or curve, which meshio's reader skips"),
    (_INP_MESH + "*NCOPY, OLD SET=A, NEW SET=B, CHANGE NUMBER=10, SHIFT\n0, 0, 1\n",
     r"line 10: .*\*NCOPY copies nodes"),
    (_INP_MESH + "*NFILL\nA, B, 4, 1\n", r"line 10: .*\*NFILL fills a region with nodes"),
    ("*SYSTEM\n0, 0, 0, 1, 0, 0\n" + _INP_MESH, r"line 1: .*\*SYSTEM sets a local coordinate system"),
    ("*PARAMETER\nx = 1.0\n" + _INP_MESH, r"line 1: .*\*PARAMETER defines parameters that later lines use"),
    (_INP_MESH + "*INCLUDE, INPUT=more.inp\n",
     r"line 10: Abaqus keyword \*INCLUDE reads lines from another file, which meshio's reader follows its own way"),
    (_INP_MESH.replace("*NODE\n", "*NODE, SYSTEM=C\n"),
     r"line 1: Abaqus keyword \*NODE gives its nodes in cylindrical coordinates \(SYSTEM=C\)"),
    (_INP_MESH.replace("*NODE\n", "*NODE, INPUT=nodes.txt\n"),
     r"line 1: Abaqus keyword \*NODE reads its data from the file 'nodes.txt' \(INPUT=\)"),
    ("*PART, NAME=P\n" + _INP_MESH + "*END PART\n*ASSEMBLY, NAME=A\n*INSTANCE, NAME=I, PART=P\n*END INSTANCE\n"
     "*NODE\n1, 0., 0., 2.\n*END ASSEMBLY\n",
     r"line 15: Abaqus keyword \*NODE opens a node block after \*END INSTANCE \(line 14\), outside the part whose "
     r"nodes begin at line 2: nodes of the assembly \(a reference point\) or of an instance number apart"),
    ("*PART, NAME=P\n" + _INP_MESH + "*END PART\n*ASSEMBLY, NAME=A\n*INSTANCE, NAME=I, PART=P\n0.5, 0., 0.\n"
     "*END INSTANCE\n*END ASSEMBLY\n",
     r"line 13: Abaqus keyword \*INSTANCE moves its part by a translation or rotation \(line 14: '0.5, 0., 0.'\)"),
    ("*PART, NAME=P\n" + _INP_MESH + "*END PART\n*ASSEMBLY, NAME=A\n*INSTANCE, NAME=I, PART=P\n*END INSTANCE\n"
     "*INSTANCE, NAME=J, PART=P\n*END INSTANCE\n*END ASSEMBLY\n",
     r"line 15: Abaqus keyword \*INSTANCE places a second instance \(the first at line 13\)"),
    (_INP_MESH + "*NSET, NSET=NODE\n1\n*BOUNDARY\nNODE, 1, 3\n",
     r"line 13: the data line 'NODE, 1, 3' of \*BOUNDARY begins with 'NODE', which meshio's Abaqus reader takes for "
     r"the keyword \*NODE"),
    (_INP_MESH.replace("*NODE\n", "* NODE\n"), r"line 1: Abaqus keyword \*NODE is written '\* NODE', which meshio's"),
])
def test_abaqus_keywords_that_change_the_mesh_are_refused(tmp_path, text, message):
    """Each of these loaded (or failed on an unrelated symptom) with meshio skipping the keyword:
    elements or nodes generated, copied or moved, a local or cylindrical coordinate system,
    parameters, an included file, a second node block that replaced the first, an instance moved
    or placed twice. Each is now a MeshError naming the file, the line and the keyword. (A second
    *NODE block of the same part, refused here before, is read: test_abaqus_node_blocks_of_a_part_are_one.)
    A *NODE block in the assembly (a reference point, numbered apart from the part's nodes) is
    refused, as before, with a message naming what it is."""
    path = _inp(tmp_path, "g.inp", text)
    for call in (palpate.load_mesh, palpate.read_mesh_sets):
        with pytest.raises(palpate.MeshError, match=message):
            call(path)


def test_abaqus_unknown_keyword_is_named_in_a_warning(tmp_path):
    path = _inp(tmp_path, "u.inp", "*HEADING\nbar\n" + _INP_MESH + "*HOURGLASS STIFFNESS\n1.0\n*FOO, BAR=1\n")
    with pytest.warns(palpate.MeshWarning, match=r"u.inp: Abaqus keywords palpate does not know, read past: "
                      r"\*HOURGLASS STIFFNESS \(line 12\), \*FOO \(line 14\); palpate takes the mesh from \*NODE, "
                      r"\*ELEMENT, \*NSET and \*ELSET") as rec:
        m = palpate.load_mesh(path)
    assert len(rec) == 1 and m.n_tets == 2



# The readers' leftovers of issue 35: Medit versions 3 and 4, the sets an Abaqus *NODE / *ELEMENT
# line names (and how Abaqus sets add up), and the physical groups of gmsh MSH 4.x entities.

@pytest.mark.parametrize("version", ["3", "4"])
def test_medit_versions_3_and_4_read_as_version_2(tmp_path, version):
    """MeshVersionFormatted 3 and 4 (64-bit file positions, 64-bit integers) differ from 2 in a
    binary .meshb only: an ASCII file's text is the same. meshio's reader took 0 to 2 and failed
    with 'cannot read as MEDIT (KeyError: '3')'; they read as version 2 now, with references
    over 2**32 (what version 4 is for) kept."""
    big = 2 ** 53 + 1
    text = (f"MeshVersionFormatted {version}\nDimension 3\nVertices\n5\n0.1234567891 0 0 1\n1 0 0 1\n0 1 0 1\n"
            f"0 0 1 1\n1 1 1 {big}\nTriangles\n1\n1 2 3 {2 ** 32 + 1}\nTetrahedra\n2\n1 2 3 4 7\n5 2 4 3 {big}\nEnd\n")
    path, v2 = tmp_path / f"v{version}.mesh", tmp_path / "v2.mesh"
    path.write_text(text)
    v2.write_text(text.replace(f"MeshVersionFormatted {version}", "MeshVersionFormatted 2"))
    m, m2 = palpate.load_mesh(path), palpate.load_mesh(v2)
    np.testing.assert_array_equal(m.points, m2.points)
    np.testing.assert_array_equal(m.tets, m2.tets)
    assert m.points[0, 0] == 0.1234567891
    nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"vertex ref 1", f"vertex ref {big}", f"ref {2 ** 32 + 1}", "ref 7", f"ref {big}"}
    np.testing.assert_array_equal(nodes[f"vertex ref {big}"], [4])
    np.testing.assert_array_equal(tets[f"ref {big}"], [1])
    np.testing.assert_array_equal(nodes[f"ref {2 ** 32 + 1}"], [0, 1, 2])


def test_medit_unknown_version_is_refused_with_the_line(tmp_path):
    path = _medit(tmp_path, "v5.mesh")
    path.write_text(path.read_text().replace("MeshVersionFormatted 2", "MeshVersionFormatted 5"))
    for call in (palpate.load_mesh, palpate.read_mesh_sets):
        with pytest.raises(palpate.MeshError, match=r"v5.mesh: line 1: MeshVersionFormatted '5' is not a Medit "
                           r"version: palpate reads ASCII Medit files of versions 0 to 4"):
            call(path)


def test_abaqus_node_block_nset_makes_a_node_set(tmp_path):
    """*NODE, NSET=<name> puts the block's nodes in that set; meshio's reader ignored the
    parameter (a scene naming the set got 'no node set')."""
    path = _inp(tmp_path, "n.inp", _INP_MESH.replace("*NODE\n", "*NODE, NSET=NALL\n") + "*NSET, NSET=TIP\n5\n")
    nodes, tets = palpate.read_mesh_sets(path)
    np.testing.assert_array_equal(nodes["NALL"], [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(nodes["TIP"], [4])
    np.testing.assert_array_equal(tets["ALL"], [0, 1])


def test_abaqus_element_block_elset_is_kept(tmp_path, bar):
    """*ELEMENT, ELSET=<name> puts the block's elements in that set. meshio's reader kept it on
    the wrong cell block when a block without ELSET came before (here the clamped face's S3
    triangles: 'IndexError: index 1 is out of bounds'), and a name given to two blocks took the
    second block's rows for both."""
    pts, tets, faces, _ = bar
    k, j = 5, 8   # tets[:k] and tets[j:] in LEFT (two blocks of one name), tets[k:j] in MID
    rows = lambda first, ts: "".join(f"{first + i}, " + ", ".join(str(n + 1) for n in t) + "\n"  # noqa: E731
                                     for i, t in enumerate(ts))
    text = ("*NODE\n" + "".join(f"{i + 1}, {x!r}, {y!r}, {z!r}\n" for i, (x, y, z) in enumerate(pts.tolist()))
            + "*ELEMENT, TYPE=S3\n" + rows(1001, faces)
            + "*ELEMENT, TYPE=C3D4, ELSET=LEFT\n" + rows(1, tets[:k])
            + "*Element, type=C3D4, elset=MID\n" + rows(1 + k, tets[k:j])
            + "*ELEMENT, TYPE=C3D4, ELSET=LEFT\n" + rows(1 + j, tets[j:]))
    path = _inp(tmp_path, "e.inp", text)
    np.testing.assert_array_equal(palpate.load_mesh(path).tets, tets)
    nodes, tet_sets = palpate.read_mesh_sets(path)
    assert set(tet_sets) == {"LEFT", "MID"}
    left = np.r_[0:k, j:len(tets)]
    np.testing.assert_array_equal(tet_sets["LEFT"], left)
    np.testing.assert_array_equal(tet_sets["MID"], np.arange(k, j))
    np.testing.assert_array_equal(nodes["LEFT"], np.unique(tets[left]))
    np.testing.assert_array_equal(nodes["MID"], np.unique(tets[k:j]))


def test_abaqus_sets_add_up_and_name_other_sets(tmp_path):
    """Abaqus sets add up: a name defined again gets the members of both definitions (labels
    compare in upper case), a data line may name other sets, and *NSET, ELSET=<set> takes the
    nodes of that element set. meshio's reader kept the last definition only (BASE = [2]),
    dropped the set names of an *NSET line (ALLN = [3]), kept only the first of an *ELSET line
    (BOTH = [0]) and left *NSET, ELSET= empty."""
    text = ("*NODE\n" + _INP_NODES + "*ELEMENT, TYPE=C3D4, ELSET=T1\n1, 1, 2, 3, 4\n"
            "*ELEMENT, TYPE=C3D4, ELSET=T2\n2, 5, 2, 4, 3\n"
            "*NSET, NSET=BASE\n1, 2\n*NSET, NSET=base\n3\n*NSET, NSET=TOP\n5\n*NSET, NSET=ALLN\nBASE, TOP\n4\n"
            "*ELSET, ELSET=BOTH\nT1, T2\n*NSET, NSET=T2NODES, ELSET=T2\n*NSET, NSET=GEN, GENERATE\n1, 5, 2\n")
    nodes, tets = palpate.read_mesh_sets(_inp(tmp_path, "s.inp", text))
    assert set(nodes) == {"T1", "T2", "BASE", "TOP", "ALLN", "BOTH", "T2NODES", "GEN"}
    np.testing.assert_array_equal(nodes["BASE"], [0, 1, 2])   # as first written
    np.testing.assert_array_equal(nodes["ALLN"], [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(nodes["T2NODES"], [1, 2, 3, 4])
    np.testing.assert_array_equal(nodes["GEN"], [0, 2, 4])
    np.testing.assert_array_equal(tets["BOTH"], [0, 1])
    np.testing.assert_array_equal(tets["T2"], [1])
    bad = _inp(tmp_path, "bad.inp", _INP_MESH + "*NSET, NSET=FIX\nBASE, 1\n")
    with pytest.raises(palpate.MeshError, match=r"bad.inp: line 11: the node set 'FIX' lists the node set 'BASE', "
                       r"which no definition before it gives .*: its members are unknown"):
        palpate.read_mesh_sets(bad)
    unnamed = _inp(tmp_path, "unnamed.inp", _INP_MESH + "*NSET\n1, 2\n")
    with pytest.raises(palpate.MeshError, match=r"unnamed.inp: line 10: Abaqus keyword \*NSET has no NSET= "
                       r"parameter"):
        palpate.read_mesh_sets(unnamed)


def test_abaqus_empty_element_block_is_left_out_of_the_sets(tmp_path):
    """An *ELEMENT block with no data lines: load_mesh read the file, read_mesh_sets failed with a
    bare ValueError (meshio gives the empty block shape (0,), which was concatenated with the
    (n, 4) tets); it is left out, as read_mesh_arrays leaves it."""
    path = _inp(tmp_path, "empty.inp", _INP_MESH + "*ELEMENT, TYPE=C3D4, ELSET=NONE\n")
    assert palpate.load_mesh(path).n_tets == 2
    nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"ALL"} and set(tets) == {"ALL"}   # an empty set is none, as before
    np.testing.assert_array_equal(tets["ALL"], [0, 1])


def test_abaqus_second_part_is_refused_clearly(tmp_path):
    """Two parts (each numbering its nodes apart): refused, naming the second part, rather than
    'a second node block ... merge the blocks'."""
    text = ("*PART, NAME=P\n" + _INP_MESH + "*END PART\n*PART, NAME=Q\n*NODE\n1, 0., 0., 2.\n*END PART\n")
    with pytest.raises(palpate.MeshError, match=r"two.inp: line 13: Abaqus keyword \*NODE opens the node block of a "
                       r"second part \(\*PART at line 12; the first part's nodes at line 2\).*palpate reads .inp files "
                       r"with one part, placed by at most one \*INSTANCE"):
        palpate.load_mesh(_inp(tmp_path, "two.inp", text))


# MSH 4.1 twin of _MSH40_PARAMETRIC (without the parametric coordinates, which 4.1 keeps apart):
# volume 1 is bounded by surface 5, which meshio made a cell set "gmsh:bounding_entities".
_MSH41 = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
2
2 1 "clamp"
3 2 "body"
$EndPhysicalNames
$Entities
0 0 1 1
5 0 0 0 1 1 0 1 1 0
1 0 0 0 1 1 1 1 2 1 5
$EndEntities
$Nodes
2 5 10 50
2 5 0 3
10
20
30
0 0 0
1 0 0
0 1 0
3 1 0 2
40
50
0 0 1
1 1 1
$EndNodes
$Elements
2 3 1 12
2 5 2 1
1 10 20 30
3 1 4 2
11 10 20 30 40
12 50 20 40 30
$EndElements
"""


def _msh4_on_surface(layout, node_surface, element_surface):
    """The clamp/body mesh in MSH ``layout`` ("4.0", "4.0 binary", "4.1") with the surface's node
    and element blocks on the given entity tags ($Entities declares surface 5)."""
    if layout == "4.0 binary":
        return _msh40_parametric_binary(node_surface, element_surface)
    if layout == "4.0":
        text = _MSH40_PARAMETRIC.replace("\n5 2 1 3\n", f"\n{node_surface} 2 1 3\n")
        return text.replace("\n5 2 2 1\n", f"\n{element_surface} 2 2 1\n").encode()
    text = _MSH41.replace("\n2 5 0 3\n", f"\n2 {node_surface} 0 3\n")
    return text.replace("\n2 5 2 1\n", f"\n2 {element_surface} 2 1\n").encode()


@pytest.mark.parametrize("layout", ["4.0", "4.0 binary", "4.1"])
def test_gmsh4_elements_on_an_undeclared_entity(tmp_path, layout):
    """An element block on an entity that $Entities does not declare: meshio's readers failed on
    it ('cannot read as GMSH (KeyError: np.int32(6))'). gmsh reads such a file when $Nodes has a
    block on the entity (a discrete entity, in no physical group) and refuses it when not
    ('Unknown entity 6 of dimension 2'); so does read_mesh_sets, with a MeshWarning in the first
    case (a mistyped tag would otherwise drop the elements from their group without a word) and
    a MeshError naming the entity in the second. load_mesh reads both, as before."""
    path = tmp_path / "u.msh"
    path.write_bytes(_msh4_on_surface(layout, 6, 6))
    assert palpate.load_mesh(path).n_tets == 2
    with pytest.warns(palpate.MeshWarning, match=r"u.msh: gmsh elements on entities \$Entities does not declare, in "
                      r"no physical group: surface 6 \(dimension 2\): element block 1 \(1 triangle\)"):
        nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"body"} and set(tets) == {"body"}   # the triangle's "clamp" is gone, as in gmsh
    np.testing.assert_array_equal(tets["body"], [0, 1])
    path.write_bytes(_msh4_on_surface(layout, 5, 6))
    assert palpate.load_mesh(path).n_tets == 2
    with pytest.raises(palpate.MeshError, match=r"u.msh: gmsh element block 1 \(1 triangle\) is on surface 6 \(entity "
                       r"of dimension 2, tag 6\), which neither \$Entities nor \$Nodes declares: gmsh refuses such a "
                       r"file \('Unknown entity 6 of dimension 2'\)"):
        palpate.read_mesh_sets(path)


@pytest.mark.parametrize("version", ["4.0", "4.1"])
def test_gmsh4_every_physical_group_of_an_entity(tmp_path, version):
    """The physical groups of MSH 4.x entities, as $Entities gives them: surface 5 in two groups
    (meshio's 4.0 reader kept the first), surface 6 in none beside them (a file saved with
    Mesh.SaveAll: meshio failed, 'Incompatible cell data'), a surface group and a volume group
    of one tag (1) told apart by their dimension, as gmsh names them; and no set of meshio's 4.1
    bounding entities, nor a tet listed twice (main: 'gmsh:bounding_entities' sets, each tet of
    'body' twice, or an IndexError)."""
    names = '$PhysicalNames\n3\n2 1 "clamp"\n2 3 "sides"\n3 1 "body"\n$EndPhysicalNames\n'
    # $Entities: surface 5 in groups 1 and 3, surface 6 in none, volume 1 (bounded by 5 and 6) in 1.
    entities = "0 0 2 1\n5 0 0 0 1 1 0 2 1 3 0\n6 0 0 0 1 1 1 0 0\n1 0 0 0 1 1 1 1 1 2 5 6\n"
    if version == "4.0":   # a triangle on surface 6 added (element blocks: tag dim type count)
        text = (_MSH40_PARAMETRIC.replace("0 0 1 1\n5 0 0 0 1 1 0 1 1 0\n1 0 0 0 1 1 1 1 2 1 5\n", entities)
                .replace("$Elements\n2 3\n5 2 2 1\n1 10 20 30\n",
                         "$Elements\n3 4\n5 2 2 1\n1 10 20 30\n6 2 2 1\n2 20 30 40\n"))
    else:   # element blocks: dim tag type count
        text = (_MSH41.replace("0 0 1 1\n5 0 0 0 1 1 0 1 1 0\n1 0 0 0 1 1 1 1 2 1 5\n", entities)
                .replace("$Elements\n2 3 1 12\n2 5 2 1\n1 10 20 30\n",
                         "$Elements\n3 4 1 12\n2 5 2 1\n1 10 20 30\n2 6 2 1\n2 20 30 40\n"))
    text = text[:text.index("$PhysicalNames")] + names + text[text.index("$Entities"):]
    path = tmp_path / "g.msh"
    path.write_text(text)
    np.testing.assert_array_equal(palpate.load_mesh(path).tets, [[0, 1, 2, 3], [4, 1, 3, 2]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"clamp", "sides", "body"} and set(tets) == {"body"}
    np.testing.assert_array_equal(nodes["clamp"], [0, 1, 2])
    np.testing.assert_array_equal(nodes["sides"], [0, 1, 2])
    np.testing.assert_array_equal(nodes["body"], [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(tets["body"], [0, 1])


def test_gmsh41_sets_of_a_bounded_volume(tmp_path):
    """A 4.1 file as gmsh writes it (the volume's $Entities line lists its bounding surface):
    read_mesh_sets failed on main with a bare IndexError (meshio's 'gmsh:bounding_entities' cell
    set, surface tag 5 taken for a row of the 2-tet block)."""
    path = tmp_path / "b.msh"
    path.write_text(_MSH41)
    nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"clamp", "body"} and set(tets) == {"body"}
    np.testing.assert_array_equal(nodes["clamp"], [0, 1, 2])
    np.testing.assert_array_equal(tets["body"], [0, 1])


# The readers' last leftovers of issue 35 (RELIABILITY.md, "Left:"): Abaqus set numbers that name
# nothing, quoted labels, several *NODE blocks of one part; gmsh 2.2 physical tag 0; an MSH 4.1
# node block of no nodes.

@pytest.mark.parametrize("text, message", [
    (_INP_MESH + "*ELSET, ELSET=E\n1, 99\n",
     r"n.inp: line 11: the element set 'E' lists element 99, which no \*ELEMENT line defines: the set's members are "
     r"unknown"),
    (_INP_MESH + "*NSET, NSET=Fix\n1, 2,\n99, 98\n",
     r"n.inp: line 12: the node set 'Fix' lists node 99, which no \*NODE line defines \(2 numbers of the line name "
     r"none\)"),
    (_INP_MESH + "*NSET, NSET=G, GENERATE\n1, 7, 2\n",
     r"n.inp: line 11: the node set 'G' lists node 7 \(GENERATE\), which no \*NODE line defines"),
    (_INP_MESH + "*ELSET, ELSET=EG, GENERATE\n1, 3\n",
     r"n.inp: line 11: the element set 'EG' lists element 3 \(GENERATE\), which no \*ELEMENT line defines"),
    (_INP_MESH + "*NSET, NSET=F\n1, 2.5\n",
     r"n.inp: line 11: the node set 'F' lists '2.5', which is neither a node number nor a set name"),
    ("*NODE\n" + _INP_NODES + "*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n2, 5, 2, 4, 99\n",
     r"n.inp: line 7: an element of this \*ELEMENT block lists node 99, which no \*NODE line defines"),
], ids=["elset", "nset", "nset generate", "elset generate", "not a number", "element node"])
def test_abaqus_number_naming_no_node_or_element_is_refused(tmp_path, text, message):
    """A number an *NSET / *ELSET lists (or a GENERATE range gives) that names no node or element:
    meshio's reader dropped an *ELSET one without a word (main: the set 'E' = [0]) and failed on an
    *NSET one with 'cannot read as ABAQUS (KeyError: np.int32(99))', on 2.5 with a bare ValueError,
    on a 2-number GENERATE line (the increment left out, 1 in Abaqus) with a ReadError, and on an
    element's undefined node with a bare KeyError. Each is a MeshError naming the file, the line,
    the set and the number, through load_mesh and read_mesh_sets (both map the sets as they read)."""
    path = _inp(tmp_path, "n.inp", text)
    for call in (palpate.load_mesh, palpate.read_mesh_sets):
        with pytest.raises(palpate.MeshError, match=message):
            call(path)


def test_abaqus_generate_ranges_as_abaqus_reads_them(tmp_path):
    """GENERATE data lines give 'first, last[, increment]' (1 by default), one range a line, as
    many lines as needed: meshio's reader took exactly three numbers in all."""
    path = _inp(tmp_path, "g.inp", _INP_MESH + "*NSET, NSET=G, GENERATE\n1, 2\n4, 5, 1\n*ELSET, ELSET=E, GENERATE\n"
                "2, 2, 1\n")
    nodes, tets = palpate.read_mesh_sets(path)
    np.testing.assert_array_equal(nodes["G"], [0, 1, 3, 4])
    np.testing.assert_array_equal(tets["E"], [1])


def test_abaqus_quoted_set_names_lose_their_quotes(tmp_path):
    """A label written in double quotes (Abaqus/CAE writes a set name holding blanks so) is the
    name without them: the sets came back named '"my set"', and a scene naming 'my set' found
    none. Names compare in upper case, quoted or not, as palpate compared every label."""
    text = (_INP_MESH.replace("*NODE\n", '*NODE, NSET="all nodes"\n').replace("ELSET=ALL", 'ELSET="my tets"')
            + '*NSET, NSET="my set"\n1, 2\n*NSET, NSET="My Set"\n3\n*NSET, NSET=B\n"my set", 5\n'
            '*NSET, NSET=T, ELSET="my tets"\n*ELSET, ELSET="both tets"\n"my tets"\n')
    nodes, tets = palpate.read_mesh_sets(_inp(tmp_path, "q.inp", text))
    assert set(nodes) == {"all nodes", "my tets", "my set", "B", "T", "both tets"}
    assert set(tets) == {"my tets", "both tets"}
    np.testing.assert_array_equal(nodes["my set"], [0, 1, 2])
    np.testing.assert_array_equal(nodes["B"], [0, 1, 2, 4])
    np.testing.assert_array_equal(nodes["T"], [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(tets["both tets"], [0, 1])


def test_abaqus_node_blocks_of_a_part_are_one(tmp_path):
    """Several *NODE blocks in one part (exporters write one per component, and elements between
    them): refused before ('opens a second node block ... merge the blocks'); meshio's reader
    replaces the nodes at each *NODE. They are read as one set of nodes, as Abaqus reads them,
    an element naming a node of a later block included, with each block's NSET=. A node number
    defined twice is a MeshError naming it and both lines (meshio kept both nodes and mapped the
    number to the second: main's load_mesh said 'node 2 is used by no tetrahedron')."""
    lines = _INP_NODES.splitlines(keepends=True)
    mesh = ("*NODE, NSET=FIRST\n" + "".join(lines[:3]) + "*ELEMENT, TYPE=C3D4, ELSET=A\n1, 1, 2, 3, 4\n"
            "*NODE, NSET=SECOND\n" + "".join(lines[3:]) + "*ELEMENT, TYPE=C3D4\n2, 5, 2, 4, 3\n*NSET, NSET=TIP\n5\n")
    for text in (mesh, "*PART, NAME=P\n" + mesh + "*END PART\n*ASSEMBLY, NAME=A\n*INSTANCE, NAME=I, PART=P\n"
                 "*END INSTANCE\n*END ASSEMBLY\n"):
        path = _inp(tmp_path, "b.inp", text)
        m = palpate.load_mesh(path)
        np.testing.assert_array_equal(m.tets, [[0, 1, 2, 3], [4, 1, 3, 2]])
        np.testing.assert_array_equal(m.points, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
        nodes, tets = palpate.read_mesh_sets(path)
        np.testing.assert_array_equal(nodes["FIRST"], [0, 1, 2])
        np.testing.assert_array_equal(nodes["SECOND"], [3, 4])
        np.testing.assert_array_equal(nodes["TIP"], [4])
        np.testing.assert_array_equal(tets["A"], [0])
    clash = _inp(tmp_path, "clash.inp", mesh.replace("4, 0, 0, 1\n", "3, 0, 0, 1\n"))
    for call in (palpate.load_mesh, palpate.read_mesh_sets):
        with pytest.raises(palpate.MeshError, match=r"clash.inp: line 8: node 3 is defined again \(first at line 4\)"):
            call(clash)
    one = _inp(tmp_path, "one.inp", "*NODE\n" + _INP_NODES + "3, 0, 0, 1\n*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n")
    with pytest.raises(palpate.MeshError, match=r"one.inp: line 7: node 3 is defined again \(first at line 4\)"):
        palpate.load_mesh(one)


_MSH22_SAVEALL = """$MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
1
3 2 "body"
$EndPhysicalNames
$Nodes
5
1 0 0 0
2 1 0 0
3 0 1 0
4 0 0 1
5 1 1 1
$EndNodes
$Elements
3
1 2 2 0 5 1 2 3
2 4 2 2 1 1 2 3 4
3 4 2 0 2 5 2 4 3
$EndElements
"""


def test_gmsh22_physical_tag_0_is_no_group(tmp_path):
    """In MSH 2.2 a physical tag 0 is no physical group (gmsh's Mesh.SaveAll writes every element,
    0 for those of entities in none): main made a set 'physical 0' of them (here a triangle on
    surface 5 and a tet of volume 2). gmsh 4.15.2 reads this file with one group, 'body', of
    tet 2 (volume 1)."""
    path = tmp_path / "all.msh"
    path.write_text(_MSH22_SAVEALL)
    assert palpate.load_mesh(path).n_tets == 2
    nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"body"} and set(tets) == {"body"}
    np.testing.assert_array_equal(tets["body"], [0])
    np.testing.assert_array_equal(nodes["body"], [0, 1, 2, 3])


def _msh41_binary(empty_block_on=None, element_surface=5, parametric=False):
    """The binary twin of _MSH41 (clamp on surface 5, body in volume 1), with a node block of no
    nodes on surface ``empty_block_on``, the triangle's block on ``element_surface``, and the
    surface's nodes parametric (``u v`` after ``x y z``) if asked."""
    q = lambda *v: struct.pack(f"<{len(v)}Q", *v)  # noqa: E731  size_t
    i = lambda *v: struct.pack(f"<{len(v)}i", *v)  # noqa: E731
    d = lambda *v: struct.pack(f"<{len(v)}d", *v)  # noqa: E731
    entities = (q(0, 0, 1, 1) + i(5) + d(0, 0, 0, 1, 1, 0) + q(1) + i(1) + q(0)
                + i(1) + d(0, 0, 0, 1, 1, 1) + q(1) + i(2) + q(1) + i(5))
    surface = d(0, 0, 0, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1) if parametric else d(0, 0, 0, 1, 0, 0, 0, 1, 0)
    blocks = [i(2, 5, int(parametric)) + q(3) + q(10, 20, 30) + surface]
    if empty_block_on is not None:
        blocks.append(i(2, empty_block_on, 0) + q(0))
    blocks.append(i(3, 1, 0) + q(2) + q(40, 50) + d(0, 0, 1, 1, 1, 1))
    elements = (q(2, 3, 1, 12) + i(2, element_surface, 2) + q(1) + q(1, 10, 20, 30)
                + i(3, 1, 4) + q(2) + q(11, 10, 20, 30, 40, 12, 50, 20, 40, 30))
    return (b"$MeshFormat\n4.1 1 8\n" + i(1) + b"\n$EndMeshFormat\n"
            + b'$PhysicalNames\n2\n2 1 "clamp"\n3 2 "body"\n$EndPhysicalNames\n'
            + b"$Entities\n" + entities + b"\n$EndEntities\n"
            + b"$Nodes\n" + q(len(blocks), 5, 10, 50) + b"".join(blocks) + b"\n$EndNodes\n"
            + b"$Elements\n" + elements + b"\n$EndElements\n")


@pytest.mark.parametrize("binary", [False, True])
def test_gmsh41_empty_node_block_declares_its_entity(tmp_path, binary):
    """An MSH 4.1 node block of no nodes (gmsh writes one for a surface whose nodes all lie on its
    curves) declares its entity, as gmsh reads it: an element block on that entity, which
    $Entities does not declare, is read in no physical group with the MeshWarning of
    test_gmsh4_elements_on_an_undeclared_entity. main: 'MeshError: ... which neither $Entities nor
    $Nodes declares' (meshio gives each node's entity, so an empty block was missed)."""
    path = tmp_path / "e.msh"
    if binary:
        path.write_bytes(_msh41_binary(empty_block_on=6, element_surface=6))
    else:
        path.write_text(_MSH41.replace("$Nodes\n2 5 10 50\n", "$Nodes\n3 5 10 50\n2 6 0 0\n")
                        .replace("\n2 5 2 1\n", "\n2 6 2 1\n"))
    assert palpate.load_mesh(path).n_tets == 2
    with pytest.warns(palpate.MeshWarning, match=r"e.msh: gmsh elements on entities \$Entities does not declare, in "
                      r"no physical group: surface 6 \(dimension 2\): element block 1 \(1 triangle\)"):
        nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"body"} and set(tets) == {"body"}
    np.testing.assert_array_equal(tets["body"], [0, 1])
    np.testing.assert_array_equal(nodes["body"], [0, 1, 2, 3, 4])


@pytest.mark.parametrize("binary", [False, True])
def test_gmsh41_parametric_nodes_sets_are_read(tmp_path, binary):
    """MSH 4.1 with a parametric node block (``u v`` after ``x y z``): load_mesh read it;
    read_mesh_sets failed with 'cannot read as GMSH (ReadError: parametric nodes not
    implemented)' (meshio's 4.1 node reader), found on the way. Read past, as for 4.0."""
    path = tmp_path / "p.msh"
    if binary:
        path.write_bytes(_msh41_binary(parametric=True))
    else:
        path.write_text(_MSH41.replace("2 5 0 3\n10\n20\n30\n0 0 0\n1 0 0\n0 1 0\n",
                                       "2 5 1 3\n10\n20\n30\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n"))
    np.testing.assert_array_equal(palpate.load_mesh(path).tets, [[0, 1, 2, 3], [4, 1, 3, 2]])
    nodes, tets = palpate.read_mesh_sets(path)
    assert set(nodes) == {"clamp", "body"} and set(tets) == {"body"}
    np.testing.assert_array_equal(nodes["clamp"], [0, 1, 2])
    np.testing.assert_array_equal(tets["body"], [0, 1])
