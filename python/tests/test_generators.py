"""The core's mesh generators, through the binding."""
import numpy as np
import pytest

import palpate


def test_ellipsoid_wall_default_is_paper_size():
    m = palpate.ellipsoid_wall()
    assert (m.n_tets, m.n_nodes) == (192, 54)      # the paper's ~188-tet "Ellipsoids Model"
    assert m.volume > 0 and m.min_dihedral_deg > 0
    m2 = palpate.ellipsoid_wall(subdivisions=2, layers=1)
    assert m2.n_tets == 3 * 1 * 8 * 16


def test_truncated_ellipsoid_wall():
    m = palpate.truncated_ellipsoid_wall()
    assert (m.n_tets, m.n_nodes) == (1320, 363)
    base = m.nodes_below(0.0)
    assert len(base) == 20 * 3
    assert np.all(m.points[base, 2] == 0.0)
    assert m.points[:, 2].min() == 0.0
    m2 = palpate.truncated_ellipsoid_wall(circumferential=8, longitudinal=3, layers=1, z_cut=0.005)
    assert m2.n_tets == 3 * 8 * 5
    assert m2.points[:, 2].min() == pytest.approx(0.005)


def test_box_mesh():
    m = palpate.box_mesh(size=(1.0, 2.0, 3.0), cells=(2, 3, 4))
    assert m.n_tets == 6 * 24 and m.n_nodes == 3 * 4 * 5
    assert m.volume == pytest.approx(6.0)
    assert len(m.boundary_faces()) == 2 * 2 * (2 * 3 + 3 * 4 + 2 * 4)


@pytest.mark.parametrize("call, match", [
    (lambda: palpate.ellipsoid_wall(layers=0), "layers"),
    (lambda: palpate.ellipsoid_wall(inner=(0.03, 0.03, 0.05)), "must each exceed"),
    (lambda: palpate.ellipsoid_wall(outer=(0.0, 1.0, 1.0)), "finite and positive"),
    (lambda: palpate.ellipsoid_wall(subdivisions=40), "too large"),
    (lambda: palpate.truncated_ellipsoid_wall(circumferential=2), "circumferential"),
    (lambda: palpate.truncated_ellipsoid_wall(z_cut=0.05), "z_cut"),
    (lambda: palpate.truncated_ellipsoid_wall(longitudinal=0), "longitudinal"),
    (lambda: palpate.box_mesh(size=(1.0, -1.0, 1.0)), "finite and positive"),
    (lambda: palpate.box_mesh(cells=(1, 0, 1)), "at least one cell"),
])
def test_generator_errors_are_value_errors_not_panics(call, match):
    with pytest.raises(ValueError, match=match):
        call()
