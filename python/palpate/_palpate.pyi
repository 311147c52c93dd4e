# Type stubs of the Rust extension palpate._palpate (python/src/*.rs). Hand-kept: update with the binding.
# Units are SI: m, m/s, N, s, Pa, kg/m^3, Pa s. Per-node arrays are float64 (n, 3).
# Defaults written `...` are the Rust core's, readable as `palpate.defaults` (one definition).
import os
from typing import Any, Dict, Optional, Sequence, Tuple, TypedDict, Union, overload

from typing_extensions import Unpack, final

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
class ModelFileIOError(ModelFileError, OSError):
    # OSError's own attributes (errno and strerror are None: the message says why)
    errno: Optional[int]
    strerror: Optional[str]
    filename: Any
    filename2: Any
    characters_written: int
class ParameterError(PalpateError, ValueError): ...
class ParameterIndexError(ParameterError, IndexError): ...
class ParameterTypeError(ParameterError, TypeError): ...
class ParameterKeyError(ParameterError, KeyError): ...

class LimitError(PalpateError):
    requested: Optional[float]
    budget: Optional[int]
    budget_source: Optional[str]

class InternalError(PalpateError): ...

class HapticsError(PalpateError): ...

class MeshWarning(UserWarning): ...
class UnitWarning(UserWarning): ...
class LoadWarning(UserWarning): ...

@final
class TetMesh:
    def __new__(cls, points: npt.ArrayLike, tets: npt.ArrayLike, *, source: Optional[str] = None) -> TetMesh: ...
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

@final
class Law:
    ST_VENANT_KIRCHHOFF: Law
    NEO_HOOKEAN: Law

@final
class Material:
    def __new__(
        cls,
        young: Optional[float] = None,
        poisson: Optional[float] = None,
        lame_lambda: Optional[float] = None,
        lame_mu: Optional[float] = None,
        density: float = 1000.0,
        phi: float = 0.0,
        psi: float = 0.0,
        law: Law = ...,
    ) -> Material: ...
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

@final
class Filter:
    PAPER: Filter
    STABLE: Filter

@final
class Solver:
    QUASI_NEWTON: Solver
    NEWTON: Solver
    LINEARISED: Solver

@final
class SemiImplicit:
    def __new__(cls, filter: Filter = ...) -> SemiImplicit: ...
    @property
    def filter(self) -> Filter: ...

@final
class BackwardEuler:
    def __new__(
        cls,
        solver: Solver = ...,
        *,
        max_iterations: Optional[int] = None,
        tolerance: Optional[float] = None,
        history: Optional[int] = None,
    ) -> BackwardEuler: ...
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

class BodyState(TypedDict):
    positions: _FloatArray
    velocities: _FloatArray
    forces: _FloatArray
    time: float
    factored_dt: float
    refreshed_at: Optional[_FloatArray]
    excess_iterations: int

class ParticleState(TypedDict):
    positions: _FloatArray
    velocities: _FloatArray
    forces: _FloatArray
    time: float
    active: _IntArray

class HybridSimState(TypedDict):
    time: float
    ticks: int
    core_positions: _FloatArray
    core_velocities: _FloatArray
    factored_dt: float
    refreshed_at: Optional[_FloatArray]
    excess_iterations: int
    factor_base_terms: _FloatArray
    factor_term_updates: _FloatArray
    particle_positions: _FloatArray
    particle_velocities: _FloatArray
    tool: Optional[_FloatArray]
    region_last_touched: _IntArray
    active_regions: _IntArray
    skin: _FloatArray
    skin_live: Optional[_IntArray]
    skin_carried: _IntArray
    skin_reference: _FloatArray
    skin_reference_tool: _FloatArray
    skin_slack: float
    skin_sweep_next: Optional[int]
    skin_sweep_reference: Optional[_FloatArray]
    skin_sweep_slack: float
    shell_off_until: int
    skin_lift_vertices: _IntArray
    skin_lift_offsets: _FloatArray
    skin_lift_start: int
    owed_skin: bool
    owed_core_dt: Optional[float]
    owed_core_forces: Optional[_FloatArray]

class IndentResult(TypedDict):
    travel: _FloatArray
    force: _FloatArray
    force_along: _FloatArray
    penetration: _FloatArray
    indentation: _FloatArray
    contact_samples: _FloatArray
    contact_area: _FloatArray
    iterations: _FloatArray
    factorisations: _FloatArray
    positions: _FloatArray
    contact_forces: _FloatArray

