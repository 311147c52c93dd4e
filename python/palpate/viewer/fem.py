"""A full-FEM body for the viewer (issue 14): :class:`FemModel`, what :class:`palpate.viewer.Viewer`
reads of a :class:`palpate.HybridModel` (``outer_points``, ``outer_triangles``, ``core_points``,
``core_tets``) made from a tet mesh, and the :class:`palpate.Body` the haptic loop runs
(``palpate_haptics::FemPhysics``: the tool meets the boundary nodes).

:func:`load_fem_model` reads a protocol mesh name (``ellipsoid_192``, ``lv_190``, ``lv_1350``,
``lv_10k``, ``lv_50k``: the benchmark's set-up, base held), a scene file (``.toml``,
:mod:`palpate.scene`: its mesh, material, fixed nodes, gravity and integrator), or a tet mesh file
(:func:`palpate.load_mesh`: ``.msh``, ``.vtu``, ``.vtk``, ``.npz``, ``.node``/``.ele``, ...;
coordinates in ``unit``; the nodes within ``base`` of its lowest z are held, so that a press does
not push the whole body away).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Optional, Tuple

import numpy as np

from .. import _palpate as _p

#: Mesh file endings :func:`load_fem_model` takes as a tet mesh (the package's readers').
MESH_SUFFIXES = (".msh", ".vtu", ".vtk", ".npz", ".node", ".ele", ".mesh", ".inp")
#: Protocol mesh names (``palpate bench protocol``'s).
PROTOCOL = ("ellipsoid_192", "lv_190", "lv_1350", "lv_10k", "lv_50k")
#: A bare mesh's held base: the nodes within this fraction of its height of its lowest z.
BASE_FRACTION = 1e-3


@dataclass
class FemModel:
    """A full-FEM body with the viewer's view of it. ``body``: the :class:`palpate.Body` the
    haptic loop is built over (the loop takes its mesh, fixed nodes, gravity and integrator, and
    the viewer's material); ``material``: the body's own (a scene's), or None for a bare mesh;
    ``outer_points`` (k, 3) [m]: the boundary nodes at rest in ascending node order (the order of
    :meth:`palpate.HapticLoop.surface` over a body); ``outer_triangles`` (t, 3): the boundary
    faces, outward, indexing ``outer_points``; ``outer_nodes`` (k,): their node indices;
    ``outer_free`` (k,) bool: which of them are not held; ``core_points``, ``core_tets``: every
    node and tet (what :meth:`palpate.HapticLoop.interior` gives: the nodes)."""
    body: "_p.Body"
    material: Optional["_p.Material"]
    outer_points: np.ndarray
    outer_triangles: np.ndarray
    outer_nodes: np.ndarray
    outer_free: np.ndarray
    core_points: np.ndarray
    core_tets: np.ndarray
    description: str

    @classmethod
    def of(cls, body: "_p.Body", material: Optional["_p.Material"], description: str) -> "FemModel":
        mesh = body.mesh
        faces = np.asarray(mesh.boundary_faces(), dtype=np.int64)
        # np.unique sorts: the boundary nodes in ascending order, FemPhysics' surface order.
        nodes, inv = np.unique(faces, return_inverse=True)
        pts = np.asarray(mesh.points, dtype=np.float64)
        free = ~np.isin(nodes, np.asarray(body.fixed, dtype=np.int64))
        return cls(body, material, pts[nodes], inv.reshape(-1, 3), nodes, free, pts,
                   np.asarray(mesh.tets, dtype=np.int64), description)


def loop_model(model: Any) -> Any:
    """What :class:`palpate.HapticLoop` takes for ``model``: a :class:`FemModel`'s body, else the
    model itself (a :class:`palpate.HybridModel`)."""
    return model.body if isinstance(model, FemModel) else model


def is_fem_spec(spec: str) -> bool:
    """Is ``spec`` for :func:`load_fem_model` (a protocol name, a scene or a mesh file name)?"""
    return spec in PROTOCOL or spec.lower().endswith((".toml",) + MESH_SUFFIXES)


def load_fem_model(spec: str, unit: str = "m") -> Tuple[str, FemModel]:
    """``(name, model)`` of a protocol mesh name, a scene file or a tet mesh file (module docs).
    Raises :class:`palpate.MeshError` (a bad or missing mesh, naming the file),
    :class:`palpate.scene.SceneError` (a bad scene), :class:`palpate.ParameterError` (neither)."""
    from .. import bench

    if spec in PROTOCOL:
        if spec == bench.GENERATED:
            case = bench.generated_case()
        else:
            path = bench.bench_mesh_path(spec[len("lv_"):])
            if path is None:
                raise _p.MeshError(f"{spec}: the shared benchmark meshes (shared/bench/meshes) are not here; "
                                   "set PALPATE_SHARED")
            case = bench.load_case(str(path))
        body = _p.Body(case.mesh, bench.material(), fixed=case.fixed)
        return spec, FemModel.of(body, bench.material(), f"protocol mesh {spec}")
    name = os.path.basename(spec)
    if spec.lower().endswith(".toml"):
        from ..scene import load_scene

        # The scene's run settings (output folder, steps) are not used: the viewer writes nothing.
        s = load_scene(spec, output=os.path.join("out", "view"))
        return name, FemModel.of(s.body, s.body.material, f"scene {name}")
    if not spec.lower().endswith(MESH_SUFFIXES):
        raise _p.ParameterError(f"{spec}: not a tet mesh ({', '.join(MESH_SUFFIXES)}), a scene (.toml) or a "
                                f"protocol mesh ({', '.join(PROTOCOL)})")
    from ..io import load_mesh

    mesh = load_mesh(spec, unit)
    z = np.asarray(mesh.points)[:, 2]
    height = float(z.max() - z.min())
    fixed = np.flatnonzero(z <= z.min() + BASE_FRACTION * height)
    body = _p.Body(mesh, _p.Material.myocardium(), fixed=fixed)
    return name, FemModel.of(body, None, f"mesh {name}")
