"""The indentation reference (``Body.indent``, ``palpate.validate``, issue 33).

- against an independent code: at a small press the reference's equilibrium under its own
  contact forces is scikit-fem's P1 linear elasticity under the same nodal forces (a wrong
  internal force, a contact force not in equilibrium with the body, or a wrong held set fail);
- the contact's bookkeeping: the nodal contact forces sum to minus the force on the sphere, and
  push along the sphere's normals (outward from its centre);
- the graded wall: same topology and volume as the ungraded one, elements smaller toward the
  tool, none inverted;
- the pipeline (``palpate validate indentation`` on tiny meshes): the table's rows, the
  convergence evidence, the files written.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import palpate
from palpate import validate

pytest.importorskip("skfem")
from test_reference_skfem import E, NU, skfem_static  # noqa: E402  (one scikit-fem solve for both tests)


@pytest.fixture(scope="module")
def small_press():
    mesh = validate.graded_ellipsoid_wall(subdivisions=3, layers=2)
    case = validate.IndentCase(hold_z=-0.015)
    fixed = validate.held_below(mesh.points, case.hold_z)
    body = palpate.Body(mesh, palpate.Material(young=E, poisson=NU, density=1000.0), fixed=fixed)
    r = body.indent(case.start(), case.direction, case.tool_radius, [2e-5, 2e-4])
    return mesh, fixed, case, r


def test_the_reference_matches_scikit_fem_under_its_own_contact_forces(small_press):
    mesh, fixed, case, r = small_press
    errors = []
    for k in range(2):
        u = r["positions"][k] - mesh.points
        u_ref = skfem_static(mesh.points, mesh.tets, fixed, r["contact_forces"][k])
        errors.append(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref))
    # First-order agreement (Green strain vs linear), shrinking with the press.
    assert errors[0] < 2e-3, errors
    assert errors[1] < 2e-2, errors
    assert errors[0] < errors[1] / 4, errors


def test_contact_forces_balance_the_sphere_and_push_outward(small_press):
    mesh, fixed, case, r = small_press
    for k in range(2):
        fc = r["contact_forces"][k]
        np.testing.assert_allclose(fc.sum(axis=0), -r["force"][k], atol=1e-12 * np.abs(fc).sum())
        # The body is pushed along the press (into the wall), the sphere back against it.
        assert r["force_along"][k] > 0
        loaded = np.linalg.norm(fc, axis=1) > 1e-6 * np.abs(fc).max()
        centre = case.start() + (r["travel"][k]) * np.asarray(case.direction)
        assert loaded.sum() >= 3
        # Every loaded node is within reach of the sphere.
        assert (np.linalg.norm(r["positions"][k][loaded] - centre, axis=1) < case.tool_radius + 0.01).all()
    assert r["force_along"][1] > r["force_along"][0]
    assert (r["indentation"] <= r["travel"]).all() and (r["penetration"] >= 0).all()


def test_the_graded_wall_is_the_same_wall_finer_under_the_tool():
    plain = palpate.ellipsoid_wall(validate.ELLIPSOIDS_INNER, validate.ELLIPSOIDS_OUTER, subdivisions=4, layers=2)
    graded = validate.graded_ellipsoid_wall(subdivisions=4, layers=2, focus=(1, 0, 0), grading=4.0)
    assert graded.n_tets == plain.n_tets and (graded.tets == plain.tets).all()
    # The same region: the exact shell's volume less the facets' chords (larger where the graded
    # mesh is coarser, opposite the focus).
    exact = 4 / 3 * np.pi * (np.prod(validate.ELLIPSOIDS_OUTER) - np.prod(validate.ELLIPSOIDS_INNER))
    assert 0.95 * exact < graded.volume < plain.volume < exact
    assert graded.min_dihedral_deg > 5.0
    # Elements near the focus are several times smaller than opposite it.
    c = graded.points[graded.tets].mean(axis=1)
    edge = np.linalg.norm(graded.points[graded.tets[:, 0]] - graded.points[graded.tets[:, 1]], axis=1)
    near, far = c[:, 0] > 0.02, c[:, 0] < -0.02
    assert edge[near].mean() * 3 < edge[far].mean()


def test_hertz_force():
    assert validate.hertz_force(1.0, 0.0, 1.0, np.array([1.0]))[0] == pytest.approx(4.0 / 3.0)
    assert validate.hertz_force(E, NU, 0.005, np.array([-1.0]))[0] == 0.0


def test_validate_indentation_cli_writes_the_table_and_files(tmp_path):
    out = tmp_path / "v"
    p = subprocess.run([sys.executable, "-m", "palpate", "validate", "indentation", "ellipsoids", "--levels", "1:1",
                        "2:1", "2:2", "--coarse", "1:1", "--depths", "0.001", "0.002", "--out", str(out), "--quiet"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert "finest FEM | FEM extrapolated | hybrid" in p.stdout and "last change" in p.stdout
    data = json.loads((out / "indentation.json").read_text())
    assert len(data["rows"]) == 2 and len(data["references"]) == 3
    # The references are quadratic tets by default (they converge where linear ones lock).
    assert "quadratic tets" in p.stdout and all(r["order"] == 2 for r in data["references"])
    assert all(r["nodes"] > r["tets"] for r in data["references"]) and data["coarse"]["order"] == 1
    for row in data["rows"]:
        assert row["reference"] > 0 and row["hybrid"] > 0 and row["coarse"] > 0
        assert len(row["dent_hybrid"]) == len(validate.DENT_DISTANCES)
    assert (out / "indentation.png").stat().st_size > 10_000
    # The hybrid again against the same reference, reused: the same reference rows, no solve.
    again = subprocess.run([sys.executable, "-m", "palpate", "validate", "indentation", "ellipsoids", "--depths", "0.001",
                            "0.002", "--reference", str(out / "indentation.json"), "--out", str(tmp_path / "w"),
                            "--quiet"], capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    reused = json.loads((tmp_path / "w" / "indentation.json").read_text())
    assert [r["reference"] for r in reused["rows"]] == [r["reference"] for r in data["rows"]]
    assert [r["tets"] for r in reused["references"]] == [r["tets"] for r in data["references"]]
    assert reused["implicit_exchange"] is True
    # The hybrid with the shell's springs capped (the explicit exchange, for comparison): recorded,
    # and softer (capped far below E h: VALIDATION.md).
    capped = subprocess.run([sys.executable, "-m", "palpate", "validate", "indentation", "ellipsoids", "--depths",
                             "0.001", "0.002", "--reference", str(out / "indentation.json"), "--explicit-exchange",
                             "--out", str(tmp_path / "i"), "--quiet"], capture_output=True, text=True, timeout=600)
    assert capped.returncode == 0, capped.stderr
    soft = json.loads((tmp_path / "i" / "indentation.json").read_text())
    assert soft["implicit_exchange"] is False
    assert all(f["hybrid"] > r["hybrid"] for f, r in zip(reused["rows"], soft["rows"])), (reused["rows"], soft["rows"])
    # ... and refused for another tool (its reference would be another press).
    other = subprocess.run([sys.executable, "-m", "palpate", "validate", "indentation", "ellipsoids", "--tool-radius",
                            "0.006", "--reference", str(out / "indentation.json"), "--out", str(tmp_path / "x")],
                           capture_output=True, text=True, timeout=600)
    assert other.returncode == 1 and "tool_radius" in other.stderr and "anew" in other.stderr


def test_validate_indentation_meshes_a_built_wall_and_checks_its_levels(tmp_path):
    # The synthetic ventricle: the reference meshes are the hybrid build's core taken across the
    # wall, held at the base, as the hybrid is.
    out = tmp_path / "v"
    p = subprocess.run([sys.executable, "-m", "palpate", "validate", "indentation", "ventricle", "--levels", "100:1",
                        "200:1", "--coarse", "60:1", "--depths", "0.001", "--order", "1", "--out", str(out), "--quiet"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    data = json.loads((out / "indentation.json").read_text())
    assert [r["tets"] for r in data["references"]] == [300, 600] and data["coarse"]["tets"] == 180
    assert all(r["order"] == 1 for r in data["references"])
    assert data["rows"][0]["reference"] > 0
    p = subprocess.run([sys.executable, "-m", "palpate", "validate", "indentation", "ellipsoids", "--levels", "4"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "A:LAYERS" in p.stderr


def test_richardson_recovers_a_known_limit_and_order():
    for h, p in (([1.0, 0.5, 0.25], 1.5), ([1.0, 0.6, 0.3], 2.0)):
        h = np.array(h)
        lim, order = validate._richardson(h, 0.3 + 2.0 * h**p)
        assert lim == pytest.approx(0.3, rel=1e-9) and order == pytest.approx(p, rel=1e-9)
    # Differences that do not shrink give no extrapolation.
    assert np.isnan(validate._richardson(np.array([1.0, 0.5, 0.25]), np.array([1.0, 1.1, 1.3]))[0])


def test_the_homogenised_core_carries_the_wall_the_papers_core_did_not():
    # Issue 33, items 1 and 4's direction: a 15 mm sphere 2 mm into the ellipsoids. The reference
    # here is the coarsest graded level (3,072 tets, ~46% stiffer than the extrapolated wall:
    # linear tets lock), so the thresholds are loose; what is checked is the order: the default
    # (900-tet core homogenised against the whole wall) carries it, the same core stiff as the
    # tissue renders about half, the paper's 192-tet core a fifth.
    case = validate.IndentCase(tool_radius=0.015, depths=(0.002,))
    ratios = {}
    for name, options in (("default", {}), ("plain", dict(homogenise=False)),
                          ("paper", dict(core_triangles=64, homogenise=False))):
        model = palpate.build_shape("ellipsoids", **options)
        hyb = validate.hybrid_curve(model, case, ramp_s=0.3, hold_s=0.3)
        if name == "default":
            assert hyb["core_stiffening"] > 1.5, hyb["core_stiffening"]
            case.hold_z = hyb["hold_z"]
            mesh, _ = validate.wall_mesh("ellipsoids", 3, 2, case)
            ref = validate.reference_curve(mesh, case, hyb["probes"])
        else:
            assert hyb["core_stiffening"] == 1.0
        at = np.array(case.depths)
        ratios[name] = float(validate._interp(hyb, at)[0] / validate._interp(ref, at)[0])
    # Measured 2026-12-06: default 0.72 (against the extrapolated wall +5%), plain 0.53 (-23%),
    # paper 0.22 (-67%).
    print(ratios)
    assert 0.62 < ratios["default"] < 0.85, ratios
    assert 0.4 < ratios["plain"] < 0.62, ratios
    assert ratios["paper"] < 0.3, ratios


def test_a_simplified_surface_keeps_the_shape_with_fewer_triangles():
    s = palpate.ellipsoid_surface((0.02, 0.02, 0.035), 5)          # 8,192 triangles
    c = s.simplified(1000)
    assert isinstance(c, palpate.TriSurface) and c.n_triangles <= 1000 and c.n_triangles > 500
    assert abs(c.volume / s.volume - 1) < 0.02                      # the shape kept
    # Vertices stay on (near) the ellipsoid: quadric-error collapse moves them along it.
    p = np.asarray(c.points) / np.array([0.02, 0.02, 0.035])
    assert np.abs(np.linalg.norm(p, axis=1) - 1).max() < 0.02
    assert s.simplified(10**6).n_triangles == s.n_triangles       # nothing to remove
    with pytest.raises(palpate.ParameterError, match="at least 4"):
        s.simplified(3)


def test_without_specks_drops_specks_and_keeps_a_cavity():
    big, speck = palpate.ellipsoid_surface((0.02, 0.02, 0.03), 2), palpate.ellipsoid_surface((1e-4, 1e-4, 1e-4), 0)
    pts = np.vstack([np.asarray(speck.points) + 0.019, np.asarray(big.points)])
    tris = np.vstack([np.asarray(speck.triangles), np.asarray(big.triangles) + speck.n_vertices])
    s, kept = palpate.TriSurface(pts, tris).without_specks()
    assert s.n_triangles == big.n_triangles and s.n_vertices == big.n_vertices
    np.testing.assert_array_equal(np.asarray(s.points)[np.asarray(s.triangles)], np.asarray(big.points)[np.asarray(big.triangles)])
    assert kept.dtype == np.int64
    np.testing.assert_array_equal(kept, np.arange(speck.n_triangles, len(tris)))
    # Kept at a fraction below the speck's volume (1e-12 / 5e-5 of the big one's).
    assert palpate.TriSurface(pts, tris).without_specks(1e-9)[0].n_triangles == len(tris)
    # A hollow wall's cavity (an inward piece) is no speck.
    inner = palpate.ellipsoid_surface((0.015, 0.015, 0.025), 2)
    wall = palpate.TriSurface(np.vstack([np.asarray(big.points), np.asarray(inner.points)]),
                              np.vstack([np.asarray(big.triangles), np.asarray(inner.triangles)[:, ::-1] + big.n_vertices]))
    assert wall.without_specks()[0].n_triangles == wall.n_triangles
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(palpate.ParameterError, match="min_volume_fraction"):
            wall.without_specks(bad)


def _gmsh_or_skip():
    try:
        import gmsh  # noqa: F401
    except (ImportError, OSError) as e:
        pytest.skip(f"gmsh not importable: {e}")


def test_gmsh_fills_a_closed_surface_keeping_it():
    _gmsh_or_skip()
    s = palpate.ellipsoid_surface((0.02, 0.02, 0.035), 3)
    m = validate.gmsh_wall(s)
    # gmsh sets SIGPIPE back to the default in the whole process; gmsh_wall restores Python's
    # "ignore" (a CI run was killed by SIGPIPE in the viewer's tests after this one).
    from conftest import _sigpipe_ignored

    assert _sigpipe_ignored() is not False
    # The boundary is the surface as given (the same triangles), so the volume is the surface's.
    assert len(m.boundary_faces()) == s.n_triangles
    assert abs(m.volume / s.volume - 1) < 1e-9
    coarse = validate.gmsh_wall(s, 128)
    assert len(coarse.boundary_faces()) <= 128 and coarse.n_tets < m.n_tets
    # A surface that crosses itself is refused by name (two overlapping closed pieces).
    pts = np.vstack([np.asarray(s.points), np.asarray(s.points) + 0.005])
    tris = np.vstack([np.asarray(s.triangles), np.asarray(s.triangles) + s.n_vertices])
    with pytest.raises(palpate.PalpateError):
        validate.gmsh_wall(palpate.TriSurface(pts, tris))


def test_rodero_wall_levels_halve_the_element_size(lv_path):
    # Rodero's reference meshes (issue 33 item 5): the data's closed surface without its two
    # specks, simplified and filled by gmsh; each level 4-8x the last's tets (measured 5.0x), the
    # coarse FEM about the hybrid core's 900 tets, each mesh's volume the surface's within 1% (the
    # coarse one, 600 triangles, measured 0.6% less).
    _gmsh_or_skip()
    surface, base = validate.rodero_surface()
    assert surface.n_triangles == 100_316
    case = validate.IndentCase(shape="rodero")
    walls = [validate.wall_mesh("rodero", *validate.default_coarse("rodero"), case)]
    walls += [validate.wall_mesh("rodero", a, b, case) for a, b in validate.GMSH_LEVELS[:2]]
    counts = [m.n_tets for m, _ in walls]
    assert 700 <= counts[0] <= 1100, counts
    assert all(4 <= b / a <= 8 for a, b in zip(counts[1:], counts[2:])), counts
    # Held at the base, as the hybrid: the held nodes lie within 2 mm of the base's points and
    # there are more of them on a finer mesh; none on the apex side.
    from scipy.spatial import cKDTree

    apex_far = np.linalg.norm(base.mean(axis=0) - np.asarray(surface.points), axis=1).max()
    held_counts = []
    for m, held in walls:
        assert abs(m.volume / surface.volume - 1) < 0.01
        d, _ = cKDTree(base).query(np.asarray(m.points)[held])
        assert len(held) >= 6 and d.max() < 2e-3, (len(held), d.max())
        assert np.linalg.norm(np.asarray(m.points)[held] - base.mean(axis=0), axis=1).max() < 0.5 * apex_far
        held_counts.append(len(held))
    assert held_counts[0] < held_counts[1] < held_counts[2], held_counts


def test_the_contact_is_as_stiff_whatever_the_skin_tessellation():
    # Issue 33 item 2: the tool meets the skin with a penalty per unit area, so a skin 2x finer
    # in edge length (4x the vertices) feels the same. Measured 2026-12-07, a 5 mm sphere on the
    # paper's ellipsoids (1.15 mm lattice) at 2 mm of travel, outer surface at 1,026 / 4,098 /
    # 16,386 vertices: force 0.088 / 0.092 / 0.090 N, the tool sank 0.31 / 0.16 / 0.17 mm
    # (per point, 60 N/m each, it had been 32% apart in force and 0.16-1.6 mm in sink). The
    # coarsest skin's vertices (11 mm^2) are capped at 2.5 squared spacings (3.3 mm^2,
    # runtime::sim::SKIN_AREA_CAP_SPACINGS2): its contact is softer per area, its force not.
    from palpate.hybrid import ELLIPSOIDS_INNER, ELLIPSOIDS_OUTER

    inner = palpate.ellipsoid_surface(ELLIPSOIDS_INNER, 5)
    case = validate.IndentCase(depths=(0.002,))
    runs = {}
    for sub in (4, 5, 6):
        m = palpate.HybridModel.build_nested(inner, palpate.ellipsoid_surface(ELLIPSOIDS_OUTER, sub))
        c = validate.hybrid_curve(m, case, ramp_s=0.3, hold_s=0.3)
        runs[sub] = (c["force"][0], c["penetration"][0], c["indentation"][0])
    (f4, pen4, ind4), (f5, pen5, ind5), (f6, pen6, ind6) = runs[4], runs[5], runs[6]
    assert abs(f5 / f6 - 1) < 0.08 and abs(f4 / f5 - 1) < 0.08, runs
    assert pen5 < 1.5 * pen6 and pen6 < 1.5 * pen5, runs
    # The contact adds little compliance: the tool sinks under a tenth of the indentation (under
    # a fifth into the capped coarse skin).
    assert pen5 < 0.1 * ind5 and pen6 < 0.1 * ind6 and pen4 < 0.2 * ind4, runs


def test_no_plot_without_matplotlib(tmp_path, monkeypatch, capsys):
    # The validate extra does not install matplotlib: the plot is skipped and said so (the
    # table and indentation.json are the result), not a crash after the run.
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)   # import matplotlib -> ImportError
    path = tmp_path / "indentation.png"
    assert validate.plot({"references": []}, str(path)) is None
    assert not path.exists() and "matplotlib not installed: no indentation.png" in capsys.readouterr().out


@pytest.fixture(scope="module")
def slab():
    """Issue 33 item 3's slab: 80 x 80 x 40 mm held at its sides (the runtime holds the core's
    nodes on the base part), the bottom free; the core takes 0.85 of the height, so the top 6 mm
    are particles (about 28,000, 1.09 mm apart), and the build's automatic layers make its 34 mm
    five prisms tall (4,500 tets). Built without homogenisation (its factor on this slab is 0.96,
    within 1% of the force: VALIDATION.md)."""
    points, tris, parts = validate.slab_surface(0.08, 0.04, 50)
    return palpate.HybridModel.build_tagged(points, tris, parts, core_fraction=0.85, homogenise=False)


def test_the_core_is_layered_to_tets_about_as_tall_as_wide(slab):
    # The build's automatic layers (core_layers = 0): the slab's 34 mm core under 300 triangles
    # about 7 mm wide takes five layers (one layer of prisms five times as tall as wide made a
    # 15 mm sphere's force 31% above Hertz at 3.1 mm, five 11%: VALIDATION.md); a ventricle's core,
    # thinner than wide, one.
    def layers(m):
        return len(m.core_tets) // (3 * len(m.core_faces))

    assert layers(slab) == 5, len(slab.core_tets)
    points, tris, parts = validate.slab_surface(0.08, 0.04, 50)
    assert layers(palpate.HybridModel.build_tagged(points, tris, parts, core_fraction=0.85, homogenise=False,
                                                   core_layers=2, particles=2000)) == 2
    from palpate.hybrid import build_shape
    assert layers(build_shape("ellipsoids", particles=2000, homogenise=False)) == 1


def _slab_press(model, radius, travels, young=E, implicit_exchange=True):
    case = validate.IndentCase(shape="slab", tool_radius=radius, point=(0.0, 0.0, 0.04), direction=(0.0, 0.0, -1.0),
                               depths=tuple(travels), young=young)
    hyb = validate.hybrid_curve(model, case, ramp_s=0.3, hold_s=0.3, implicit_exchange=implicit_exchange)
    # (hybrid_curve adds a travel 30% past the deepest.)
    d, f = np.asarray(hyb["indentation"]), np.asarray(hyb["force"])
    return d, f, validate.hertz_force(young, NU, radius, d)


@pytest.fixture(scope="module")
def slab_presses(slab):
    """The slab pressed by a 7.5 and a 15 mm sphere (travels 2 / 3 mm and 3.4 / 4.4 mm, and 30%
    past the deepest), the shell's springs at the tissue's stiffness (``implicit_exchange``):
    {radius: (indentation, force, Hertz)}."""
    return {radius: _slab_press(slab, radius, travels) for radius, travels in ((0.0075, (0.002, 0.003)),
                                                                               (0.015, (0.0034, 0.0044)))}


def test_a_sphere_on_the_hybrid_slab_follows_hertz(slab, slab_presses):
    # Issue 33 item 3 (VALIDATION.md, "Hertz on a hybrid slab"), with the implicit exchange (the
    # shell's springs at the tissue's stiffness; the default's capped springs: the xfail below).
    # The slab's own converged FEM
    # follows Hertz here (15 mm sphere, 129k tets: +12 / +8 / +4 / +3% at 0.8-4.5 mm, converging
    # toward it). Measured 2026-12-07 with this test's set-up: 7.5 mm sphere +13 / +2 / -4% at 1.84 /
    # 2.80 / 3.64 mm of indentation (3.4 / 4.2 / 4.8 spacings of contact radius); 15 mm sphere
    # +11 / -0 / -10% at 3.15 / 4.15 / 5.46 mm (6.3 / 7.2 / 8.3 spacings). Shallower presses of the
    # 15 mm sphere are not yet within the bound (the xfail below).
    for radius, (d, f, hertz) in slab_presses.items():
        a = np.sqrt(radius * d) / slab.spacing
        assert (a >= 3.0).all(), a
        err = f / hertz - 1.0
        assert (np.abs(err) <= 0.15).all(), (radius, d, f, hertz, err)


@pytest.mark.xfail(strict=True, reason="issue 33: with the default, capped shell springs the slab is 10-23% softer than "
                                       "Hertz (VALIDATION.md)")
def test_the_default_exchange_follows_hertz_on_the_slab(slab):
    # The default HybridSim caps the springs tying the shell to the core (10 N/m here against the
    # tissue's E h = 33 N/m) for the explicit exchange's stability; with the core's automatic
    # layers the slab is then too soft (measured 2026-12-07: 7.5 mm sphere -17 / -19 / -23% at
    # 1.86 / 2.83 / 3.68 mm). With one layer of 34 mm prisms it was within 8%: two errors
    # cancelling.
    d, f, hertz = _slab_press(slab, 0.0075, (0.002, 0.003), implicit_exchange=False)
    err = f / hertz - 1.0
    assert (np.abs(err) <= 0.15).all(), (d, f, hertz, err)


@pytest.mark.xfail(strict=True, reason="issue 33: a 15 mm sphere's shallow press on the slab is 20-28% above Hertz "
                                       "at 4-5.4 spacings of contact radius (VALIDATION.md)")
def test_a_large_sphere_at_a_shallow_press_follows_hertz(slab):
    # Measured 2026-12-07: +28 / +20% at 1.40 / 2.29 mm (4.2 / 5.4 spacings). The slab's own FEM
    # is +12 / +8% at 0.8 / 1.7 mm on 129k tets: a shallow press of a large sphere asks much of
    # any discretisation; here the coarse core under a 6 mm shell carries the stress bulb's deep
    # part.
    d, f, hertz = _slab_press(slab, 0.015, (0.0015,))
    assert (np.sqrt(0.015 * d) / slab.spacing >= 3.0).all()
    err = f / hertz - 1.0
    assert (np.abs(err) <= 0.15).all(), (d, f, hertz, err)


def test_the_hybrid_slabs_force_grows_as_the_square_root_of_the_radius(slab_presses):
    # Hertz: at a given indentation F is proportional to sqrt(R). The 15 mm curve (log-log
    # between its points) at the 7.5 mm sphere's deepest indentation, against sqrt(2) times the
    # 7.5 mm force, corrected by the exact sphere's (Sneddon's) departure from Hertz at each d / R.
    # Measured 2026-12-07 with the implicit exchange: 1.067 (the default's capped springs 1.087;
    # with them and a one-layer core, 1.12).
    (d1, f1, _), (d2, f2, _) = slab_presses[0.0075], slab_presses[0.015]
    at = d1[-1]
    assert d2[0] <= at <= d2[-1], (d1, d2)
    f15 = np.exp(np.interp(np.log(at), np.log(d2), np.log(f2)))
    ratio = f15 / f1[-1] / (np.sqrt(2.0) * _sneddon_over_hertz(0.015, at) / _sneddon_over_hertz(0.0075, at))
    assert ratio == pytest.approx(1.0, abs=0.10), ratio


def _sneddon_over_hertz(radius, d):
    """The exact rigid sphere's force (Sneddon 1965) over Hertz's at indentation ``d``."""
    from scipy.optimize import brentq
    a = brentq(lambda a: a / 2 * np.log((radius + a) / (radius - a)) - d, 1e-12, radius * (1 - 1e-12))
    sneddon = 0.5 * ((a * a + radius * radius) * np.log((radius + a) / (radius - a)) - 2 * a * radius)
    return sneddon / (4.0 / 3.0 * np.sqrt(radius) * d**1.5)


def test_the_hybrid_slabs_force_is_proportional_to_e(slab):
    # Hertz: F proportional to E at a given indentation; so is every stiffness of the model with
    # the implicit exchange, the coupling springs (`E h`) included. Measured 2026-12-07: 2.000.
    # (The default caps the springs by the explicit exchange's stability, 10 N/m against E h = 33
    # N/m, and gives 1.77-1.82.)
    d1, f1, _ = _slab_press(slab, 0.0075, (0.0015,), young=E)
    d2, f2, _ = _slab_press(slab, 0.0075, (0.0015,), young=2 * E)
    ratio = (f2 / f1) * (d1 / d2) ** 1.5  # at the same indentation (Hertz's d^1.5)
    assert ratio == pytest.approx(2.0, rel=0.02), (d1, d2, f1, f2)
