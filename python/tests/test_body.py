"""Bodies: stepping stays finite, energies, reset, static solve, the probe run, GIL release."""

import numpy as np
import pytest

import palpate

from conftest import python_work_during

INTEGRATORS = [palpate.SemiImplicit(), palpate.SemiImplicit(filter=palpate.Filter.STABLE), palpate.BackwardEuler(),
               palpate.BackwardEuler(palpate.Solver.NEWTON), palpate.BackwardEuler(palpate.Solver.LINEARISED)]


def bar(material, integrator=None):
    """A 10 x 2 x 2 cm bar clamped at x = 0 (box_mesh: 240 tets)."""
    mesh = palpate.box_mesh(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    fixed = np.flatnonzero(mesh.points[:, 0] == 0.0)
    return palpate.Body(mesh, material, fixed=fixed, integrator=integrator)


@pytest.mark.parametrize("integrator", INTEGRATORS, ids=repr)
def test_stepping_under_gravity_is_finite(integrator):
    mesh = palpate.box_mesh(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    fixed = np.flatnonzero(mesh.points[:, 0] == 0.0)
    stiff = palpate.Material(young=1e6, poisson=0.3, density=1000.0)   # sags ~1 mm
    body = palpate.Body(mesh, stiff, fixed=fixed, gravity=(0, 0, -9.81), integrator=integrator)
    stats = body.step(200, dt=1e-3)
    assert stats["steps"] == 200
    assert body.time == pytest.approx(0.2)
    x = body.positions
    assert np.isfinite(x).all() and np.isfinite(body.velocities).all()
    assert np.abs(x[fixed] - mesh.points[fixed]).max() == 0.0        # fixed nodes stay put
    assert body.displacements[:, 2].min() < 0.0                        # it sags
    assert np.abs(body.displacements).max() < 0.01
    assert body.strain_energy() > 0.0 and body.kinetic_energy() >= 0.0


def test_step_defaults_and_stats(material):
    body = bar(material)
    stats = body.step()
    assert body.time == pytest.approx(1e-3)
    assert set(stats) == {"steps", "iterations", "iterations_max", "evaluations", "factorizations", "solves", "unconverged_steps",
                          "max_residual", "inverted_max", "inverted", "potential_change"}
    assert stats["iterations"] >= 1 and stats["solves"] >= 1 and stats["potential_change"] <= 0.0


def test_reset(material):
    body = bar(material)
    f = np.zeros((body.n_nodes, 3))
    f[-1, 2] = -0.01
    body.set_forces(f)
    body.step(50)
    assert np.abs(body.displacements).max() > 0
    body.reset()
    assert body.time == 0.0
    np.testing.assert_array_equal(body.positions, body.mesh.points)
    assert not body.velocities.any() and not body.forces.any()
    assert body.strain_energy() < 1e-20 and body.kinetic_energy() == 0.0


def test_static_solve_matches_long_damped_run():
    viscous = palpate.Material(young=1e6, poisson=0.3, density=1000.0, phi=5.0, psi=5.0)
    body = bar(viscous, palpate.BackwardEuler())
    tip = np.flatnonzero(body.mesh.points[:, 0] == 0.1)
    f = np.zeros((body.n_nodes, 3))
    f[tip, 2] = -1e-2 / len(tip)  # 10 mN down at the tip [N]
    x = body.static_solve(f, tolerance=1e-8)
    assert x.shape == (body.n_nodes, 3)
    assert body.time == 0.0 and not body.displacements.any()          # state untouched
    u = x - body.mesh.points
    assert u[tip, 2].mean() < 0
    body.set_forces(f)
    body.step(3000, dt=1e-3)                                           # viscous: settles to rest
    np.testing.assert_allclose(body.displacements, u, atol=1e-3 * np.abs(u).max())
    np.testing.assert_allclose(body.static_solve(tolerance=1e-8), x)   # default: the current forces


def test_bad_time_step_is_a_step_error(material):
    body = bar(material)
    with pytest.raises(palpate.StepError, match="dt = -0.001 s must be positive") as e:
        body.step(3, dt=-1e-3)
    assert isinstance(e.value, palpate.PalpateError)
    assert body.time == 0.0


def test_model_error_for_non_finite_gravity(unit_tet, material):
    with pytest.raises(ValueError, match="gravity"):
        palpate.Body(palpate.TetMesh(*unit_tet), material, gravity=(0, 0, float("inf")))


def test_run_probe(material):
    mesh = palpate.truncated_ellipsoid_wall()
    body = palpate.Body(mesh, material, fixed=mesh.nodes_below(0.0))
    loaded = [int(np.argmax(mesh.points[:, 2]))]                       # the apex
    r = body.run_probe(loaded, (0.0, 0.0, -0.05), 0.1, 200, dt=1e-3)
    assert r["steps"] == 200 and r["error"] is None and r["stable"]
    assert r["wall_s"] > 0
    assert r["mean_disp"].shape == (body.n_nodes, 3)
    assert r["probe_disp"].shape == (200,)
    assert 0 < r["probe_disp_avg_m"] <= r["max_disp_m"] < 0.02
    np.testing.assert_allclose(body.forces[loaded[0]], [0, 0, -0.05])  # full load after the ramp
    with pytest.raises(ValueError, match="at least one loaded node"):
        body.run_probe([], (0, 0, 1), 0.1, 10)


def test_step_releases_the_gil(material):
    """A Python thread keeps running while body.step(2000) runs in another thread."""
    mesh = palpate.truncated_ellipsoid_wall()
    body = palpate.Body(mesh, material, fixed=mesh.nodes_below(0.0))
    f = np.zeros((body.n_nodes, 3))
    f[int(np.argmax(mesh.points[:, 2])), 2] = -0.05
    body.set_forces(f)
    count, wall = python_work_during(lambda: body.step(2000, dt=1e-3))
    assert body.time == pytest.approx(2.0)
    # Holding the GIL for the whole call would leave this loop at a handful of iterations.
    rate = count / wall
    assert count > 1000 and rate > 1e4, (count, wall)


def test_a_firm_press_does_the_same_work_every_time():
    """Issue 38: the refactorisation and every other decision that changes the arithmetic depend
    on the state, never on the clock: the same firm press twice gives bit-identical results and
    the same iterations, force evaluations and factorisations (the step time may differ)."""
    mesh = palpate.truncated_ellipsoid_wall()            # the protocol's wall, 1,440 tets
    pts = mesh.points
    fixed = np.flatnonzero(pts[:, 2] <= 1e-9)
    loaded = np.argsort(np.linalg.norm(pts - (0.026, 0.0, 0.02), axis=1))[:4]
    mat = palpate.Material(young=30e3, poisson=0.4, density=1000.0)
    runs = []
    for _ in range(2):
        body = palpate.Body(mesh, mat, fixed=fixed)
        # 2 N on four nodes: elements invert under it, the quasi-Newton refreshes its factor.
        r = body.run_probe(loaded, (-2.0, 0.0, 0.0), 0.05, 200)
        runs.append((r, body.positions))
    (a, xa), (b, xb) = runs
    assert a["factorizations"] > 1, a["factorizations"]
    for key in ("iterations_mean", "iterations_max", "evaluations", "factorizations", "inverted_max"):
        assert a[key] == b[key], key
    np.testing.assert_array_equal(xa, xb)
