"""Sphere indentation at the protocol's probe point (issue 12, "the paper's claim, measured"):
force against indentation depth for whole-wall FEM meshes (lv_190 = the paper's scale, lv_1350,
lv_10k, lv_50k = the reference) and for the hybrid model (HybridSim on build_shape("ventricle")),
same material (St. Venant-Kirchhoff, E = 30 kPa, nu = 0.4, 1000 kg/m^3; ``--law nh`` runs the FEM
meshes with the Neo-Hookean law instead), same 5 mm rigid sphere, same probe point P and direction
n (shared/bench/PROTOCOL.md; mesh units x 0.01 = m).

    OMP_NUM_THREADS=1 PALPATE_SHARED=../shared nice -n 10 \\
        .venv/bin/python bench/indentation.py --meshes 190 1350 10k --core-fractions 0.3 0.7
    ... bench/indentation.py --meshes 50k --no-hybrid --depths 1 2 3 4          (~10 min)
    ... bench/indentation.py --meshes 190 1350 10k 50k --law nh --no-hybrid      (~5 min)

``INDENT_DEBUG=1`` prints every outer iteration. Each model's curve is kept in out/indentation/curve_<label>.json as soon as it is done; every run
rebuilds out/indentation/indentation.csv, indentation.png and the printed tables (VALIDATION.md)
from all the curves there.

What is compared (the same quantity for every model)
----------------------------------------------------
The sphere's centre moves along the protocol's inward normal n through P: ``c(t) = P - R n + t n``.
Each model's surface is a different discretisation of the same ellipsoid (lv_190's facets lie
0.44 mm inside it at P), so each model has its own first-contact travel ``t0`` (the least t at
which the sphere touches one of that model's contact points at rest). The *indentation* is the
tool travel beyond first contact minus the deepest penetration of the contact law:
``delta = t - t0 - max penetration``, how far the tissue surface was pushed in at the deepest
contact point. Reported against it: the normal force ``F = force on the tool . (-n)`` [N] (the
tissue pushes the tool back out). Subtracting the penetration makes the curve (nearly)
independent of the penalty (checked: FEM with the penalty / 4, hybrid with 30 instead of 60 N/m).

FEM contact (Python, here): the outer-surface triangles near P are sampled with points at
barycentric sub-triangle centroids (about SAMPLE_SPACING apart), each carrying its sub-triangle's
area A_i, so that the contact resolves the sphere on any mesh (lv_190's triangles are 30 mm across:
contact on its nodes alone would be a point load on one node). A point inside the sphere by g_i
receives ``f_i = KAPPA A_i g_i`` along the sphere's normal, spread to its triangle's nodes by its
barycentric weights: a pressure penalty, independent of the mesh resolution (penetration 15-150 um
here). Equilibrium with the contact: an outer iteration on the point forces f. Each step solves
the contact of the *linearised* wall around the current state exactly (active-set Newton with the
rest-linear compliance of the contact points, assembled here from P1 linear elasticity with the
same Lame constants and fixed base, scaled by the secant ratio of the actual to the linear
displacement; relaxed when the contact flips between facets), then palpate computes the nonlinear
static state under the resulting nodal forces (``FemIndenter._static``: backward-Euler Newton steps
of 1 s from the previous state, where inertia is ~1e-6 of the stiffness, until no node moves by
1 nm; ``Body.static_solve`` restarts from rest and failed under the concentrated contact). So the
answer is palpate's nonlinear static equilibrium; the linear model only steers the iteration.
A depth counts as converged when the tool force of the applied point forces and the penalty
force of the configuration they produce agree within 0.5%; others are dropped from the table.

Hybrid: ``HybridSim(model, material, tool_radius=5 mm)``; the tool is a penalty per skin vertex
(60 N/m by default). The tool centre moves in a staircase (1 mm in 0.5 s, then held 0.5 s) and
force, penetration (``last["max_depth_m"]``) and indentation are averaged over each hold's last
0.25 s. First contact ``t0``: the least travel at which the sphere touches a skin vertex at rest.
"""
from __future__ import annotations

import argparse
import csv
import os
import platform
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import palpate
from palpate import bench

