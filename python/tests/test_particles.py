"""Particle bodies: building from arrays and from sampling, stepping, momentum, the active set,
errors, the timed run, GIL release, and the `palpate bench particles` command."""
import json

import numpy as np
import pytest

import palpate

from conftest import python_work_during
from test_cli import palpate_cli

S = 1e-3          # lattice spacing [m]
H = 1.8 * S       # support radius [m]


def block(n=6, spacing=S, density=1000.0):
    """An n x n x n cubic lattice block: positions (n^3, 3) [m], masses (n^3,) [kg]."""
    g = np.arange(n) * spacing
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    return pos, np.full(len(pos), density * spacing ** 3)


def test_build_from_arrays(material):
    pos, m = block()
    body = palpate.ParticleBody(pos, m, material, H)
    assert body.n_particles == len(body) == 216
    assert body.kernel == palpate.Kernel.WENDLAND_C2
    assert body.support_radius == H and body.hourglass == 0.5
    # 26 neighbours inside the lattice (offsets up to sqrt(3) spacings < 1.8), fewer at the faces
    centre = int(np.argmin(np.linalg.norm(pos - pos.mean(0), axis=1)))
    # 26 lattice neighbours within 1.8 spacings; the 8 corners (W/W(0) = 1e-5) are not paired.
    assert len(body.neighbours(centre)) == 18
    every = palpate.ParticleBody(body.rest_positions, body.masses, body.material, H, min_relative_weight=0.0)
    assert len(every.neighbours(centre)) == 26
    assert body.n_pairs == sum(len(body.neighbours(i)) for i in range(body.n_particles))
    np.testing.assert_allclose(body.densities, 1000.0, rtol=1e-12)    # Shepard-normalised
    np.testing.assert_allclose(body.volumes, S ** 3, rtol=1e-12)
    np.testing.assert_array_equal(body.masses, m)
    np.testing.assert_array_equal(body.positions, pos)
    np.testing.assert_array_equal(body.rest_positions, pos)
    np.testing.assert_array_equal(body.active, np.arange(216))
    assert body.fixed.size == 0
    assert 0 < body.stable_dt < 1e-3 and body.omega_max > 0
    assert body.substeps(1e-3) == int(np.ceil(1e-3 / body.stable_dt))
    assert body.strain_energy() == 0.0 and body.kinetic_energy() == 0.0
    assert repr(body).startswith("<palpate.ParticleBody: 216 particles")


@pytest.mark.parametrize("kernel", [palpate.Kernel.WENDLAND_C2, palpate.Kernel.CUBIC_SPLINE,
                                    palpate.Kernel.LINEAR_LENNARD_JONES])
def test_kernels_step_finite(material, kernel):
    pos, m = block(5)
    body = palpate.ParticleBody(pos, m, material, H, kernel=kernel, fixed=pos[:, 2] == 0.0,
                                gravity=(0, 0, -9.81))
    assert body.kernel == kernel
    stats = body.step(20, dt=1e-3)
    assert stats == {"steps": 20, "substeps": body.substeps(1e-3), "substep_dt": pytest.approx(1e-3 / body.substeps(1e-3))}
    assert body.time == pytest.approx(0.02)
    assert np.isfinite(body.positions).all() and np.isfinite(body.velocities).all()
    assert body.displacements[:, 2].min() < 0.0                        # it sags
    np.testing.assert_array_equal(body.displacements[body.fixed], 0.0)  # the base stays


def test_kernel_is_a_typed_enum():
    assert {k for k in dir(palpate.Kernel) if not k.startswith("_")} == {"WENDLAND_C2", "CUBIC_SPLINE", "LINEAR_LENNARD_JONES"}
    assert palpate.Kernel.CUBIC_SPLINE != palpate.Kernel.WENDLAND_C2
    assert len({palpate.Kernel.CUBIC_SPLINE, palpate.Kernel.CUBIC_SPLINE}) == 1     # hashable


def test_build_from_sampling_and_step(material):
    sphere = palpate.ellipsoid_surface((0.01, 0.01, 0.01), 4)
    pos, m = palpate.sample_inside(sphere, 1.5e-3, 1000.0)
    assert pos.shape == (len(m), 3) and len(m) > 1000
    assert m.sum() == pytest.approx(len(m) * 1000.0 * 1.5e-3 ** 3)
    body = palpate.ParticleBody(pos, m, material, 1.8 * 1.5e-3)
    f = np.zeros((body.n_particles, 3))
    top = np.argmax(pos[:, 2])
    f[top, 2] = -1e-3
    body.set_forces(f)
    np.testing.assert_array_equal(body.forces, f)
    body.step(30)
    assert np.isfinite(body.positions).all()
    assert body.displacements[top, 2] < 0
    assert body.strain_energy() > 0 and body.kinetic_energy() > 0
    # A free body under a net force: the momentum grows by the impulse, 30 ms x 1 mN.
    np.testing.assert_allclose(body.momentum(), [0, 0, -1e-3 * 0.03], atol=1e-12)


