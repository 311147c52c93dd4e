# Type stubs of the Rust extension palpate._palpate (python/src/*.rs). Hand-kept: update with the binding.
# Units are SI: m, m/s, N, s, Pa, kg/m^3, Pa s. Per-node arrays are float64 (n, 3).
import os
from typing import Optional, Sequence, Tuple, TypedDict, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str

_FloatArray = npt.NDArray[np.float64]
_IntArray = npt.NDArray[np.int64]
_Vec3 = Union[Sequence[float], npt.NDArray[np.floating]]
_Indices = Union[Sequence[int], npt.NDArray[np.integer], npt.NDArray[np.bool_]]

class PalpateError(Exception): ...

class MeshError(PalpateError):
    tet: Optional[int]
    node: Optional[int]

class MaterialError(PalpateError): ...
class ModelError(PalpateError): ...
class SolveError(PalpateError): ...

class StepError(PalpateError):
    node: Optional[int]
    time: Optional[float]

class SurfaceError(MeshError):
    tet: Optional[int]  # inherited from MeshError; always None here
    node: Optional[int]  # inherited from MeshError; always None here
    triangle: Optional[int]
    vertex: Optional[int]

class ModelFileError(PalpateError): ...

class MeshWarning(UserWarning): ...

class TetMesh:
    def __init__(self, points: npt.ArrayLike, tets: npt.ArrayLike, *, source: Optional[str] = None) -> None: ...
    @property
    def points(self) -> _FloatArray: ...
    @property
    def tets(self) -> _IntArray: ...
    @property
    def n_nodes(self) -> int: ...
    @property
    def n_tets(self) -> int: ...
    @property
    def volume(self) -> float: ...
    @property
    def min_dihedral_deg(self) -> float: ...
    def boundary_faces(self) -> _IntArray: ...
    def nodes_below(self, z_cut: float = 0.0, tol: float = 1e-9) -> _IntArray: ...
    def __len__(self) -> int: ...

class Law:
    ST_VENANT_KIRCHHOFF: Law
    NEO_HOOKEAN: Law

class Material:
    def __init__(
        self,
        young: Optional[float] = None,
        poisson: Optional[float] = None,
        lame_lambda: Optional[float] = None,
        lame_mu: Optional[float] = None,
        density: float = 1000.0,
        phi: float = 0.0,
        psi: float = 0.0,
        law: Law = ...,
    ) -> None: ...
    @staticmethod
    def myocardium() -> Material: ...
    @staticmethod
    def paper_ellipsoids() -> Material: ...
    @property
    def law(self) -> Law: ...
    @property
    def young(self) -> float: ...
    @property
    def poisson(self) -> float: ...
    @property
    def lame_lambda(self) -> float: ...
    @property
    def lame_mu(self) -> float: ...
    @property
    def density(self) -> float: ...
    @property
    def phi(self) -> float: ...
    @property
    def psi(self) -> float: ...
    @property
    def wave_speed(self) -> float: ...

class Filter:
    PAPER: Filter
    STABLE: Filter

class Solver:
    QUASI_NEWTON: Solver
    NEWTON: Solver
    LINEARISED: Solver

class SemiImplicit:
    def __init__(self, filter: Filter = ...) -> None: ...
    @property
    def filter(self) -> Filter: ...

class BackwardEuler:
    def __init__(
        self,
        solver: Solver = ...,
        *,
        max_iterations: Optional[int] = None,
        tolerance: Optional[float] = None,
        history: Optional[int] = None,
    ) -> None: ...
    @property
    def solver(self) -> Solver: ...
    @property
    def max_iterations(self) -> Optional[int]: ...
    @property
    def tolerance(self) -> Optional[float]: ...
    @property
    def history(self) -> Optional[int]: ...

class StepStats(TypedDict):
    steps: int
    iterations: int
    iterations_max: int
    evaluations: int
    factorizations: int
    solves: int
    unconverged_steps: int
    max_residual: float
    inverted_max: int
    inverted: int
    potential_change: float

