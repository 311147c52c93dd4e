"""The defaults of palpate's builders and solvers, read from the Rust core where each is defined.

One definition, in Rust; this module, the CLI's options and help, and the docs read it, so they
cannot disagree::

    >>> import palpate
    >>> palpate.defaults.hybrid.particles            # HybridOptions::default()
    28000
    >>> palpate.defaults.newton.tolerance            # Integrator::NEWTON_TOLERANCE
    1e-08

* :data:`hybrid`: :meth:`palpate.HybridModel.build_nested` / ``build_tagged``'s options
  (``palpate_core::hybrid::HybridOptions::default()``), plus the automatic core resolutions.
* :data:`quasi_newton`, :data:`newton`: :class:`palpate.BackwardEuler`'s per-solver
  ``max_iterations`` / ``tolerance`` (/ ``history``) (``Integrator::QUASI_NEWTON_*``,
  ``Integrator::NEWTON_*``).
* :data:`static_solve`: :meth:`palpate.Body.static_solve`'s (``StaticOptions::default()``).
* :data:`particles`: :class:`palpate.ParticleBody`'s ``kernel``, ``hourglass`` and
  ``min_relative_weight`` (``palpate_core::meshfree``).
* :data:`tissue`: the default tissue (``Material::myocardium()``: E = 30 kPa, nu = 0.4,
  1060 kg/m^3), the tissue of ``palpate touch``, ``palpate haptic`` (damped), ``palpate
  validate``, the demo's touch, a scene file's density when it gives none, and the hybrid
  builder's density; :func:`tissue_material` makes it a :class:`palpate.Material`. (The shared
  benchmark protocol keeps its 1000 kg/m^3, to compare with its peers: ``palpate bench``
  protocol and particles, the demo's FEM bodies, ``palpate sweep``'s material defaults, the
  protocol scenes in ``scenes/``.)

Units are SI, as in the functions that take them.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Dict, Optional

from . import _palpate as _p


@dataclass(frozen=True)
class HybridDefaults:
    """Options of the hybrid builder (``HybridOptions::default()``)."""
    projection: "_p.Projection"
    core_fraction: float           # [-], of the wall's transmural coordinate
    core_triangles: int            # 0: automatic (the two values below)
    core_layers: int               # 0: automatic (tets about as tall as wide)
    spacing: Optional[float]       # [m]; None: about ``particles`` particles
    particles: Optional[int]
    density: float                 # [kg/m^3]
    min_region_particles: int
    field_voxels: int
    homogenise: bool               # compute the core's homogenised stiffness (HybridModel.homogenisation)
    auto_core_triangles_closed: int  # core_triangles = 0 on a closed wall
    auto_core_triangles_base: int    # ... and on a wall with a base

    def options(self) -> Dict[str, Any]:
        """The builders' keyword arguments (without the automatic resolutions)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("auto_")}


@dataclass(frozen=True)
class QuasiNewtonDefaults:
    """``BackwardEuler(Solver.QUASI_NEWTON)``: iteration cap, relative gradient tolerance, L-BFGS pairs."""
    max_iterations: int
    tolerance: float
    history: int


@dataclass(frozen=True)
class NewtonDefaults:
    """``BackwardEuler(Solver.NEWTON)``: iteration cap, relative gradient tolerance."""
    max_iterations: int
    tolerance: float


@dataclass(frozen=True)
class StaticSolveDefaults:
    """``Body.static_solve``: Newton iterations, tolerance on max |residual| / max |force|, load steps."""
    max_iterations: int
    tolerance: float
    load_steps: int


@dataclass(frozen=True)
class ParticleDefaults:
    """``ParticleBody``: kernel, hourglass stiffness kappa [-], minimum relative kernel weight of a pair [-]."""
    kernel: "_p.Kernel"
    hourglass: float
    min_relative_weight: float


@dataclass(frozen=True)
class TissueDefaults:
    """The default tissue (``Material::myocardium()``)."""
    young: float                   # [Pa]
    poisson: float                 # [-]
    density: float                 # [kg/m^3]


def tissue_material(**overrides: Any) -> "_p.Material":
    """The default tissue as a :class:`palpate.Material` (St. Venant-Kirchhoff, undamped), with
    ``overrides`` (``young``, ``poisson``, ``density``, ``phi``, ``psi``, ``law``) applied."""
    kw: Dict[str, Any] = dict(young=tissue.young, poisson=tissue.poisson, density=tissue.density)
    kw.update(overrides)
    return _p.Material(**kw)


_RAW = _p._defaults()
hybrid = HybridDefaults(**_RAW["hybrid"])
quasi_newton = QuasiNewtonDefaults(**_RAW["quasi_newton"])
newton = NewtonDefaults(**_RAW["newton"])
static_solve = StaticSolveDefaults(**_RAW["static_solve"])
particles = ParticleDefaults(**_RAW["particles"])
_M = _p.Material.myocardium()
tissue = TissueDefaults(young=float(round(_M.young, 6)), poisson=float(round(_M.poisson, 12)), density=_M.density)
del _RAW, _M

__all__ = ["hybrid", "quasi_newton", "newton", "static_solve", "particles", "tissue", "tissue_material",
           "HybridDefaults", "QuasiNewtonDefaults", "NewtonDefaults", "StaticSolveDefaults", "ParticleDefaults",
           "TissueDefaults"]
