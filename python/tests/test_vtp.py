"""VTK XML PolyData (.vtp) reader, .vtp in load_surface, tagged surfaces (read_tagged_surface)."""
import base64
import itertools
import json
import re
import warnings
import zlib

import numpy as np
import pytest

import palpate
from palpate.vtp import read_vtp, write_vtp
from vtpwrite import OCTA_POINTS, OCTA_TAGS, OCTA_TRIS, vtp

ENCODINGS = [
    dict(fmt="ascii"),
    dict(fmt="binary"),
    dict(fmt="binary", joint=True),
    dict(fmt="binary", compress=True),
    dict(fmt="binary", compress=True, block_size=16),          # many blocks, a short last one
    dict(fmt="binary", compress=True, block_size=8),           # many blocks, all full
    dict(fmt="binary", header_type="UInt64"),
    dict(fmt="binary", compress=True, header_type="UInt64", block_size=40),
    dict(fmt="appended"),
    dict(fmt="appended", compress=True, block_size=24),
    dict(fmt="appended", header_type="UInt64"),
    dict(fmt="appended-base64"),
    dict(fmt="appended-base64", joint=True),
    dict(fmt="appended-base64", compress=True, block_size=16, header_type="UInt64"),
    dict(fmt="binary", compress=True, big_endian=True),
    dict(fmt="appended", big_endian=True, header_type="UInt64"),
]


def _data():
    rng = np.random.default_rng(7)
    cd = {
        "surface-id": np.array(OCTA_TAGS, dtype=np.int32),
        "u8": np.arange(8, dtype=np.uint8),
        "i16": -np.arange(8, dtype=np.int16),
        "u64": np.arange(8, dtype=np.uint64) * (2 ** 40),
        "normals": rng.normal(size=(8, 3)),
        "f32x2": rng.normal(size=(8, 2)).astype(np.float32),
    }
    pd = {"i8": np.arange(6, dtype=np.int8) - 3, "id": np.arange(6, dtype=np.int64) * (2 ** 33),
          "u16": np.arange(6, dtype=np.uint16), "u32": np.arange(6, dtype=np.uint32)}
    return cd, pd


@pytest.mark.parametrize("kw", ENCODINGS, ids=lambda kw: "-".join(f"{k}={v}" for k, v in kw.items()))
def test_round_trip(tmp_path, kw):
    cd, pd = _data()
    path = tmp_path / "octa.vtp"
    path.write_bytes(vtp(OCTA_POINTS, OCTA_TRIS, cell_data=cd, point_data=pd, **kw))
    d = read_vtp(path)
    np.testing.assert_array_equal(d.points, np.array(OCTA_POINTS))
    assert d.points.dtype == np.float64 and d.triangles.dtype == np.int64
    np.testing.assert_array_equal(d.triangles, OCTA_TRIS)
    assert set(d.cell_data) == set(cd) and set(d.point_data) == set(pd)
    for k, v in itertools.chain(cd.items(), pd.items()):
        got = d.cell_data.get(k, d.point_data.get(k))
        assert got.dtype == v.dtype and got.shape == v.shape, k
        if v.dtype.kind == "f" and kw["fmt"] == "ascii":
            np.testing.assert_allclose(got, v, rtol=1e-7)
        else:
            np.testing.assert_array_equal(got, v)


def test_verts_and_lines_are_ignored(tmp_path):
    path = tmp_path / "mixed.vtp"
    cd = {"tag": np.array([7, 8] + OCTA_TAGS, dtype=np.int64)}       # one vert, one line, then polys
    path.write_bytes(vtp(OCTA_POINTS, OCTA_TRIS, cell_data=cd, verts=[[0]], lines=[[0, 1]], fmt="binary",
                         compress=True))
    d = read_vtp(path)
    np.testing.assert_array_equal(d.triangles, OCTA_TRIS)
    np.testing.assert_array_equal(d.cell_data["tag"], OCTA_TAGS)


def test_float32_points_and_write_vtp(tmp_path):
    s = palpate.ellipsoid_surface((20.0, 20.0, 35.0), 2)
    for fmt, compress in [("ascii", False), ("binary", False), ("binary", True), ("appended", True), ("appended", False)]:
        path = tmp_path / f"lv_{fmt}_{compress}.vtp"
        write_vtp(path, s.points, s.triangles, cell_data={"id": np.arange(s.n_triangles, dtype=np.int32)},
                  fmt=fmt, compress=compress)
        d = read_vtp(path)
        np.testing.assert_array_equal(d.points, s.points)
        np.testing.assert_array_equal(d.triangles, s.triangles)
        np.testing.assert_array_equal(d.cell_data["id"], np.arange(s.n_triangles))
    path = tmp_path / "f32.vtp"
    path.write_bytes(vtp(s.points, s.triangles.tolist(), fmt="binary", compress=True, points_dtype=np.float32))
    np.testing.assert_array_equal(read_vtp(path).points, s.points.astype(np.float32))


