"""Wrong-typed arguments to the binding (issue 15: everything palpate raises derives from
PalpateError): every public constructor, method and function of ``palpate._palpate`` that takes
arguments, each argument in turn given a str, None, a list of str or a dict, must raise a
``palpate.ParameterTypeError`` (a PalpateError that is also a TypeError) whose message names the
argument; never pyo3's bare TypeError, never a panic.

What a wrong implementation would do: an argument pyo3 converts without ``conv::arg`` (a new
float, flag or class argument) raises pyo3's bare ``TypeError``; an array argument given a str
or a dict is called a shape error (a ValueError); a new function or method is added and never
tried (the walk refuses a callable it has no valid arguments for).
"""
import inspect

import numpy as np
import pytest

import palpate
from palpate import _palpate as ext

BAD = {"str": "abc", "None": None, "list of str": ["a", "b", "c"], "dict": {"a": 1}}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """One valid instance of each class, and a valid value for each argument: by the name of
    ``Callable.argument`` first, then of the argument alone."""
    mesh = palpate.box_mesh(size=(0.02, 0.01, 0.01), cells=(2, 1, 1))
    mat = palpate.Material(young=3e4, poisson=0.4, density=1000.0)
    body = palpate.Body(mesh, mat, fixed=mesh.nodes_below(0.0))
    n = mesh.n_nodes
    surf = palpate.ellipsoid_surface((0.026, 0.026, 0.042), 1)
    inner = palpate.ellipsoid_surface((0.02, 0.02, 0.035), 1)
    pos, masses = palpate.sample_inside(surf, 0.006, 1000.0)
    particles = palpate.ParticleBody(pos, masses, mat, 0.012)
    model = palpate.build_shape("ellipsoids", particles=400, field_voxels=20000)
    sim = palpate.HybridSim(model, mat)
    loop = palpate.HapticLoop(model, mat, "hand", hand_start=np.array([0.0, 0.0, 0.1]))
    vp, vt, vparts = palpate.ventricle_surface(24, 6)
    rec = tmp_path_factory.mktemp("args") / "x.palprec"
    instances = {"Body": body, "ParticleBody": particles, "TetMesh": mesh, "TriSurface": surf,
                 "HybridModel": model, "HybridSim": sim, "HapticLoop": loop, "Material": mat}
    valid = {
        # by Callable.argument
        "TetMesh.points": mesh.points, "TriSurface.points": surf.points, "neighbours.points": pos,
        "TriSurface.contains.points": np.zeros(3), "TriSurface.winding_number.points": np.zeros(3),
        "HybridModel.build_tagged.points": vp, "HybridModel.build_tagged.triangles": vt, "HybridModel.build_nested.inner": inner,
        "HybridModel.build_nested.outer": surf, "sample_between.inner": inner, "sample_between.outer": surf,
        "Body.set_state.state": body.get_state(), "ParticleBody.set_state.state": particles.get_state(),
        "HybridSim.set_state.state": sim.get_state(), "Body.material": mat, "ParticleBody.positions": pos,
        "ParticleBody.set_forces.forces": np.zeros_like(pos), "ParticleBody.set_positions.positions": pos,
        "ParticleBody.set_velocities.velocities": np.zeros_like(pos), "HybridSim.model": model,
        "HapticLoop.model": model, "ellipsoid_wall.inner": (0.02, 0.02, 0.035),
        "ellipsoid_wall.outer": (0.026, 0.026, 0.042), "truncated_ellipsoid_wall.inner": (0.02, 0.02, 0.035),
        "truncated_ellipsoid_wall.outer": (0.026, 0.026, 0.042), "HapticLoop.run.max_ticks": 1,
        "Body.indent.start": (0.01, 0.005, 0.03), "Body.indent.direction": (0.0, 0.0, -1.0),
        "Body.indent.travels": [1e-4], "Body.order": 2, "Body.indent.stiffness": 1e7, "Body.indent.max_increment": 1e-4,
        "Body.indent.sample_spacing": 1e-3, "TriSurface.simplified.triangles": 8, "TriSurface.without_specks.min_volume_fraction": 1e-3,
        # by argument
        "tets": mesh.tets, "triangles": surf.triangles, "mesh": mesh, "material": mat, "forces": np.zeros((n, 3)),
        "positions": mesh.points, "velocities": np.zeros((n, 3)), "fixed": [0], "gravity": (0.0, 0.0, -9.81),
        "integrator": palpate.BackwardEuler(), "n": 1, "dt": 1e-3, "max_iterations": 5, "tolerance": 1e-6,
        "load_steps": 1, "nodes": [n - 1], "total_force": (0.0, 0.0, -1e-3), "ramp_time": 0.01, "steps": 2,
        "stable_limit": 0.05, "max_wall_s": 1.0, "loads": [([n - 1], (0.0, 0.0, -1e-3), 0.01)], "ramp_start": 0.0,
        "young": 3e4, "poisson": 0.4, "density": 1000.0, "phi": 0.0, "psi": 0.0, "law": palpate.Law.NEO_HOOKEAN,
        "lame_lambda": 1e5, "lame_mu": 1e4, "filter": palpate.Filter.STABLE, "solver": palpate.Solver.QUASI_NEWTON,
        "history": 3, "source": "x.msh", "z_cut": 0.0, "tol": 1e-9, "method": "parity", "masses": masses,
        "support_radius": 0.012, "kernel": palpate.Kernel.WENDLAND_C2, "hourglass": 0.1, "min_relative_weight": 0.0,
        "ticks": 1, "i": 0, "s": 0, "path": str(rec), "data": model.to_bytes(), "parts": vparts,
        "tool_centre": np.array([0.0, 0.0, 0.1]), "tool_radius": 0.005, "core_contact_stiffness": 2000.0, "tool_area_stiffness": 1e7, "hold": True,
        "activation_margin": 0.001, "max_tool_speed": 1.0, "linger": 0.01, "max_substeps": 50,
        "mass_scaling": 0.95, "shell_fallback": True, "shell_pause": 0.01, "homogenise": True, "implicit_exchange": False, "strict_units": False, "device": "hand", "rate_hz": 1000.0, "times": np.array([0.0, 1.0]),
        "knots": np.zeros((2, 3)), "recording": str(rec), "port": 0, "host": "127.0.0.1", "kind": "simulated",
        "hand_start": np.array([0.0, 0.0, 0.1]), "idle": False, "coupling_stiffness": 300.0,
        "coupling_damping": 1.0, "proxy_mass": 0.01, "max_force": 3.0, "max_rate": 100.0, "ramp": 0.5,
        "stall_timeout": 0.1, "silence": 0.05, "physics_rate": 500.0, "single_rate": False, "unsafe_limits": False, "bridge_key": None, "record_ticks": 0, "max_ticks": 1, "spin": 0.0, "realtime": False, "threads": 1, "timeout": 0.0,
        "p": np.array([0.0, 0.0, 0.1]), "size": (0.02, 0.01, 0.01), "cells": (2, 1, 1), "semi_axes": (0.02, 0.02, 0.03),
        "subdivisions": 1, "layers": 1, "circumferential": 8, "longitudinal": 4, "surface": surf, "spacing": 0.006,
        "r": 0.001, "h": 0.01, "radius": 0.01, "enabled": True, "inner": inner, "outer": surf, "finish": True,
    }
    return instances, valid