R_TOOL = 5e-3            # [m]
KAPPA = 3e9              # pressure penalty [Pa/m]
SAMPLE_SPACING = 0.35e-3 # [m]
STATIC_DT = 1.0           # [s]: see FemIndenter._static
LATERAL = 8e-3           # contact points within this distance of the tool's axis [m]
NEAR = 20e-3             # ... and of P [m] (the axis also crosses the opposite wall)
OUT = Path("out/indentation")


def probe():
    """P [m] and the inward unit normal n (PROTOCOL.md)."""
    P, n = bench.probe_point()
    return P * bench.SCALE, n


def tool_centre(t):
    P, n = probe()
    return P - R_TOOL * n + t * n


def first_contact(points):
    """Least travel t at which the sphere c(t) touches one of ``points`` (inf if none)."""
    P, n = probe()
    c0 = P - R_TOOL * n
    r = points - c0
    a = r @ n
    perp2 = np.einsum("ij,ij->i", r, r) - a * a
    ok = perp2 < R_TOOL ** 2
    if not ok.any():
        return np.inf
    return float(np.min(a[ok] - np.sqrt(R_TOOL ** 2 - perp2[ok])))


# ---------------------------------------------------------------------------- FEM side

def linear_stiffness(X, tets, lam, mu):
    """Assembled P1 linear-elasticity stiffness (3n x 3n, csr) of the rest mesh X [m]."""
    x0 = X[tets[:, 0]]
    Dm = np.stack([X[tets[:, 1]] - x0, X[tets[:, 2]] - x0, X[tets[:, 3]] - x0], axis=2)  # (t,3,3) columns
    vol = np.abs(np.linalg.det(Dm)) / 6.0
    Dinv = np.linalg.inv(Dm)                      # rows: gradients of N1..N3
    g = np.concatenate([-Dinv.sum(axis=1, keepdims=True), Dinv], axis=1)  # (t,4,3)
    gg = np.einsum("tai,tbi->tab", g, g)
    eye = np.eye(3)
    Ke = (lam * np.einsum("tai,tbj->taibj", g, g) + mu * np.einsum("taj,tbi->taibj", g, g)
          + mu * np.einsum("tab,ij->taibj", gg, eye)) * vol[:, None, None, None, None]
    dof = (3 * tets[:, :, None] + np.arange(3)[None, None, :]).reshape(len(tets), 12)
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    n = 3 * len(X)
    return sp.csr_matrix((Ke.reshape(len(tets), 144).ravel(), (rows, cols)), shape=(n, n))


def outer_faces(mesh, points_mu):
    """Boundary faces whose three nodes lie on the outer ellipsoid (bench.setup's test)."""
    level = np.sqrt(((points_mu / bench.OUTER) ** 2).sum(1))
    on = np.abs(level - 1) < 1e-3
    f = mesh.boundary_faces()
    return f[on[f].all(axis=1)]


def sample_faces(X, faces, spacing):
    """Points at the centroids of an m x m barycentric subdivision of each face (m from the
    longest edge / spacing): (face index, barycentric (p,3), area (p,))."""
    out_f, out_b, out_a = [], [], []
    for k, tri in enumerate(faces):
        a, b, c = X[tri]
        edge = max(np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c))
        m = max(1, int(np.ceil(edge / spacing)))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a))
        i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        i, j = i.ravel(), j.ravel()
        up = i + j <= m - 1                      # upward sub-triangles: centroid (i+1/3, j+1/3)
        dn = i + j <= m - 2                      # downward: (i+2/3, j+2/3)
        u = np.concatenate([i[up] + 1 / 3, i[dn] + 2 / 3]) / m
        v = np.concatenate([j[up] + 1 / 3, j[dn] + 2 / 3]) / m
        bary = np.stack([1 - u - v, u, v], axis=1)
        out_f.append(np.full(len(u), k))
        out_b.append(bary)
        out_a.append(np.full(len(u), area / (m * m)))
    return np.concatenate(out_f), np.concatenate(out_b), np.concatenate(out_a)