def test_load_surface_vtp(tmp_path):
    s = palpate.ellipsoid_surface((20.0, 20.0, 35.0), 2)          # in mm
    path = tmp_path / "lv.vtp"
    path.write_bytes(vtp(s.points, s.triangles.tolist(), fmt="appended", compress=True))
    with warnings.catch_warnings():
        warnings.simplefilter("error", palpate.MeshWarning)
        loaded = palpate.load_surface(path, unit="mm")
    assert loaded.n_triangles == s.n_triangles
    assert loaded.volume == pytest.approx(s.volume * 1e-9, rel=1e-12)
    p, t = palpate.read_surface_arrays(path, unit="cm")
    np.testing.assert_allclose(p, s.points * 1e-2)
    # an open surface is still a SurfaceError naming the file and the edge
    path.write_bytes(vtp(s.points, s.triangles.tolist()[1:], fmt="binary"))
    with pytest.raises(palpate.SurfaceError, match=r"lv.vtp: open surface: edge"):
        palpate.load_surface(path, unit="mm")


def _b64_block(arr, header=np.uint32):
    raw = arr.tobytes()
    return (base64.b64encode(np.array([len(raw)], header).tobytes()) + base64.b64encode(raw)).decode()


@pytest.mark.parametrize("case, match", [
    ("not_xml", r"bad.vtp: not a VTK XML file"),
    ("truncated", r"bad.vtp: not well-formed XML, the file is truncated or corrupt"),
    ("unstructured", r"bad.vtp: VTK XML file of type 'UnstructuredGrid', not 'PolyData'"),
    ("no_points", r"bad.vtp: no <Points>"),
    ("zero_points", r"bad.vtp: no points \(NumberOfPoints = 0"),
    ("bad_base64", r"bad.vtp: Points: corrupt base64 data"),
    ("short_base64", r"bad.vtp: Points: the block header announces 144 bytes but 72 are present"),
    ("corrupt_zlib", r"bad.vtp: Points: corrupt zlib data in block 0 of 1"),
    ("zlib_size", r"bad.vtp: Points: zlib block 0 inflates to 144 bytes, expected 200"),
    ("size_mismatch", r"bad.vtp: Points: holds 15 values, expected 18 \(6 x 3 components\): size mismatch"),
    ("quad", r"bad.vtp: polygon 2 \(VTK cell 2\) has 4 vertices, not 3"),
    ("index", r"bad.vtp: polygon 5 \(VTK cell 5\): vertex index 6 out of range \(the surface has 6 points\)"),
    ("negative", r"bad.vtp: polygon 1 \(VTK cell 1\): vertex index -1 out of range"),
    ("offsets", r"bad.vtp: Polys: the last offset is 24 but the connectivity holds 21 indices"),
    ("strips", r"bad.vtp: 1 triangle strip\(s\)"),
    ("appended_offset", r"bad.vtp: Polys offsets: offset 99999 lies beyond"),
    ("appended_truncated", r"bad.vtp: .*(truncated|cut short)"),
    ("compressor", r"bad.vtp: unsupported compressor 'vtkLZ4DataCompressor'"),
    ("ascii_value", r"bad.vtp: Points: bad ASCII value"),
])
def test_vtp_errors(tmp_path, case, match):
    good = vtp(OCTA_POINTS, OCTA_TRIS, fmt="binary").decode()
    pts = np.array(OCTA_POINTS, dtype=np.float64)
    b64 = _b64_block(pts)
    if case == "not_xml":
        text = "solid x\n facet normal 0 0 1\n"
    elif case == "truncated":
        text = good[: good.index("<Polys>") + 60]
    elif case == "unstructured":
        text = good.replace('type="PolyData"', 'type="UnstructuredGrid"')
    elif case == "no_points":
        text = good[: good.index("<Points>")] + good[good.index("</Points>") + len("</Points>"):]
    elif case == "zero_points":
        text = good.replace('NumberOfPoints="6"', 'NumberOfPoints="0"')
    elif case == "bad_base64":
        text = good.replace(b64, b64[:20] + "!!!!" + b64[24:])
    elif case == "short_base64":
        raw = pts.tobytes()
        short = (base64.b64encode(np.array([len(raw)], np.uint32).tobytes()) + base64.b64encode(raw[:72])).decode()
        text = good.replace(b64, short)
    elif case in ("corrupt_zlib", "zlib_size"):
        raw = pts.tobytes()
        c = zlib.compress(raw)
        ok = (base64.b64encode(np.array([1, len(raw), 0, len(c)], np.uint32).tobytes())
              + base64.b64encode(c)).decode()
        head = [1, len(raw), 0, len(c)]
        if case == "corrupt_zlib":
            c = c[:5] + b"\x00" * 7 + c[12:]
        else:
            head[1] = 200
        bad = (base64.b64encode(np.array(head, np.uint32).tobytes()) + base64.b64encode(c)).decode()
        good_c = vtp(OCTA_POINTS, OCTA_TRIS, fmt="binary", compress=True).decode()
        assert ok in good_c
        text = good_c.replace(ok, bad)
    elif case == "size_mismatch":
        text = good.replace(b64, _b64_block(pts.ravel()[:15]))
    elif case == "quad":
        text = vtp(OCTA_POINTS, OCTA_TRIS[:2] + [(0, 1, 2, 3)] + OCTA_TRIS[2:]).decode()
    elif case == "index":
        tris = [list(t) for t in OCTA_TRIS]
        tris[5][1] = 6
        text = vtp(OCTA_POINTS, tris, fmt="binary", compress=True).decode()
    elif case == "negative":
        tris = [list(t) for t in OCTA_TRIS]
        tris[1][2] = -1
        text = vtp(OCTA_POINTS, tris, fmt="ascii").decode()
    elif case == "offsets":
        a = vtp(OCTA_POINTS, OCTA_TRIS, fmt="ascii").decode()
        conn = " ".join(str(i) for t in OCTA_TRIS for i in t)
        text = a.replace(conn, conn.rsplit(" ", 3)[0])
    elif case == "strips":
        text = good.replace('NumberOfStrips="0"', 'NumberOfStrips="1"')
    elif case == "appended_offset":
        a = vtp(OCTA_POINTS, OCTA_TRIS, fmt="appended")
        offs = re.findall(rb'Name="offsets" NumberOfComponents="1" format="appended" offset="(\d+)"', a)[0]
        (tmp_path / "bad.vtp").write_bytes(a.replace(b'Name="offsets" NumberOfComponents="1" format="appended" offset="'
                                                     + offs + b'"', b'Name="offsets" NumberOfComponents="1" '
                                                     b'format="appended" offset="99999"'))
        text = None
    elif case == "appended_truncated":
        a = vtp(OCTA_POINTS, OCTA_TRIS, fmt="appended", compress=True)
        (tmp_path / "bad.vtp").write_bytes(a[: a.index(b"_") + 1 + 150])
        text = None
    elif case == "compressor":
        text = good.replace('header_type="UInt32"', 'header_type="UInt32" compressor="vtkLZ4DataCompressor"')
    elif case == "ascii_value":
        a = vtp(OCTA_POINTS, OCTA_TRIS, fmt="ascii").decode()
        text = a.replace("-1.0", "-1.O", 1)
    if text is not None:
        (tmp_path / "bad.vtp").write_text(text)
    with pytest.raises(palpate.SurfaceError, match=match) as e:
        read_vtp(tmp_path / "bad.vtp")
    assert isinstance(e.value, palpate.MeshError)
    assert e.value.__cause__ is None and e.value.__suppress_context__ or e.value.__context__ is None
    assert "\n" not in str(e.value)
    with pytest.raises(palpate.SurfaceError, match="bad.vtp"):
        palpate.load_surface(tmp_path / "bad.vtp")


