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
