"""A study's specification: a TOML file (or the same dict in Python), checked once, before any
scenario runs; every error names the file and the key (``study.seed``, ``parameters.young``) and
says what was expected.

    [study]
    name = "stiffness"        # optional (default: the file's stem)
    seed = 0                  # the seed of the random draws (default 0)
    samples = 16              # random draws per point of the grid (needed with random parameters)

    [model]
    mesh = "ellipsoid_192"    # probe loading: a protocol ventricle: "ellipsoid_192", a shared
                              # bench mesh "190" | "1350" | "10k" | "50k", or a mesh file in
                              # mesh units (shared/bench/PROTOCOL.md)
    # hybrid = "ventricle"    # press loading: a hybrid model file, or a shape name
                              # ("ventricle", "ellipsoids", "rodero"), built once

    [loading]
    kind = "probe"            # the protocol's probe: a force ramped on the outer nodes near the
                              # probe point (FEM, palpate.bench); or "press": the tool pressed
                              # into the hybrid model at the probe point (palpate.touch)
    force = 0.2               # probe [N]; ramp = 0.1 [s]; steps = 1000; dt = 1e-3 [s];
                              # integrator = "backward-euler"; probe_z = 0.02 [m]
                              # press: depth = 0.003 [m], duration = 0.3 [s] (the press),
                              # hold = 0.1 [s], tool_radius = 0.005 [m], dt = 1e-3 [s];
                              # or script = "path.toml": a palpate touch script (press,
                              # hold, slide, release: palpate/touch.py) instead of the press

    [parameters]              # what varies; each parameter one of:
    young = [2e4, 3e4, 4e4]                               # a list of values
    poisson = { grid = [0.3, 0.45], num = 4 }             # evenly spaced, ends included
    phi = { grid = [0.1, 10.0], num = 3, scale = "log" }  # geometrically spaced
    density = { random = "uniform", low = 900, high = 1100 }  # "uniform" | "loguniform" | "normal"
                                                               # (normal: mean, std)

    [outputs]
    curve = true              # the force-depth curve (list columns), default true
    field = false             # the final displacement field of each scenario, in fields/

Scenarios are the Cartesian product of the list and grid parameters (in the order the file gives
them, the last varying fastest), each with ``samples`` joint random draws of the random ones
(``samples`` 1 without random parameters). The draws come from ``numpy.random.default_rng(seed)``
in the driver, before anything runs, so the scenarios (and the table) do not depend on the number
of workers or their order of completion.

Parameters and units: ``young`` [Pa], ``poisson`` [-], ``density`` [kg/m^3], ``phi`` and ``psi``
(the viscous Lame-like constants [Pa s]), ``dt`` [s]; probe loading also ``force`` [N],
``probe_z`` [m] (height of the probe point on the outer ellipsoid), ``integrator`` (a name of
``palpate bench protocol --integrator``) and ``steps``; press loading also ``depth`` [m] and
``tool_radius`` [m]. A parameter given in ``[parameters]`` overrides the same key of
``[loading]``.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import tomllib
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from .. import _palpate as _p
from .. import bench as _bench
from .._fields import FieldChecker
from ..hybrid import SHAPES as HYBRID_SHAPES  # the shape names palpate.hybrid.load_model resolves


class SweepSpecError(_p.PalpateError, ValueError):
    """A study specification that cannot run: the message names the file and the key."""


#: Material parameters every loading takes, with their defaults: the shared benchmark protocol's
#: material (palpate.bench: 3e4 Pa, 0.4, 1000 kg/m^3, the probe loading's case); no damping unless asked.
MATERIAL_DEFAULTS = {"young": _bench.E, "poisson": _bench.NU, "density": _bench.RHO, "phi": 0.0, "psi": 0.0}

#: Loading keys and their defaults, per kind.
LOADING_DEFAULTS: Dict[str, Dict[str, Any]] = {
    "probe": {"force": 0.2, "ramp": 0.1, "steps": 1000, "dt": 1e-3, "integrator": "backward-euler", "probe_z": 0.02},
    "press": {"depth": 0.003, "duration": 0.3, "hold": 0.1, "tool_radius": 0.005, "dt": 1e-3},
}

#: Keys that may vary, per kind (the material's and the loading's, except the ramp's and press's
#: shape, which stay fixed within a study).
VARIABLE: Dict[str, Tuple[str, ...]] = {
    "probe": tuple(MATERIAL_DEFAULTS) + ("force", "steps", "dt", "integrator", "probe_z"),
    "press": tuple(MATERIAL_DEFAULTS) + ("depth", "tool_radius", "dt"),
}

#: The press's own path, which a script (``loading.script``) replaces.
SCRIPTED = ("depth", "duration", "hold")

#: Parameters whose values are names, not numbers.
TEXT = {"integrator"}
#: Parameters whose values are whole numbers.
WHOLE = {"steps"}

RANDOM_KINDS = ("uniform", "loguniform", "normal")


@dataclass(frozen=True)
class Axis:
    """One varied parameter: ``values`` for a list or a grid, else a random draw."""
    name: str
    values: Optional[Tuple[Any, ...]] = None
    random: Optional[str] = None
    a: float = 0.0           # low (uniform, loguniform) or mean (normal)
    b: float = 0.0           # high, or std


@dataclass(frozen=True)
class Spec:
    """A checked study specification (:func:`load_spec`, :func:`spec_from_dict`)."""
    name: str
    seed: int
    samples: int
    model: Dict[str, str]         # {"mesh": ...} or {"hybrid": ...}, paths resolved
    kind: str                     # "probe" | "press"
    loading: Dict[str, Any]       # every key of LOADING_DEFAULTS[kind] and MATERIAL_DEFAULTS
    axes: Tuple[Axis, ...]
    curve: bool = True
    field: bool = False
    script: Optional[str] = None  # press loading: a palpate touch script's path (the tool's path)
    source: Dict[str, Any] = dataclasses.field(default_factory=dict, compare=False)   # the document as given

    def scenarios(self) -> List[Dict[str, Any]]:
        """Every scenario's full parameter set (the loading's fixed values and the varied ones),
        in the study's order; ``scenario`` is the index. Deterministic in (spec, seed)."""
        fixed_axes = [a for a in self.axes if a.random is None]
        random_axes = [a for a in self.axes if a.random is not None]
        rng = np.random.default_rng(self.seed)
        out: List[Dict[str, Any]] = []
        for combo in itertools.product(*[a.values for a in fixed_axes]):
            for _ in range(self.samples):
                s = dict(self.loading)
                s.update({a.name: v for a, v in zip(fixed_axes, combo)})
                for a in random_axes:
                    s[a.name] = _draw(rng, a)
                s["scenario"] = len(out)
                out.append(s)
        return out

    def digest(self) -> str:
        """A hash of what defines the table (model, loading, axes, seed, outputs): a resumed study
        must have the same."""
        script = hashlib.sha256(Path(self.script).read_bytes()).hexdigest() if self.script else None
        key = {"model": self.model, "kind": self.kind, "loading": self.loading, "seed": self.seed, "script": script,
               "samples": self.samples, "curve": self.curve, "field": self.field,
               "axes": [[a.name, list(a.values) if a.values is not None else None, a.random, a.a, a.b] for a in self.axes]}
        return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:16]

    def varied(self) -> List[str]:
        """The names of the varied parameters, in the file's order."""
        return [a.name for a in self.axes]