# --- tagged surfaces -----------------------------------------------------------------------------

def _octa(tmp_path, name="wall.vtp", tags=OCTA_TAGS, array="surface-id", **kw):
    path = tmp_path / name
    path.write_bytes(vtp(OCTA_POINTS, OCTA_TRIS, cell_data={array: np.array(tags, dtype=np.int32)},
                         fmt="binary", compress=True, **kw))
    return path


def test_tagged_defaults(tmp_path):
    p, t, part = palpate.read_tagged_surface(_octa(tmp_path), unit="mm")
    np.testing.assert_allclose(p, np.array(OCTA_POINTS) * 1e-3)
    np.testing.assert_array_equal(t, OCTA_TRIS)
    assert part.dtype == np.int8
    np.testing.assert_array_equal(part, [0, 0, 0, 2, 1, 1, 1, 2])     # 1 inner, 2 outer, 3 and 4 base


def test_tagged_part_definition_and_overrides(tmp_path):
    path = _octa(tmp_path, "case_surface.vtp", tags=[5, 5, 5, 7, 6, 6, 6, 8])
    (tmp_path / "case_part_definition.json").write_text(json.dumps({"LV": {"id": 1, "enclosed_by_boundaries": {
        "lv-endocardium": 5, "lv-epicardium": 6, "mitral-valve-plane": 7, "aortic-valve-plane": 8}}}))
    _, _, part = palpate.read_tagged_surface(path)
    np.testing.assert_array_equal(part, [0, 0, 0, 2, 1, 1, 1, 2])
    # explicit arguments override the part definition (and take the value from the base)
    _, _, part = palpate.read_tagged_surface(path, outer=[6, 7])
    np.testing.assert_array_equal(part, [0, 0, 0, 1, 1, 1, 1, 2])
    # the <stem>_part_definition.json naming, a flat mapping
    path2 = _octa(tmp_path, "shell.vtp", tags=[5, 5, 5, 7, 6, 6, 6, 8])
    (tmp_path / "shell_part_definition.json").write_text(json.dumps(
        {"endocardium": 5, "epicardium": 6, "base-ring": 7, "septum": 8}))
    with pytest.raises(palpate.SurfaceError,
                       match=r"shell.vtp: triangle 7: tag value 8 \('septum'\) of 'surface-id' is not mapped"):
        palpate.read_tagged_surface(path2)
    _, _, part = palpate.read_tagged_surface(path2, base=[7, 8])
    np.testing.assert_array_equal(part, [0, 0, 0, 2, 1, 1, 1, 2])
    # ignoring the JSON: defaults 1 / 2 / rest find no inner triangles
    with pytest.raises(palpate.SurfaceError, match=r"shell.vtp: no inner triangles"):
        palpate.read_tagged_surface(path2, part_definition=False)
    _, _, part = palpate.read_tagged_surface(path2, part_definition=False, inner=5, outer=6)
    np.testing.assert_array_equal(part, [0, 0, 0, 2, 1, 1, 1, 2])