def test_momentum_conserved_for_free_cluster():
    viscous = palpate.Material(young=3e4, poisson=0.4, density=1000.0, phi=0.5, psi=0.5)
    pos, m = block(5)
    body = palpate.ParticleBody(pos, m, viscous, H)
    rng = np.random.default_rng(1)
    body.set_positions(pos + 0.05 * S * rng.standard_normal(pos.shape))
    body.set_velocities(0.01 * rng.standard_normal(pos.shape))
    p0 = body.momentum()
    assert np.abs(p0).max() > 0
    body.step(50)
    assert body.kinetic_energy() > 0
    np.testing.assert_allclose(body.momentum(), p0, rtol=0, atol=1e-12 * np.abs(p0).max() + 1e-18)


def test_active_set_semantics(material):
    pos, m = block(6)
    body = palpate.ParticleBody(pos, m, material, H)
    body.set_forces(np.tile([0.0, 0.0, 1e-4], (body.n_particles, 1)))
    active = np.flatnonzero(pos[:, 0] < 2.5 * S)
    body.active = active
    np.testing.assert_array_equal(body.active, active)
    body.step(10)
    frozen = np.setdiff1d(np.arange(body.n_particles), active)
    np.testing.assert_array_equal(body.positions[frozen], pos[frozen])   # bit for bit
    assert not body.velocities[frozen].any()
    assert np.abs(body.displacements[active]).max() > 0
    # A boolean mask works too; reset keeps the active set.
    mask = pos[:, 2] > 2.5 * S
    body.active = mask
    np.testing.assert_array_equal(body.active, np.flatnonzero(mask))
    body.reset()
    np.testing.assert_array_equal(body.active, np.flatnonzero(mask))
    assert body.time == 0.0 and not body.velocities.any() and not body.forces.any()
    np.testing.assert_array_equal(body.positions, pos)
    # Nothing active: stepping only advances time.
    body.active = []
    body.step(3)
    assert body.time == pytest.approx(3e-3)
    np.testing.assert_array_equal(body.positions, pos)


def test_active_set_is_validated(material):
    pos, m = block(4)
    body = palpate.ParticleBody(pos, m, material, H)
    with pytest.raises(ValueError, match=r"active: particle index 64 out of range \(the body has 64 particles\)"):
        body.active = [0, 64]
    with pytest.raises(ValueError, match="active: particle index -1 out of range"):
        body.active = [-1]
    with pytest.raises(ValueError, match="active: particle 3 is listed more than once"):
        body.active = [3, 5, 3]
    with pytest.raises(ValueError, match="boolean mask must have length 64"):
        body.active = np.ones(10, dtype=bool)
    with pytest.raises(TypeError, match="active"):
        body.active = [0.5, 1.5]
    with pytest.raises(ValueError, match="1-D"):
        body.active = np.zeros((2, 2), dtype=int)
    np.testing.assert_array_equal(body.active, np.arange(64))        # unchanged by the failures


def test_build_errors_name_the_particle(material):
    pos, m = block(4)
    bad = m.copy()
    bad[2] = -1.0
    with pytest.raises(palpate.ModelError, match=r"particle 2: mass -1 kg must be positive"):
        palpate.ParticleBody(pos, bad, material, H)
    bad[2] = 0.0
    with pytest.raises(palpate.ModelError, match="particle 2: mass 0 kg"):
        palpate.ParticleBody(pos, bad, material, H)
    nan = pos.copy()
    nan[7, 1] = np.nan
    with pytest.raises(palpate.ModelError, match=r"particle 7: non-finite position"):
        palpate.ParticleBody(nan, m, material, H)
    with pytest.raises(ValueError, match=r"masses must have shape \(64,\)"):
        palpate.ParticleBody(pos, m[:-1], material, H)
    with pytest.raises(TypeError, match="masses must be real numbers"):
        palpate.ParticleBody(pos, m.astype(str), material, H)
    with pytest.raises(ValueError, match=r"positions must have shape \(n, 3\)"):
        palpate.ParticleBody(pos[:, :2], m, material, H)
    with pytest.raises(palpate.ModelError, match="support radius"):
        palpate.ParticleBody(pos, m, material, -1.0)
    flat = pos[pos[:, 2] == 0.0]                                 # one layer: neighbours in a plane
    with pytest.raises(palpate.ModelError, match="particle 0: its 3 neighbours .* do not span 3D"):
        palpate.ParticleBody(flat, m[:len(flat)], material, H)
    with pytest.raises(palpate.ModelError, match="hourglass"):
        palpate.ParticleBody(pos, m, material, H, hourglass=-1.0)
    with pytest.raises(ValueError, match="fixed: particle index 99 out of range"):
        palpate.ParticleBody(pos, m, material, H, fixed=[99])
    with pytest.raises(TypeError):
        palpate.ParticleBody(pos, m, material, H, kernel="wendland")
    with pytest.raises(ValueError, match="gravity"):
        palpate.ParticleBody(pos, m, material, H, gravity=(0, np.inf, 0))


