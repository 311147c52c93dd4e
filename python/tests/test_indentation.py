"""The sphere-indentation contact of bench/indentation.py (issue 12, VALIDATION.md "Sphere
indentation"), on the two small protocol meshes.

What a wrong implementation would do: push the tool in with a force that does not grow with the
depth, or pull (negative force); spread the point forces to the nodes with weights that do not sum
to one (the nodes would carry a different force than the tool); report a curve that depends on
the penalty (force against travel instead of against indentation, or penetration not subtracted);
mis-measure the first contact; leave the Newton iteration unconverged; get the sign or scale of the
linear compliance wrong (then the small-depth answer differs from the linear contact solution).
"""
import sys

import numpy as np
import pytest

from conftest import REPO, needs_shared

sys.path.insert(0, str(REPO / "bench"))
indentation = pytest.importorskip("indentation")

pytestmark = needs_shared

DEPTHS = [1e-3, 3e-3]


@pytest.fixture(scope="module")
def curves():
    out = {}
    for name in ["190", "1350"]:
        fem = indentation.FemIndenter(name, verbose=False)
        out[name] = (fem, fem.curve(DEPTHS, verbose=False))
    return out


def test_first_contact_geometry():
    P, n = indentation.probe()
    assert indentation.first_contact(P[None, :]) == pytest.approx(0.0, abs=1e-12)
    assert indentation.first_contact((P + 1e-3 * n)[None, :]) == pytest.approx(1e-3, abs=1e-12)
    # a point 3 mm off the axis is met later, by sqrt(R^2 - 3^2) less of the sphere's height
    side = np.cross(n, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    t = indentation.first_contact((P + 3e-3 * side)[None, :])
    assert t == pytest.approx(indentation.R_TOOL - np.sqrt(indentation.R_TOOL ** 2 - 9e-6), abs=1e-12)


def test_force_positive_growing_and_converged(curves):
    for name, (fem, rows) in curves.items():
        f = [r["force"] for r in rows]
        assert all(r["converged"] for r in rows), name
        assert f[0] > 0.01 and f[1] > 1.5 * f[0], f"lv_{name}: {f}"
        for r, d in zip(rows, DEPTHS):
            # the indentation is the travel beyond contact less a small penetration
            assert 0 < r["pen"] < 0.15 * d and r["indentation"] == pytest.approx(d - r["pen"], abs=1e-12)


def test_tool_force_equals_the_nodal_contact_forces(curves):
    P, n = indentation.probe()
    for name, (fem, rows) in curves.items():
        for r in rows:
            # the nodes receive exactly what the tool gives (barycentric weights sum to one)
            assert np.allclose(r["nodal_sum"], -r["tool_force"], rtol=1e-12, atol=1e-15)
            assert r["force"] == pytest.approx(float(-r["tool_force"] @ n))
            # the applied forces and the penalty of the configuration they make agree
            assert r["force_iter"] == pytest.approx(r["force"], rel=2e-3)
        assert np.allclose(fem.B.sum(axis=1), 1.0)


def test_coarse_mesh_is_stiffer(curves):
    # Linear tets lock and lv_190's facets are 30 mm across: its wall is stiffer than lv_1350's.
    f190 = [r["force"] for r in curves["190"][1]]
    f1350 = [r["force"] for r in curves["1350"][1]]
    assert all(a > 1.3 * b for a, b in zip(f190, f1350)), (f190, f1350)


def test_force_against_indentation_does_not_depend_on_the_penalty():
    fem = indentation.FemIndenter("1350", verbose=False)
    stiff = fem.curve(DEPTHS, verbose=False)
    soft = indentation.FemIndenter("1350", kappa=indentation.KAPPA / 10, verbose=False).curve(DEPTHS, verbose=False)
    for a, b in zip(stiff, soft):
        assert b["pen"] > 2 * a["pen"]               # the softer penalty penetrates more...
        by_travel = b["force"] / a["force"]
        by_indentation = (b["force"] / b["indentation"]) / (a["force"] / a["indentation"])
        print(f"penalty / 10: pen {a['pen'] * 1e6:.1f} -> {b['pen'] * 1e6:.1f} um, force at the same travel x{by_travel:.4f}, "
              f"force / indentation x{by_indentation:.4f}")
        # ... so force against travel differs (3-9%), force against indentation less (1-2%: the
        # softer penalty spreads the contact a little, like a coated sphere)
        assert abs(by_indentation - 1) < 0.02, (by_travel, by_indentation)
        assert abs(by_indentation - 1) < abs(by_travel - 1), (by_travel, by_indentation)


def test_small_depth_matches_the_linear_contact_solution():
    fem = indentation.FemIndenter("1350", verbose=False)
    t = fem.t0 + 0.05e-3
    r = fem.solve(t)
    c = indentation.tool_centre(t)
    g, nn = fem._gap(fem.X, c)
    cand = np.flatnonzero(g > -1e-3)
    f_lin = fem._linear_contact(g[cand], np.zeros(cand.size), fem._G(cand, nn), fem.k_i[cand])
    F_lin = float((f_lin[:, None] * nn[cand]).sum(axis=0) @ indentation.probe()[1])   # on the tissue, along n
    assert r["force"] == pytest.approx(F_lin, rel=0.01)