def test_tagged_errors(tmp_path):
    path = _octa(tmp_path, array="region")
    with pytest.raises(palpate.SurfaceError, match=r"wall.vtp: missing tag array 'surface-id' \(cell data arrays: \['region'\]\)"):
        palpate.read_tagged_surface(path)
    _, _, part = palpate.read_tagged_surface(path, tag_array="region")
    assert (part == 0).sum() == 3
    with pytest.raises(palpate.SurfaceError, match=r"wall.vtp: tag value\(s\) \[1\] assigned to both inner and outer"):
        palpate.read_tagged_surface(path, tag_array="region", inner=1, outer=[1, 2])
    with pytest.raises(palpate.SurfaceError, match=r"no outer triangles"):
        palpate.read_tagged_surface(_octa(tmp_path, "x.vtp", tags=[1, 1, 1, 1, 3, 3, 3, 3]))
    with pytest.raises(palpate.SurfaceError, match=r"tag value 4 of 'surface-id' is not mapped"):
        palpate.read_tagged_surface(_octa(tmp_path), base=3)
    with pytest.raises(ValueError, match="unit must be one of"):
        palpate.read_tagged_surface(path, unit="inch")


@pytest.mark.parametrize("ext", [".vtk", ".vtu"])
def test_tagged_meshio_formats(tmp_path, ext):
    import meshio

    path = tmp_path / f"wall{ext}"
    meshio.write(str(path), meshio.Mesh(np.array(OCTA_POINTS), [("triangle", np.array(OCTA_TRIS))],
                                        cell_data={"surface-id": [np.array(OCTA_TAGS, dtype=np.int32)]}))
    p, t, part = palpate.read_tagged_surface(path, unit="cm")
    np.testing.assert_allclose(p, np.array(OCTA_POINTS) * 1e-2)
    np.testing.assert_array_equal(part, [0, 0, 0, 2, 1, 1, 1, 2])


def test_orient_consistently():
    p = np.array(OCTA_POINTS)
    t = np.array(OCTA_TRIS)
    bad = t.copy()
    bad[[1, 4, 6]] = bad[[1, 4, 6]][:, ::-1]
    with pytest.raises(palpate.SurfaceError, match="inconsistent orientation"):
        palpate.TriSurface(p, bad)
    fixed, n = palpate.orient_consistently(p, bad)
    assert n == 3
    s = palpate.TriSurface(p, fixed)
    assert s.volume == pytest.approx(4 / 3)
    # all inward: every triangle flipped back
    fixed, n = palpate.orient_consistently(p, t[:, ::-1])
    assert n == 8
    assert palpate.TriSurface(p, fixed).volume == pytest.approx(4 / 3)
