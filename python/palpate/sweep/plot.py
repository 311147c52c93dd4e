"""The study's plot (``results.png`` beside the table, :func:`palpate.sweep.sweep`): the
force-indentation curves of the scenarios, one line a scenario labelled by its varied parameters;
or, for a study without curves (``outputs.curve = false``), its main outcome (probe: the final
depth; press: the peak force) against the first varied parameter.

Needs matplotlib (the ``plot`` extra): :func:`plot_study` raises ``ImportError`` without it, and
the caller goes on without the plot. Drawn with the non-interactive Agg backend.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

#: The parameters' SI units, for labels (spec.py's list).
UNITS = {"young": "Pa", "poisson": "", "density": "kg/m^3", "phi": "Pa s", "psi": "Pa s", "dt": "s", "force": "N",
         "probe_z": "m", "steps": "", "integrator": "", "depth": "m", "tool_radius": "m"}
#: Up to this many lines have a legend; more are coloured by the first varied parameter.
LEGEND_MOST = 12
#: At most this many curves are drawn (evenly spaced over the study's order); the title says so.
CURVES_MOST = 200
#: The main outcome of a study without curves, per loading: (column, label, scale to the axis' unit).
OUTCOME = {"probe": ("final_depth_m", "final depth [mm]", 1e3), "press": ("max_force_n", "peak force [N]", 1.0)}


def _value(k: str, v: Any) -> str:
    unit = UNITS.get(k, "")
    text = f"{v:.3g}" if isinstance(v, float) else str(v)
    return f"{k} = {text}" + (f" {unit}" if unit else "")


def label(row: Dict[str, Any], varied: Sequence[str]) -> str:
    """A scenario's label: its varied parameters' values, with their units (else its index)."""
    return ", ".join(_value(k, row.get(k)) for k in varied) if varied else f"scenario {row.get('scenario')}"


def _axis_label(k: str) -> str:
    unit = UNITS.get(k, "")
    return f"{k} [{unit}]" if unit else k


def _numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def _spread(values: Sequence[float]) -> bool:
    """Whether positive values spanning more than a factor 20 read better on a log axis."""
    v = [float(x) for x in values if x is not None]
    return bool(v) and min(v) > 0 and max(v) / min(v) > 20


def plot_study(table: Any, path: os.PathLike, *, name: str, kind: str, varied: Sequence[str]) -> Path:
    """Draw the study ``table`` (the pyarrow table of :func:`palpate.sweep.sweep`) into the PNG
    ``path`` (written whole or not at all) and return ``path``. Raises ``ImportError`` without
    matplotlib."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    varied = [k for k in varied if k in table.column_names]
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=110)
    try:
        if "curve_force_n" in table.column_names:
            title = _curves(ax, table, varied, plt)
        else:
            title = _outcome(ax, table, varied, kind)
        ax.set_title(f"palpate sweep: {name} ({kind}, {table.num_rows} scenarios{title})", fontsize=10)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        tmp = path.with_name(path.name + ".tmp")
        fig.savefig(tmp, format="png")
        os.replace(tmp, path)
    finally:
        plt.close(fig)
    return path


