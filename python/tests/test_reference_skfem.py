"""Static solve vs an independent code: scikit-fem's P1 linear elasticity on the benchmark meshes.

palpate's static solve uses the full Green-strain (St. Venant-Kirchhoff) forces, so under a small
load it must agree with linear elasticity with the same Lame constants to first order in the
strain; the difference shrinks in proportion to the load (a wrong force convention, e.g. the
paper's eq. (22) with vol/2, would give twice the displacement and fail by 50%).
"""
import os

import numpy as np
import pytest

import palpate

skfem = pytest.importorskip("skfem")
from skfem.models.elasticity import linear_elasticity  # noqa: E402

SHARED = os.environ.get("PALPATE_SHARED", os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared"))
MESHES = os.path.join(SHARED, "bench", "meshes")
E, NU, RHO = 3.0e4, 0.4, 1000.0
MU, LAM = E / (2 * (1 + NU)), E * NU / ((1 + NU) * (1 - 2 * NU))


def skfem_static(points, tets, fixed, forces):
    mesh = skfem.MeshTet(points.T.copy(), tets.T.copy())
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    K = skfem.asm(linear_elasticity(LAM, MU), basis)
    f = np.zeros(basis.N)
    dofs = basis.nodal_dofs  # (3, n_nodes)
    for c in range(3):
        f[dofs[c]] = forces[:, c]
    u = skfem.solve(*skfem.condense(K, f, D=dofs[:, fixed].ravel()))
    return u[dofs].T


@pytest.mark.parametrize("name", ["190", "1350"])
def test_static_small_load_matches_scikit_fem_linear_elasticity(name):
    path = os.path.join(MESHES, f"lv_{name}.npz")
    if not os.path.exists(path):
        pytest.skip(f"shared benchmark meshes not found at {MESHES}")
    d = np.load(path)
    points, tets = d["points"] * 0.01, d["tets"].astype(np.int64)
    fixed = np.flatnonzero(points[:, 2] <= 1e-8)
    body = palpate.Body(palpate.TetMesh(points, tets), palpate.Material(young=E, poisson=NU, density=RHO), fixed=fixed)
    # A probe-like load: 2 mN spread over the outer nodes near (2.29, 0, 2.0) cm, pushing inward.
    probe = np.array([0.0228629, 0.0, 0.02])
    near = np.argsort(np.linalg.norm(points - probe, axis=1))[:4]
    forces = np.zeros_like(points)
    errors = []
    for scale in (1e-3, 1e-4):
        forces[near] = np.array([-0.948142, 0.0, -0.317848]) * 2.0 * scale / len(near)
        u_ref = skfem_static(points, tets, fixed, forces)
        u = body.static_solve(forces) - points
        errors.append(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref))
    # First-order agreement, and the geometric nonlinearity shrinks with the load.
    assert errors[0] < 1e-3, errors
    assert errors[1] < errors[0] / 5, errors


def test_quadratic_body_matches_scikit_fem_p2():
    """``Body(order=2)`` against scikit-fem's P2 linear elasticity on a perturbed box under small
    nodal loads on vertices and edge nodes alike: the same element, written twice (a wrong
    quadrature weight, edge numbering or edge-node placement fails by far more)."""
    mesh = palpate.box_mesh(size=(0.03, 0.02, 0.01), cells=(3, 2, 1))
    rng = np.random.default_rng(4)
    pts = mesh.points + rng.uniform(-1e-3, 1e-3, mesh.points.shape) * (mesh.points[:, [0]] > 0)
    mesh = palpate.TetMesh(pts, mesh.tets)
    fixed = np.flatnonzero(pts[:, 0] == 0.0)
    body = palpate.Body(mesh, palpate.Material(young=E, poisson=NU, density=RHO), fixed=fixed, order=2)
    nv = mesh.n_nodes
    assert body.order == 2 and body.n_nodes == nv + len(body.edges)
    rest = body.positions
    np.testing.assert_allclose(rest[nv:], 0.5 * (pts[body.edges[:, 0]] + pts[body.edges[:, 1]]), atol=1e-15)

    sk = skfem.MeshTet(pts.T.copy(), mesh.tets.T.astype(np.int64).copy())
    basis = skfem.Basis(sk, skfem.ElementVector(skfem.ElementTetP2()))
    K = skfem.asm(linear_elasticity(LAM, MU), basis)
    # palpate's node of each skfem dof: vertices as they are, skfem's edges by their vertex pair.
    our_edge = {tuple(e): nv + k for k, e in enumerate(body.edges)}
    sk_edges = [our_edge[tuple(sorted(e))] for e in sk.edges.T]
    nodes = np.concatenate([np.arange(nv), sk_edges])                 # skfem node order -> ours
    dofs = np.concatenate([basis.nodal_dofs, basis.edge_dofs], axis=1)  # (3, nv + n_edges)
    held = np.flatnonzero(np.isin(nodes, body.fixed))
    forces = rng.normal(size=(body.n_nodes, 3)) * 1e-6
    forces[body.fixed] = 0.0
    f = np.zeros(basis.N)
    for c in range(3):
        f[dofs[c]] = forces[nodes, c]
    u_ref = skfem.solve(*skfem.condense(K, f, D=dofs[:, held].ravel()))[dofs].T
    u = (body.static_solve(forces) - rest)[nodes]
    err = np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref)
    assert err < 1e-4, err


def test_quadratic_body_order_is_checked_and_pickles():
    import pickle
    mesh = palpate.box_mesh(size=(0.02, 0.01, 0.01), cells=(2, 1, 1))
    mat = palpate.Material(young=E, poisson=NU, density=RHO)
    for bad in (0, 3, -1):
        with pytest.raises(palpate.ParameterError, match="order"):
            palpate.Body(mesh, mat, order=bad)
    with pytest.raises(palpate.ModelError, match="semi-implicit"):
        palpate.Body(mesh, mat, order=2, integrator=palpate.SemiImplicit())
    fixed = np.flatnonzero(mesh.points[:, 0] == 0.0)
    body = palpate.Body(mesh, mat, fixed=fixed, order=2, gravity=(0, 0, -9.81))
    # Edge nodes between two fixed vertices are fixed too.
    assert len(body.fixed) > len(fixed) and set(fixed) <= set(body.fixed)
    body.step(5)
    again = pickle.loads(pickle.dumps(body))
    assert again.order == 2 and again.n_nodes == body.n_nodes
    np.testing.assert_array_equal(again.positions, body.positions)
    body.step(3)
    again.step(3)
    np.testing.assert_array_equal(again.positions, body.positions)
    assert palpate.Body(mesh, mat).order == 1 and palpate.Body(mesh, mat).edges.shape == (0, 2)