def _draw(rng: np.random.Generator, a: Axis) -> float:
    if a.random == "uniform":
        return float(rng.uniform(a.a, a.b))
    if a.random == "loguniform":
        return float(math.exp(rng.uniform(math.log(a.a), math.log(a.b))))
    return float(rng.normal(a.a, a.b))


def load_spec(path: Union[str, os.PathLike]) -> Spec:
    """Read and check the study file ``path`` (TOML); relative model paths are taken from the
    file's folder. Raises :class:`SweepSpecError`."""
    p = Path(path)
    name = str(p)
    from .._readers import read_text
    text = read_text(str(p), SweepSpecError)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SweepSpecError(f"{name}: not valid TOML: {e}") from None
    return spec_from_dict(doc, name=name, base=p.parent, default_name=p.stem)


def spec_from_dict(doc: Dict[str, Any], name: str = "<spec>", base: Union[str, os.PathLike, None] = None,
                   default_name: str = "study") -> Spec:
    """Check a study given as a dict (the TOML file's structure). Raises :class:`SweepSpecError`."""
    ck = FieldChecker(name, SweepSpecError)
    if not isinstance(doc, dict):
        raise SweepSpecError(f"{name}: a study is a table (dict), got {type(doc).__name__}")
    ck.known(doc, "", {"study", "model", "loading", "parameters", "outputs"})
    study = ck.table(doc, "study")
    ck.known(study, "study", {"name", "seed", "samples"})
    sname = study.get("name", default_name)
    if not isinstance(sname, str) or not sname.strip():
        raise ck.err("study.name", f"must be a non-empty string, got {sname!r}")
    seed = ck.number(study, "study", "seed", default=0, integer=True, nonneg=True)

    model = ck.table(doc, "model", required=True)
    ck.known(model, "model", {"mesh", "hybrid"})
    if len(model) != 1:
        raise ck.err("model", "give exactly one of mesh = ... (probe loading) or hybrid = ... (press loading)")
    (mkey, mval), = model.items()
    if not isinstance(mval, str) or not mval:
        raise ck.err(f"model.{mkey}", f"must be a name or a path, got {mval!r}")
    model_out = {mkey: _resolve_model(ck, mkey, mval, base)}

    loading = ck.table(doc, "loading", required=True)
    kind = loading.get("kind")
    if kind not in LOADING_DEFAULTS:
        raise ck.err("loading.kind", f"must be one of {', '.join(repr(k) for k in LOADING_DEFAULTS)}, got {kind!r}")
    want = "mesh" if kind == "probe" else "hybrid"
    if mkey != want:
        raise ck.err(f"model.{mkey}", f"loading.kind = {kind!r} needs model.{want} (a probe loads an FEM mesh, "
                                      "a press a hybrid model)")
    defaults = dict(MATERIAL_DEFAULTS, **LOADING_DEFAULTS[kind])
    ck.known(loading, "loading", set(defaults) | {"kind"} | ({"script"} if kind == "press" else set()))
    script = None
    if "script" in loading:
        script = loading["script"]
        if not isinstance(script, str) or not script:
            raise ck.err("loading.script", f"must be the path of a palpate touch script (.toml or .csv), got {script!r}")
        sp = Path(script)
        if not sp.is_absolute() and base is not None:
            sp = Path(base) / sp
        if not sp.is_file():
            raise ck.err("loading.script", f"{script!r}: no such file ({sp})")
        script = str(sp.resolve())
        for k in SCRIPTED:
            if k in loading:
                raise ck.err(f"loading.{k}", "the script gives the tool's path: no press depth or timing beside it")
        for k in ("depth",):
            if k in doc.get("parameters", {}) if isinstance(doc.get("parameters"), dict) else False:
                raise ck.err(f"parameters.{k}", "the script gives the tool's path: the depth cannot vary")
    fixed: Dict[str, Any] = {}
    for k, d in defaults.items():
        if k in TEXT:
            v = loading.get(k, d)
            _check_value(ck, f"loading.{k}", k, v)
            fixed[k] = v
        else:
            v = ck.number(loading, "loading", k, default=d, integer=k in WHOLE)
            _check_value(ck, f"loading.{k}", k, v)
            fixed[k] = v

    params = ck.table(doc, "parameters")
    ck.known(params, "parameters", set(VARIABLE[kind]))
    axes = tuple(_axis(ck, k, v) for k, v in params.items())
    has_random = any(a.random for a in axes)
    if has_random:
        samples = ck.number(study, "study", "samples", required=True, integer=True, positive=True)
        if samples > MAX_SCENARIOS:
            raise ck.err("study.samples", f"{samples} draws: more than a study may have ({MAX_SCENARIOS})")
    else:
        samples = ck.number(study, "study", "samples", default=1, integer=True, positive=True)
        if samples != 1:
            raise ck.err("study.samples", "only with a random parameter (every other scenario would repeat)")

    outputs = ck.table(doc, "outputs")
    ck.known(outputs, "outputs", {"curve", "field"})
    flags = {}
    for k, d in (("curve", True), ("field", False)):
        v = outputs.get(k, d)
        if not isinstance(v, bool):
            raise ck.err(f"outputs.{k}", f"must be true or false, got {v!r}")
        flags[k] = v
    if script is not None:
        for k in SCRIPTED:
            fixed.pop(k, None)
    spec = Spec(name=sname, seed=int(seed), samples=int(samples), model=model_out, kind=kind, loading=fixed,
                axes=axes, curve=flags["curve"], field=flags["field"], script=script, source=doc)
    if script is not None:
        from ..touch import ScriptError, parse_script
        try:
            parse_script(script)
        except ScriptError as e:
            raise ck.err("loading.script", str(e)) from None
    n = 1
    for a in axes:
        n *= len(a.values) if a.values is not None else 1
    n *= spec.samples
    if n > MAX_SCENARIOS:
        raise ck.err("parameters", f"the study has {n} scenarios, more than {MAX_SCENARIOS}: split it")
    return spec