class ProbeRun(TypedDict):
    steps: int
    wall_s: float
    stable: bool
    max_disp_m: float
    probe_disp_avg_m: float
    mean_disp: _FloatArray
    probe_disp: _FloatArray
    step_us: _FloatArray
    iterations_mean: float
    iterations_max: int
    evaluations: int
    factorizations: int
    inverted_max: int
    unconverged_steps: int
    error: Optional[str]

class Body:
    def __init__(
        self,
        mesh: TetMesh,
        material: Material,
        fixed: Optional[_Indices] = None,
        gravity: Optional[_Vec3] = None,
        integrator: Optional[Union[SemiImplicit, BackwardEuler]] = None,
    ) -> None: ...
    def step(self, n: int = 1, dt: float = 1e-3) -> StepStats: ...
    def set_forces(self, forces: npt.ArrayLike) -> None: ...
    @property
    def forces(self) -> _FloatArray: ...
    @property
    def positions(self) -> _FloatArray: ...
    @property
    def velocities(self) -> _FloatArray: ...
    @property
    def displacements(self) -> _FloatArray: ...
    @property
    def time(self) -> float: ...
    @property
    def n_nodes(self) -> int: ...
    @property
    def n_tets(self) -> int: ...
    @property
    def mesh(self) -> TetMesh: ...
    @property
    def material(self) -> Material: ...
    @property
    def integrator(self) -> Union[SemiImplicit, BackwardEuler]: ...
    @property
    def fixed(self) -> _IntArray: ...
    @property
    def masses(self) -> _FloatArray: ...
    @property
    def gravity(self) -> _FloatArray: ...
    def strain_energy(self) -> float: ...
    def kinetic_energy(self) -> float: ...
    def reset(self) -> None: ...
    def static_solve(
        self,
        forces: Optional[npt.ArrayLike] = None,
        *,
        max_iterations: Optional[int] = None,
        tolerance: Optional[float] = None,
        load_steps: Optional[int] = None,
    ) -> _FloatArray: ...
    def run_probe(
        self,
        nodes: _Indices,
        total_force: _Vec3,
        ramp_time: float,
        steps: int,
        dt: float = 1e-3,
        stable_limit: float = 0.02,
        max_wall_s: Optional[float] = None,
    ) -> ProbeRun: ...
    def run_loads(
        self,
        loads: Sequence[Tuple[_Indices, _Vec3, float]],
        steps: int,
        dt: float = 1e-3,
        *,
        ramp_start: Optional[float] = None,
        stable_limit: float = ...,
        max_wall_s: Optional[float] = None,
    ) -> ProbeRun: ...

def ellipsoid_wall(
    inner: Optional[Tuple[float, float, float]] = None,
    outer: Optional[Tuple[float, float, float]] = None,
    subdivisions: Optional[int] = None,
    layers: Optional[int] = None,
) -> TetMesh: ...
def truncated_ellipsoid_wall(
    inner: Optional[Tuple[float, float, float]] = None,
    outer: Optional[Tuple[float, float, float]] = None,
    z_cut: Optional[float] = None,
    circumferential: Optional[int] = None,
    longitudinal: Optional[int] = None,
    layers: Optional[int] = None,
) -> TetMesh: ...
def box_mesh(
    size: Tuple[float, float, float] = (0.1, 0.02, 0.02),
    cells: Tuple[int, int, int] = (10, 2, 2),
) -> TetMesh: ...

class Kernel:
    WENDLAND_C2: Kernel
    CUBIC_SPLINE: Kernel
    LINEAR_LENNARD_JONES: Kernel

class ParticleStepStats(TypedDict):
    steps: int
    substeps: int
    substep_dt: float

