"""numpy <-> core conversions: round trips, accepted dtypes, clear dtype / shape errors."""
import numpy as np
import pytest

import palpate


def test_points_and_tets_round_trip(unit_tet):
    p, t = unit_tet
    m = palpate.TetMesh(p, t)
    assert m.points.dtype == np.float64 and m.points.shape == (4, 3)
    assert m.tets.dtype == np.int64 and m.tets.shape == (1, 4)
    np.testing.assert_array_equal(m.points, p)
    np.testing.assert_array_equal(m.tets, t)
    assert m.n_nodes == 4 and m.n_tets == 1 and len(m) == 1
    assert m.volume == pytest.approx(1 / 6)
    assert m.min_dihedral_deg == pytest.approx(54.7356, abs=1e-3)
    assert m.boundary_faces().shape == (4, 3)


def test_returned_arrays_are_copies(unit_tet):
    m = palpate.TetMesh(*unit_tet)
    a = m.points
    a[:] = 99.0
    assert m.points[1, 0] == 1.0


@pytest.mark.parametrize("dtype", [np.float32, np.int32, np.int64, np.uint8])
def test_points_accept_real_dtypes(unit_tet, dtype):
    p, t = unit_tet
    m = palpate.TetMesh(p.astype(dtype), t)
    np.testing.assert_array_equal(m.points, p)


@pytest.mark.parametrize("dtype", [np.int8, np.int16, np.int32, np.uint16, np.uint32, np.uint64])
def test_tets_accept_integer_dtypes(unit_tet, dtype):
    p, t = unit_tet
    np.testing.assert_array_equal(palpate.TetMesh(p, t.astype(dtype)).tets, t)


def test_lists_are_accepted():
    m = palpate.TetMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]])
    assert m.n_tets == 1


def test_non_contiguous_input_is_read_through_strides(unit_tet):
    p, t = unit_tet
    wide = np.zeros((4, 6))
    wide[:, ::2] = p
    view = wide[:, ::2]
    assert not view.flags.c_contiguous
    np.testing.assert_array_equal(palpate.TetMesh(view, t).points, p)
    np.testing.assert_array_equal(palpate.TetMesh(np.asfortranarray(p), np.asfortranarray(t)).points, p)


@pytest.mark.parametrize("bad, match", [
    (np.zeros((4, 2)), r"points must have shape \(n, 3\), got \(4, 2\)"),
    (np.zeros(12), r"points must have shape \(n, 3\), got \(12,\)"),
    (np.zeros((4, 3, 1)), r"points must have shape \(n, 3\), got \(4, 3, 1\)"),
])
def test_points_shape_errors(unit_tet, bad, match):
    with pytest.raises(ValueError, match=match):
        palpate.TetMesh(bad, unit_tet[1])


@pytest.mark.parametrize("dtype", [bool, complex, object, "U3"])
def test_points_dtype_errors(unit_tet, dtype):
    with pytest.raises(TypeError, match="points must hold real numbers"):
        palpate.TetMesh(unit_tet[0].astype(dtype), unit_tet[1])


def test_tets_shape_and_dtype_errors(unit_tet):
    p, t = unit_tet
    with pytest.raises(ValueError, match=r"tets must have shape \(m, 4\), got \(1, 3\)"):
        palpate.TetMesh(p, t[:, :3])
    with pytest.raises(TypeError, match=r"tets must be an integer array, got dtype float64.*astype"):
        palpate.TetMesh(p, t.astype(float))
    with pytest.raises(TypeError, match="tets must be an integer array"):
        palpate.TetMesh(p, t.astype(bool))


def test_huge_unsigned_index_is_out_of_range_not_wrapped(unit_tet):
    p, _ = unit_tet
    t = np.array([[0, 1, 2, 2**64 - 1]], dtype=np.uint64)
    with pytest.raises(palpate.MeshError, match="out of range"):
        palpate.TetMesh(p, t)


def test_body_arrays_shapes_and_errors(unit_tet, material):
    body = palpate.Body(palpate.TetMesh(*unit_tet), material, fixed=[0, 1, 2])
    for a in (body.positions, body.velocities, body.displacements, body.forces):
        assert a.shape == (4, 3) and a.dtype == np.float64
    assert body.masses.shape == (4,)
    assert body.masses.sum() == pytest.approx(1000.0 / 6)
    with pytest.raises(ValueError, match=r"forces must have shape \(4, 3\)"):
        body.set_forces(np.zeros((3, 3)))
    with pytest.raises(TypeError, match="forces must hold real numbers"):
        body.set_forces(np.zeros((4, 3), dtype=complex))
    with pytest.raises(ValueError, match="row 2 is not finite"):
        f = np.zeros((4, 3))
        f[2, 1] = np.nan
        body.set_forces(f)
    f = np.arange(12.0).reshape(4, 3)
    body.set_forces(f.astype(np.float32))
    np.testing.assert_array_equal(body.forces, f)


def test_fixed_indices_validation(unit_tet, material):
    mesh = palpate.TetMesh(*unit_tet)
    with pytest.raises(ValueError, match="node index 4 out of range"):
        palpate.Body(mesh, material, fixed=[4])
    with pytest.raises(ValueError, match="node index -1 out of range"):
        palpate.Body(mesh, material, fixed=[-1])
    with pytest.raises(TypeError, match="fixed must be an integer array"):
        palpate.Body(mesh, material, fixed=[0.0, 1.0])
    with pytest.raises(ValueError, match="1-D"):
        palpate.Body(mesh, material, fixed=[[0, 1]])
    b = palpate.Body(mesh, material, fixed=np.array([True, False, True, False]))
    np.testing.assert_array_equal(b.fixed, [0, 2])
    assert palpate.Body(mesh, material, fixed=[]).fixed.shape == (0,)
    with pytest.raises(ValueError, match="gravity must be 3 numbers"):
        palpate.Body(mesh, material, gravity=(0, 0))