def test_step_errors(material):
    pos, m = block(4)
    body = palpate.ParticleBody(pos, m, material, H)
    with pytest.raises(palpate.StepError, match="dt = 0"):
        body.step(1, dt=0.0)
    with pytest.raises(ValueError, match="forces: row 5 is not finite"):
        f = np.zeros((64, 3))
        f[5, 0] = np.nan
        body.set_forces(f)
    with pytest.raises(ValueError, match=r"forces must have shape \(64, 3\)"):
        body.set_forces(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="dt"):
        body.substeps(-1.0)
    with pytest.raises(ValueError, match=r"i = 64: out of range \(64 particles\)"):
        body.neighbours(64)
    assert body.time == 0.0


def test_run_timed(material):
    pos, m = block(5)
    body = palpate.ParticleBody(pos, m, material, H)
    r = body.run_timed(7, dt=1e-3)
    assert r["ticks"] == 7 and r["error"] is None
    w = r["tick_wall_s"]
    assert w.shape == (7,) and (w > 0).all()
    assert r["substeps"] == body.substeps(1e-3)
    assert body.time == pytest.approx(7e-3)
    r = body.run_timed(1000, dt=1e-3, max_wall_s=0.0)
    assert r["ticks"] == 1 and "wall-clock cap" in r["error"]
    with pytest.raises(ValueError, match="dt"):
        body.run_timed(1, dt=np.nan)


def test_internal_forces_balance(material):
    pos, m = block(4)
    body = palpate.ParticleBody(pos, m, material, H)
    rng = np.random.default_rng(0)
    body.set_positions(pos + 0.1 * S * rng.standard_normal(pos.shape))
    f = body.internal_forces()
    assert np.abs(f).max() > 0
    np.testing.assert_allclose(f.sum(0), 0.0, atol=1e-12 * np.abs(f).max())


def test_step_releases_the_gil(material):
    pos, m = block(8)
    body = palpate.ParticleBody(pos, m, material, H)
    count, wall = python_work_during(lambda: body.step(300))
    assert body.time == pytest.approx(0.3)
    assert count > 1000 and count / wall > 1e4, (count, wall)


def test_cli_bench_particles_json():
    r = palpate_cli("bench", "particles", 200, "--ticks", 5, "--json")
    assert r.returncode == 0, r.stderr
    rows = [json.loads(line) for line in r.stdout.splitlines()]
    assert len(rows) == 1
    row = rows[0]
    assert row["n"] == 200 and row["ticks"] == 5 and row["error"] is None and row["finite"]
    assert 15 <= row["mean_neighbours_in_support"] <= 30
    assert row["mean_neighbours"] <= row["mean_neighbours_in_support"]
    assert row["substeps"] >= 1 and row["substep_dt_s"] * row["substeps"] == pytest.approx(1e-3)
    assert row["tick_median_s"] > 0 and row["ticks_per_s"] == pytest.approx(1 / row["tick_median_s"])
    assert row["flops_per_tick"] == row["substeps"] * (50 * row["pairs"] + 285 * 200)
    assert row["fixed"] == 20 and row["kernel"] == "wendland"


def test_cli_bench_particles_text_and_errors():
    r = palpate_cli("bench", "particles", 100, "--ticks", 3, "--kernel", "cubic")
    assert r.returncode == 0, r.stderr
    assert "GFlop/s" in r.stdout and "kernel cubic" in r.stdout
    r = palpate_cli("bench", "particles", "--ticks", 3)
    assert r.returncode == 2 and "give N or --all" in r.stderr     # usage
    r = palpate_cli("bench", "particles", 10 ** 7, "--ticks", 1)
    assert r.returncode == 1 and "exceeds" in r.stderr             # a value the benchmark refuses