def callables():
    """``(label, owner class or None, name)`` of every public callable of the extension that takes
    arguments (constructors, methods, static methods, functions)."""
    out = []
    for name in sorted(dir(ext)):
        obj = getattr(ext, name)
        if name.startswith("_") or (isinstance(obj, type) and issubclass(obj, BaseException)):
            continue
        if isinstance(obj, type):
            try:
                inspect.signature(obj)
                out.append((name, obj, None))
            except ValueError:
                pass   # no constructor (enums, HybridModel: built by its static methods)
            for meth in sorted(obj.__dict__):
                if not meth.startswith("_") and callable(getattr(obj, meth)) and not isinstance(getattr(obj, meth), obj):
                    out.append((f"{name}.{meth}", obj, meth))
        elif callable(obj):
            out.append((name, None, name))
    return [c for c in out if _params(c)]


def _target(c, instances):
    label, owner, meth = c
    if owner is None:
        return getattr(ext, meth)
    if meth is None:
        return owner
    raw = inspect.getattr_static(owner, meth)
    return getattr(owner, meth) if isinstance(raw, staticmethod) else getattr(instances[owner.__name__], meth)


def _params(c):
    label, owner, meth = c
    f = owner if meth is None else getattr(owner, meth) if owner is not None else getattr(ext, meth)
    return [p for p in inspect.signature(f).parameters.values()
            if p.name != "self" and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)]


