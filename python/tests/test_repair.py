"""palpate.repair_surface: orientation, non-manifold edge / vertex splitting, duplicate and
zero-area triangles; the repair= keyword of read_tagged_surface / load_surface / read_surface_arrays;
the real Rodero et al. left ventricle made acceptable to palpate.TriSurface."""
import time
import warnings

import numpy as np
import pytest

import palpate
from vtpwrite import OCTA_POINTS, OCTA_TAGS, OCTA_TRIS, vtp

# unit cube, outward
CUBE_POINTS = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
CUBE_TRIS = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def _tet(a, b, c, d):
    """Triangles of the tetrahedron (a, b, c, d): outward if d lies on the side of the plane
    a, b, c that a -> b -> c turns counter-clockwise about (inward otherwise)."""
    return [[a, c, b], [a, b, d], [b, c, d], [c, a, d]]


def _volume(p, t):
    return np.einsum("ij,ij->i", p[t[:, 0]], np.cross(p[t[:, 1]], p[t[:, 2]])).sum() / 6


def _edge_counts(t):
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)[1]


def test_cube_fixture_is_valid():
    s = palpate.TriSurface(CUBE_POINTS, CUBE_TRIS)
    assert s.volume == pytest.approx(1.0)


def test_clean_surface_unchanged():
    p, t, part, rep = palpate.repair_surface(CUBE_POINTS, CUBE_TRIS, np.arange(12))
    np.testing.assert_array_equal(p, CUBE_POINTS)
    np.testing.assert_array_equal(t, CUBE_TRIS)
    np.testing.assert_array_equal(part, np.arange(12))
    assert rep == {"flipped": 0, "components": 1, "split_vertices": 0, "added_vertices": 0,
                   "nonmanifold_edges": [], "removed_triangles": 0, "duplicate_triangles": 0,
                   "zero_area_triangles": 0}
    assert palpate.surfaces.repair_summary(rep) is None


def test_flipped_triangle_in_cube():
    bad = CUBE_TRIS.copy()
    bad[5] = bad[5][::-1]
    with pytest.raises(palpate.SurfaceError):
        palpate.TriSurface(CUBE_POINTS, bad)
    p, t, part, rep = palpate.repair_surface(CUBE_POINTS, bad)
    assert part is None
    assert rep["flipped"] == 1 and rep["components"] == 1 and rep["added_vertices"] == 0
    np.testing.assert_array_equal(t, CUBE_TRIS)
    assert palpate.TriSurface(p, t).volume == pytest.approx(1.0)


def test_inside_out_sphere():
    sphere = palpate.ellipsoid_surface((0.02, 0.02, 0.03), subdivisions=3)
    p0, t0 = sphere.points, sphere.triangles
    p, t, _, rep = palpate.repair_surface(p0, t0[:, ::-1])
    assert rep["flipped"] == len(t0) and rep["components"] == 1
    assert rep["nonmanifold_edges"] == [] and rep["added_vertices"] == 0
    np.testing.assert_array_equal(np.sort(t, axis=1), np.sort(t0, axis=1))
    assert _volume(p, t) > 0
    assert palpate.TriSurface(p, t).volume == pytest.approx(sphere.volume, rel=1e-12)


def test_two_tets_sharing_an_edge_are_split():
    # tets (0, 1, 2, 3) and (0, 1, 4, 5) share the edge (0, 1); the second is stored inside out
    p0 = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 0.4, 1],
                   [0.5, -1, 0], [0.5, -0.4, -1]], dtype=float)
    t0 = np.array(_tet(0, 1, 2, 3) + _tet(0, 4, 1, 5))
    part0 = np.array([0, 0, 0, 0, 1, 1, 1, 1], dtype=np.int8)
    assert sorted(_edge_counts(t0).tolist()) == [2] * 10 + [4]
    with pytest.raises(palpate.SurfaceError):
        palpate.TriSurface(p0, t0)
    p, t, part, rep = palpate.repair_surface(p0, t0, part0)
    assert rep["nonmanifold_edges"] == [(0, 1, 4)]
    assert rep["flipped"] == 4 and rep["components"] == 2
    assert rep["split_vertices"] == 2 and rep["added_vertices"] == 2
    assert len(p) == 8 and len(t) == 8
    np.testing.assert_array_equal(p[:6], p0)
    np.testing.assert_array_equal(p[6:], p0[[0, 1]])          # copies of 0 and 1, appended
    np.testing.assert_array_equal(part, part0)                # triangle order unchanged
    # each tet keeps or gets its own copy of the shared edge; vertices 2..5 untouched
    first, second = set(t[:4].ravel()), set(t[4:].ravel())
    assert first == {0, 1, 2, 3} and second == {6, 7, 4, 5}
    assert (_edge_counts(t) == 2).all()
    s = palpate.TriSurface(p, t)
    assert s.volume == pytest.approx(abs(_volume(p0, t0[:4])) + abs(_volume(p0, t0[4:])))