class TimedRun(TypedDict):
    ticks: int
    tick_wall_s: _FloatArray
    substeps: int
    substep_dt: float
    error: Optional[str]

class ParticleBody:
    def __init__(
        self,
        positions: npt.ArrayLike,
        masses: npt.ArrayLike,
        material: Material,
        support_radius: float,
        kernel: Kernel = ...,
        fixed: Optional[_Indices] = None,
        gravity: Optional[_Vec3] = None,
        hourglass: float = 0.5,
        min_relative_weight: float = 1e-3,
    ) -> None: ...
    def step(self, n: int = 1, dt: float = 1e-3) -> ParticleStepStats: ...
    def run_timed(self, ticks: int, dt: float = 1e-3, max_wall_s: Optional[float] = None) -> TimedRun: ...
    def set_forces(self, forces: npt.ArrayLike) -> None: ...
    def set_positions(self, positions: npt.ArrayLike) -> None: ...
    def set_velocities(self, velocities: npt.ArrayLike) -> None: ...
    @property
    def forces(self) -> _FloatArray: ...
    @property
    def positions(self) -> _FloatArray: ...
    @property
    def velocities(self) -> _FloatArray: ...
    @property
    def displacements(self) -> _FloatArray: ...
    @property
    def rest_positions(self) -> _FloatArray: ...
    @property
    def active(self) -> _IntArray: ...
    @active.setter
    def active(self, active: _Indices) -> None: ...
    @property
    def fixed(self) -> _IntArray: ...
    @property
    def stable_dt(self) -> float: ...
    @property
    def omega_max(self) -> float: ...
    def substeps(self, dt: float) -> int: ...
    @property
    def n_particles(self) -> int: ...
    @property
    def n_pairs(self) -> int: ...
    def neighbours(self, i: int) -> _IntArray: ...
    @property
    def densities(self) -> _FloatArray: ...
    @property
    def volumes(self) -> _FloatArray: ...
    @property
    def masses(self) -> _FloatArray: ...
    @property
    def kernel(self) -> Kernel: ...
    @property
    def support_radius(self) -> float: ...
    @property
    def hourglass(self) -> float: ...
    @property
    def material(self) -> Material: ...
    @property
    def time(self) -> float: ...
    def strain_energy(self) -> float: ...
    def kinetic_energy(self) -> float: ...
    def momentum(self) -> _FloatArray: ...
    def internal_forces(self) -> _FloatArray: ...
    def reset(self) -> None: ...
    def __len__(self) -> int: ...

class TriSurface:
    def __init__(self, points: npt.ArrayLike, triangles: npt.ArrayLike, *, source: Optional[str] = None) -> None: ...
    @property
    def points(self) -> _FloatArray: ...
    @property
    def triangles(self) -> _IntArray: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def n_triangles(self) -> int: ...
    @property
    def volume(self) -> float: ...
    @property
    def area(self) -> float: ...
    @property
    def bounding_box(self) -> Tuple[_FloatArray, _FloatArray]: ...
    @overload
    def contains(self, points: _Vec3, method: str = "winding") -> bool: ...
    @overload
    def contains(self, points: npt.ArrayLike, method: str = "winding") -> npt.NDArray[np.bool_]: ...
    @overload
    def winding_number(self, points: _Vec3) -> float: ...
    @overload
    def winding_number(self, points: npt.ArrayLike) -> _FloatArray: ...
    def __len__(self) -> int: ...

def ellipsoid_surface(
    semi_axes: Tuple[float, float, float] = (0.026, 0.026, 0.042),
    subdivisions: int = 4,
) -> TriSurface: ...
class Projection:
    TRANSMURAL: Projection
    RADIAL: Projection

class RegionField(TypedDict):
    origin: _FloatArray
    h: float
    label: npt.NDArray[np.uint8]
    gradient: npt.NDArray[np.float32]