@final
class Body:
    def __new__(
        cls,
        mesh: TetMesh,
        material: Material,
        fixed: Optional[_Indices] = None,
        gravity: Optional[_Vec3] = None,
        integrator: Optional[Union[SemiImplicit, BackwardEuler]] = None,
        *,
        order: int = 1,
    ) -> Body: ...
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
    def order(self) -> int: ...
    @property
    def edges(self) -> _IntArray: ...
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
    def element_fields(self) -> Dict[str, _FloatArray]: ...
    def reset(self) -> None: ...
    def get_state(self) -> BodyState: ...
    def set_state(self, state: BodyState) -> None: ...
    def set_positions(self, positions: npt.ArrayLike) -> None: ...
    def set_velocities(self, velocities: npt.ArrayLike) -> None: ...
    def prepare(self, dt: float) -> bool: ...
    def copy(self) -> Body: ...
    def __copy__(self) -> Body: ...
    def __deepcopy__(self, memo: Any) -> Body: ...
    def static_solve(
        self,
        forces: Optional[npt.ArrayLike] = None,
        *,
        max_iterations: Optional[int] = None,
        tolerance: Optional[float] = None,
        load_steps: Optional[int] = None,
    ) -> _FloatArray: ...
    def indent(
        self,
        start: _Vec3,
        direction: _Vec3,
        radius: float,
        travels: npt.ArrayLike,
        *,
        stiffness: Optional[float] = None,
        max_increment: Optional[float] = None,
        sample_spacing: Optional[float] = None,
        tolerance: Optional[float] = None,
    ) -> IndentResult: ...
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

def memory_budget() -> Tuple[int, str]: ...
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
    size: Tuple[float, float, float] = ...,   # (0.1, 0.02, 0.02) [m]
    cells: Tuple[int, int, int] = ...,       # (10, 2, 2)
) -> TetMesh: ...

@final
class Kernel:
    WENDLAND_C2: Kernel
    CUBIC_SPLINE: Kernel
    LINEAR_LENNARD_JONES: Kernel

@overload
def kernel_value(kernel: Kernel, r: float, h: float) -> float: ...
@overload
def kernel_value(kernel: Kernel, r: npt.ArrayLike, h: float) -> _FloatArray: ...

def neighbours(points: npt.ArrayLike, radius: float) -> Tuple[_IntArray, _IntArray]: ...

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

@final
class ParticleBody:
    def __new__(
        cls,
        positions: npt.ArrayLike,
        masses: npt.ArrayLike,
        material: Material,
        support_radius: float,
        kernel: Kernel = ...,
        fixed: Optional[_Indices] = None,
        gravity: Optional[_Vec3] = None,
        hourglass: float = ...,              # palpate.defaults.particles.hourglass
        min_relative_weight: float = ...,    # palpate.defaults.particles.min_relative_weight
    ) -> ParticleBody: ...
    def step(self, n: int = 1, dt: float = 1e-3) -> ParticleStepStats: ...
    def run_timed(self, ticks: int, dt: float = 1e-3, max_wall_s: Optional[float] = None) -> TimedRun: ...
    def set_forces(self, forces: npt.ArrayLike) -> None: ...
    def set_positions(self, positions: npt.ArrayLike) -> None: ...
    def set_velocities(self, velocities: npt.ArrayLike) -> None: ...
    def get_state(self) -> ParticleState: ...
    def set_state(self, state: ParticleState) -> None: ...
    def copy(self) -> ParticleBody: ...
    def __copy__(self) -> ParticleBody: ...
    def __deepcopy__(self, memo: Any) -> ParticleBody: ...
    @property
    def gravity(self) -> _FloatArray: ...
    @property
    def min_relative_weight(self) -> float: ...
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

@final
class TriSurface:
    def __new__(cls, points: npt.ArrayLike, triangles: npt.ArrayLike, *, source: Optional[str] = None) -> TriSurface: ...
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
    def contains(self, points: _Vec3, method: str = "winding") -> bool: ...  # type: ignore[overload-overlap]  # one point (3,)
    @overload
    def contains(self, points: npt.ArrayLike, method: str = "winding") -> npt.NDArray[np.bool_]: ...
    @overload
    def winding_number(self, points: _Vec3) -> float: ...  # type: ignore[overload-overlap]  # one point (3,)
    @overload
    def winding_number(self, points: npt.ArrayLike) -> _FloatArray: ...
    def simplified(self, triangles: int) -> TriSurface: ...
    def without_specks(self, min_volume_fraction: float = 0.001) -> Tuple[TriSurface, _IntArray]: ...
    def __len__(self) -> int: ...

def ellipsoid_surface(
    semi_axes: Tuple[float, float, float] = ...,   # (0.026, 0.026, 0.042) [m]
    subdivisions: int = 4,
) -> TriSurface: ...
@final
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

class _HybridOptions(TypedDict, total=False):
    # The hybrid builders' keyword options; each one not given is palpate.defaults.hybrid's.
    projection: Projection
    core_fraction: float
    core_triangles: int
    core_layers: int
    spacing: Optional[float]
    particles: int
    density: float
    min_region_particles: int
    field_voxels: int
    homogenise: bool