def test_two_tets_sharing_a_vertex_are_split():
    p0 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1],
                   [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)
    t0 = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [0, 4, 5], [0, 6, 4], [0, 5, 6], [4, 6, 5]])
    assert _volume(p0, t0[:4]) > 0 and _volume(p0, t0[4:]) > 0    # every edge manifold; vertex 0 is not
    p, t, _, rep = palpate.repair_surface(p0, t0)
    assert rep["nonmanifold_edges"] == [] and rep["flipped"] == 0
    assert rep["split_vertices"] == 1 and rep["added_vertices"] == 1
    np.testing.assert_array_equal(t[:4], t0[:4])
    assert (t[4:] == 7).sum() == 3 and (t[4:] == 0).sum() == 0
    assert "split 1 non-manifold vertex" in palpate.surfaces.repair_summary(rep)
    assert palpate.TriSurface(p, t).volume == pytest.approx(2 / 6)


def test_duplicate_and_zero_area_triangles_removed():
    p0 = np.vstack([CUBE_POINTS, [[0.5, 0.5, 0.5]]])
    t0 = np.vstack([CUBE_TRIS[:3], [[3, 1, 0]], CUBE_TRIS[3:7], [[4, 4, 2]], CUBE_TRIS[7:],
                    [[0, 7, 8]], CUBE_TRIS[[0]]])             # duplicate (reversed), repeated vertex, collinear, duplicate
    part0 = np.arange(len(t0))
    p, t, part, rep = palpate.repair_surface(p0, t0, part0)
    assert rep["duplicate_triangles"] == 2 and rep["zero_area_triangles"] == 2 and rep["removed_triangles"] == 4
    np.testing.assert_array_equal(t, CUBE_TRIS)
    np.testing.assert_array_equal(part, [0, 1, 2, 4, 5, 6, 7, 9, 10, 11, 12, 13])
    assert "removed 2 duplicate and 2 zero-area" in palpate.surfaces.repair_summary(rep)


