"""Locking study: how stiff a coarse tet mesh of the whole ellipsoid wall is, per element technology.

A Hertz-like pressure presses on the side of the paper's closed wall (the region between the
ellipsoids :data:`palpate.validate.ELLIPSOIDS_INNER` and ``ELLIPSOIDS_OUTER``), held at every node
with z <= -15.4 mm; linear elasticity, E = 30 kPa, nu = 0.4. Each mesh is solved with

- ``P1``: linear (constant-strain) tets;
- ``P2``: quadratic tets on the same (straight-sided) mesh, assembled by scikit-fem;
- ``FS``: face-based smoothed FEM with linear tets (FS-FEM-T4, Nguyen-Thoi, Liu et al. 2009): the
  strain of an interior face's smoothing domain is the volume-weighted mean of its two tets'
  strains, its volume a quarter of theirs; a boundary face takes its one tet's;
- ``NS``: node-based smoothed FEM (NS-FEM-T4): the strain of a node's domain is the mean of its
  tets' strains weighted by a quarter of their volumes (a lower bound of the stiffness).

P1, FS and NS share one assembly, ``K = S^T blockdiag(vol_k D) S`` with ``S`` the smoothing of the
element strains (the identity for P1). The load is ``p(r) = p0 sqrt(1 - r^2/a^2)``, r the distance
from the x axis, along -x on the outer surface's triangles with x > 0, integrated on each triangle
split into sub-triangles of at most a/20 (3 points each) with the element's own face shape
functions, ``p0`` such that the total force is exactly 0.1 N; a = 7.7 mm (a 15 mm sphere about
4 mm deep) and a = 4.5 mm (a 5 mm sphere).

Per (mesh, element, load) it reports the tets, DOFs, the compliance ``C = f.u / F^2`` [m/N], the
outer surface's displacement along -x at 0, 5, 10 and 20 mm from the load axis (toward +y) and
the solve time, then the compliance relative to the reference (P2 on the finest graded wall it
solves with P2), the Richardson extrapolation of P1 over the graded levels, and the dent profiles.

Meshes: the graded reference walls of :func:`palpate.validate.graded_ellipsoid_wall` (3,2), (4,4),
(5,8) (the last P1 only); uniform walls of :func:`palpate.ellipsoid_wall`; the hybrid build's core
taken across the wall (:func:`palpate.hybrid.build_shape`, core fraction 0.999); and those of at
most 1000 tets refined twice (each tet into 8) and solved with P2, once with a new node held when
both ends of its edge are (the converged answer of the coarse mesh's own faceted geometry and
held set: what is left is the element error) and once held at z <= -15.4 mm as the finer mesh
resolves it (what is left against the reference is the error of its flat or simplified surfaces;
the difference between the two, that of where the coarse nodes put the clamp's edge).

Checks first: the plain-strain assembly equals scikit-fem's P1 matrix, and a linear displacement
prescribed on the boundary of a two-layer wall is reproduced inside by P1, P2, FS and NS.

Direct solves (SuperLU) up to 40k DOFs; larger ones by CG preconditioned with a two-level
additive method (a nested P1 space solved directly, nodal 3x3 block Jacobi).

Run (from the repository root; about 7 minutes on 2 busy cores, ``--quick`` about 20 s)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \\
        .venv/bin/python bench/locking_study.py [--quick] [--json results.json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components
from skfem import Basis, ElementTetP1, ElementTetP2, ElementVector, MeshTet, asm
from skfem.models.elasticity import lame_parameters, linear_elasticity

import palpate
from palpate.hybrid import build_shape
from palpate.validate import (ELLIPSOIDS_INNER, ELLIPSOIDS_OUTER, IndentCase, dent_probes, graded_ellipsoid_wall,
                              surface_weights)

YOUNG, POISSON = 30e3, 0.4
LAME = lame_parameters(YOUNG, POISSON)
HOLD_Z = -0.0154
FORCE = 0.1
RADII = (7.7e-3, 4.5e-3)
PROBES = (0.0, 0.005, 0.010, 0.020)
SUBTRIANGLES_PER_RADIUS = 20
DIRECT_MAX_DOFS = 40_000
CG_RTOL = 1e-10
ELEMENTS = ("P1", "P2", "FS", "NS")

# Voigt strain rows (xx, yy, zz, yz, xz, xy; engineering shears) as (row, component, derivative).
VOIGT = ((0, 0, 0), (1, 1, 1), (2, 2, 2), (3, 1, 2), (3, 2, 1), (4, 0, 2), (4, 2, 0), (5, 0, 1), (5, 1, 0))


def elasticity_matrix() -> np.ndarray:
    lam, mu = LAME
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[np.arange(3), np.arange(3)] += 2 * mu
    d[np.arange(3, 6), np.arange(3, 6)] = mu
    return d


# ----------------------------------------------------------------------------------------- meshes

@dataclass
class Wall:
    """A tet mesh of the wall, its held vertices, the elements to solve it with, and (for the
    large solves' preconditioner) a coarser wall whose P1 space ``prolong`` maps onto its vertices."""

    label: str
    group: str
    mesh: MeshTet
    held: np.ndarray
    elements: Tuple[str, ...]
    parent: Optional["Wall"] = None
    prolong: Optional[sp.csr_matrix] = None

    @property
    def points(self) -> np.ndarray:
        return self.mesh.p.T

    @property
    def tets(self) -> np.ndarray:
        return self.mesh.t.T


def from_palpate(label: str, group: str, m: palpate.TetMesh, elements: Sequence[str] = ELEMENTS) -> Wall:
    p = np.ascontiguousarray(np.asarray(m.points, dtype=float).T)
    mesh = MeshTet(p, np.ascontiguousarray(np.asarray(m.tets).T))
    return Wall(label, group, mesh, p[2] <= HOLD_Z, tuple(elements))


def midpoint_prolongation(n: int, edges: np.ndarray) -> sp.csr_matrix:
    """Nodal values on ``n`` vertices -> the vertices and then the midpoints of ``edges`` (2, m)."""
    m = edges.shape[1]
    rows = np.r_[np.arange(n), n + np.arange(m), n + np.arange(m)]
    cols = np.r_[np.arange(n), edges[0], edges[1]]
    return sp.csr_matrix((np.r_[np.ones(n), np.full(2 * m, 0.5)], (rows, cols)), shape=(n + m, n))


def refined(wall: Wall, label: str, elements: Sequence[str], hold_by_z: bool = False) -> Wall:
    """``wall`` with each tet split into 8 (the same faceted geometry); a new vertex is held when
    both ends of its edge are, so the held part of the boundary is the same, or with
    ``hold_by_z`` every vertex with z <= HOLD_Z (the clamp's edge as this finer mesh resolves it)."""
    fine = wall.mesh.refined()
    e = wall.mesh.edges
    assert np.allclose(fine.p[:, wall.mesh.nvertices:], (wall.mesh.p[:, e[0]] + wall.mesh.p[:, e[1]]) / 2)
    held = fine.p[2] <= HOLD_Z if hold_by_z else np.r_[wall.held, wall.held[e[0]] & wall.held[e[1]]]
    return Wall(label, "refined", fine, held, tuple(elements))


def graded(a: int, b: int, elements: Sequence[str], parent: Optional[Wall] = None) -> Wall:
    """The graded reference wall of level (a, b); with ``parent`` (level (a-1, b/2)), the
    interpolation of its P1 space: the parent's vertices are this wall's (its first geodesic
    directions, every second layer), a new direction is the mean of the two old ones it splits,
    an odd layer the mean of its neighbours."""
    w = from_palpate(f"graded ({a},{b})", "graded", graded_ellipsoid_wall(subdivisions=a, layers=b, focus=(1.0, 0, 0)),
                     elements)
    if parent is None:
        return w
    nv_c, nv_f = 4 * 4 ** (a - 1) + 2, 4 * 4 ** a + 2
    e = w.mesh.edges
    split = (e[1] < nv_f) & (e[0] < nv_c) & (e[1] >= nv_c)  # inner-surface edges from an old to a new direction
    child, old = e[1, split], e[0, split]
    assert np.all(np.bincount(child - nv_c, minlength=nv_f - nv_c) == 2)
    p_dir = sp.csr_matrix((np.r_[np.ones(nv_c), np.full(len(child), 0.5)], (np.r_[np.arange(nv_c), child],
                                                                             np.r_[np.arange(nv_c), old])),
                          shape=(nv_f, nv_c))
    lf = np.arange(b + 1)
    p_layer = sp.csr_matrix((np.full(2 * (b + 1), 0.5), (np.r_[lf, lf], np.r_[lf // 2, (lf + 1) // 2])),
                            shape=(b + 1, b // 2 + 1))
    w.parent, w.prolong = parent, sp.kron(p_layer, p_dir, format="csr")
    assert w.prolong.shape == (w.mesh.nvertices, parent.mesh.nvertices)
    return w


def core(n: int, layers: int, elements: Sequence[str] = ELEMENTS) -> Wall:
    m = build_shape("ellipsoids", core_fraction=0.999, core_triangles=n, core_layers=layers, particles=2000)
    return from_palpate(f"core ({n},{layers})", "core", palpate.TetMesh(m.core_points, m.core_tets), elements)


def uniform(a: int, b: int) -> Wall:
    return from_palpate(f"uniform ({a},{b})", "uniform",
                        palpate.ellipsoid_wall(ELLIPSOIDS_INNER, ELLIPSOIDS_OUTER, subdivisions=a, layers=b))


def walls(quick: bool) -> List[Wall]:
    """The walls to solve, each coarse one followed by its same-geometry references: P2 on it
    refined x8 and x64 with its own held set, and x64 held at z <= HOLD_Z ("z-held")."""
    if quick:
        c64 = core(64, 1)
        return [graded(3, 2, ELEMENTS), uniform(2, 2), c64, refined(c64, "core (64,1) x8", ("P2",)), core(300, 1)]
    g44 = graded(4, 4, ELEMENTS)
    coarse = [uniform(a, b) for a, b in ((2, 1), (2, 2), (3, 1), (3, 2))]
    coarse += [core(n, l) for n, l in ((64, 1), (300, 1), (300, 2), (1000, 1), (1000, 2))]
    out = [graded(3, 2, ELEMENTS), g44, graded(5, 8, ("P1",), g44)]
    for w in coarse:
        out.append(w)
        if w.mesh.nelements <= 1000:
            x8 = refined(w, f"{w.label} x8", ("P2",))
            out += [x8, refined(x8, f"{w.label} x64", ("P2",)),
                    refined(x8, f"{w.label} x64 z-held", ("P2",), hold_by_z=True)]
    return out


# --------------------------------------------------------------------------------- discretisation

def tet_gradients(p: np.ndarray, t: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Volumes (T,) and the gradients of the four barycentric coordinates (T, 4, 3)."""
    j = np.stack([p[t[:, k]] - p[t[:, 0]] for k in (1, 2, 3)], axis=2)
    jinv = np.linalg.inv(j)
    return np.abs(np.linalg.det(j)) / 6, np.concatenate([-jinv.sum(axis=1, keepdims=True), jinv], axis=1)


def strain_operator(p: np.ndarray, t: np.ndarray) -> Tuple[sp.csr_matrix, np.ndarray]:
    """The element strains (6T rows, Voigt) of the nodal displacements (3N, node-major) and the
    tets' volumes."""
    vol, g = tet_gradients(p, t)
    rows = [np.repeat(6 * np.arange(len(t)) + r, 4) for r, _, _ in VOIGT]
    cols = [3 * t.ravel() + c for _, c, _ in VOIGT]
    vals = [g[:, :, d].ravel() for _, _, d in VOIGT]
    b = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(6 * len(t), 3 * len(p)))
    return b, vol


def tet_faces(t: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The distinct faces (sorted vertex triples) and, per tet's four faces (row-major), its face."""
    faces = np.sort(t[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3), axis=1)
    uniq, inv = np.unique(faces, axis=0, return_inverse=True)
    return uniq, inv.ravel()


def smoothing(t: np.ndarray, vol: np.ndarray, element: str) -> Tuple[sp.csr_matrix, np.ndarray]:
    """The smoothing ``A`` (domains x tets: a domain's strain is ``A`` times the tets' strains) and
    the domains' volumes. P1: the tets themselves; FS: a face's (its tets' volumes over 4); NS: a
    node's (its tets' volumes over 4)."""
    if element == "P1":
        return sp.identity(len(t), format="csr"), vol
    domain = {"FS": lambda: tet_faces(t)[1], "NS": t.ravel}[element]()
    a = sp.csr_matrix((np.repeat(vol / 4, 4), (domain, np.repeat(np.arange(len(t)), 4))),
                      shape=(domain.max() + 1, len(t)))
    dvol = np.asarray(a.sum(axis=1)).ravel()
    return sp.diags(1 / dvol) @ a, dvol


def smoothed_stiffness(b: sp.csr_matrix, a: sp.csr_matrix, dvol: np.ndarray) -> sp.csr_matrix:
    s = sp.kron(a, sp.identity(6), format="csr") @ b
    return (s.T @ sp.kron(sp.diags(dvol), elasticity_matrix(), format="csr") @ s).tocsr()


def p2_stiffness(mesh: MeshTet) -> sp.csr_matrix:
    basis = Basis(mesh, ElementVector(ElementTetP2()), intorder=2)
    nv, ne = mesh.nvertices, mesh.edges.shape[1]
    # node-major DOFs, the vertices then the edges (mesh.edges' order): 3 * node + component
    assert np.array_equal(basis.nodal_dofs, 3 * np.arange(nv) + np.arange(3)[:, None])
    assert np.array_equal(basis.edge_dofs, 3 * (nv + np.arange(ne)) + np.arange(3)[:, None])
    return asm(linear_elasticity(*LAME), basis).tocsr()


@dataclass
class Discrete:
    """One element technology on one wall: the stiffness (node-major DOFs), the nodes (P2: the
    vertices then the edge midpoints), which are held, and a nested P1 space (node-level
    prolongation and its held nodes) for the preconditioner of a large solve."""

    element: str
    K: sp.csr_matrix
    nodes: np.ndarray
    held: np.ndarray
    coarse: Optional[Tuple[sp.csr_matrix, np.ndarray]]

    @property
    def order(self) -> int:
        return 2 if self.element == "P2" else 1


def discretise(wall: Wall, element: str) -> Discrete:
    p, t = wall.points, wall.tets
    if element == "P2":
        e = wall.mesh.edges
        nodes = np.vstack([p, (p[e[0]] + p[e[1]]) / 2])
        held = np.r_[wall.held, wall.held[e[0]] & wall.held[e[1]]]
        return Discrete(element, p2_stiffness(wall.mesh), nodes, held,
                        (midpoint_prolongation(len(p), e), wall.held))
    b, vol = strain_operator(p, t)
    k = smoothed_stiffness(b, *smoothing(t, vol, element))
    coarse = (wall.prolong, wall.parent.held) if wall.parent is not None else None
    return Discrete(element, k, p, wall.held, coarse)


# ------------------------------------------------------------------------------- surface, load

def outer_faces(wall: Wall) -> np.ndarray:
    """The boundary triangles of the outer surface: of the closed wall's two boundary components,
    the one holding the boundary face farthest from the origin."""
    faces, inv = tet_faces(wall.tets)
    bnd = faces[np.bincount(inv, minlength=len(faces)) == 1]
    inc = sp.csr_matrix((np.ones(bnd.size), (np.repeat(np.arange(len(bnd)), 3), bnd.ravel())))
    n, comp = connected_components(inc @ inc.T, directed=False)
    assert n == 2, f"{wall.label}: {n} boundary components"
    far = np.argmax(np.linalg.norm(wall.points[bnd].mean(axis=1), axis=1))
    return bnd[comp == comp[far]]


def edge_ids(mesh: MeshTet, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    nv = mesh.nvertices
    keys = mesh.edges[0] * nv + mesh.edges[1]
    order = np.argsort(keys)
    want = np.minimum(a, b) * nv + np.maximum(a, b)
    pos = order[np.searchsorted(keys, want, sorter=order)]
    assert np.array_equal(keys[pos], want)
    return pos


def face_nodes(wall: Wall, faces: np.ndarray, order: int) -> np.ndarray:
    """The nodes of each triangle: its 3 vertices, for P2 then its edges (01, 12, 02)."""
    if order == 1:
        return faces
    nv = wall.mesh.nvertices
    mids = [nv + edge_ids(wall.mesh, faces[:, i], faces[:, j]) for i, j in ((0, 1), (1, 2), (0, 2))]
    return np.column_stack([faces] + mids)


def face_shapes(lam: np.ndarray, order: int) -> np.ndarray:
    """The triangle's shape functions at barycentric points ``lam`` (Q, 3): (Q, 3) or (Q, 6)."""
    if order == 1:
        return lam
    l0, l1, l2 = lam.T
    return np.column_stack([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1),
                            4 * l0 * l1, 4 * l1 * l2, 4 * l0 * l2])


@lru_cache(maxsize=None)
def subdivided_rule(n: int) -> Tuple[np.ndarray, np.ndarray]:
    """Barycentric points and weights (summing to 1) of the triangle split into n^2 sub-triangles,
    each with the 3-point degree-2 rule."""
    tris = []
    for i in range(n):
        for j in range(n - i):
            tris.append(((i, j), (i + 1, j), (i, j + 1)))
            if i + j < n - 1:
                tris.append(((i + 1, j), (i + 1, j + 1), (i, j + 1)))
    ij = np.array(tris, dtype=float) / n  # (s, 3 corners, 2)
    corners = np.concatenate([1 - ij.sum(axis=2, keepdims=True), ij], axis=2)  # (s, 3, 3) barycentric
    mix = np.full((3, 3), 1 / 6) + np.eye(3) / 2
    pts = np.einsum("qc,scb->sqb", mix, corners).reshape(-1, 3)
    return pts, np.full(len(pts), 1 / len(pts))


def load_vectors(wall: Wall, d: Discrete, outer: np.ndarray) -> np.ndarray:
    """The nodal forces (3 * nodes, len(RADII)) of the pressure along -x, 0.1 N in total."""
    p = wall.points
    f = np.zeros((3 * len(d.nodes), len(RADII)))
    front = outer[p[outer].mean(axis=1)[:, 0] > 0]
    nodes = face_nodes(wall, front, d.order)
    v = p[front]  # (F, 3, 3)
    cen = v.mean(axis=1)
    reach = np.linalg.norm(v - cen[:, None], axis=2).max(axis=1)
    longest = np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2).max(axis=1)
    area = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1) / 2
    for col, a in enumerate(RADII):
        hit = np.hypot(cen[:, 1], cen[:, 2]) - reach < a
        subdiv = np.ceil(longest * SUBTRIANGLES_PER_RADIUS / a).astype(int)
        fx = np.zeros(len(d.nodes))
        for n in np.unique(subdiv[hit]):
            sel = np.flatnonzero(hit & (subdiv == n))
            lam, w = subdivided_rule(int(n))
            x = np.einsum("qc,fcd->fqd", lam, v[sel])
            r2 = (x[:, :, 1] ** 2 + x[:, :, 2] ** 2) / a**2
            pw = np.sqrt(np.clip(1 - r2, 0, None)) * w * area[sel, None]  # (F, Q)
            np.add.at(fx, nodes[sel], pw @ face_shapes(lam, d.order))
        f[0::3, col] = -FORCE * fx / fx.sum()
    return f


def probe_operator(wall: Wall, d: Discrete, outer: np.ndarray) -> sp.csr_matrix:
    """Rows: the outer surface's displacement along -x at PROBES from the load axis toward +y."""
    p = wall.points
    pts = dent_probes(IndentCase(), (p, outer), distances=PROBES, azimuths=1)
    tri, lam = surface_weights(p, outer, pts)
    nodes = face_nodes(wall, outer[tri], d.order)
    shapes = face_shapes(lam, d.order)
    rows = np.repeat(np.arange(len(PROBES)), nodes.shape[1])
    return sp.csr_matrix((-shapes.ravel(), (rows, 3 * nodes.ravel())), shape=(len(PROBES), 3 * len(d.nodes)))


def shape_summary(wall: Wall) -> Dict:
    """How well the mesh holds the wall: its volume over the exact wall's, its thickness along the
    load axis (exact: 6 mm), its mean edge and its held nodes."""
    p, t = wall.points, wall.tets
    vol, _ = tet_gradients(p, t)
    exact = 4 / 3 * math.pi * (np.prod(ELLIPSOIDS_OUTER) - np.prod(ELLIPSOIDS_INNER))
    faces, inv = tet_faces(t)
    bnd = faces[np.bincount(inv) == 1]
    v = p[bnd]
    # where the +x half of the load axis (y = z = 0) crosses the boundary triangles
    yz = v[:, :, 1:]
    m = np.stack([yz[:, 1] - yz[:, 0], yz[:, 2] - yz[:, 0]], axis=2)
    ok = np.abs(np.linalg.det(m)) > 0
    uv = np.linalg.solve(m[ok], -yz[ok, 0][..., None])[..., 0]
    lam = np.column_stack([1 - uv.sum(axis=1), uv])
    inside = (lam >= -1e-12).all(axis=1)
    x = (lam[inside] * v[ok][inside][:, :, 0]).sum(axis=1)
    x = np.unique(np.round(x[x > 0], 9))[::-1]  # a hit on an edge or vertex counts once
    edges = wall.mesh.p[:, wall.mesh.edges]
    return dict(mesh=wall.label, tets=wall.mesh.nelements, volume=float(vol.sum() / exact),
                thickness=float(x[0] - x[1]), outer_x=float(x[0]),
                edge=float(np.linalg.norm(edges[:, 0] - edges[:, 1], axis=0).mean()), held=int(wall.held.sum()),
                nodes=int(wall.mesh.nvertices))


# ------------------------------------------------------------------------------------------ solve

def solve(d: Discrete, f: np.ndarray) -> Tuple[np.ndarray, float, str]:
    """The displacements (3 * nodes, columns of ``f``), the solve's seconds and how it was solved."""
    free = np.flatnonzero(np.repeat(~d.held, 3))
    kf = d.K[free][:, free].tocsc()
    u = np.zeros_like(f)
    t0 = time.perf_counter()
    if len(free) <= DIRECT_MAX_DOFS or d.coarse is None:
        lu = spla.splu(kf, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
        u[free] = lu.solve(f[free])
        return u, time.perf_counter() - t0, "direct"
    prolong, coarse_held = d.coarse
    pf = sp.kron(prolong, sp.identity(3), format="csr")[free][:, np.flatnonzero(np.repeat(~coarse_held, 3))]
    coarse = spla.splu((pf.T @ kf @ pf).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options=dict(SymmetricMode=True))
    blocks = np.stack([np.stack([kf[i::3, j::3].diagonal() for j in range(3)], axis=1) for i in range(3)], axis=1)
    binv = np.linalg.inv(blocks)

    def precondition(r: np.ndarray) -> np.ndarray:
        return pf @ coarse.solve(pf.T @ r) + np.einsum("nij,nj->ni", binv, r.reshape(-1, 3)).ravel()

    m = spla.LinearOperator(kf.shape, precondition)
    iterations = []
    for col in range(f.shape[1]):
        count = [0]
        x, info = spla.cg(kf, f[free, col], M=m, rtol=CG_RTOL, maxiter=5000,
                          callback=lambda _: count.__setitem__(0, count[0] + 1))
        assert info == 0, f"CG did not converge ({info})"
        u[free, col] = x
        iterations.append(count[0])
    return u, time.perf_counter() - t0, "PCG " + "/".join(map(str, iterations)) + " it"


def run(wall: Wall, element: str) -> List[Dict]:
    t0 = time.perf_counter()
    d = discretise(wall, element)
    outer = outer_faces(wall)
    f = load_vectors(wall, d, outer)
    assembly = time.perf_counter() - t0
    u, seconds, how = solve(d, f)
    dents = probe_operator(wall, d, outer) @ u
    out = []
    for col, a in enumerate(RADII):
        out.append(dict(mesh=wall.label, group=wall.group, element=element, radius=a, tets=wall.mesh.nelements,
                        dofs=3 * len(d.nodes), compliance=float(f[:, col] @ u[:, col]) / FORCE**2,
                        dent=[float(x) for x in dents[:, col]], assembly_s=assembly, solve_s=seconds, method=how))
    print(f"  {wall.label:22s} {element}: {wall.mesh.nelements:7d} tets {3 * len(d.nodes):7d} DOFs  C = "
          + ", ".join(f"{r['compliance'] * 1e3:.3f}" for r in out)
          + f" mm/N  ({assembly:.1f} s + {seconds:.1f} s {how})", flush=True)
    return out


# ----------------------------------------------------------------------------------------- checks

def checks() -> List[str]:
    """The plain-strain assembly against scikit-fem's P1, and the patch test of every element."""
    wall = uniform(2, 2)
    lines = []
    ours = discretise(wall, "P1").K
    ref = asm(linear_elasticity(*LAME), Basis(wall.mesh, ElementVector(ElementTetP1()), intorder=1))
    lines.append(f"plain-strain assembly vs scikit-fem P1 ({wall.label}): |K - K_skfem| / |K_skfem| = "
                 f"{sp.linalg.norm(ours - ref) / sp.linalg.norm(ref):.1e}")
    grad = np.array([[1.0, 0.4, -0.3], [0.2, -0.7, 0.5], [0.6, 0.1, 0.9]]) * 1e-2
    faces, inv = tet_faces(wall.tets)
    faces = faces[np.bincount(inv) == 1]
    for element in ELEMENTS:
        d = discretise(wall, element)
        boundary = np.zeros(len(d.nodes), bool)
        boundary[face_nodes(wall, faces, d.order).ravel()] = True
        exact = (d.nodes @ grad.T).ravel()
        inner, outer_ = np.flatnonzero(np.repeat(~boundary, 3)), np.flatnonzero(np.repeat(boundary, 3))
        u = exact.copy()
        u[inner] = spla.spsolve(d.K[inner][:, inner].tocsc(), -d.K[inner][:, outer_] @ exact[outer_])
        lines.append(f"patch test, linear displacement on the boundary of {wall.label}, {element}: "
                     f"{len(inner) // 3} interior nodes, max error / max displacement = "
                     f"{np.abs(u - exact).max() / np.abs(exact).max():.1e}")
    return lines


# ---------------------------------------------------------------------------------------- reports

def richardson(c: Sequence[float]) -> Tuple[float, float]:
    """Observed order and extrapolated limit of three values on meshes halving h."""
    p = math.log2((c[1] - c[0]) / (c[2] - c[1]))
    return p, c[2] + (c[2] - c[1]) / (2**p - 1)


def report(results: List[Dict], shapes: List[Dict], check_lines: List[str]) -> str:
    out = ["## Checks", ""] + [f"- {line}" for line in check_lines]
    meshes_table = ["", "## Meshes", "",
                    "| mesh | tets | nodes | held nodes | mean edge [mm] | volume / exact wall | "
                    "thickness on the load axis [mm] (exact 6) | outer surface on the axis, x [mm] (exact 26) |",
                    "|---|---:|---:|---:|---:|---:|---:|---:|"]
    meshes_table += [f"| {g['mesh']} | {g['tets']} | {g['nodes']} | {g['held']} | {g['edge'] * 1e3:.2f} | "
                     f"{g['volume']:.3f} | {g['thickness'] * 1e3:.2f} | {g['outer_x'] * 1e3:.2f} |" for g in shapes]
    by = {(r["mesh"], r["element"], r["radius"]): r for r in results}
    meshes = list(dict.fromkeys(r["mesh"] for r in results))
    ref_mesh = [m for m in meshes if (m, "P2", RADII[0]) in by and m.startswith("graded")][-1]
    bounded = [[by[(m, e, a)]["compliance"] for e in ("P1", "FS", "NS")] + [f"{m} a={a * 1e3:.1f} mm"]
               for m in meshes for a in RADII if all((m, e, a) in by for e in ("P1", "FS", "NS"))]
    unordered = [name for p1, fs, ns, name in bounded if not p1 <= fs <= ns]
    out.append("- C_P1 <= C_FS <= C_NS (the smoothed models' bounds): "
               + (f"FAILS on {', '.join(unordered)}" if unordered else "holds on every mesh and load"))
    out += meshes_table + ["", "## All solves", "",
                           "| mesh | element | tets | DOFs | a [mm] | C [mm/N] | dent 0 / 5 / 10 / 20 mm [mm] "
                           "| assembly s | solve s | solver |",
                           "|---|---|---:|---:|---:|---:|---|---:|---:|---|"]
    for r in results:
        out.append(f"| {r['mesh']} | {r['element']} | {r['tets']} | {r['dofs']} | {r['radius'] * 1e3:.1f} | "
                   f"{r['compliance'] * 1e3:.4f} | " + " / ".join(f"{x * 1e3:.4f}" for x in r["dent"])
                   + f" | {r['assembly_s']:.1f} | {r['solve_s']:.1f} | {r['method']} |")

    def same_geometry(m: str, a: float) -> Optional[Dict]:
        """P2 on the finest refinement of mesh ``m`` (its own faceted geometry converged)."""
        return next((by[(f"{m} {s}", "P2", a)] for s in ("x64", "x8") if (f"{m} {s}", "P2", a) in by), None)

    def ratio(m: str, e: str, a: float, to: Dict) -> str:
        return f"{by[(m, e, a)]['compliance'] / to['compliance']:.3f}" if (m, e, a) in by else ""

    unrefined = [m for m in meshes if not m.endswith(("x8", "x64", "z-held"))]
    for a in RADII:
        ref = by[(ref_mesh, "P2", a)]
        out += ["", f"## a = {a * 1e3:.1f} mm: compliance / reference (P2 on {ref_mesh}: "
                    f"C = {ref['compliance'] * 1e3:.4f} mm/N, centre dent {ref['dent'][0] * 1e3:.4f} mm)", "",
                "| mesh | tets | P1 | P2 | FS | NS | its own geometry and held set converged (P2 refined) "
                "| its surfaces converged, held at z <= -15.4 mm (P2 x64) |",
                "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for m in unrefined:
            g = same_geometry(m, a)
            cells = [ratio(m, e, a, ref) for e in ELEMENTS]
            cells.append(f"{g['compliance'] / ref['compliance']:.3f} ({g['mesh'].split()[-1]})" if g else "")
            cells.append(ratio(f"{m} x64 z-held", "P2", a, ref))
            out.append(f"| {m} | {by[(m, 'P1', a)]['tets']} | " + " | ".join(cells) + " |")
        out += ["", f"Element error alone, a = {a * 1e3:.1f} mm: compliance / P2 on the same mesh refined "
                    "(the same faceted geometry and held set); last column: x8 over x64 (its convergence)", "",
                "| mesh | tets | P1 | P2 | FS | NS | P2 x8 / x64 |", "|---|---:|---:|---:|---:|---:|---:|"]
        for m in unrefined:
            g = same_geometry(m, a)
            if g is None:
                continue
            x8 = ratio(f"{m} x8", "P2", a, g) if g["mesh"].endswith("x64") else ""
            out.append(f"| {m} | {by[(m, 'P1', a)]['tets']} | " + " | ".join(ratio(m, e, a, g) for e in ELEMENTS)
                       + f" | {x8} |")
        levels = [by[(m, "P1", a)] for m in meshes if m.startswith("graded")]
        if len(levels) == 3:
            p, lim = richardson([r["compliance"] for r in levels])
            pd, limd = richardson([r["dent"][0] for r in levels])
            out += ["", f"P1 over {', '.join(r['mesh'] for r in levels)}: compliance "
                        + ", ".join(f"{r['compliance'] * 1e3:.4f}" for r in levels)
                    + f" mm/N, observed order {p:.2f} (in h), Richardson limit {lim * 1e3:.4f} mm/N = "
                    f"{lim / ref['compliance']:.3f} x the reference; centre dent order {pd:.2f}, limit "
                    f"{limd * 1e3:.4f} mm = {limd / ref['dent'][0]:.3f} x the reference's."]
        out += ["", f"Dent profile / reference's (0, 5, 10, 20 mm; reference "
                    + ", ".join(f"{x * 1e3:.4f}" for x in ref["dent"]) + " mm):", "",
                "| mesh | " + " | ".join(ELEMENTS) + " |", "|---|" + "---|" * len(ELEMENTS)]
        for m in meshes:
            if m == ref_mesh:
                continue
            cells = [" / ".join(f"{x / y:.2f}" for x, y in zip(by[(m, e, a)]["dent"], ref["dent"]))
                     if (m, e, a) in by else "" for e in ELEMENTS]
            out.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="coarse meshes only; the reference is P2 on graded (3,2)")
    ap.add_argument("--json", help="write every solve's numbers to this file")
    args = ap.parse_args()
    t0 = time.perf_counter()
    check_lines = checks()
    print("\n".join(check_lines), flush=True)
    results, shapes = [], []
    for wall in walls(args.quick):
        shapes.append(shape_summary(wall))
        for element in wall.elements:
            results += run(wall, element)
    print()
    print(report(results, shapes, check_lines))
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(meshes=shapes, solves=results), fh, indent=1)


if __name__ == "__main__":
    main()
