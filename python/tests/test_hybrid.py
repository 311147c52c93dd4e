"""The compiled hybrid model (palpate.HybridModel): building it from the shipped geometries and
from files, saving and loading it, rejecting damaged model files, and `palpate build` / `palpate
info` on the command line."""
import struct
import time
import warnings

import meshio
import numpy as np
import pytest

import palpate
from palpate import cli, hybrid

from conftest import DATA
from test_cli import palpate_cli
from vtpwrite import vtp

MAGIC = b"PALPATE\0HYBRID\0\0"
HEADER = 40


@pytest.fixture(scope="module")
def ellipsoids():
    return palpate.build_shape("ellipsoids")


@pytest.fixture(scope="module")
def small():
    """A small model for the file tests (the layout does not depend on the size)."""
    inner, outer = (palpate.ellipsoid_surface(a, 3) for a in (hybrid.ELLIPSOIDS_INNER, hybrid.ELLIPSOIDS_OUTER))
    return palpate.HybridModel.build_nested(inner, outer, particles=2000, field_voxels=5000)


def _check_model(m, particles=28000, tol=0.05):
    i = m.info()
    assert abs(len(m.particles) - particles) <= tol * particles, len(m.particles)
    assert i["particles"] == len(m.particles) == len(m.particle_masses)
    assert abs(m.core_volume + m.shell_volume - m.wall_volume) <= 0.02 * m.wall_volume
    assert np.isclose(m.particle_masses.sum(), palpate.defaults.hybrid.density * m.shell_volume, rtol=1e-9)
    assert palpate.defaults.hybrid.density == palpate.defaults.tissue.density == 1060.0
    b = m.skin_barycentric
    assert b.shape == (len(m.outer_points), 3)
    assert (b >= 0).all() and (b <= 1).all() and np.allclose(b.sum(axis=1), 1.0)
    assert m.n_regions == len(m.outer_points)
    assert all(len(m.region_particles(s)) > 0 for s in range(m.n_regions))
    assert m.core_tets.min() >= 0 and m.core_tets.max() < len(m.core_points)
    assert m.particle_outer_triangle.max() < len(m.outer_triangles)
    assert m.particle_core_face.max() < len(m.core_faces)
    return i


def test_ellipsoids_model(ellipsoids):
    m = ellipsoids
    i = _check_model(m)
    assert 800 <= len(m.core_tets) <= 1400                                   # the automatic core: 300 triangles
    assert len(m.outer_points) == 4098 and len(m.outer_triangles) == 8192   # ellipsoid_surface(..., 5)
    assert len(m.core_base_nodes) == 0                                      # a closed wall
    assert i["region_particles_min"] >= 50
    # the wall between the ellipsoids of semi-axes (20, 20, 35) and (26, 26, 42) mm
    exact = 4 / 3 * np.pi * (0.026 * 0.026 * 0.042 - 0.020 * 0.020 * 0.035)
    assert abs(m.wall_volume - exact) < 0.02 * exact
    f = m.region_field(0)
    assert f["label"].dtype == np.uint8 and f["gradient"].shape == f["label"].shape + (3,)
    assert f["h"] > 0 and (f["label"] == 1).any()
    assert len(m.region_curve(0)) > 0 and len(m.region_triangles(0)) > 0 and len(m.region_core_faces(0)) > 0
    with pytest.raises(IndexError):
        m.region_particles(m.n_regions)
    assert repr(m).startswith("HybridModel(") and "particles" in repr(m)


def test_ventricle_model():
    m = palpate.build_shape("ventricle")
    _check_model(m)
    assert len(m.core_base_nodes) > 0                                       # the base is held
    # near the cut plane z = 0 (the core's base follows the simplified inner surface's rim)
    assert np.abs(m.core_points[m.core_base_nodes, 2]).max() < 0.25 * m.spacing
    assert m.particles[:, 2].min() >= -0.25 * m.spacing