class FemIndenter:
    """One whole-wall FEM mesh (a protocol mesh name or arrays) under the sphere."""

    def __init__(self, name, points_mu=None, tets=None, kappa=KAPPA, spacing=SAMPLE_SPACING, verbose=True, law=None):
        t_setup = time.perf_counter()
        if points_mu is None:
            path = bench.bench_mesh_path(name)
            if path is None:
                raise FileNotFoundError(f"lv_{name}: shared bench meshes not found (PALPATE_SHARED)")
            from palpate.io import read_mesh_arrays
            points_mu, tets, _, _ = read_mesh_arrays(str(path), unit="m")   # raw mesh units
        self.name = name
        points_mu = np.asarray(points_mu, dtype=np.float64)
        tets = np.asarray(tets, dtype=np.int64)
        self.X = points_mu * bench.SCALE
        self.mesh = palpate.TetMesh(self.X, tets, source=name)
        self.fixed = np.flatnonzero(points_mu[:, 2] <= bench.BASE_TOL)
        self.material = bench.material() if law is None else palpate.Material(
            young=bench.E, poisson=bench.NU, density=bench.RHO, law=law)
        self.body = palpate.Body(self.mesh, self.material, fixed=self.fixed,
                                 integrator=palpate.BackwardEuler(palpate.Solver.NEWTON, max_iterations=100,
                                                                  tolerance=1e-10))
        self.kappa = kappa
        # contact points: samples of the outer faces near the tool's axis
        faces = outer_faces(self.mesh, points_mu)
        P, n = probe()
        near = np.linalg.norm(self.X[faces].mean(axis=1) - P, axis=1) < NEAR + 40e-3  # coarse pre-filter
        faces = faces[near]
        fi, bary, area = sample_faces(self.X, faces, spacing)
        y = np.einsum("pk,pkj->pj", bary, self.X[faces[fi]])
        r = y - P
        lat = np.linalg.norm(r - np.outer(r @ n, n), axis=1)
        keep = (lat < LATERAL) & (np.linalg.norm(r, axis=1) < NEAR)
        self.tri_nodes = faces[fi[keep]]            # (p,3)
        self.bary = bary[keep]
        self.area = area[keep]
        self.k_i = kappa * self.area                # penalty per point [N/m]
        self.t0 = first_contact(self.Y(self.X))
        p = len(self.area)
        self.B = sp.csr_matrix((self.bary.ravel(), (np.repeat(np.arange(p), 3), self.tri_nodes.ravel())),
                               shape=(p, len(self.X)))
        # linear compliance of the local nodes (Newton's Jacobian)
        self.local = np.unique(self.tri_nodes)
        K = linear_stiffness(self.X, tets, self.material.lame_lambda, self.material.lame_mu)
        free = np.ones(3 * len(self.X), bool)
        free[(3 * self.fixed[:, None] + np.arange(3)).ravel()] = False
        fdofs = np.flatnonzero(free)
        pos = -np.ones(3 * len(self.X), np.int64)
        pos[fdofs] = np.arange(len(fdofs))
        ldofs = (3 * self.local[:, None] + np.arange(3)).ravel()
        Kff = K[fdofs][:, fdofs].tocsc()
        t = time.perf_counter()
        lu = spla.splu(Kff, permc_spec="COLAMD")
        lf = pos[ldofs] >= 0                        # a fixed node of a contact face: zero compliance
        rhs = np.zeros((len(fdofs), int(lf.sum())))
        rhs[pos[ldofs][lf], np.arange(int(lf.sum()))] = 1.0
        self.C = np.zeros((len(ldofs), len(ldofs)))
        self.C[np.ix_(lf, lf)] = lu.solve(rhs)[pos[ldofs][lf]]   # (3L, 3L) [m/N]
        self.C = 0.5 * (self.C + self.C.T)
        self.factor_s = time.perf_counter() - t
        self.lpos = -np.ones(len(self.X), np.int64)
        self.lpos[self.local] = np.arange(len(self.local))
        self.setup_s = time.perf_counter() - t_setup
        self.solves = 0
        self.failed = 0
        self.steps = 0
        self.unconverged = 0
        self.solve_s = 0.0
        if verbose:
            print(f"lv_{name}: {len(self.X)} nodes, {len(tets)} tets, {p} contact points on "
                  f"{len(np.unique(fi[keep]))} faces ({len(self.local)} nodes), t0 = {self.t0 * 1e3:.3f} mm, "
                  f"set-up {self.setup_s:.1f} s (factorisation + compliance {self.factor_s:.1f} s)", flush=True)

    def Y(self, x):
        """Contact point positions for node positions x."""
        return np.einsum("pk,pkj->pj", self.bary, x[self.tri_nodes])

    def nodal(self, f, normals):
        """Nodal forces (n,3) of point forces f along normals."""
        return np.asarray(self.B.T @ (f[:, None] * normals))

    def _static(self, F):
        """Static equilibrium under nodal forces F, warm-started from the last one: backward-Euler
        steps (Newton, minimising the incremental potential with a line search) of STATIC_DT, so
        long that inertia weighs ~1e-6 of the stiffness, until a step moves no node by 1 nm.
        (``Body.static_solve`` restarts from rest each call and its Newton iteration fails where
        St. Venant-Kirchhoff's tangent turns indefinite under a concentrated contact.)"""
        t = time.perf_counter()
        try:
            self.body.set_forces(F)
            x_prev = self.body.positions
            for _ in range(30):
                st = self.body.step(1, dt=STATIC_DT)
                self.steps += 1
                self.unconverged += st["unconverged_steps"]
                x = self.body.positions
                if np.abs(x - x_prev).max() < 1e-9:
                    return x
                x_prev = x
            raise palpate.SolveError(f"lv_{self.name}: no static equilibrium within 30 steps")
        finally:
            self.solves += 1
            self.solve_s += time.perf_counter() - t

    def _gap(self, x, c):
        d = self.Y(x) - c
        dist = np.linalg.norm(d, axis=1)
        return R_TOOL - dist, d / dist[:, None]

    def _G(self, idx, nn):
        """Linear compliance between the points idx along their normals nn[idx] [m/N]."""
        p = len(idx)
        rows = (3 * self.lpos[self.tri_nodes[idx]][:, :, None] + np.arange(3)).reshape(p, 9)
        W = (self.bary[idx][:, :, None] * nn[idx][:, None, :]).reshape(p, 9)
        Wm = np.zeros((len(self.C), p))
        np.add.at(Wm, (rows, np.repeat(np.arange(p)[:, None], 9, 1)), W)
        return Wm.T @ (self.C @ Wm)

    def _linear_contact(self, g, f, G, k):
        """The penalty contact of the linearised model: f' = k max(0, g - G (f' - f)), by
        semi-smooth Newton on the active set (exact for the linear model in finitely many steps)."""
        b = g + G @ f
        A = g > 0
        for sweep in range(100):
            fn = np.zeros_like(f)
            if A.any():
                ia = np.flatnonzero(A)
                fn[ia] = sla.solve(G[np.ix_(ia, ia)] + np.diag(1.0 / k[ia]), b[ia], assume_a="pos")
            gp = b - G @ fn
            A_new = (A & (fn > 0)) | (~A & (gp > 0))
            if np.array_equal(A_new, A):
                break
            A = A_new
        if os.environ.get("INDENT_DEBUG"):
            print(f"      linear contact: {sweep + 1} active-set iterations, {int(A.sum())} active of {len(A)}")
        return np.maximum(fn, 0.0)

    def solve(self, t, f=None, normals=None, tol=1e-5, max_iter=60, kappa=None):
        """Static equilibrium with the tool at travel t [m]: an outer Newton iteration with the
        rest-linear compliance as Jacobian, each step the full (active-set) contact solution of
        the linearised model around the current nonlinear state, then palpate's nonlinear static
        solve under the resulting nodal forces. Returns a dict (force along -n on the tool,
        indentation, penetration, point forces and normals to warm-start the next)."""
        k_i = self.k_i if kappa is None else kappa * self.area
        P, n = probe()
        c = tool_centre(t)
        p = len(self.area)
        if f is None:
            f, normals = np.zeros(p), np.tile(n, (p, 1))
        x = self.X if not f.any() else self._static(self.nodal(f, normals))
        F_prev = self.nodal(f, normals)
        it, scale, omega, last_change = 0, getattr(self, "_scale", 1.0), 1.0, np.inf
        while True:
            g, nn = self._gap(x, c)
            cand = np.flatnonzero((g > -1e-3) | (f > 0))       # points that can touch within this step
            G = scale * self._G(cand, nn)
            fc = self._linear_contact(g[cand], f[cand], G, k_i[cand])
            f_new = np.zeros(p)
            f_new[cand] = fc
            # relaxation: the contact can flip between facets of the discrete surface in a 2-cycle;
            # halve the step each time the change does not shrink
            f_new = f + omega * (f_new - f)
            F = self.nodal(f_new, nn)
            for _ in range(6):                                   # backtrack a step without equilibrium
                try:
                    x_new = self._static(F)
                    break
                except palpate.SolveError:
                    f_new = 0.5 * (f_new + f)
                    F = self.nodal(f_new, nn)
            else:
                raise palpate.SolveError(f"lv_{self.name}: no static equilibrium near travel {t * 1e3:.3f} mm")
            it += 1
            # secant from rest: scale the linear compliance by the ratio of the actual displacement
            # of the loaded points along their normals to the linear model's under the same forces
            # (the nonlinear wall is softer or stiffer than the rest-linear one)
            w = f_new[cand] > 0
            if w.any():
                G0 = self._G(cand[w], nn)
                u_lin = G0 @ f_new[cand][w]
                u_act = np.einsum("ij,ij->i", self.Y(x_new)[cand[w]] - self.Y(self.X)[cand[w]], nn[cand[w]])
                if u_lin @ u_lin > 0:
                    est = float(np.clip((u_act @ u_lin) / (u_lin @ u_lin), 0.1, 10.0))
                    scale = est if it == 1 else float(np.sqrt(scale * est))
            change = np.abs(F - F_prev).max() / max(np.abs(F).max(), 1e-12)
            if it > 1 and change > 0.5 * last_change:
                omega = max(0.1, 0.5 * omega)
            last_change = change
            if os.environ.get("INDENT_DEBUG"):
                print(f"    it {it}: candidates {cand.size}, total {f_new.sum():.5g} N, change {change:.1e}, scale {scale:.3f}, omega {omega:.3f}")
            f, normals, x, F_prev = f_new, nn, x_new, F
            # residual: the applied point forces against the penalty of the configuration they made
            g_x, n_x = self._gap(x, c)
            f_x = k_i * np.maximum(g_x, 0.0)
            resid = np.abs(self.nodal(f_x, n_x) - F).max() / max(np.abs(F).max(), 1e-12)
            if os.environ.get("INDENT_DEBUG"):
                print(f"      residual {resid:.1e}")
            F_tool = float((f_x[:, None] * n_x).sum(axis=0) @ n)
            F_applied = float((f[:, None] * normals).sum(axis=0) @ n)
            ok = change < tol and (resid < 1e-3 or abs(F_tool - F_applied) < 1e-3 * abs(F_tool))
            if ok or it >= max_iter:
                break
        self._scale = scale
        g, nn = self._gap(x, c)
        # the consistent force: the penalty of the final configuration
        f_fin = k_i * np.maximum(g, 0.0)
        tool_force = -(f_fin[:, None] * nn).sum(axis=0)           # on the tool
        return dict(t=t, force=float(-tool_force @ n), tool_force=tool_force, pen=float(max(g.max(), 0.0)),
                    indentation=t - self.t0 - max(g.max(), 0.0), f=f, normals=normals, x=x, iterations=it,
                    converged=bool(ok), resid=resid,
                    change=change, contacts=int((g > 0).sum()), nodal_sum=self.nodal(f_fin, nn).sum(axis=0),
                    force_iter=float((f[:, None] * normals).sum(axis=0) @ n))

    def curve(self, depths, verbose=True, kappa=None):
        rows, f, nrm = [], None, None
        for d in depths:
            t = time.perf_counter()
            s0 = self.solves
            r = self.solve(self.t0 + d, f, nrm, kappa=kappa)
            f, nrm = r["f"], r["normals"]
            r["wall_s"] = time.perf_counter() - t
            r["static_solves"] = self.solves - s0
            rows.append(r)
            if verbose:
                print(f"  travel {d * 1e3:.2f} mm: F = {r['force']:.5f} N, indentation {r['indentation'] * 1e3:.4f} mm, "
                      f"pen {r['pen'] * 1e6:.2f} um, {r['contacts']} points, {r['iterations']} iterations, applied {r['force_iter']:.5f} N, residual {r['resid']:.1e} "
                      f"(change {r['change']:.1e}), {r['wall_s']:.1f} s", flush=True)
        return rows


