"""The Neo-Hookean law option: ``palpate.Law`` in ``Material`` (repr, equality), an FEM body with it
under a protocol-like press, the particle solid refusing it, and the scene key ``material.law``.

What a wrong binding would do: drop the ``law`` keyword (the body would silently run SVK: the
press test sees the NH and SVK responses identical), compare or print materials without their
law (two different materials equal), let ``ParticleBody`` run SVK for an NH material (no error),
or accept a misspelt law in a scene file.
"""
import numpy as np
import pytest

import palpate
from palpate import bench
from palpate.scene import SceneError, load_scene

NH = palpate.Law.NEO_HOOKEAN
SVK = palpate.Law.ST_VENANT_KIRCHHOFF


def test_law_in_material_repr_and_equality():
    default = palpate.Material(young=3e4, poisson=0.4, density=1000.0)
    assert default.law == SVK
    assert palpate.Material.myocardium().law == SVK
    nh = palpate.Material(young=3e4, poisson=0.4, density=1000.0, law=NH)
    assert nh.law == NH and nh.law != SVK
    assert (nh.lame_lambda, nh.lame_mu, nh.density) == (default.lame_lambda, default.lame_mu, default.density)
    assert nh != default
    assert nh == palpate.Material(young=3e4, poisson=0.4, density=1000.0, law=NH)
    assert default == palpate.Material(young=3e4, poisson=0.4, density=1000.0, law=SVK)
    assert repr(nh).endswith("law=Law.NEO_HOOKEAN)") and repr(default).endswith("law=Law.ST_VENANT_KIRCHHOFF)")
    assert repr(NH) == "Law.NEO_HOOKEAN"
    assert len({NH, SVK, palpate.Law.NEO_HOOKEAN}) == 2           # hashable enum
    with pytest.raises(TypeError):
        palpate.Material(young=3e4, poisson=0.4, law="neo-hookean")


def _press(law, force, steps=300):
    case = bench.generated_case()
    mat = palpate.Material(young=bench.E, poisson=bench.NU, density=bench.RHO, law=law)
    body = palpate.Body(case.mesh, mat, fixed=case.fixed, integrator=palpate.BackwardEuler())
    r = body.run_probe(case.loaded, force * case.total_force / np.linalg.norm(case.total_force), bench.RAMP,
                       steps, dt=1e-3)
    return body, case, r


def test_body_with_neo_hookean_runs_a_press():
    # The benchmark probe (0.2 N) on the generated 192-tet ellipsoid wall.
    body, case, r = _press(NH, 0.2)
    assert body.material.law == NH
    assert r["stable"] and r["steps"] == 300 and r["error"] is None
    _, _, r_svk = _press(SVK, 0.2)
    # Same Lame constants: close at this moderate load, but not identical (the law is in use).
    a, b = r["probe_disp_avg_m"], r_svk["probe_disp_avg_m"]
    assert a > 0 and abs(a - b) / b < 0.2 and a != b
    f = np.zeros((body.n_nodes, 3))
    f[case.loaded] = case.total_force / len(case.loaded)
    x = body.static_solve(f, load_steps=4)
    assert np.isfinite(x).all()


def test_neo_hookean_survives_a_hard_press():
    # Ten times the protocol load (2 N): the NH wall stays stable, dented by ~1 cm (SVK, same
    # case, exceeds the 2 cm stability bound: see VALIDATION.md).
    _, _, r = _press(NH, 2.0)
    assert r["stable"] and r["error"] is None
    assert 0.005 < r["probe_disp_avg_m"] < 0.015


def test_particle_body_refuses_neo_hookean():
    g = np.arange(4) * 1e-3
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    m = np.full(len(pos), 1e-6)
    nh = palpate.Material(young=3e4, poisson=0.4, density=1000.0, law=NH)
    with pytest.raises(palpate.MaterialError, match="St. Venant-Kirchhoff law only") as e:
        palpate.ParticleBody(pos, m, nh, 1.8e-3)
    assert isinstance(e.value, palpate.PalpateError) and "Neo-Hookean" in str(e.value)
    palpate.ParticleBody(pos, m, palpate.Material(young=3e4, poisson=0.4, density=1000.0), 1.8e-3)


SCENE = '[mesh]\ngenerator = "ellipsoid_wall"\n[material]\n{material}\n[run]\nsteps = 2\n'


@pytest.mark.parametrize("material, law", [
    ('young = 3e4\npoisson = 0.4', SVK),
    ('young = 3e4\npoisson = 0.4\nlaw = "st-venant-kirchhoff"', SVK),
    ('young = 3e4\npoisson = 0.4\nlaw = "neo-hookean"', NH),
    ('preset = "myocardium"\nlaw = "neo-hookean"', NH),
])
def test_scene_material_law(tmp_path, material, law):
    f = tmp_path / "s.toml"
    f.write_text(SCENE.format(material=material))
    scene = load_scene(f)
    assert scene.body.material.law == law
    if "preset" in material:
        assert scene.body.material.density == palpate.Material.myocardium().density


@pytest.mark.parametrize("value", ['"neo_hookean"', '"NeoHookean"', '1', '"svk"'])
def test_scene_bad_law_names_the_key(tmp_path, value):
    f = tmp_path / "bad.toml"
    f.write_text(SCENE.format(material=f'young = 3e4\npoisson = 0.4\nlaw = {value}'))
    with pytest.raises(SceneError, match=r"bad\.toml: material\.law: must be one of \['neo-hookean', 'st-venant-kirchhoff'\]"):
        load_scene(f)
