"""Material parameters, presets and integrator objects."""
import pytest

import palpate


def test_young_poisson_to_lame():
    m = palpate.Material(young=3.0e4, poisson=0.4, density=1000.0)
    assert m.lame_mu == pytest.approx(10714.2857142857)
    assert m.lame_lambda == pytest.approx(42857.1428571428)
    assert m.young == pytest.approx(3.0e4)
    assert m.poisson == pytest.approx(0.4)
    assert m.density == 1000.0 and m.phi == 0.0 and m.psi == 0.0
    assert m.wave_speed == pytest.approx(((m.lame_lambda + 2 * m.lame_mu) / 1000.0) ** 0.5)


def test_lame_pair_and_damping():
    m = palpate.Material(lame_lambda=5.5, lame_mu=2.5, density=1.0, phi=1e-3, psi=2e-3)
    assert (m.lame_lambda, m.lame_mu, m.phi, m.psi) == (5.5, 2.5, 1e-3, 2e-3)


def test_presets():
    myo = palpate.Material.myocardium()
    assert myo.young == pytest.approx(3.0e4) and myo.density == 1060.0
    paper = palpate.Material.paper_ellipsoids()
    assert paper.lame_lambda == 5.5 and paper.lame_mu == 2.5
    assert paper.phi == pytest.approx(1.8e-4)  # the paper's 9e-5 in palpate's strain-rate convention


@pytest.mark.parametrize("kw, match", [
    (dict(young=3e4, poisson=0.5), "Poisson ratio nu = 0.5"),
    (dict(young=3e4, poisson=-1.2), "Poisson ratio"),
    (dict(young=-1.0, poisson=0.3), "must be positive"),
    (dict(young=float("nan"), poisson=0.3), "not finite"),
    (dict(young=3e4, poisson=0.3, density=0.0), "density"),
    (dict(young=3e4, poisson=0.3, phi=-1.0), "viscosity phi"),
    (dict(lame_lambda=1.0, lame_mu=-1.0), "shear modulus mu"),
    (dict(lame_lambda=-10.0, lame_mu=1.0), "bulk modulus"),
    (dict(), "give the elastic moduli"),
    (dict(young=3e4), "poisson is missing"),
    (dict(poisson=0.3), "young is missing"),
    (dict(lame_mu=1.0), "lame_lambda is missing"),
    (dict(young=3e4, poisson=0.3, lame_mu=1.0), "not both"),
])
def test_material_errors(kw, match):
    with pytest.raises(palpate.MaterialError, match=match) as e:
        palpate.Material(**kw)
    assert isinstance(e.value, palpate.PalpateError)


def test_error_hierarchy():
    for cls in (palpate.MeshError, palpate.MaterialError, palpate.ModelError, palpate.SolveError, palpate.StepError):
        assert issubclass(cls, palpate.PalpateError)
        assert cls.__module__ == "palpate"
    assert issubclass(palpate.PalpateError, Exception)
    assert issubclass(palpate.MeshWarning, UserWarning)


def test_integrators():
    assert repr(palpate.SemiImplicit()) == "SemiImplicit()"
    assert palpate.SemiImplicit().filter == palpate.Filter.PAPER
    assert palpate.SemiImplicit(filter=palpate.Filter.STABLE) != palpate.SemiImplicit()
    be = palpate.BackwardEuler()
    # The defaults are the core's (one definition: Integrator::QUASI_NEWTON_* / NEWTON_*).
    assert be.solver == palpate.Solver.QUASI_NEWTON
    assert (be.max_iterations, be.tolerance, be.history) == (25, 2e-2, 5)
    nt = palpate.BackwardEuler(palpate.Solver.NEWTON)
    assert nt.solver == palpate.Solver.NEWTON and nt.max_iterations == 30 and nt.tolerance == 1e-8
    assert nt.history is None
    lin = palpate.BackwardEuler(palpate.Solver.LINEARISED)
    assert lin.max_iterations is None and lin.tolerance is None
    assert palpate.BackwardEuler(palpate.Solver.NEWTON, max_iterations=5, tolerance=1e-6).max_iterations == 5
    assert palpate.BackwardEuler() == palpate.BackwardEuler()
    assert palpate.BackwardEuler() != nt
    for bad, match in [(dict(max_iterations=0), "max_iterations"), (dict(tolerance=2.0), "tolerance"),
                       (dict(history=100), "history")]:
        with pytest.raises(ValueError, match=match):
            palpate.BackwardEuler(**bad)
    with pytest.raises(ValueError, match="LINEARISED"):
        palpate.BackwardEuler(palpate.Solver.LINEARISED, tolerance=1e-3)
    with pytest.raises(ValueError, match="history"):
        palpate.BackwardEuler(palpate.Solver.NEWTON, history=3)
    with pytest.raises(TypeError):
        palpate.BackwardEuler("newton")


def test_integrator_must_be_an_object(unit_tet, material):
    mesh = palpate.TetMesh(*unit_tet)
    with pytest.raises(TypeError, match="not strings"):
        palpate.Body(mesh, material, integrator="semi-implicit")
    for integ, expect in [(palpate.SemiImplicit(), palpate.SemiImplicit), (None, palpate.BackwardEuler),
                          (palpate.BackwardEuler(palpate.Solver.NEWTON, max_iterations=7), palpate.BackwardEuler)]:
        b = palpate.Body(mesh, material, fixed=[0, 1, 2], integrator=integ)
        assert isinstance(b.integrator, expect)
    assert palpate.Body(mesh, material, integrator=palpate.BackwardEuler(palpate.Solver.NEWTON, max_iterations=7)).integrator.max_iterations == 7
    assert palpate.Body(mesh, material).integrator == palpate.BackwardEuler()
