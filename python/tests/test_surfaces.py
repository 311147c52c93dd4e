"""Triangle surfaces: validation errors, inside tests, lattice sampling, surface files (meshio)."""
import warnings

import meshio
import numpy as np
import pytest

import palpate

CUBE_POINTS = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float)
CUBE_TRIS = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])


def test_cube_surface():
    s = palpate.TriSurface(CUBE_POINTS, CUBE_TRIS)
    assert (s.n_vertices, s.n_triangles, len(s)) == (8, 12, 12)
    assert s.volume == pytest.approx(1.0) and s.area == pytest.approx(6.0)
    lo, hi = s.bounding_box
    np.testing.assert_array_equal(lo, 0.0)
    np.testing.assert_array_equal(hi, 1.0)
    assert s.contains([0.5, 0.5, 0.5]) is True and s.contains((2, 0, 0)) is False
    q = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [0.1, 0.9, 0.2]])
    np.testing.assert_array_equal(s.contains(q), [True, False, True])
    np.testing.assert_array_equal(s.contains(q, method="parity"), [True, False, True])
    np.testing.assert_allclose(s.winding_number(q), [1, 0, 1], atol=1e-12)
    assert s.winding_number([0.5, 0.5, 0.5]) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="method"):
        s.contains(q, method="ray")
    np.testing.assert_array_equal(s.triangles, CUBE_TRIS)
    assert "TriSurface(n_vertices=8" in repr(s)


def test_inward_surface_is_reversed_with_warning():
    with pytest.warns(palpate.MeshWarning, match="oriented inward .* reversed all 12 triangles"):
        s = palpate.TriSurface(CUBE_POINTS, CUBE_TRIS[:, ::-1], source="inside_out.stl")
    assert s.volume == pytest.approx(1.0)
    np.testing.assert_array_equal(s.triangles, CUBE_TRIS[:, [2, 0, 1]])


def _with(tris=None, points=None):
    return (CUBE_POINTS if points is None else points), (CUBE_TRIS if tris is None else tris)


@pytest.mark.parametrize("case, match, triangle, vertex", [
    ("nan", r"vertex 3: non-finite coordinate", None, 3),
    ("index", r"triangle 5: vertex index 9 out of range \(surface has 8 vertices\)", 5, None),
    ("negative", r"triangle 5: vertex index -1 out of range", 5, None),
    ("repeated", r"triangle 4: vertex 1 appears twice", 4, 1),
    ("degenerate", r"triangle 12: degenerate \(area", 12, None),
    ("duplicate", r"triangle 12: duplicate of triangle 1", 12, None),
    ("open", r"open surface: edge \(\d, \d\) of triangle \d+ belongs to no other triangle", None, None),
    ("flipped", r"non-manifold \(inconsistent orientation\): edge .* triangle 7", None, None),
    ("fin", r"non-manifold: edge \(0, 1\) is shared by 4 triangles", 0, None),
    ("empty", r"empty surface: no triangles", None, None),
])
def test_malformed_surfaces(case, match, triangle, vertex):
    p, t = CUBE_POINTS.copy(), CUBE_TRIS.copy()
    if case == "nan":
        p[3, 1] = np.nan
    elif case == "index":
        t[5, 2] = 9
    elif case == "negative":
        t[5, 2] = -1
    elif case == "repeated":
        t[4] = [1, 1, 4]
    elif case == "degenerate":
        p = np.vstack([p, [0.5, 0, 0]])
        t = np.vstack([t, [0, 8, 1]])
    elif case == "duplicate":
        t = np.vstack([t, [2, 1, 3]])
    elif case == "open":
        t = np.delete(t, 2, axis=0)
    elif case == "flipped":
        t[7] = t[7, ::-1]
    elif case == "fin":
        p = np.vstack([p, [0.5, -1, -1], [0.5, -1, -0.5]])
        t = np.vstack([t, [0, 1, 8], [1, 0, 9]])
    elif case == "empty":
        t = np.zeros((0, 3), dtype=np.int64)
    with pytest.raises(palpate.SurfaceError, match=match) as e:
        palpate.TriSurface(p, t)
    assert isinstance(e.value, palpate.MeshError) and isinstance(e.value, palpate.PalpateError)
    if triangle is not None:
        assert e.value.triangle == triangle
    if vertex is not None:
        assert e.value.vertex == vertex
    if case == "flipped":
        assert e.value.triangle is not None


def test_surface_argument_errors():
    with pytest.raises(ValueError, match=r"triangles must have shape \(m, 3\)"):
        palpate.TriSurface(CUBE_POINTS, CUBE_TRIS[:, :2])
    with pytest.raises(TypeError, match="triangles must be an integer array"):
        palpate.TriSurface(CUBE_POINTS, CUBE_TRIS.astype(float))
    with pytest.raises(ValueError, match=r"points must have shape \(n, 3\)"):
        palpate.TriSurface(CUBE_POINTS[:, :2], CUBE_TRIS)


def test_ellipsoid_surface_volume_converges():
    a, b, c = 0.02, 0.03, 0.05
    exact = 4 / 3 * np.pi * a * b * c
    errs = [abs(palpate.ellipsoid_surface((a, b, c), s).volume - exact) / exact for s in range(1, 6)]
    assert all(e2 < e1 / 3 for e1, e2 in zip(errs, errs[1:])), errs
    s = palpate.ellipsoid_surface((a, b, c), 3)
    assert s.n_triangles == 8 * 4 ** 3 and s.n_vertices == 4 * 4 ** 3 + 2
    with pytest.raises(ValueError, match="semi_axes"):
        palpate.ellipsoid_surface((0.0, 1.0, 1.0))


