"""The core's kernels and neighbour search as the binding exposes them (palpate.kernel_value,
palpate.neighbours): checked against independent NumPy references written here from the formulas
(a reference in a test, not a second implementation for use).

What a wrong implementation would do: return a kernel off by its normalisation or its support
convention (h the support radius, not a smoothing length), keep a point as its own neighbour,
count a pair at exactly the radius, or lose the CSR order or the shape of the input.
"""
import numpy as np
import pytest

import palpate

K = palpate.Kernel


def reference_w(kernel, r, h):
    """W(r, h) from the formulas of meshfree/kernel.rs (independent NumPy reference)."""
    q = np.asarray(r, dtype=float) / h
    inside = q < 1
    if kernel == K.WENDLAND_C2:
        w = 21 / (2 * np.pi * h ** 3) * (1 - q) ** 4 * (1 + 4 * q)
    elif kernel == K.CUBIC_SPLINE:
        q2 = 2 * q
        w = 8 / (np.pi * h ** 3) * np.where(q2 < 1, 1 - 1.5 * q2 ** 2 + 0.75 * q2 ** 3, 0.25 * np.clip(2 - q2, 0, None) ** 3)
    else:
        w = 3 / (np.pi * h ** 3) * (1 - q)
    return np.where(inside, w, 0.0)


@pytest.mark.parametrize("kernel", [K.WENDLAND_C2, K.CUBIC_SPLINE, K.LINEAR_LENNARD_JONES])
def test_kernel_value_matches_the_formulas_and_is_normalised(kernel):
    h = 2e-3
    r = np.linspace(0, 1.5 * h, 301).reshape(7, 43)
    w = palpate.kernel_value(kernel, r, h)
    assert w.shape == r.shape and w.dtype == np.float64
    np.testing.assert_allclose(w, reference_w(kernel, r, h), rtol=1e-13, atol=0)
    assert palpate.kernel_value(kernel, h, h) == 0.0
    assert isinstance(palpate.kernel_value(kernel, 0.5 * h, h), float)
    s = np.linspace(0, h, 20001)                     # int 4 pi r^2 W dr = 1 (trapezoid)
    f = 4 * np.pi * s ** 2 * palpate.kernel_value(kernel, s, h)
    assert np.sum((f[1:] + f[:-1]) / 2 * np.diff(s)) == pytest.approx(1.0, rel=1e-6)


def test_kernel_value_refuses_a_bad_radius():
    with pytest.raises(ValueError, match="h = 0"):
        palpate.kernel_value(K.WENDLAND_C2, 0.1, 0.0)
    with pytest.raises(palpate.ParameterTypeError, match=r"r must be an array-like of numbers, got list \(numpy reads it as dtype <U1\)"):
        palpate.kernel_value(K.WENDLAND_C2, ["a"], 1.0)


def test_neighbours_match_brute_force():
    rng = np.random.default_rng(3)
    pts = rng.random((300, 3)) * [0.02, 0.01, 0.015]
    pts[7] = pts[3] + [0.004, 0, 0]                  # a pair at exactly the radius: not neighbours
    r = 0.004
    ptr, idx = palpate.neighbours(pts, r)
    assert ptr.shape == (301,) and ptr[0] == 0 and ptr[-1] == len(idx)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)   # independent reference: all pairs
    for i in range(len(pts)):
        expected = np.flatnonzero((d[i] < r) & (np.arange(len(pts)) != i))
        np.testing.assert_array_equal(idx[ptr[i]:ptr[i + 1]], expected)
    assert 7 not in idx[ptr[3]:ptr[4]]


def test_neighbours_of_no_points_and_bad_radius():
    ptr, idx = palpate.neighbours(np.zeros((0, 3)), 1.0)
    assert ptr.tolist() == [0] and len(idx) == 0
    with pytest.raises(ValueError, match="radius"):
        palpate.neighbours(np.zeros((2, 3)), -1.0)
    with pytest.raises(ValueError, match=r"points must have shape \(n, 3\)"):
        palpate.neighbours(np.zeros((2, 2)), 1.0)


def test_defaults_are_the_cores():
    d = palpate.defaults
    assert d.hybrid.projection == palpate.Projection.TRANSMURAL
    assert d.particles.kernel == K.WENDLAND_C2
    assert d.newton.max_iterations >= 1 and 0 < d.newton.tolerance < 1
    # What BackwardEuler fills in is what defaults says.
    qn = palpate.BackwardEuler()
    assert (qn.max_iterations, qn.tolerance, qn.history) == (
        d.quasi_newton.max_iterations, d.quasi_newton.tolerance, d.quasi_newton.history)
    nt = palpate.BackwardEuler(palpate.Solver.NEWTON)
    assert (nt.max_iterations, nt.tolerance) == (d.newton.max_iterations, d.newton.tolerance)
    assert set(d.hybrid.options()) == {"projection", "core_fraction", "core_triangles", "core_layers", "spacing",
                                       "particles", "density", "min_region_particles", "field_voxels", "homogenise"}
    # One default tissue (issue 36): the core's Material::myocardium, the builder's density, and
    # the tissue of palpate touch, palpate haptic and the hybrid bench.
    from palpate import bench_hybrid, haptics
    from palpate.cli import touch

    m = palpate.Material.myocardium()
    assert (d.tissue.young, d.tissue.poisson, d.tissue.density) == (30e3, 0.4, 1060.0) == (
        round(m.young, 6), round(m.poisson, 12), m.density)
    assert d.hybrid.density == d.tissue.density
    t = d.tissue_material(phi=1.0)
    assert (t.density, t.phi) == (1060.0, 1.0) and abs(t.young - 30e3) < 1e-6
    for mod in (touch, haptics):
        assert (mod.YOUNG, mod.POISSON, mod.DENSITY) == (d.tissue.young, d.tissue.poisson, d.tissue.density)
    assert (bench_hybrid.E, bench_hybrid.NU, bench_hybrid.RHO) == (d.tissue.young, d.tissue.poisson, d.tissue.density)
    assert haptics.material().density == bench_hybrid.material().density == d.tissue.density


def test_hybrid_builders_refuse_an_unknown_option():
    s = palpate.ellipsoid_surface((0.02, 0.02, 0.03), 1)
    with pytest.raises(TypeError, match="unexpected keyword argument 'core_fractoin'"):
        palpate.HybridModel.build_nested(s, s, core_fractoin=0.5)
    with pytest.raises(TypeError, match="core_fraction"):
        palpate.HybridModel.build_nested(s, s, core_fraction="half")