# ---------------------------------------------------------------------------- hybrid side

def hybrid_curve(depths, material, tool_area_stiffness=None, ramp_s=0.5, hold_s=0.5, dt=1e-3, model=None, verbose=True):
    """Staircase press of the hybrid model; per depth the means over the last half of the hold."""
    model = palpate.build_shape("ventricle") if model is None else model
    sim = palpate.HybridSim(model, material, tool_radius=R_TOOL, tool_area_stiffness=tool_area_stiffness)
    P, n = probe()
    S0 = sim.surface.copy()
    t0 = first_contact(S0)
    start = t0 - 1e-3
    i_axis = int(np.argmin(np.linalg.norm(np.cross(S0 - P, n), axis=1) + 1e3 * (np.linalg.norm(S0 - P, axis=1) > NEAR)))
    rows, prev, depth = [], 0.0, 0.0
    tick_times = []
    # approach from 1 mm outside to contact
    for j in range(200):
        sim.step(tool_centre(start + 1e-3 * (j + 1) / 200), dt)
    try:
        for d in depths:
            n_ramp, n_hold = int(round(ramp_s / dt)), int(round(hold_s / dt))
            acc = []
            for j in range(n_ramp + n_hold):
                depth = prev + (d - prev) * min(1.0, (j + 1) / n_ramp)
                w = time.perf_counter()
                fvec = sim.step(tool_centre(t0 + depth), dt)
                tick_times.append(time.perf_counter() - w)
                if j >= n_ramp + n_hold // 2:
                    pen = sim.last["max_depth_m"]
                    acc.append((float(fvec @ (-n)), pen,
                                depth - pen, float((sim.surface[i_axis] - S0[i_axis]) @ n)))
            a = np.array(acc)
            rows.append(dict(t=t0 + d, travel=d, force=a[:, 0].mean(), force_sd=a[:, 0].std(), pen=a[:, 1].mean(),
                             indentation=a[:, 2].mean(), u_axis=a[:, 3].mean(), active=sim.last["active"],
                             contacts=sim.last["particle_contacts"] + sim.last["skin_contacts"],
                             core_contacts=sim.last["core_contacts"]))
            prev = d
            if verbose:
                r = rows[-1]
                print(f"  travel {d * 1e3:.2f} mm: F = {r['force']:.5f} N (sd {r['force_sd']:.1e}), indentation "
                      f"{r['indentation'] * 1e3:.4f} mm, pen {r['pen'] * 1e3:.3f} mm, {r['contacts']} skin contacts, "
                      f"{r['core_contacts']} core contacts, {r['active']} active", flush=True)
    except palpate.StepError as e:
        print(f"  hybrid: StepError at travel {depth * 1e3:.3f} mm (tick {sim.ticks}): {e}")
        rows.append(dict(error=str(e), travel=depth))
    return rows, t0, np.array(tick_times)