def test_ventricle_surface_tags():
    p, t, part = hybrid.ventricle_surface()
    counts = np.bincount(part, minlength=3)
    c, n = hybrid.VENTRICLE_CIRCUMFERENTIAL, hybrid.VENTRICLE_LONGITUDINAL
    assert counts[0] == counts[1] == c * (2 * n - 1)                        # each ellipsoid's cap
    assert counts[2] == 2 * c                                               # the ring at z = 0
    assert np.allclose(p[t[part == 2]][..., 2], 0.0)
    s = palpate.TriSurface(p, t)
    assert s.volume > 0


def test_save_load_round_trip(small, tmp_path):
    path = tmp_path / "m.palpate"
    small.save(path)
    raw = path.read_bytes()
    assert raw[:16] == MAGIC and raw == small.to_bytes()
    assert hybrid.is_model_file(path)
    back = palpate.HybridModel.load(path)
    assert back.to_bytes() == small.to_bytes()
    for name in ("core_points", "core_tets", "core_faces", "core_base_nodes", "particles", "particle_masses",
                 "particle_outer_triangle", "particle_core_face", "outer_points", "outer_triangles", "skin_faces",
                 "skin_barycentric", "skin_offsets"):
        a, b = getattr(small, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    for name in ("n_regions", "spacing", "wall_volume", "core_volume", "shell_volume"):
        assert getattr(small, name) == getattr(back, name), name
    for s in (0, small.n_regions // 2, small.n_regions - 1):
        assert np.array_equal(small.region_particles(s), back.region_particles(s))
        assert np.array_equal(small.region_curve(s), back.region_curve(s))
        fa, fb = small.region_field(s), back.region_field(s)
        assert np.array_equal(fa["label"], fb["label"]) and np.array_equal(fa["gradient"], fb["gradient"])
    assert small.info() == back.info()


# ---- damaged model files -------------------------------------------------------------------

def _fnv1a(payload: bytes) -> int:
    """FNV-1a 64 of the payload (the file's checksum): a plain loop, over a small model's payload."""
    h = 0xCBF29CE484222325
    for b in payload:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def _with_payload(raw: bytes, payload: bytes) -> bytes:
    """A well-formed header (right length and checksum) over ``payload``."""
    return raw[:24] + struct.pack("<QQ", len(payload), _fnv1a(payload)) + payload


def _flip(raw: bytes, at: int) -> bytes:
    b = bytearray(raw)
    b[at] ^= 0x5A
    return bytes(b)


STL = b"solid wall\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid wall\n"


def _malformed(raw: bytes, n_core_points: int):
    """(case name, file bytes, expected message fragments)."""
    n = len(raw)
    cases = [
        ("foreign_stl", STL, ["not a palpate model file"]),
        ("empty", b"", ["not a palpate model file"]),
        ("magic_only_partly", raw[:10], ["not a palpate model file"]),
        ("wrong_magic", b"PALPATE\0HYBRIX\0\0" + raw[16:], ["not a palpate model file"]),
        ("truncated_in_header", raw[:30], ["truncated", "header"]),
        ("truncated_after_header", raw[:HEADER], ["truncated", "payload"]),
        ("truncated_after_options", raw[:HEADER + 70], ["truncated", "payload"]),
        ("truncated_half", raw[: n // 2], ["truncated", "payload"]),
        ("truncated_last_byte", raw[:-1], ["truncated", "payload"]),
        ("flipped_first_payload_byte", _flip(raw, HEADER), ["corrupted: checksum"]),
        ("flipped_middle_byte", _flip(raw, n // 2), ["corrupted: checksum"]),
        ("flipped_last_byte", _flip(raw, n - 1), ["corrupted: checksum"]),
        ("flipped_stored_checksum", _flip(raw, 33), ["corrupted: checksum"]),
        ("version_4", raw[:16] + struct.pack("<I", 4) + raw[20:], ["format version 4", "palpate build"]),
        ("version_0", raw[:16] + struct.pack("<I", 0) + raw[20:], ["format version 0"]),
        ("trailing_bytes", raw + b"\0" * 7, ["corrupted", "7 bytes after the end"]),
    ]
    payload = raw[HEADER:]
    # Damage that the checksum does not catch (recomputed): the structure checks must.
    cases.append(("bad_projection_code", _with_payload(raw, b"\x07" + payload[1:]),
                  ["corrupted", "projection code 7"]))
    tets_at = 1 + 8 + 8 + 8 + 1 + 8 + 8 + 8 + 8 + 8 + 8 + 24 * n_core_points + 8   # first core tet index
    bad = payload[:tets_at] + struct.pack("<I", 0xFFFFFFFF) + payload[tets_at + 4:]
    cases.append(("core_tet_index_out_of_range", _with_payload(raw, bad), ["corrupted"]))
    cases.append(("payload_cut_checksum_fixed", _with_payload(raw, payload[: len(payload) // 3]),
                  ["truncated"]))
    return cases


@pytest.fixture(scope="module")
def malformed_dir(small, tmp_path_factory):
    d = tmp_path_factory.mktemp("malformed_models")
    raw = small.to_bytes()
    # the layout read above: the first core point is where _malformed expects it
    assert struct.unpack_from("<Q", raw, HEADER + 66)[0] == len(small.core_points)
    cases = _malformed(raw, len(small.core_points))
    for name, content, _ in cases:
        (d / f"{name}.palpate").write_bytes(content)
    return d, {name: parts for name, _, parts in cases}


MALFORMED = [c[0] for c in _malformed(MAGIC + b"\0" * 200, 1)]


@pytest.mark.parametrize("name", MALFORMED)
def test_malformed_model_rejected(malformed_dir, name):
    d, expected = malformed_dir
    path = d / f"{name}.palpate"
    with pytest.raises(palpate.ModelFileError) as e:
        palpate.HybridModel.load(path)
    assert isinstance(e.value, palpate.PalpateError)
    msg = str(e.value)
    assert str(path) in msg, f"message does not name the file: {msg}"
    assert "\n" not in msg
    for part in expected[name]:
        assert part in msg, f"{part!r} not in {msg!r}"


def test_missing_model_file_is_oserror(tmp_path):
    with pytest.raises(OSError):
        palpate.HybridModel.load(tmp_path / "nothere.palpate")


# ---- from files ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def ellipsoid_stls(tmp_path_factory):
    d = tmp_path_factory.mktemp("surfaces")
    out = {}
    for name, axes in (("inner", hybrid.ELLIPSOIDS_INNER), ("outer", hybrid.ELLIPSOIDS_OUTER)):
        s = palpate.ellipsoid_surface(axes, 4)
        out[name] = d / f"{name}.stl"
        meshio.write_points_cells(out[name], s.points * 1e3, [("triangle", s.triangles)])   # millimetres
    return out


def test_build_from_files(ellipsoid_stls):
    m = palpate.build_from_files(ellipsoid_stls["inner"], ellipsoid_stls["outer"], unit="mm", particles=5000)
    _check_model(m, particles=5000)
    assert len(m.outer_points) == 1026


def test_build_from_files_not_nested(ellipsoid_stls):
    with pytest.raises(palpate.SurfaceError, match="inside the outer"):
        palpate.build_from_files(ellipsoid_stls["outer"], ellipsoid_stls["inner"], unit="mm")


def test_build_tagged_file(tmp_path):
    p, t, part = hybrid.ventricle_surface(48, 12)
    f = tmp_path / "lv.vtp"
    f.write_bytes(vtp(p * 1e3, t.tolist(), cell_data={"wall-part": (part.astype(np.int32) + 10)}))
    m = palpate.build_tagged_file(f, unit="mm", tag_array="wall-part", inner=10, outer=11, base=12,
                                  particles=4000)
    _check_model(m, particles=4000)
    assert len(m.core_base_nodes) > 0


def test_build_shape_unknown():
    with pytest.raises(ValueError, match="ellipsoids, ventricle, rodero"):
        palpate.build_shape("torus")


# ---- command line --------------------------------------------------------------------------

def test_cli_build_and_info(tmp_path):
    out = tmp_path / "x.palpate"
    r = palpate_cli("build", "--shape", "ellipsoids", "-o", out)
    assert r.returncode == 0, r.stderr
    assert out.exists() and out.read_bytes()[:16] == MAGIC
    m = palpate.HybridModel.load(out)
    tets = f"{len(m.core_tets)} tets"
    assert 800 <= len(m.core_tets) <= 1400                    # the automatic core of a closed wall
    assert tets in r.stdout and "particles" in r.stdout and "mL" in r.stdout and "build time" in r.stdout
    r = palpate_cli("info", out)
    assert r.returncode == 0, r.stderr
    assert str(out) in r.stdout and "palpate hybrid model" in r.stdout
    assert f"{len(m.particles)} particles" in r.stdout and tets in r.stdout
    assert f"wall {m.wall_volume * 1e6:.3f} mL" in r.stdout
    assert "MB" in r.stdout and "build time" in r.stdout


def test_cli_info_on_mesh_unchanged(tmp_path):
    """A mesh file still gets the mesh summary (not routed to the model loader)."""
    r = palpate_cli("info", DATA / "malformed" / "gmsh2_inverted_tet.msh")
    assert r.returncode == 0 and "2 tets" in r.stdout


@pytest.mark.parametrize("name", ["flipped_middle_byte", "truncated_half", "version_4", "truncated_in_header"])
def test_cli_info_damaged_model(malformed_dir, name):
    d, expected = malformed_dir
    path = d / f"{name}.palpate"
    r = palpate_cli("info", path)
    assert r.returncode == 1     # bad input
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert str(path) in lines[0] and expected[name][0] in lines[0]


def test_cli_info_model_with_magic_but_other_extension(small, tmp_path):
    f = tmp_path / "model.bin"
    f.write_bytes(small.to_bytes())
    r = palpate_cli("info", f)
    assert r.returncode == 0, r.stderr
    assert "palpate hybrid model" in r.stdout


def test_cli_build_not_nested(ellipsoid_stls, tmp_path):
    out = tmp_path / "bad.palpate"
    r = palpate_cli("build", ellipsoid_stls["outer"], ellipsoid_stls["inner"], "--unit", "mm", "-o", out)
    assert r.returncode == 1     # bad input: the surfaces
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "outer.stl" in lines[0] and "inner.stl" in lines[0] and "must lie inside the outer" in lines[0]
    assert not out.exists()


def test_cli_build_files_and_tagged(ellipsoid_stls, tmp_path):
    out = tmp_path / "f.palpate"
    r = palpate_cli("build", ellipsoid_stls["inner"], ellipsoid_stls["outer"], "--unit", "mm", "-o", out,
                    "--particles", 3000, "--projection", "radial", "--core-fraction", 0.4)
    assert r.returncode == 0, r.stderr
    i = palpate.HybridModel.load(out).info()
    assert i["projection"] == "radial" and i["core_fraction"] == 0.4
    # The size read, in the unit assumed and in metres (issue 37): a wrong --unit shows at once.
    ext = np.ptp(np.asarray(palpate.HybridModel.load(out).outer_points), axis=0)
    line = next(ln for ln in r.stdout.splitlines() if "input read in mm" in ln)
    assert f"{ext[0] * 1e3:.4g} x" in line and f"({ext[0]:.4g} x" in line and line.endswith(" m)"), line
    p, t, part = hybrid.ventricle_surface(48, 12)
    f = tmp_path / "lv.vtp"
    f.write_bytes(vtp(p * 1e3, t.tolist(), cell_data={"surface-id": (part.astype(np.int32) + 1)}))
    r = palpate_cli("build", "--tagged", f, "--unit", "mm", "--inner", "1", "--outer", "2", "--base", "3",
                    "-o", out, "--spacing", 0.0015)
    assert r.returncode == 0, r.stderr
    m = palpate.HybridModel.load(out)
    assert m.spacing == pytest.approx(0.0015) and len(m.core_base_nodes) > 0


@pytest.mark.parametrize("args, fragment, code", [
    # usage (2): the command line as written
    ([], "exactly one", 2),
    (["--shape", "ellipsoids", "a.stl"], "exactly one", 2),
    (["only_one.stl"], "two surface files", 2),
    (["--shape", "ellipsoids", "--inner", "1"], "go with --tagged", 2),
    (["--shape", "ellipsoids", "--unit", "mm"], "--unit", 2),
    (["--shape", "ellipsoids", "--spacing", "-1"], "--spacing must be positive", 2),
    (["--tagged", "x.vtp", "--inner", "a,b"], "--inner", 2),
    # bad input (1): a value the builder refuses, files that are not there
    (["--shape", "ellipsoids", "--core-fraction", "1.5"], "core fraction", 1),
    (["--tagged", "missing.vtp"], "missing.vtp", 1),
    (["a.stl", "b.stl"], "a.stl", 1),
])
def test_cli_build_errors(tmp_path, args, fragment, code):
    r = palpate_cli("build", *args, "-o", tmp_path / "m.palpate", cwd=tmp_path)
    assert r.returncode == code, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert fragment in lines[0]


def test_cli_main_in_process(tmp_path, capsys):
    out = tmp_path / "v.palpate"
    assert cli.main(["build", "--shape", "ventricle", "-o", str(out), "--particles", "3000"]) == 0
    assert "base nodes" in capsys.readouterr().out
    assert cli.main(["info", str(out)]) == 0
    assert "palpate hybrid model" in capsys.readouterr().out
    out.write_bytes(out.read_bytes()[:100])
    assert cli.main(["info", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "truncated" in err


# ---- the real left ventricle ---------------------------------------------------------------

def test_rodero_model(lv_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", palpate.MeshWarning)      # the known repair of the file
        points, triangles, part = palpate.read_tagged_surface(lv_path, unit="mm")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", palpate.MeshWarning)      # specks left by the repair
        m = palpate.HybridModel.build_tagged(points, triangles, part)
    wall = time.perf_counter() - t0
    i = m.info()
    print(f"\nRodero LV hybrid build: {wall:.2f} s wall ({i['build_s']:.2f} s in the builder), "
          f"{i['core_tets']} core tets, {i['particles']} particles, {i['regions']} regions")
    assert 27000 <= len(m.particles) <= 29000
    _check_model(m)
    assert len(m.core_base_nodes) > 0
    assert 100e-6 < m.wall_volume < 250e-6                        # an adult LV myocardium, in m^3


def test_a_surface_in_the_wrong_unit_is_caught(ellipsoid_stls, tmp_path):
    # Issue 37: surfaces in millimetres read as metres made a 120 m^3 organ with no warning.
    msg = hybrid.organ_scale_warning(1.19e5, "m", "outer.stl")   # 119 mL, its millimetres read as metres
    assert "1.19e+08 L" in msg and "read in mm it would be 0.119 L" in msg and "--unit mm" in msg, msg
    assert "read in m it would be 0.119 L" in hybrid.organ_scale_warning(1.19e-13, "mm", "x")   # metres read as mm
    assert hybrid.organ_scale_warning(1.19e-4, "m", "x") is None          # an organ: 119 mL
    assert "pass unit" not in hybrid.organ_scale_warning(1e12, "m", "x")  # no unit makes it an organ
    with pytest.raises(palpate.ParameterError, match="encloses .* m\\^3 .*read in m:.*--unit mm"):
        palpate.build_from_files(ellipsoid_stls["inner"], ellipsoid_stls["outer"], strict_units=True)
    p, t, part = hybrid.ventricle_surface(48, 12)
    f = tmp_path / "lv.vtp"
    f.write_bytes(vtp(p * 1e3, t.tolist(), cell_data={"surface-id": (part.astype(np.int32) + 1)}))
    with pytest.raises(palpate.ParameterError, match="the wall encloses"):
        palpate.build_tagged_file(f, unit="m", inner=1, outer=2, base=3, strict_units=True)
    r = palpate_cli("build", ellipsoid_stls["inner"], ellipsoid_stls["outer"], "--strict-units", "-o", tmp_path / "x.palpate")
    assert r.returncode == 1 and "--unit mm" in r.stderr and not (tmp_path / "x.palpate").exists(), r.stderr
    # In the right unit: no note.
    with warnings.catch_warnings():
        warnings.simplefilter("error", palpate.MeshWarning)
        hybrid._check_scale(1.19e-4, "mm", "x", strict=True)