def test_sample_inside_sphere():
    r = 0.01
    sphere = palpate.ellipsoid_surface((r, r, r), 5)
    exact = 4 / 3 * np.pi * r ** 3
    errs = []
    for div in (4, 16, 40):
        s = r / div
        pos, m = palpate.sample_inside(sphere, s, 1000.0)
        assert pos.dtype == np.float64 and pos.shape == (len(m), 3)
        np.testing.assert_allclose(m, 1000.0 * s ** 3)
        assert (np.linalg.norm(pos, axis=1) < r).all()
        errs.append(abs(len(m) * s ** 3 - exact) / exact)
    assert errs[-1] < 0.02 and errs[-1] < errs[0], errs
    with pytest.raises(ValueError, match="spacing"):
        palpate.sample_inside(sphere, 0.0, 1000.0)
    with pytest.raises(ValueError, match="density"):
        palpate.sample_inside(sphere, 1e-3, -1.0)
    with pytest.raises(ValueError, match="lattice would have"):
        palpate.sample_inside(sphere, 1e-8, 1000.0)


def test_sample_between_shell():
    inner = palpate.ellipsoid_surface((0.020, 0.020, 0.035), 3)
    outer = palpate.ellipsoid_surface((0.026, 0.026, 0.042), 3)
    pos, m = palpate.sample_between(inner, outer, 2e-3, 1000.0)
    assert len(m) > 1000
    assert outer.contains(pos).all()
    assert not inner.contains(pos).any()
    # the parity test (what the sampler uses) agrees with the winding number on the whole lattice
    lo, hi = outer.bounding_box
    g = np.random.default_rng(3).uniform(lo, hi, size=(3000, 3))
    np.testing.assert_array_equal(outer.contains(g), outer.contains(g, method="parity"))
    with pytest.raises(palpate.SurfaceError, match="inner surface vertex 0 .* lies outside the outer surface") as e:
        palpate.sample_between(outer, inner, 2e-3, 1000.0)
    assert e.value.vertex == 0


# --- files -------------------------------------------------------------------------------------

@pytest.mark.parametrize("ext, kw", [(".stl", {"binary": False}), (".stl", {"binary": True}), (".obj", {}),
                                     (".ply", {}), (".off", {}), (".vtk", {}), (".vtu", {})])
def test_load_surface_formats(tmp_path, ext, kw):
    s = palpate.ellipsoid_surface((20.0, 20.0, 35.0), 2)          # in mm
    path = tmp_path / f"lv{ext}"
    meshio.write(str(path), meshio.Mesh(s.points, [("triangle", s.triangles)]), **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error", palpate.MeshWarning)
        loaded = palpate.load_surface(path, unit="mm")
    assert loaded.n_triangles == s.n_triangles
    assert loaded.volume == pytest.approx(s.volume * 1e-9, rel=1e-5)   # float32 in binary STL
    assert loaded.contains([0.0, 0.0, 0.0])


def test_load_surface_errors(tmp_path):
    with pytest.raises(palpate.SurfaceError, match=r"nope.stl: no such file"):
        palpate.load_surface(tmp_path / "nope.stl")
    (tmp_path / "x.msh").write_text("")
    with pytest.raises(palpate.SurfaceError, match=r"x.msh: unsupported surface format '.msh'"):
        palpate.load_surface(tmp_path / "x.msh")
    (tmp_path / "empty.obj").write_text("")
    with pytest.raises(palpate.SurfaceError, match=r"empty.obj: empty file"):
        palpate.load_surface(tmp_path / "empty.obj")
    (tmp_path / "junk.stl").write_text("solid junk\n facet normal what\n")
    with pytest.raises(palpate.SurfaceError, match=r"junk.stl: cannot read as STL"):
        palpate.load_surface(tmp_path / "junk.stl")
    # quads
    quads = tmp_path / "quads.obj"
    pts = CUBE_POINTS
    meshio.write(str(quads), meshio.Mesh(pts, [("quad", np.array([[0, 2, 3, 1], [4, 5, 7, 6]]))]))
    with pytest.raises(palpate.SurfaceError, match=r"quads.obj: cells of type 'quad' \(2 of them\) are not triangles"):
        palpate.load_surface(quads)
    # a tetrahedral mesh
    vol = tmp_path / "tets.vtu"
    meshio.write(str(vol), meshio.Mesh(pts[:4], [("tetra", np.array([[0, 1, 2, 3]]))]))
    with pytest.raises(palpate.SurfaceError, match=r"tets.vtu: cells of type 'tetra' .*palpate.load_mesh"):
        palpate.load_surface(vol)
    # an open surface names the file and the edge
    openf = tmp_path / "open.stl"
    meshio.write(str(openf), meshio.Mesh(pts, [("triangle", CUBE_TRIS[1:])]), binary=False)
    with pytest.raises(palpate.SurfaceError, match=r"open.stl: open surface: edge \(\d, \d\) of triangle"):
        palpate.load_surface(openf)
    with pytest.raises(ValueError, match="unit must be one of"):
        palpate.load_surface(openf, unit="inch")
