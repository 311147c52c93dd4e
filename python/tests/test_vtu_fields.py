"""VTU output (issue 16, item 8): what a ParaView user plots, read back with meshio and checked
against values computed here from the positions alone (numpy, the textbook formulas).

What a wrong implementation would do: the first Piola or the second Piola stress written as
"von Mises" (not the Cauchy stress's), an energy density per deformed volume or per element
instead of per rest volume, flags on the wrong nodes: each differs from the reference below."""
import meshio
import numpy as np
import pytest

import palpate
from palpate.io import VtuSeries, read_pvd

LAM, MU = 2.0e4, 1.0e4   # [Pa]


def pressed_bar():
    mesh = palpate.box_mesh(size=(0.1, 0.02, 0.02), cells=(8, 2, 2))
    body = palpate.Body(mesh, palpate.Material(lame_lambda=LAM, lame_mu=MU, density=1000.0),
                        fixed=np.flatnonzero(mesh.points[:, 0] == 0.0))
    tip = np.flatnonzero(mesh.points[:, 0] == 0.1)
    f = np.zeros((body.n_nodes, 3))
    f[tip] = (0.05, 0.0, -0.2)
    body.set_forces(f)
    body.step(60)
    return body, tip


def reference(points, tets, x):
    """Per tet: von Mises of the Cauchy stress, SVK energy density per rest volume, det F, rest volume."""
    X, Y = points[tets], x[tets]
    dm = np.stack([X[:, k] - X[:, 0] for k in (1, 2, 3)], axis=2)
    ds = np.stack([Y[:, k] - Y[:, 0] for k in (1, 2, 3)], axis=2)
    F = ds @ np.linalg.inv(dm)
    I = np.eye(3)
    E = 0.5 * (np.transpose(F, (0, 2, 1)) @ F - I)
    trE = np.trace(E, axis1=1, axis2=2)
    S = LAM * trE[:, None, None] * I + 2 * MU * E
    J = np.linalg.det(F)
    sigma = F @ S @ np.transpose(F, (0, 2, 1)) / J[:, None, None]
    dev = sigma - np.trace(sigma, axis1=1, axis2=2)[:, None, None] / 3 * I
    vm = np.sqrt(1.5 * np.sum(dev * dev, axis=(1, 2)))
    psi = MU * np.sum(E * E, axis=(1, 2)) + 0.5 * LAM * trE ** 2
    return vm, psi, J, np.abs(np.linalg.det(dm)) / 6


def test_body_frame_fields_read_back(tmp_path):
    body, tip = pressed_bar()
    series = VtuSeries(tmp_path, body.mesh.tets)
    series.write_body(body, loaded=tip)
    m = meshio.read(tmp_path / "frame_00000.vtu")
    pts, tets = body.mesh.points, body.mesh.tets
    assert np.array_equal(m.cells_dict["tetra"], tets)
    np.testing.assert_array_equal(m.points, body.positions)
    np.testing.assert_array_equal(m.point_data["displacement"], body.positions - pts)
    np.testing.assert_array_equal(m.point_data["velocity"], body.velocities)
    assert set(np.flatnonzero(m.point_data["fixed"])) == set(np.flatnonzero(pts[:, 0] == 0.0))
    assert set(np.flatnonzero(m.point_data["loaded"])) == set(tip)
    vm, psi, J, vol = reference(pts, tets, body.positions)
    assert vm.max() > 1e2    # deformed enough to mean something [Pa]
    np.testing.assert_allclose(m.cell_data["von_mises"][0], vm, rtol=1e-9, atol=1e-9 * vm.max())
    np.testing.assert_allclose(m.cell_data["energy_density"][0], psi, rtol=1e-9, atol=1e-12 * psi.max())
    np.testing.assert_allclose(m.cell_data["det_f"][0], J, rtol=1e-12)
    assert np.sum(m.cell_data["energy_density"][0] * vol) == pytest.approx(body.strain_energy(), rel=1e-9)
    assert not m.cell_data["inverted"][0].any()
    assert [(t, p.split("/")[-1]) for t, p in read_pvd(series.pvd_path)] == [(body.time, "frame_00000.vtu")]