def _valid(label, pname, valid):
    for key in (f"{label}.{pname}", f"{label.split('.')[0]}.{pname}", pname):
        if key in valid:
            return valid[key]
    raise KeyError(f"no valid value for {label}({pname}=...): add one to the test's table")


CASES = [(c, p.name) for c in callables() for p in _params(c)]


def test_the_walk_covers_the_api():
    labels = {c[0] for c, _ in CASES}
    assert {"Material", "Body", "Body.step", "Body.run_probe", "ParticleBody", "HybridSim.step", "HapticLoop",
            "HybridModel.load", "box_mesh", "sample_between", "TetMesh", "TriSurface.contains"} <= labels
    assert len(CASES) > 150, len(CASES)


@pytest.mark.parametrize("case, pname", CASES, ids=[f"{c[0]}({p})" for c, p in CASES])
def test_a_wrong_type_is_a_parameter_type_error(world, case, pname):
    instances, valid = world
    label = case[0]
    params = _params(case)
    f = _target(case, instances)
    good = {p.name: _valid(label, p.name, valid) for p in params}
    tried = 0
    for what, bad in BAD.items():
        default = next(p.default for p in params if p.name == pname)
        if bad is None and default is None:
            continue   # None is this argument's default: accepted
        if what == "str" and isinstance(good[pname], str):
            continue   # a str (a path, a name) is the argument's type
        if what == "dict" and isinstance(good[pname], dict):
            continue   # a state dict: its keys are checked, not its type
        if label == "HapticLoop" and pname in ("times", "knots"):
            good["device"] = "scripted"   # read only for a scripted device
        kwargs = dict(good, **{pname: bad})
        args = [kwargs.pop(p.name) for p in params if p.kind == p.POSITIONAL_ONLY]
        with pytest.raises(BaseException) as e:
            f(*args, **kwargs)
        tried += 1
        err = e.value
        assert isinstance(err, palpate.ParameterTypeError) and isinstance(err, TypeError), \
            f"{label}({pname}={bad!r}): {type(err).__mro__}: {err}"
        assert pname in str(err), f"{label}({pname}={bad!r}): the message does not name the argument: {err}"
    assert tried


def test_the_valid_values_are_valid(world):
    """The table's values are accepted: a wrong type is what the walk changes, nothing else."""
    instances, valid = world
    for c in callables():
        label, owner, meth = c
        if label in ("HapticLoop", "HapticLoop.run", "HapticLoop.wait", "HapticLoop.save_recording", "HapticLoop.set_hand_target",
                     "HybridModel.save", "HybridModel.load", "Body.set_state", "ParticleBody.set_state"):
            continue   # a second servo thread, a loop that is not running, files: not needed here
        kwargs = {p.name: _valid(label, p.name, valid) for p in _params(c)}
        if label == "Material":
            del kwargs["lame_lambda"], kwargs["lame_mu"]   # the other pair of moduli
        _target(c, instances)(**kwargs)


def test_a_property_setter_and_the_argument_name_in_the_note():
    mat = palpate.Material.myocardium()
    pos = np.array([[0.0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.01]])
    pb = palpate.ParticleBody(pos, np.full(4, 1e-3), mat, 0.02)
    with pytest.raises(palpate.ParameterTypeError, match="active"):
        pb.active = "abc"
    with pytest.raises(palpate.ParameterTypeError, match=r"argument 'young': must be real number, not str \(got 'abc'\)"):
        palpate.Material(young="abc", poisson=0.4)
    with pytest.raises(TypeError):   # still what `except TypeError` callers catch
        palpate.box_mesh(cells=("a", 1, 1))
