"""Pickling (issue 16): models and states cross process boundaries (multiprocessing, Dask).

What a wrong implementation would do: a pickle that rebuilds the body at rest, or with the
Young/Poisson pair instead of the stored Lame constants (a last-bit change of lambda), or without
the integrator's memory, steps on to other positions (compared with array_equal)."""
import multiprocessing as mp
import pickle

import numpy as np
import pytest

import palpate
from test_state import bar, ellipsoids_sim, same_state


def test_body_pickles_and_steps_on_bit_identically():
    body = bar()
    body.step(40)
    clone = pickle.loads(pickle.dumps(body))
    assert clone.n_nodes == body.n_nodes and clone.time == body.time
    assert clone.material == body.material and clone.integrator == body.integrator
    assert np.array_equal(clone.fixed, body.fixed) and np.array_equal(clone.gravity, body.gravity)
    body.step(30)
    clone.step(30)
    assert np.array_equal(clone.positions, body.positions)


@pytest.mark.parametrize("obj", [
    palpate.Material(lame_lambda=5.5, lame_mu=2.5, density=1.0, phi=1e-4, psi=2e-4, law=palpate.Law.NEO_HOOKEAN),
    palpate.Material(young=3e4, poisson=0.4),
    palpate.SemiImplicit(palpate.Filter.STABLE),
    palpate.BackwardEuler(),
    palpate.BackwardEuler(palpate.Solver.NEWTON, max_iterations=7, tolerance=1e-6),
    palpate.BackwardEuler(palpate.Solver.LINEARISED),
    palpate.Law.ST_VENANT_KIRCHHOFF, palpate.Kernel.CUBIC_SPLINE, palpate.Solver.NEWTON, palpate.Filter.PAPER,
    palpate.Projection.TRANSMURAL,
])
def test_values_pickle(obj):
    back = pickle.loads(pickle.dumps(obj))
    assert back == obj and repr(back) == repr(obj)
    if isinstance(obj, palpate.Material):
        assert (back.lame_lambda, back.lame_mu) == (obj.lame_lambda, obj.lame_mu)


def test_meshes_pickle():
    m = palpate.box_mesh(size=(0.1, 0.02, 0.02), cells=(3, 2, 2))
    back = pickle.loads(pickle.dumps(m))
    assert np.array_equal(back.points, m.points) and np.array_equal(back.tets, m.tets)
    s = palpate.ellipsoid_surface((0.01, 0.01, 0.02), 2)
    back = pickle.loads(pickle.dumps(s))
    assert np.array_equal(back.points, s.points) and np.array_equal(back.triangles, s.triangles)


def test_particle_body_pickles(material):
    g = np.arange(5) * 1e-3
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    body = palpate.ParticleBody(pos, np.full(len(pos), 1e-6), material, 1.8e-3, kernel=palpate.Kernel.CUBIC_SPLINE,
                                fixed=np.arange(25), gravity=(0, 0, -9.81), hourglass=0.3, min_relative_weight=0.01)
    body.step(10, dt=1e-4)
    body.active = np.arange(100)
    back = pickle.loads(pickle.dumps(body))
    assert (back.kernel, back.hourglass, back.min_relative_weight, back.n_pairs) == \
        (body.kernel, body.hourglass, body.min_relative_weight, body.n_pairs)
    assert np.array_equal(back.active, body.active)
    body.step(10, dt=1e-4)
    back.step(10, dt=1e-4)
    assert np.array_equal(back.positions, body.positions)


def test_hybrid_model_pickles():
    inner, outer = (palpate.ellipsoid_surface(a, 2) for a in ((0.02, 0.02, 0.03), (0.03, 0.03, 0.04)))
    m = palpate.HybridModel.build_nested(inner, outer, particles=1000, field_voxels=3000)
    back = pickle.loads(pickle.dumps(m))
    assert back.to_bytes() == m.to_bytes()
    with pytest.raises(palpate.ModelFileError):
        palpate.HybridModel.from_bytes(m.to_bytes()[:-10])


def _advance(body):
    body.step(30)
    return body


def test_bodies_cross_processes():
    # Spawn: a fresh interpreter that imports palpate and unpickles (as Dask's workers do).
    body = bar()
    body.step(10)
    with mp.get_context("spawn").Pool(1) as pool:
        done = pool.apply(_advance, (body,))
    _advance(body)
    assert np.array_equal(done.positions, body.positions)


def test_hybrid_sim_pickles_and_ticks_on_bit_identically():
    sim, path = ellipsoids_sim(tool_area_stiffness=1e8, max_tool_speed=0.4, mass_scaling=0.9)
    for c in path[:56]:
        sim.step(c)
    back = pickle.loads(pickle.dumps(sim))
    # Rebuilt from its model, material and constructor options, then its state restored.
    assert back.model.to_bytes() == sim.model.to_bytes() and back.material == sim.material
    assert back.options == sim.options and back.options["max_tool_speed"] == 0.4 and back.options["mass_scaling"] == 0.9
    assert same_state(back.get_state(), sim.get_state())
    for c in path[56:]:
        assert np.array_equal(back.step(c), sim.step(c))
        assert np.array_equal(back.particle_positions(), sim.particle_positions())
    assert np.array_equal(back.surface, sim.surface) and back.ticks == sim.ticks


def _tick_on(sim, path):
    return np.array([sim.step(c) for c in path]), sim.particle_positions()


def test_hybrid_sims_cross_processes():
    sim, path = ellipsoids_sim()
    for c in path[:20]:
        sim.step(c)
    with mp.get_context("spawn").Pool(1) as pool:
        forces, x = pool.apply(_tick_on, (sim, path[20:]))
    here, y = _tick_on(sim, path[20:])
    assert np.abs(here).max() > 0 and np.array_equal(forces, here) and np.array_equal(x, y)


def test_a_pickle_of_the_tick_counted_options_loads_in_seconds():
    """Pickles made when the options counted 1 ms ticks (``linger_ticks``, ``max_tool_step`` [m a
    tick], ``shell_pause`` [ticks]) and whose states have no ``dt`` load with those options in
    seconds, and tick on as the same simulation made with them."""
    from palpate import _pickle

    sim, path = ellipsoids_sim(max_tool_speed=0.4, linger=0.01, shell_pause=0.02)
    for c in path[:20]:
        sim.step(c)
    state = sim.get_state()
    del state["dt"]
    old = {k: sim.options[k] for k in _pickle._HYBRID_SIM_OPTIONS if k not in ("max_tool_speed", "linger", "shell_pause")}
    old.update(max_tool_step=4e-4, linger_ticks=10, shell_pause=20)
    back = _pickle._hybrid_sim(sim.model, sim.material, old, state)
    assert back.options["max_tool_speed"] == pytest.approx(0.4) and back.options["linger"] == pytest.approx(0.01)
    assert back.options["shell_pause"] == pytest.approx(0.02)
    for c in path[20:40]:
        assert np.array_equal(back.step(c), sim.step(c))
