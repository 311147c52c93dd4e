# Type stubs of the Rust extension palpate._palpate (python/src/*.rs). Hand-kept: update with the binding.
# Units are SI: m, m/s, N, s, Pa, kg/m^3, Pa s. Per-node arrays are float64 (n, 3).
from typing import Optional, Sequence, Tuple, TypedDict, Union

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
    ) -> None: ...
    @staticmethod
    def myocardium() -> Material: ...
    @staticmethod
    def paper_ellipsoids() -> Material: ...
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

class SemiImplicit:
    def __init__(self) -> None: ...

class BackwardEuler:
    def __init__(self, newton: bool = False, max_iterations: int = 20, tolerance: float = 1e-9) -> None: ...
    @property
    def newton(self) -> bool: ...
    @property
    def max_iterations(self) -> int: ...
    @property
    def tolerance(self) -> float: ...

class StepStats(TypedDict):
    steps: int
    solves: int
    unconverged_steps: int
    max_residual: float

class ProbeRun(TypedDict):
    steps: int
    wall_s: float
    stable: bool
    max_disp_m: float
    probe_disp_avg_m: float
    mean_disp: _FloatArray
    probe_disp: _FloatArray
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