# ---------------------------------------------------------------------------- report

def interp_force(rows, delta):
    """Force at indentation delta by linear interpolation of a curve through (0, 0)."""
    d = np.array([0.0] + [r["indentation"] for r in rows if "force" in r])
    f = np.array([0.0] + [r["force"] for r in rows if "force" in r])
    o = np.argsort(d)
    d, f = d[o], f[o]
    if delta > d[-1] + 0.1e-3 or len(d) < 2:      # extrapolate the last segment by at most 0.1 mm
        return np.nan
    if delta > d[-1]:
        return float(f[-1] + (f[-1] - f[-2]) / (d[-1] - d[-2]) * (delta - d[-1]))
    return float(np.interp(delta, d, f))


def save_curve(out, label, rows, timing):
    """Each model's curve kept as JSON as soon as it is done, so that models can be (re)run one at
    a time and the table built from all of them."""
    import json
    keep = [{k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in r.items()
             if isinstance(v, (int, float, str, bool, np.floating))} for r in rows]
    with open(out / f"curve_{label.replace(' ', '_').replace('/', '_')}.json", "w") as fh:
        json.dump(dict(label=label, rows=keep, timing=timing, date=time.strftime("%Y-%m-%d %H:%M"),
                       host=platform.node()), fh, indent=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", nargs="*", default=["190", "1350", "10k", "50k"])
    ap.add_argument("--depths", nargs="*", type=float, default=[1, 2, 3, 4, 5], help="tool travel beyond contact [mm]")
    ap.add_argument("--damping", type=float, default=2.0, help="phi = psi [Pa s] of the damped hybrid run")
    ap.add_argument("--no-hybrid", action="store_true")
    ap.add_argument("--hybrid-only", action="store_true", help="skip the FEM meshes")
    ap.add_argument("--law", choices=["svk", "nh"], default="svk",
                    help="the FEM meshes' law (the hybrid is always St. Venant-Kirchhoff); nh labels them 'lv_* NH'")
    ap.add_argument("--core-fractions", nargs="*", type=float, default=[],
                    help="also the hybrid built with these core fractions (default build: 0.5)")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    depths = [d * 1e-3 for d in args.depths]
    curves = {}
    timing = {}
    P, n = probe()
    for name in ([] if args.hybrid_only else args.meshes):
        w = time.perf_counter()
        law = palpate.Law.NEO_HOOKEAN if args.law == "nh" else None
        label = f"lv_{name}" + (" NH" if args.law == "nh" else "")
        fem = FemIndenter(name, law=law)
        curves[label] = fem.curve(depths)
        timing[label] = (time.perf_counter() - w, fem.solves, fem.solve_s)
        print(f"  {label}: {timing[label][0]:.1f} s, {fem.solves} static solves ({fem.solve_s:.1f} s)", flush=True)
        save_curve(out, label, curves[label], timing[label])
    if not args.no_hybrid:
        model = palpate.build_shape("ventricle")
        variants = [(f"hybrid core fraction {cf:g}", bench.material(), None, cf) for cf in args.core_fractions]
        for label, mat, k, *cf in [("hybrid", bench.material(), None),
                              (f"hybrid damped {args.damping:g} Pa s",
                               palpate.Material(young=bench.E, poisson=bench.NU, density=bench.RHO,
                                                phi=args.damping, psi=args.damping), None),
                              ("hybrid tool 4.3e7 N/m^3 (half the default)", bench.material(), 4.3e7)] + variants:
            print(f"{label}:", flush=True)
            w = time.perf_counter()
            m = palpate.build_shape("ventricle", core_fraction=cf[0]) if cf else model
            if cf:
                info = m.info()
                print(f"  core {info['core_tets']} tets, {info['core_volume_m3'] * 1e6:.2f} mL of {info['wall_volume_m3'] * 1e6:.2f} mL, "
                      f"{info['particles']} particles", flush=True)
            # one more millimetre of travel: the hybrid's penetration is ~0.5 mm, so that its
            # indentation covers the FEM's
            rows, t0, ticks = hybrid_curve(depths + [depths[-1] + 1e-3], mat, tool_area_stiffness=k, model=m)
            timing[label] = (time.perf_counter() - w, len(ticks), float(np.median(ticks)) if len(ticks) else np.nan)
            print(f"  first contact t0 = {t0 * 1e3:.3f} mm, {len(ticks)} ticks, median {timing[label][2] * 1e3:.2f} ms, "
                  f"{timing[label][0]:.1f} s", flush=True)
            curves[label] = rows
            save_curve(out, label, rows, timing[label])
    import json
    curves = {}
    for pth in sorted(out.glob("curve_*.json")):
        d = json.load(open(pth))
        # converged: the tool force of the applied point forces and the penalty force of the
        # configuration they make agree to 0.5% (FEM), or the hybrid's rows (no flag)
        curves[d["label"]] = [r for r in d["rows"] if "force" not in r or "force_iter" not in r
                              or abs(r["force"] - r["force_iter"]) < 5e-3 * abs(r["force"])]
        timing[d["label"]] = d["timing"]
    order = ["lv_190", "lv_1350", "lv_10k", "lv_50k", "lv_190 NH", "lv_1350 NH", "lv_10k NH", "lv_50k NH"]
    curves = dict(sorted(curves.items(), key=lambda kv: (order.index(kv[0]) if kv[0] in order else 9, kv[0])))
    # CSV
    with open(out / "indentation.csv", "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(["model", "travel_mm", "indentation_mm", "force_N", "penetration_mm", "contacts", "error"])
        for label, rows in curves.items():
            for r in rows:
                if "force" not in r:
                    wr.writerow([label, f"{r['travel'] * 1e3:.4f}", "", "", "", "", r.get("error", "")])
                    continue
                wr.writerow([label, f"{(r['indentation'] + r['pen']) * 1e3:.4f}", f"{r['indentation'] * 1e3:.5f}",
                             f"{r['force']:.6f}", f"{r['pen'] * 1e3:.5f}", r["contacts"], ""])
    # table at common indentations
    deltas = [d for d in depths]
    # Richardson extrapolation of the three finest meshes, F(h) = F_inf + C h^p (h: the gmsh mesh
    # size of shared/bench/meshes/summary.json, mesh units)
    for suffix in ["", " NH"]:
        H = {"lv_1350" + suffix: 0.5984, "lv_10k" + suffix: 0.2556, "lv_50k" + suffix: 0.1429}
        if not all(k in curves for k in H):
            continue
        ext = []
        for d in deltas:
            F = [interp_force(curves[k], d) for k in H]
            h = list(H.values())
            if not np.all(np.isfinite(F)) or not (F[0] > F[1] > F[2]):
                ext.append("-")
                continue
            ratio = (F[0] - F[1]) / (F[1] - F[2])
            lo, hi = 0.1, 4.0
            for _ in range(60):
                pm = 0.5 * (lo + hi)
                if (h[0] ** pm - h[1] ** pm) / (h[1] ** pm - h[2] ** pm) < ratio:
                    lo = pm
                else:
                    hi = pm
            C = (F[1] - F[2]) / (h[1] ** pm - h[2] ** pm)
            ext.append(f"{F[2] - C * h[2] ** pm:.4f} (p = {pm:.2f})")
        print(f"\nFEM{suffix} extrapolated to h -> 0 from lv_1350, lv_10k, lv_50k: | " + " | ".join(ext) + " |")
    for ref_label in ["lv_50k", "lv_50k NH"]:
        ref = curves.get(ref_label)
        if ref is None:
            continue
        print(f"\nforce [N] at indentation (linear interpolation of each curve); error vs {ref_label}")
        print("| model | " + " | ".join(f"{d * 1e3:g} mm" for d in deltas) + " |")
        print("|---|" + "---|" * len(deltas))
        for label, rows in curves.items():
            cells = []
            for d in deltas:
                F = interp_force(rows, d)
                s = f"{F:.4f}" if np.isfinite(F) else "-"
                if label != ref_label:
                    Fr = interp_force(ref, d)
                    if np.isfinite(F) and np.isfinite(Fr):
                        s += f" ({(F - Fr) / Fr * 100:+.1f}%)"
                cells.append(s)
            print(f"| {label} | " + " | ".join(cells) + " |")
    print("\ntiming:", {k: tuple(round(v, 3) for v in t) for k, t in timing.items()})
    # figure
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for label, rows in curves.items():
        d = [0.0] + [r["indentation"] * 1e3 for r in rows if "force" in r]
        f = [0.0] + [r["force"] for r in rows if "force" in r]
        style = "s--" if label.startswith("hybrid") else ("^:" if label.endswith("NH") else "o-")
        ax.plot(d, f, style, label=label, ms=4)
    ax.set_xlabel("indentation [mm] (tool travel beyond first contact - penetration)")
    ax.set_ylabel("force on the tool along the outward normal [N]")
    ax.set_title("5 mm sphere at the protocol's probe point, E = 30 kPa, nu = 0.4 (SVK)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "indentation.png", dpi=120)
    print(f"wrote {out / 'indentation.csv'} and {out / 'indentation.png'}; {platform.node()} {time.strftime('%Y-%m-%d %H:%M')}")


if __name__ == "__main__":
    main()