@final
class HybridSim:
    """The hybrid model you can touch: tool position in, force out (issue 12)."""
    def __new__(
        cls,
        model: HybridModel,
        material: Material,
        *,
        tool_radius: Optional[float] = None,
        tool_area_stiffness: Optional[float] = None,
        core_contact_stiffness: Optional[float] = None,
        hold: bool = True,
        activation_margin: Optional[float] = None,
        max_tool_speed: Optional[float] = None,
        linger: Optional[float] = None,
        max_substeps: Optional[int] = None,
        mass_scaling: Optional[float] = None,
        shell_fallback: bool = True,
        shell_pause: Optional[float] = None,
        homogenise: bool = True,
        implicit_exchange: bool = True,
        strict_units: bool = False,
    ) -> HybridSim: ...
    def step(self, tool_centre: _Vec3, dt: float = 1e-3, *, finish: bool = True) -> _FloatArray: ...
    def finish(self) -> None: ...
    def copy(self) -> HybridSim: ...
    def __copy__(self) -> HybridSim: ...
    def __deepcopy__(self, memo: Any) -> HybridSim: ...
    def reset(self) -> None: ...
    def get_state(self) -> HybridSimState: ...
    def set_state(self, state: HybridSimState) -> None: ...
    @property
    def model(self) -> HybridModel: ...
    @property
    def material(self) -> Material: ...
    @property
    def tool_radius(self) -> float: ...
    @property
    def tool_position(self) -> Optional[_FloatArray]: ...
    @property
    def options(self) -> Dict[str, Any]: ...
    @property
    def last(self) -> Dict[str, Any]: ...
    @property
    def surface(self) -> _FloatArray: ...
    @property
    def surface_triangles(self) -> _IntArray: ...
    @property
    def core_positions(self) -> _FloatArray: ...
    @property
    def core_tets(self) -> _IntArray: ...
    @property
    def active(self) -> _IntArray: ...
    def particle_positions(self) -> _FloatArray: ...
    @property
    def time(self) -> float: ...
    @property
    def ticks(self) -> int: ...
    @property
    def n_particles(self) -> int: ...

@final
class HybridModel:
    @staticmethod
    def build_nested(inner: TriSurface, outer: TriSurface, **options: Unpack[_HybridOptions]) -> HybridModel: ...
    @staticmethod
    def build_tagged(
        points: npt.ArrayLike, triangles: npt.ArrayLike, parts: npt.ArrayLike, **options: Unpack[_HybridOptions]
    ) -> HybridModel: ...
    def save(self, path: Union[str, os.PathLike[str]]) -> None: ...
    @staticmethod
    def load(path: Union[str, os.PathLike[str]]) -> HybridModel: ...
    @staticmethod
    def from_bytes(data: bytes) -> HybridModel: ...
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
    def homogenisation(self) -> Dict[str, Any]: ...
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

@final
class HapticLoop:
    """The haptic loop over a hybrid model (issue 13) or a full-FEM body (issue 14): a native servo thread, device in, force out."""
    def __new__(
        cls,
        model: Union[HybridModel, Body],
        material: Material,
        device: str,
        *,
        rate_hz: float = 1000.0,
        times: Optional[npt.ArrayLike] = None,
        knots: Optional[npt.ArrayLike] = None,
        recording: Optional[Union[str, os.PathLike[str]]] = None,
        port: Optional[int] = None,
        host: str = "127.0.0.1",
        kind: Optional[str] = None,
        hand_start: Optional[npt.ArrayLike] = None,
        idle: bool = False,
        tool_radius: Optional[float] = None,
        core_contact_stiffness: Optional[float] = None,
        tool_area_stiffness: Optional[float] = None,
        hold: bool = True,
        coupling_stiffness: Optional[float] = None,
        coupling_damping: Optional[float] = None,
        proxy_mass: Optional[float] = None,
        max_force: Optional[float] = None,
        max_rate: Optional[float] = None,
        ramp: Optional[float] = None,
        stall_timeout: Optional[float] = None,
        silence: Optional[float] = None,
        record_ticks: int = 0,
        max_ticks: Optional[int] = None,
        spin: Optional[float] = None,
        realtime: bool = False,
        threads: int = 1,
        physics_rate: Optional[float] = None,
        single_rate: bool = False,
        unsafe_limits: bool = False,
        bridge_key: Optional[bytes] = None,
        strict_units: bool = False,
    ) -> HapticLoop: ...
    def start(self) -> None: ...
    def snapshot(self) -> Optional[Dict[str, Any]]: ...
    def surface(self) -> Optional[Tuple[int, _FloatArray]]: ...
    def interior(self) -> Optional[Tuple[int, _FloatArray]]: ...
    def finished(self) -> bool: ...
    def wait(self, timeout: Optional[float] = None) -> bool: ...
    def stop(self) -> Dict[str, Any]: ...
    def run(self, max_ticks: Optional[int] = None) -> Dict[str, Any]: ...
    def save_recording(self, path: Union[str, os.PathLike[str]]) -> int: ...
    def recorded(self) -> Dict[str, _FloatArray]: ...
    def set_hand_target(self, p: npt.ArrayLike) -> None: ...
    def bridge_stats(self) -> Optional[Dict[str, int]]: ...
    @property
    def bridge_address(self) -> Optional[str]: ...
    @property
    def identity(self) -> Tuple[int, str]: ...
    @property
    def rate_hz(self) -> float: ...
    @property
    def physics_rate_hz(self) -> Optional[float]: ...

def simd_path() -> str: ...
def set_simd_enabled(enabled: bool) -> None: ...
def _defaults() -> Dict[str, Dict[str, Any]]: ...