def _curves(ax: Any, table: Any, varied: List[str], plt: Any) -> str:
    """One line a scenario: force [N] against indentation depth [mm]; unstable ones dashed and
    left out of the axes' limits (they run far past the stable ones)."""
    n = table.num_rows
    idx = list(range(n)) if n <= CURVES_MOST else sorted(set(np.linspace(0, n - 1, CURVES_MOST).round().astype(int).tolist()))
    sub = table.take(idx).select(["scenario", "status", "curve_depth_m", "curve_force_n"] + varied).to_pylist()
    drawn = [r for r in sub if r["curve_depth_m"] and r["curve_force_n"]]
    colour = None
    if len(drawn) > LEGEND_MOST and varied and _numeric([r[varied[0]] for r in drawn]):
        # Too many for a legend: the first varied parameter's value is the colour.
        from matplotlib.colors import LogNorm, Normalize
        vals = [float(r[varied[0]]) for r in drawn]
        norm = (LogNorm if _spread(vals) else Normalize)(min(vals), max(vals))
        cmap = plt.get_cmap("viridis")
        colour = lambda r: cmap(norm(float(r[varied[0]])))  # noqa: E731
        sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
        sm.set_array([])
        ax.figure.colorbar(sm, ax=ax, label=_axis_label(varied[0]))
    lim_x, lim_y = [], []
    for r in drawn:
        d = 1e3 * np.asarray(r["curve_depth_m"], dtype=np.float64)
        f = np.asarray(r["curve_force_n"], dtype=np.float64)
        unstable = r["status"] != "ok"
        kw: Dict[str, Any] = {"lw": 1.2, "ls": "--" if unstable else "-"}
        if colour is not None:
            kw["color"] = colour(r)
        if len(drawn) <= LEGEND_MOST:
            kw["label"] = label(r, varied) + (f" ({r['status']})" if unstable else "")
        ax.plot(d, f, **kw)
        if not unstable:
            lim_x += [np.nanmin(d), np.nanmax(d)]
            lim_y += [np.nanmin(f), np.nanmax(f)]
    if lim_x and len(lim_x) < 2 * len(drawn):   # unstable curves beside stable ones: frame the stable
        _frame(ax, lim_x, lim_y)
    ax.set_xlabel("indentation depth [mm]")
    ax.set_ylabel("force [N]")
    if drawn and len(drawn) <= LEGEND_MOST:
        ax.legend(fontsize=7, loc="best")
    notes = []
    if len(sub) < n:
        notes.append(f"{len(sub)} curves shown")
    if len(drawn) < len(sub):
        notes.append(f"{len(sub) - len(drawn)} without a curve")
    if any(r["status"] != "ok" for r in drawn):
        notes.append("dashed: unstable")
    return "; " + ", ".join(notes) if notes else ""


def _frame(ax: Any, xs: List[float], ys: List[float]) -> None:
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    px, py = 0.05 * (x1 - x0 or 1.0), 0.05 * (y1 - y0 or 1.0)
    ax.set_xlim(x0 - px, x1 + px)
    ax.set_ylim(y0 - py, y1 + py)


def _outcome(ax: Any, table: Any, varied: List[str], kind: str) -> str:
    """A study without curves: its main outcome against the first varied parameter, a line for
    each combination of the others (points alone when there are too many)."""
    col, ylabel, scale = OUTCOME.get(kind, OUTCOME["probe"])
    rows = table.select(["scenario", "status", col] + varied).to_pylist()
    xkey: Optional[str] = varied[0] if varied else None
    rest = varied[1:]
    pts = [r for r in rows if r[col] is not None and (xkey is None or r[xkey] is not None)]
    x_of = (lambda r: r[xkey]) if xkey else (lambda r: r["scenario"])  # noqa: E731
    groups: Dict[tuple, List[Dict[str, Any]]] = {}
    for r in pts:
        groups.setdefault(tuple(r[k] for k in rest), []).append(r)
    numeric = _numeric([x_of(r) for r in pts])
    as_lines = len(groups) <= LEGEND_MOST and all(len(g) > 1 for g in groups.values())
    if as_lines:
        for key, g in groups.items():
            if numeric:
                g = sorted(g, key=x_of)
            kw: Dict[str, Any] = {"marker": "o", "ms": 4, "lw": 1.2}
            if rest:
                kw["label"] = ", ".join(_value(k, v) for k, v in zip(rest, key))
            ax.plot([x_of(r) for r in g], [scale * r[col] for r in g], **kw)
            bad = [r for r in g if r["status"] != "ok"]
            if bad:
                ax.plot([x_of(r) for r in bad], [scale * r[col] for r in bad], "kx", ms=7)
        if rest:
            ax.legend(fontsize=7, loc="best")
    else:
        ok = [r for r in pts if r["status"] == "ok"]
        bad = [r for r in pts if r["status"] != "ok"]
        ax.plot([x_of(r) for r in ok], [scale * r[col] for r in ok], "o", ms=4)
        if bad:
            ax.plot([x_of(r) for r in bad], [scale * r[col] for r in bad], "kx", ms=7)
    if numeric and _spread([x_of(r) for r in pts]):
        ax.set_xscale("log")
    ax.set_xlabel(_axis_label(xkey) if xkey else "scenario")
    ax.set_ylabel(ylabel)
    notes = []
    if len(pts) < len(rows):
        notes.append(f"{len(rows) - len(pts)} without a value")
    if any(r["status"] != "ok" for r in pts):
        notes.append("x: unstable")
    return "; " + ", ".join(notes) if notes else ""
