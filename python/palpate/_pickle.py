"""Pickling of palpate's extension objects (``multiprocessing``, Dask, ``copy.deepcopy``).

Registered with :mod:`copyreg` when palpate is imported, so the Rust classes need no pickling
code of their own: each object is rebuilt from what its public getters return, through its public
constructor, then (bodies) its state restored with ``set_state``. That makes a pickle of a body
carry its mesh, material, fixed nodes, gravity, integrator and state (with the integrator's
memory: an unpickled body steps on bit for bit as the original); its model (orderings, symbolic
factorisation) is recompiled on unpickling. A ``HybridModel`` travels as its model-file bytes, a
``HybridSim`` as its model, material, constructor options and ``get_state()`` (recompiled, then
restored: its ticks go on bit for bit as the original's).
"""
from __future__ import annotations

import copyreg
from typing import Any, Dict

from . import _palpate as _ext


def _enum(cls: type, name: str) -> Any:
    return getattr(cls, name)


def _enum_reducer(cls: type):
    names = {getattr(cls, n): n for n in dir(cls) if not n.startswith("_") and isinstance(getattr(cls, n), cls)}
    return lambda v: (_enum, (cls, names[v]))


def _material(lame_lambda: float, lame_mu: float, density: float, phi: float, psi: float, law: Any) -> Any:
    # The core stores the Lame constants: rebuilding from them is exact.
    return _ext.Material(lame_lambda=lame_lambda, lame_mu=lame_mu, density=density, phi=phi, psi=psi, law=law)


def _backward_euler(solver: Any, kwargs: Dict[str, Any]) -> Any:
    return _ext.BackwardEuler(solver, **kwargs)


def _body(mesh: Any, material: Any, fixed: Any, gravity: Any, integrator: Any, state: Dict[str, Any],
          order: int = 1) -> Any:
    b = _ext.Body(mesh, material, fixed=fixed, gravity=gravity, integrator=integrator, order=order)
    b.set_state(state)
    return b


def _particle_body(args: Dict[str, Any], state: Dict[str, Any]) -> Any:
    b = _ext.ParticleBody(**args)
    b.set_state(state)
    return b


# Options of pickles made before they were times in seconds (at the 1 ms tick they counted).
_TICK_OPTIONS = {"linger_ticks": ("linger", 1e-3), "max_tool_step": ("max_tool_speed", 1e3)}


def _hybrid_sim(model: Any, material: Any, options: Dict[str, Any], state: Dict[str, Any]) -> Any:
    options = dict(options)
    if "linger_ticks" in options and options.get("shell_pause") is not None:
        options["shell_pause"] = options["shell_pause"] * 1e-3   # ticks, in those older pickles
    for old, (new, scale) in _TICK_OPTIONS.items():
        if old in options:
            options[new] = options.pop(old) * scale
    s = _ext.HybridSim(model, material, **options)
    s.set_state(state)
    return s


# The constructor's keywords; the other entries of HybridSim.options are resolved from these and
# the model (coupling, confinement), so rebuilding from these remakes the same simulation.
_HYBRID_SIM_OPTIONS = ("tool_radius", "tool_area_stiffness", "core_contact_stiffness", "hold", "activation_margin",
                       "max_tool_speed", "linger", "max_substeps", "mass_scaling", "shell_fallback", "shell_pause",
                       "homogenise", "implicit_exchange", "strict_units")


def _reduce_hybrid_sim(s: Any):
    o = s.options
    return _hybrid_sim, (s.model, s.material, {k: o[k] for k in _HYBRID_SIM_OPTIONS}, s.get_state())


def _reduce_backward_euler(i: Any):
    kw = {k: getattr(i, k) for k in ("max_iterations", "tolerance", "history") if getattr(i, k) is not None}
    return _backward_euler, (i.solver, kw)


def _reduce_particle_body(b: Any):
    args = dict(positions=b.rest_positions, masses=b.masses, material=b.material, support_radius=b.support_radius,
                kernel=b.kernel, fixed=b.fixed, gravity=b.gravity, hourglass=b.hourglass,
                min_relative_weight=b.min_relative_weight)
    return _particle_body, (args, b.get_state())


def register() -> None:
    for cls in (_ext.Law, _ext.Filter, _ext.Solver, _ext.Kernel, _ext.Projection):
        copyreg.pickle(cls, _enum_reducer(cls))
    copyreg.pickle(_ext.Material, lambda m: (_material, (m.lame_lambda, m.lame_mu, m.density, m.phi, m.psi, m.law)))
    copyreg.pickle(_ext.SemiImplicit, lambda i: (_ext.SemiImplicit, (i.filter,)))
    copyreg.pickle(_ext.BackwardEuler, _reduce_backward_euler)
    copyreg.pickle(_ext.TetMesh, lambda m: (_ext.TetMesh, (m.points, m.tets)))
    copyreg.pickle(_ext.TriSurface, lambda s: (_ext.TriSurface, (s.points, s.triangles)))
    copyreg.pickle(_ext.Body, lambda b: (_body, (b.mesh, b.material, b.fixed, b.gravity, b.integrator, b.get_state(),
                                                 b.order)))
    copyreg.pickle(_ext.ParticleBody, _reduce_particle_body)
    copyreg.pickle(_ext.HybridModel, lambda m: (_ext.HybridModel.from_bytes, (m.to_bytes(),)))
    copyreg.pickle(_ext.HybridSim, _reduce_hybrid_sim)