#: A study larger than this is refused (its table alone would be gigabytes): split it.
MAX_SCENARIOS = 1_000_000


def _resolve_model(ck: FieldChecker, key: str, v: str, base) -> str:
    from ..bench import GENERATED, MESHES
    if key == "mesh" and (v == GENERATED or v in MESHES or v in {f"lv_{m}" for m in MESHES}):
        return v
    if key == "hybrid" and v in HYBRID_SHAPES:
        return v
    p = Path(v)
    if not p.is_absolute() and base is not None:
        p = Path(base) / p
    if not p.is_file():
        names = f"{GENERATED!r}, {', '.join(repr(m) for m in MESHES)}" if key == "mesh" else ", ".join(repr(s) for s in HYBRID_SHAPES)
        raise ck.err(f"model.{key}", f"{v!r} is neither a file ({p} not found) nor one of {names}")
    return str(p.resolve())


def _check_value(ck: FieldChecker, label: str, k: str, v: Any) -> None:
    """The per-parameter range checks (the material's own are the core's, at run time: a bad
    combination there is a failed scenario, not a bad spec)."""
    from ..bench import INTEGRATORS
    if k in TEXT:
        if v not in INTEGRATORS:
            raise ck.err(label, f"must be one of {', '.join(INTEGRATORS)}, got {v!r}")
        return
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ck.err(label, f"must be a finite number, got {v!r}")
    if k in WHOLE and (not isinstance(v, int) or v < 1):
        raise ck.err(label, f"must be a whole number of at least 1, got {v!r}")
    positive = {"young", "density", "dt", "ramp", "duration", "tool_radius", "depth", "force"}
    if k in positive and not v > 0:
        raise ck.err(label, f"must be positive, got {v!r}")
    if k in {"phi", "psi", "hold", "probe_z"} and v < 0:
        raise ck.err(label, f"must not be negative, got {v!r}")
    if k == "poisson" and not -1.0 < v < 0.5:
        raise ck.err(label, f"must be within (-1, 0.5), got {v!r}")
    if k == "probe_z" and not v < 0.042:
        raise ck.err(label, f"must be below the ventricle's apex height 0.042 m, got {v!r}")
    if k == "dt" and v > 0.1:
        raise ck.err(label, f"must be at most 0.1 s, got {v!r}")