def test_inverted_elements_flagged(tmp_path):
    body, _ = pressed_bar()
    x = body.mesh.points.copy()
    t0 = body.mesh.tets[0]
    # Push the first tet's last vertex through its opposite face: that tet inverts.
    a, b, c, d = x[t0]
    n = np.cross(b - a, c - a)
    x[t0[3]] = d - 2.5 * np.dot(d - a, n) / np.dot(n, n) * n
    body.set_positions(x)
    VtuSeries(tmp_path, body.mesh.tets).write_body(body)
    m = meshio.read(tmp_path / "frame_00000.vtu")
    inv = m.cell_data["inverted"][0]
    _, _, J, _ = reference(body.mesh.points, body.mesh.tets, x)
    assert inv[0] == 1 and np.array_equal(inv, (J <= 0).astype(inv.dtype))
    assert np.isfinite(m.cell_data["von_mises"][0]).all()
    # The default loaded flags: the nodes carrying a force.
    assert set(np.flatnonzero(m.point_data["loaded"])) == set(np.flatnonzero(np.any(body.forces != 0, axis=1)))


def test_particle_body_vtu(tmp_path, material):
    g = np.arange(4) * 1e-3
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    body = palpate.ParticleBody(pos, np.full(len(pos), 1e-6), material, 1.8e-3, fixed=np.arange(16),
                                gravity=(0, 0, -9.81))
    body.active = np.arange(40)
    body.step(5, dt=1e-4)
    m = meshio.read(palpate.write_particles(tmp_path / "p.vtu", body))
    np.testing.assert_array_equal(m.points, body.positions)
    np.testing.assert_array_equal(m.point_data["displacement"], body.positions - pos)
    np.testing.assert_array_equal(m.point_data["velocity"], body.velocities)
    assert set(np.flatnonzero(m.point_data["fixed"])) == set(range(16))
    assert set(np.flatnonzero(m.point_data["active"])) == set(range(40))
    assert len(m.cells_dict["vertex"]) == body.n_particles


def test_hybrid_model_parts(tmp_path):
    inner, outer = (palpate.ellipsoid_surface(a, 2) for a in ((0.02, 0.02, 0.03), (0.03, 0.03, 0.04)))
    model = palpate.HybridModel.build_nested(inner, outer, particles=1000, field_voxels=3000)
    pvd = palpate.write_hybrid_model(tmp_path, model)
    names = [p.split("/")[-1] for _, p in read_pvd(pvd)]
    assert names == ["hybrid_core.vtu", "hybrid_shell.vtu", "hybrid_skin.vtu"]
    core = meshio.read(tmp_path / "hybrid_core.vtu")
    np.testing.assert_array_equal(core.points, model.core_points)
    np.testing.assert_array_equal(core.cells_dict["tetra"], model.core_tets)
    shell = meshio.read(tmp_path / "hybrid_shell.vtu")
    np.testing.assert_array_equal(shell.points, model.particles)
    np.testing.assert_array_equal(shell.point_data["outer_triangle"], model.particle_outer_triangle)
    np.testing.assert_allclose(shell.point_data["mass"].sum(), model.particle_masses.sum())
    skin = meshio.read(tmp_path / "hybrid_skin.vtu")
    np.testing.assert_array_equal(skin.cells_dict["triangle"], model.outer_triangles)
    assert len(skin.points) == model.n_regions


def test_a_quadratic_body_is_written_with_its_ten_node_cells(tmp_path):
    """A ``Body(order=2)`` frame holds VTK ``tetra10`` cells over all its nodes (vertices, then
    edge nodes), each edge node at its edge's midpoint at rest: ParaView draws the curved
    elements rather than the vertices' linear tets."""
    import meshio

    mesh = palpate.box_mesh(size=(0.02, 0.01, 0.01), cells=(2, 1, 1))
    fixed = np.flatnonzero(mesh.points[:, 0] == 0.0)
    body = palpate.Body(mesh, palpate.Material(young=3e4, poisson=0.4, density=1000.0), fixed=fixed,
                        gravity=(0, 0, -9.81), order=2)
    path = palpate.VtuSeries(tmp_path, mesh.tets).write_body(body)
    m = meshio.read(path)
    (block,) = m.cells
    assert block.type == "tetra10" and block.data.shape == (mesh.n_tets, 10)
    assert len(m.points) == body.n_nodes
    p = body.positions
    for a, b, e in ((0, 1, 4), (1, 2, 5), (0, 2, 6), (0, 3, 7), (1, 3, 8), (2, 3, 9)):
        np.testing.assert_allclose(p[block.data[:, e]], 0.5 * (p[block.data[:, a]] + p[block.data[:, b]]), atol=1e-15)
    np.testing.assert_array_equal(block.data[:, :4], mesh.tets)
