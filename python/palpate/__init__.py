"""palpate: real-time soft-tissue FEM (and meshfree particles) for haptic interaction.

After M. G. Mero and A. Susin, "Deformable Hybrid Approach for Haptic Interaction". The physics
runs in Rust (``palpate-core``); this package is a thin Python layer over it.

Units are SI throughout: positions and displacements [m], velocities [m/s], forces [N], time [s],
moduli and stresses [Pa], densities [kg/m^3], viscosities [Pa s]. Per-node arrays are float64 of
shape (n, 3) in the world frame; tets are integer arrays of shape (m, 4), 0-based.

>>> import numpy as np, palpate
>>> mesh = palpate.box_mesh(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
>>> tissue = palpate.defaults.tissue_material()   # E = 30 kPa, nu = 0.4, 1060 kg/m^3 (palpate.defaults)
>>> body = palpate.Body(mesh, tissue, fixed=np.flatnonzero(mesh.points[:, 0] == 0.0),
...                     integrator=palpate.BackwardEuler())
>>> f = np.zeros((body.n_nodes, 3)); f[mesh.points[:, 0] == 0.1, 2] = -1e-3   # [N]
>>> body.set_forces(f); _ = body.step(100, dt=1e-3)
>>> bool(np.isfinite(body.positions).all())
True
"""
from ._palpate import (
    BackwardEuler,
    Body,
    Filter,
    HapticLoop,
    HapticsError,
    HybridModel,
    HybridSim,
    InternalError,
    Kernel,
    Law,
    LimitError,
    LoadWarning,
    Material,
    MaterialError,
    MeshError,
    MeshWarning,
    UnitWarning,
    ModelError,
    ModelFileError,
    ModelFileIOError,
    PalpateError,
    ParameterError,
    ParameterIndexError,
    ParameterKeyError,
    ParameterTypeError,
    ParticleBody,
    Projection,
    SemiImplicit,
    Solver,
    SolveError,
    StepError,
    SurfaceError,
    TetMesh,
    TriSurface,
    __version__,
    box_mesh,
    ellipsoid_surface,
    ellipsoid_wall,
    kernel_value,
    memory_budget,
    neighbours,
    sample_between,
    sample_inside,
    set_simd_enabled,
    simd_path,
    truncated_ellipsoid_wall,
    ventricle_surface,
)
from . import defaults
from . import _pickle

_pickle.register()
from .hybrid import build_from_files, build_shape, build_tagged_file
from .io import (UNITS, VtuSeries, load_mesh, read_mesh_arrays, read_mesh_sets, write_hybrid_model,
                 write_particles)
from .surfaces import (load_surface, orient_consistently, read_surface_arrays, read_tagged_surface,
                       repair_surface)
from .vtp import read_vtp

__all__ = [
    "BackwardEuler",
    "Body",
    "Filter",
    "HapticLoop",
    "HapticsError",
    "HybridModel",
    "HybridSim",
    "InternalError",
    "Kernel",
    "Law",
    "LimitError",
    "LoadWarning",
    "Material",
    "MaterialError",
    "MeshError",
    "MeshWarning",
    "UnitWarning",
    "ModelError",
    "ModelFileError",
    "ModelFileIOError",
    "PalpateError",
    "ParameterError",
    "ParameterIndexError",
    "ParameterKeyError",
    "ParameterTypeError",
    "ParticleBody",
    "Projection",
    "SemiImplicit",
    "Solver",
    "SolveError",
    "StepError",
    "SurfaceError",
    "TetMesh",
    "TriSurface",
    "UNITS",
    "VtuSeries",
    "read_mesh_sets",
    "write_hybrid_model",
    "write_particles",
    "__version__",
    "box_mesh",
    "build_from_files",
    "build_shape",
    "build_tagged_file",
    "defaults",
    "ellipsoid_surface",
    "ellipsoid_wall",
    "load_mesh",
    "memory_budget",
    "kernel_value",
    "load_surface",
    "neighbours",
    "orient_consistently",
    "read_mesh_arrays",
    "read_surface_arrays",
    "read_tagged_surface",
    "read_vtp",
    "repair_surface",
    "sample_between",
    "sample_inside",
    "set_simd_enabled",
    "simd_path",
    "truncated_ellipsoid_wall",
    "ventricle_surface",
]