def test_bad_input():
    with pytest.raises(ValueError, match="shape"):
        palpate.repair_surface(np.zeros((3, 2)), [[0, 1, 2]])
    with pytest.raises(ValueError, match="indices"):
        palpate.repair_surface(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(ValueError, match="part"):
        palpate.repair_surface(CUBE_POINTS, CUBE_TRIS, np.zeros(3))


# --- the repair= keyword ---------------------------------------------------------------------

def test_read_tagged_surface_repairs_and_warns(tmp_path):
    t_bad = np.array(OCTA_TRIS)
    t_bad[[1, 4]] = t_bad[[1, 4]][:, ::-1]
    path = tmp_path / "flipped.vtp"
    path.write_bytes(vtp(OCTA_POINTS, t_bad.tolist(), cell_data={"surface-id": np.array(OCTA_TAGS, dtype=np.int32)}))
    with pytest.warns(palpate.MeshWarning, match=r"flipped.vtp: repaired the surface: re-oriented 2 triangle") as rec:
        p, t, part = palpate.read_tagged_surface(path, unit="mm")
    assert len(rec) == 1
    np.testing.assert_array_equal(t, OCTA_TRIS)
    np.testing.assert_array_equal(part, [0, 0, 0, 2, 1, 1, 1, 2])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, t, _ = palpate.read_tagged_surface(path, unit="mm", repair=False)
    np.testing.assert_array_equal(t, t_bad)
    # nothing to repair: no warning
    ok = tmp_path / "ok.vtp"
    ok.write_bytes(vtp(OCTA_POINTS, OCTA_TRIS, cell_data={"surface-id": np.array(OCTA_TAGS, dtype=np.int32)}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, t, _ = palpate.read_tagged_surface(ok, unit="mm")
    np.testing.assert_array_equal(t, OCTA_TRIS)


def test_load_surface_repair_keyword(tmp_path):
    import meshio

    p0 = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 0.4, 1],
                   [0.5, -1, 0], [0.5, -0.4, -1]], dtype=float)
    t0 = np.array(_tet(0, 1, 2, 3) + [tri[::-1] for tri in _tet(0, 4, 1, 5)])
    path = tmp_path / "bowtie.obj"
    meshio.write(str(path), meshio.Mesh(p0, [("triangle", t0)]))
    with pytest.raises(palpate.SurfaceError, match="bowtie.obj"):
        palpate.load_surface(path)                             # repair defaults to False
    with pytest.warns(palpate.MeshWarning, match=r"bowtie.obj: .*split 1 non-manifold edge\(s\) \[\(0, 1\) shared by 4"):
        s = palpate.load_surface(path, unit="mm", repair=True)
    assert s.n_vertices == 8 and s.n_triangles == 8
    assert s.volume == pytest.approx((abs(_volume(p0, t0[:4])) + abs(_volume(p0, t0[4:]))) * 1e-9)
    p, t = palpate.read_surface_arrays(path)
    np.testing.assert_array_equal(t, t0)
    with pytest.warns(palpate.MeshWarning, match="bowtie.obj"):
        p, t = palpate.read_surface_arrays(path, repair=True)
    assert len(p) == 8 and (_edge_counts(t) == 2).all()


# --- the real left ventricle -----------------------------------------------------------------

def test_rodero_repair(lv_path):
    p0, t0, part0 = palpate.read_tagged_surface(lv_path, unit="mm", repair=False)
    times = []
    for _ in range(3):
        t_start = time.perf_counter()
        p, t, part, rep = palpate.repair_surface(p0, t0, part0)
        times.append(time.perf_counter() - t_start)
    print(f"\nRodero LV repair: best {min(times) * 1e3:.0f} ms of 3; {rep}")
    assert rep == {"flipped": 7040, "components": 3, "split_vertices": 4, "added_vertices": 4,
                   "nonmanifold_edges": [(157, 1366, 4), (1116, 1118, 4)], "removed_triangles": 0,
                   "duplicate_triangles": 0, "zero_area_triangles": 0}
    assert min(times) < 2.0                                    # ~0.2 s measured; generous for shared CPUs
    assert len(p) == len(p0) + 4 and len(t) == len(t0)
    np.testing.assert_array_equal(p[len(p0):], p0[[157, 1116, 1118, 1366]])
    np.testing.assert_array_equal(part, part0)
    assert (_edge_counts(t) == 2).all()
    s = palpate.TriSurface(p, t, source=lv_path.name)          # accepted: no SurfaceError
    assert s.volume * 1e6 == pytest.approx(163.3, abs=0.5)     # mL
    assert np.bincount(part).tolist() == [35339, 63265, 1720]  # inner, outer, base


def test_rodero_read_tagged_surface_default(lv_path):
    with pytest.warns(palpate.MeshWarning) as rec:
        p, t, part = palpate.read_tagged_surface(lv_path, unit="mm")
    msgs = [str(w.message) for w in rec if issubclass(w.category, palpate.MeshWarning)]
    assert len(msgs) == 1
    assert msgs[0].startswith("rodero_01_leftventricle_surface.vtp: repaired the surface: re-oriented 7040 triangle")
    assert "(157, 1366) shared by 4 triangles, (1116, 1118) shared by 4 triangles" in msgs[0]
    s = palpate.TriSurface(p, t)
    assert s.volume * 1e6 == pytest.approx(163.3, abs=0.5)
    assert np.bincount(part).tolist() == [35339, 63265, 1720]