def _axis(ck: FieldChecker, k: str, v: Any) -> Axis:
    label = f"parameters.{k}"
    if isinstance(v, list):
        if not v:
            raise ck.err(label, "an empty list")
        for i, x in enumerate(v):
            _check_value(ck, f"{label}[{i}]", k, x)
        return Axis(k, values=tuple(v))
    if not isinstance(v, dict):
        raise ck.err(label, f"must be a list of values, a grid {{ grid = [lo, hi], num = N }} or a random draw "
                            f"{{ random = \"uniform\", low = a, high = b }}, got {v!r}")
    if "grid" in v:
        ck.known(v, label, {"grid", "num", "scale"})
        g = v["grid"]
        if (not isinstance(g, list) or len(g) != 2
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in g)):
            raise ck.err(f"{label}.grid", f"must be [low, high], two finite numbers, got {g!r}")
        num = ck.number(v, label, "num", required=True, integer=True, positive=True)
        if num > MAX_SCENARIOS:
            raise ck.err(f"{label}.num", f"{num} points: more than a study may have ({MAX_SCENARIOS})")
        scale = v.get("scale", "linear")
        if scale not in ("linear", "log"):
            raise ck.err(f"{label}.scale", f"must be 'linear' or 'log', got {scale!r}")
        if k in TEXT or k in WHOLE:
            raise ck.err(label, "a grid is for real-valued parameters: give a list")
        lo, hi = float(g[0]), float(g[1])
        if scale == "log":
            if not (lo > 0 and hi > 0):
                raise ck.err(f"{label}.grid", f"a log grid needs positive ends, got {g!r}")
            vals = np.geomspace(lo, hi, int(num))
        else:
            vals = np.linspace(lo, hi, int(num))
        out = tuple(float(x) for x in vals)
        for x in (out[0], out[-1]):
            _check_value(ck, f"{label}.grid", k, x)
        return Axis(k, values=out)
    if "random" in v:
        kind = v["random"]
        if kind not in RANDOM_KINDS:
            raise ck.err(f"{label}.random", f"must be one of {', '.join(RANDOM_KINDS)}, got {kind!r}")
        if k in TEXT or k in WHOLE:
            raise ck.err(label, "a random draw is for real-valued parameters: give a list")
        if kind == "normal":
            ck.known(v, label, {"random", "mean", "std"})
            a = ck.number(v, label, "mean", required=True)
            b = ck.number(v, label, "std", required=True, positive=True)
        else:
            ck.known(v, label, {"random", "low", "high"})
            a = ck.number(v, label, "low", required=True)
            b = ck.number(v, label, "high", required=True)
            if not a < b:
                raise ck.err(label, f"low must be below high, got low = {a!r}, high = {b!r}")
            if kind == "loguniform" and not a > 0:
                raise ck.err(f"{label}.low", f"a log-uniform draw needs positive bounds, got {a!r}")
            _check_value(ck, f"{label}.low", k, a)
            _check_value(ck, f"{label}.high", k, b)
        return Axis(k, random=kind, a=float(a), b=float(b))
    raise ck.err(label, "a table needs 'grid' (with num) or 'random' (with its bounds)")