class HybridInfo(TypedDict):
    projection: str
    core_fraction: float
    core_tets: int
    core_nodes: int
    core_faces: int
    core_base_nodes: int
    core_min_dihedral_deg: float
    core_volume_ratio: float
    particles: int
    spacing_m: float
    wall_volume_m3: float
    core_volume_m3: float
    shell_volume_m3: float
    outer_vertices: int
    outer_triangles: int
    regions: int
    region_particles_min: int
    region_particles_median: int
    region_particles_max: int
    voxels: int
    voxel_m: float
    file_bytes: int
    build_s: float
    build_field_s: float
    build_core_s: float
    build_particles_s: float
    build_regions_s: float
    field_cg_iterations: int
    fallback_particle_outer: int
    fallback_particle_core: int
    fallback_skin: int

class HybridModel:
    @staticmethod
    def build_nested(
        inner: TriSurface,
        outer: TriSurface,
        *,
        projection: Projection = ...,
        core_fraction: float = 0.5,
        core_triangles: int = 0,
        core_layers: int = 1,
        spacing: Optional[float] = None,
        particles: int = 28000,
        density: float = 1000.0,
        min_region_particles: int = 50,
        field_voxels: int = 120000,
    ) -> HybridModel: ...
    @staticmethod
    def build_tagged(
        points: npt.ArrayLike,
        triangles: npt.ArrayLike,
        parts: npt.ArrayLike,
        *,
        projection: Projection = ...,
        core_fraction: float = 0.5,
        core_triangles: int = 0,
        core_layers: int = 1,
        spacing: Optional[float] = None,
        particles: int = 28000,
        density: float = 1000.0,
        min_region_particles: int = 50,
        field_voxels: int = 120000,
    ) -> HybridModel: ...
    def save(self, path: Union[str, os.PathLike[str]]) -> None: ...
    @staticmethod
    def load(path: Union[str, os.PathLike[str]]) -> HybridModel: ...
    def to_bytes(self) -> bytes: ...
    @property
    def core_points(self) -> _FloatArray: ...
    @property
    def core_tets(self) -> _IntArray: ...
    @property
    def core_faces(self) -> _IntArray: ...
    @property
    def core_base_nodes(self) -> _IntArray: ...
    @property
    def particles(self) -> _FloatArray: ...
    @property
    def particle_masses(self) -> _FloatArray: ...
    @property
    def particle_outer_triangle(self) -> _IntArray: ...
    @property
    def particle_core_face(self) -> _IntArray: ...
    @property
    def outer_points(self) -> _FloatArray: ...
    @property
    def outer_triangles(self) -> _IntArray: ...
    @property
    def skin_faces(self) -> _IntArray: ...
    @property
    def skin_barycentric(self) -> _FloatArray: ...
    @property
    def skin_offsets(self) -> _FloatArray: ...
    @property
    def n_regions(self) -> int: ...
    @property
    def spacing(self) -> float: ...
    @property
    def wall_volume(self) -> float: ...
    @property
    def core_volume(self) -> float: ...
    @property
    def shell_volume(self) -> float: ...
    def region_particles(self, s: int) -> _IntArray: ...
    def region_triangles(self, s: int) -> _IntArray: ...
    def region_core_faces(self, s: int) -> _IntArray: ...
    def region_curve(self, s: int) -> _FloatArray: ...
    def region_field(self, s: int) -> RegionField: ...
    def info(self) -> HybridInfo: ...

def sample_inside(surface: TriSurface, spacing: float, density: float) -> Tuple[_FloatArray, _FloatArray]: ...
def sample_between(inner: TriSurface, outer: TriSurface, spacing: float, density: float) -> Tuple[_FloatArray, _FloatArray]: ...
def ventricle_surface(circumferential: int = 96, longitudinal: int = 24) -> Tuple[_FloatArray, _IntArray, npt.NDArray[np.int8]]: ...
def simd_path() -> str: ...
def set_simd_enabled(enabled: bool) -> None: ...
