"""Material identification from a measured palpation (``palpate fit``): which Young's modulus
(and optionally Poisson's ratio and the viscosity) makes the study's loading reproduce a measured
force-depth curve.

Two stages on the same runner as :func:`palpate.sweep.sweep` (in this process, a
``LocalCluster`` or any Dask cluster):
1. a coarse sweep: a grid over the fitted parameters (geometric for ``young``, ``phi`` and
   ``psi``, even for ``poisson``); its best point starts
2. a local least-squares refinement (``scipy.optimize.least_squares``, trust region reflective,
   within the bounds), whose finite-difference Jacobian runs its perturbed scenarios side by
   side on the runner.

The residual compares what the loading does not prescribe: the probe loading prescribes the force
(a ramp), so the residual is the simulated depth at each measured force minus the measured depth
[m]; the press prescribes the depth, so it is the simulated normal force at each measured depth
minus the measured force [N]. Simulated curves are interpolated (linearly) on their loading part
(the ramp, the press), where the prescribed quantity increases.

The confidence interval (95%) is the linearised one at the optimum: the covariance
``s^2 (J^T J)^-1`` with ``s^2 = |r|^2 / (m - p)`` (m measured points, p parameters) and
Student's t quantile, in the fitted coordinates (``log`` of the moduli), mapped back: it is
asymmetric for ``young``. It says how well the data pin the parameters down under the model, not
how right the model is.
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _palpate as _p
from .._extras import install_hint
from .runner import Runner, model_payload
from .spec import Spec, load_spec, spec_from_dict

#: What may be fitted, with the bounds of the search and whether it is searched in log space.
FITTABLE: Dict[str, Tuple[float, float, bool]] = {
    "young": (1.0e2, 1.0e8, True),
    "poisson": (0.0, 0.499, False),
    "phi": (1.0e-4, 1.0e3, True),
    "psi": (1.0e-4, 1.0e3, True),
}

#: Coarse grid points per fitted parameter.
COARSE_POINTS = {1: 9, 2: 5, 3: 4, 4: 3}


class FitError(_p.PalpateError, ValueError):
    """A fit that cannot start (a bad measured curve, a parameter that cannot be fitted) or whose
    every coarse scenario failed."""


@dataclass
class FitResult:
    """The fitted parameters, their 95% confidence intervals, and how well the curve fits."""
    values: Dict[str, float]
    ci95: Dict[str, Tuple[float, float]]
    rms: float                       # root mean square residual [m] (probe) or [N] (press)
    residual_unit: str
    evaluations: int                 # scenarios run (coarse sweep and refinement)
    coarse_best: Dict[str, float]
    measured: np.ndarray             # (m, 2): depth [m], force [N]
    fitted_curve: np.ndarray         # (k, 2): depth [m], force [N] of the fitted material
    status: str                      # least_squares' message
    plot: Optional[str] = None
    extra: Dict[str, Any] = field(default_factory=dict)

    def summary(self) -> str:
        lines = []
        for k, v in self.values.items():
            lo, hi = self.ci95[k]
            lines.append(f"  {k} = {v:.6g} (95% CI {lo:.6g} .. {hi:.6g})")
        lines.append(f"  residual rms {self.rms:.3g} {self.residual_unit} over {len(self.measured)} points; "
                     f"{self.evaluations} scenarios run")
        return "\n".join(lines)


def read_curve(path: Union[str, os.PathLike]) -> np.ndarray:
    """A measured force-depth curve: CSV with a header naming a depth column (``depth_m`` or
    ``depth``, metres) and a force column (``force_n`` or ``force``, newtons); other columns are
    ignored. Returns (m, 2): depth, force. Raises :class:`FitError` naming the file and the line."""
    name = str(path)
    from .._readers import read_text
    text = read_text(str(path), FitError)
    rows = list(csv.reader(line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")))
    if not rows:
        raise FitError(f"{name}: empty (expected a header with depth_m and force_n, then rows)")
    head = [h.strip().lower() for h in rows[0]]

    def col(names: Sequence[str]) -> int:
        for n in names:
            if n in head:
                return head.index(n)
        raise FitError(f"{name}: line 1: no {' or '.join(names)} column in the header {rows[0]}")
    di, fi = col(("depth_m", "depth")), col(("force_n", "force"))
    out = []
    for k, r in enumerate(rows[1:], start=2):
        try:
            d, f = float(r[di]), float(r[fi])
        except (IndexError, ValueError):
            raise FitError(f"{name}: line {k}: expected numbers in columns {rows[0][di]!r} and {rows[0][fi]!r}, got {r}") from None
        if not (math.isfinite(d) and math.isfinite(f)):
            raise FitError(f"{name}: line {k}: not finite: {r}")
        out.append((d, f))
    if len(out) < 3:
        raise FitError(f"{name}: {len(out)} data rows: a fit needs at least 3")
    return np.array(out, dtype=np.float64)


def _loading_part(row: Dict[str, Any], kind: str) -> Tuple[np.ndarray, np.ndarray]:
    """(prescribed, response) along the loading part of a scenario's curve: force -> depth (probe,
    over the ramp) or depth -> force (press, while the depth increases)."""
    d = np.asarray(row.get("curve_depth_m") or [], dtype=np.float64)
    f = np.asarray(row.get("curve_force_n") or [], dtype=np.float64)
    if kind == "probe":
        x, y = f, d
    else:
        x, y = d, f
    if len(x) == 0:
        return x, y
    # Up to where the prescribed quantity stops increasing (the end of the ramp or the press).
    stop = int(np.argmax(x)) + 1
    x, y = x[:stop], y[:stop]
    keep = np.concatenate([[True], np.diff(x) > 0])
    return x[keep], y[keep]


def residuals(row: Dict[str, Any], measured: np.ndarray, kind: str) -> Optional[np.ndarray]:
    """The residual vector of one scenario's row against the measured (depth, force) points, or
    None if the scenario failed or its curve does not reach the measured range."""
    if row.get("status") == "failed":
        return None
    x, y = _loading_part(row, kind)
    mx, my = (measured[:, 1], measured[:, 0]) if kind == "probe" else (measured[:, 0], measured[:, 1])
    if len(x) < 2 or mx.max() > x.max() * (1 + 1e-9) or mx.min() < x.min() - 1e-12 * max(1.0, abs(x.min())):
        return None
    return np.interp(mx, x, y) - my


def fit(spec: Union[Spec, Dict[str, Any], str, os.PathLike], measured: Union[np.ndarray, str, os.PathLike],
        params: Sequence[str] = ("young",), *, client: Any = None, scheduler: Optional[str] = None,
        workers: Optional[int] = None, plot: Optional[str] = None, log: Optional[Callable[[str], None]] = None,
        coarse: Optional[int] = None) -> FitResult:
    """Fit ``params`` (a subset of ``young``, ``poisson``, ``phi``, ``psi``) of ``spec``'s loading
    to ``measured`` ((m, 2) depth [m], force [N], or a CSV path: :func:`read_curve`); the spec's
    other values are kept, its ``[parameters]`` ignored. ``plot``: a PNG of measured against
    fitted (without matplotlib: none, ``FitResult.plot`` None, a note on stderr). ``coarse``: grid points per parameter (default by their number). Raises
    :class:`FitError` or :class:`SweepSpecError`."""
    from scipy import optimize, stats

    sp = spec if isinstance(spec, Spec) else spec_from_dict(spec) if isinstance(spec, dict) else load_spec(spec)
    say = log or (lambda s: None)
    params = list(dict.fromkeys(params))
    for p in params:
        if p not in FITTABLE:
            raise FitError(f"cannot fit {p!r}: fittable are {', '.join(FITTABLE)}")
    if not params:
        raise FitError("nothing to fit: name at least one of " + ", ".join(FITTABLE))
    data = read_curve(measured) if not isinstance(measured, np.ndarray) else np.asarray(measured, dtype=np.float64)
    if data.ndim != 2 or data.shape[1] != 2 or len(data) < 3 or not np.all(np.isfinite(data)):
        raise FitError(f"measured: expected (m >= 3, 2) finite depth [m], force [N] points, got shape {data.shape}")
    if len(data) <= len(params):
        raise FitError(f"{len(data)} measured points for {len(params)} parameters: a fit needs more points than parameters")
    kind = sp.kind
    unit = "m" if kind == "probe" else "N"
    base = dict(sp.loading)

    def to_x(v: Dict[str, float]) -> np.ndarray:
        return np.array([math.log(v[p]) if FITTABLE[p][2] else v[p] for p in params])

    def from_x(x: np.ndarray) -> Dict[str, float]:
        return {p: float(math.exp(xi) if FITTABLE[p][2] else xi) for p, xi in zip(params, x)}

    lo = np.array([math.log(FITTABLE[p][0]) if FITTABLE[p][2] else FITTABLE[p][0] for p in params])
    hi = np.array([math.log(FITTABLE[p][1]) if FITTABLE[p][2] else FITTABLE[p][1] for p in params])
    count = {"n": 0}
    payload = model_payload(sp)
    with Runner(payload, client=client, scheduler=scheduler, workers=workers, log=say) as runner:

        def run(points: List[Dict[str, float]]) -> List[Dict[str, Any]]:
            scen = []
            for v in points:
                s = dict(base)
                s.update(v)
                s["scenario"] = count["n"]
                count["n"] += 1
                scen.append(s)
            return runner.map(scen)

        # 1. Coarse: a grid around the spec's values (a decade each way for the moduli).
        k = coarse or COARSE_POINTS.get(len(params), 3)
        axes = []
        for p in params:
            c = float(base[p])
            if p == "poisson":
                axes.append(np.linspace(0.2, 0.49, k))
            else:
                c = c if c > 0 else 1.0
                axes.append(np.geomspace(max(c / 10, FITTABLE[p][0]), min(c * 10, FITTABLE[p][1]), k))
        grid = [dict(zip(params, map(float, combo))) for combo in np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(params), -1).T]
        rows = run(grid)
        costs = []
        for v, r in zip(grid, rows):
            res = residuals(r, data, kind)
            costs.append(float(res @ res) if res is not None else math.inf)
        if not np.isfinite(min(costs)):
            errs = {r.get("error") for r in rows if r.get("error")}
            raise FitError(f"every coarse scenario failed or fell short of the measured range ({len(grid)} run; "
                           f"errors: {'; '.join(sorted(map(str, errs))[:3]) or 'none: curves too short'})")
        best = grid[int(np.argmin(costs))]
        say(f"palpate fit: coarse sweep of {len(grid)} scenarios: best {', '.join(f'{k} = {v:.4g}' for k, v in best.items())}")

        # 2. Refinement. A failed or short scenario is a large residual, which steers the trust
        # region back rather than stopping the fit.
        penalty = 10.0 * max(float(np.abs(data[:, 0 if kind == 'probe' else 1]).max()), 1e-12)

        def rvec(r: Dict[str, Any]) -> np.ndarray:
            res = residuals(r, data, kind)
            return res if res is not None else np.full(len(data), penalty)

        cache: Dict[Tuple[float, ...], np.ndarray] = {}

        def fun(x: np.ndarray) -> np.ndarray:
            key = tuple(np.round(x, 14))
            if key not in cache:
                cache[key] = rvec(run([from_x(x)])[0])
            return cache[key]

        def jac(x: np.ndarray) -> np.ndarray:
            # Forward differences, every perturbed scenario at once on the runner.
            h = np.array([1e-3 if FITTABLE[p][2] else 1e-3 * max(abs(xi), 0.1) for p, xi in zip(params, x)])
            pts = []
            for i in range(len(x)):
                xp = x.copy()
                xp[i] = xp[i] + h[i] if xp[i] + h[i] <= hi[i] else xp[i] - h[i]
                pts.append(xp)
            r0 = fun(x)
            rs = run([from_x(xp) for xp in pts])
            J = np.empty((len(data), len(x)))
            for i, (xp, r) in enumerate(zip(pts, rs)):
                J[:, i] = (rvec(r) - r0) / (xp[i] - x[i])
            return J

        x0 = np.clip(to_x(best), lo + 1e-12, hi - 1e-12)
        sol = optimize.least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale="jac", xtol=1e-8, ftol=1e-10,
                                     gtol=1e-10, max_nfev=50)
        values = from_x(sol.x)
        r = sol.fun
        m, p = len(data), len(params)
        dof = m - p
        s2 = float(r @ r) / dof
        J = sol.jac
        try:
            cov = s2 * np.linalg.inv(J.T @ J)
            half = stats.t.ppf(0.975, dof) * np.sqrt(np.maximum(np.diag(cov), 0.0))
        except np.linalg.LinAlgError:
            half = np.full(p, math.inf)
        ci = {}
        for i, q in enumerate(params):
            a, b = sol.x[i] - half[i], sol.x[i] + half[i]
            ci[q] = (float(math.exp(a)), float(math.exp(b))) if FITTABLE[q][2] else (float(a), float(b))
        final = run([values])[0]
    curve = np.column_stack([np.asarray(final.get("curve_depth_m") or [], dtype=np.float64),
                             np.asarray(final.get("curve_force_n") or [], dtype=np.float64)])
    result = FitResult(values=values, ci95=ci, rms=float(math.sqrt(float(r @ r) / m)), residual_unit=unit,
                       evaluations=count["n"], coarse_best=best, measured=data, fitted_curve=curve,
                       status=str(sol.message))
    if plot:
        try:
            result.plot = _plot(result, plot, sp)
        except ImportError:  # matplotlib is an extra (palpate[plot]): the fit stands without its plot
            import sys

            print(f"(matplotlib not installed: no {plot}; {install_hint('plot')})", file=sys.stderr)
    return result


def _plot(r: FitResult, path: str, sp: Spec) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4), dpi=110)
    ax.plot(1e3 * r.measured[:, 0], r.measured[:, 1], "o", ms=4, label="measured")
    if len(r.fitted_curve):
        ax.plot(1e3 * r.fitted_curve[:, 0], r.fitted_curve[:, 1], "-", label="fitted: " + ", ".join(f"{k} = {v:.4g}" for k, v in r.values.items()))
    ax.set_xlabel("depth [mm]")
    ax.set_ylabel("force [N]")
    ax.set_title(f"palpate fit: {sp.name} ({sp.kind}, rms {r.rms:.3g} {r.residual_unit})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
