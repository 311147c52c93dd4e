"""``palpate bench particles``: the cost of one 1 ms haptic tick of a meshfree particle body.

The case. The left-ventricle-sized shell between the ellipsoids of semi-axes (20, 20, 35) mm and
(26, 26, 42) mm (:func:`palpate.ellipsoid_surface`, 8192 triangles each) is filled with particles
on a cubic lattice of the given spacing (default 0.9 mm: 82,544 particles;
:func:`palpate.sample_between`). The benchmark body is the ``N`` particles of that fill nearest to
the probe point ``P`` on the outer surface at z = 20 mm (the shared FEM protocol's probe point),
kept in lattice order: a full-thickness patch of the wall for large ``N``, a ball inside the wall
for small ``N``. Where the cut meets the wall's surfaces it leaves a sharp rim whose particles can
have neighbours in one plane only (which the core refuses): such particles are pruned and the
next nearest taken instead, until exactly ``N`` remain (:func:`cluster`). All ``N`` are active; the farthest 10 % from ``P`` (the rim of the patch) are
fixed; the 5 particles nearest ``P`` share a constant 0.01 N along the inward normal. E = 30 kPa,
nu = 0.4, rho = 1000 kg/m^3, undamped, no gravity, support radius 1.8 spacings (26 neighbours
inside the lattice; the mean over the patch, fewer at its surface, is reported as ``in h``). The
body pairs only the neighbours whose kernel weight is at least 1e-3 of its peak (the core's
default, ``DEFAULT_MIN_WEIGHT``): the 8 corner neighbours at sqrt(3) spacings, W/W(0) = 1e-5,
are not paired, which leaves 18 inside the lattice (``nbrs``, the pairs actually computed).

Timing. ``ParticleBody.run_timed`` times each tick (one ``step`` of dt = 1 ms, i.e.
``substeps`` explicit sub-steps at the stable step) in Rust with ``Instant``; the report gives
the median (and minimum) over the ticks and ``ticks_per_s = 1 / median``.

Flop count, read off ``crates/palpate-core/src/meshfree/pair_loop.rs`` (undamped path; adds,
multiplies and divides count one each, padding lanes not counted, 3x3 products as 45):

* per directed neighbour pair and sub-step: :data:`FLOPS_PER_PAIR` = 50 — pass 1 gathers
  ``K += (u_j - u_i) q^T`` (3 + 18 = 21); pass 2 gathers ``B_j q`` (18) and the hourglass term
  ``(gamma_i + gamma_j) w (u_j - u_i)`` (2 + 3 + 6 = 11), i.e. 29.
* per active particle and sub-step: :data:`FLOPS_PER_PARTICLE` = 285 — ``H = K R`` (45),
  ``F = I + H`` (3), ``F^T F`` and its symmetric part (63), Green strain (12), stress (24),
  ``P = F S`` (45), ``P - gamma K`` (18), ``B = (P - gamma K) R`` (45), ``B_i Q_i`` and the
  volume factor (18), the Verlet update (12).

The peak is one core's: ``cpu MHz`` from ``/proc/cpuinfo`` x 16 double-precision flops per cycle
(AVX2 FMA: 2 FMA units x 4 lanes x 2 flops; a Zen 4 runs AVX-512 as two 256-bit halves, so 16
holds there too). The step is single-threaded.
"""
from __future__ import annotations

import re
import time
from typing import Dict, Optional, Tuple

import numpy as np

from .. import _palpate as _p
from ..hybrid import ELLIPSOIDS_INNER, ELLIPSOIDS_OUTER, ELLIPSOIDS_SUBDIVISIONS
from . import E, NU, RHO, probe_on_ellipsoid  # noqa: F401 - the shared protocol's material [Pa, -, kg/m^3]

SPACING = 9e-4                 # [m]
SUPPORT_FACTOR = 1.8           # support radius / spacing
INNER = ELLIPSOIDS_INNER       # [m], (0.020, 0.020, 0.035): the paper's ellipsoids, the protocol's wall
OUTER = ELLIPSOIDS_OUTER       # [m], (0.026, 0.026, 0.042)
SUBDIVISIONS = ELLIPSOIDS_SUBDIVISIONS  # 5: 8192 triangles per ellipsoid
PROBE_Z = 0.020                # [m]
PROBE_FORCE = 0.01             # [N], total
N_PROBE = 5
FIXED_FRACTION = 0.10
DT = 1e-3                      # one haptic tick [s]
ALL = [200, 600, 2000, 28000]  # --all
TICKS = 200                    # ticks timed per case

FLOPS_PER_PAIR = 50
FLOPS_PER_PARTICLE = 285
FLOPS_PER_CYCLE = 16

KERNELS = {
    "wendland": _p.Kernel.WENDLAND_C2,
    "cubic": _p.Kernel.CUBIC_SPLINE,
    "lj": _p.Kernel.LINEAR_LENNARD_JONES,
}


def cpu_mhz() -> Optional[float]:
    """The first ``cpu MHz`` of ``/proc/cpuinfo``, or None."""
    try:
        with open("/proc/cpuinfo") as fh:
            m = re.search(r"^cpu MHz\s*:\s*([0-9.]+)", fh.read(), re.M)
        return float(m.group(1)) if m else None
    except OSError:
        return None


def probe_point() -> Tuple[np.ndarray, np.ndarray]:
    """Probe point P [m] on the outer ellipsoid at z = PROBE_Z, and the inward unit normal there
    (the protocol's, :func:`palpate.bench.probe_on_ellipsoid`, in metres)."""
    return probe_on_ellipsoid(OUTER, PROBE_Z)


_FILLS: Dict[float, Tuple[np.ndarray, np.ndarray, float]] = {}


def shell_fill(spacing: float) -> Tuple[np.ndarray, np.ndarray, float]:
    """The LV shell filled at ``spacing`` [m]: positions, masses and the sampling time [s] (cached)."""
    if spacing not in _FILLS:
        inner = _p.ellipsoid_surface(INNER, SUBDIVISIONS)
        outer = _p.ellipsoid_surface(OUTER, SUBDIVISIONS)
        t0 = time.perf_counter()
        pos, m = _p.sample_between(inner, outer, spacing, RHO)
        _FILLS[spacing] = (pos, m, time.perf_counter() - t0)
    return _FILLS[spacing]


def neighbourhood_moments(pos: np.ndarray, radius: float, kernel: str) -> Tuple[np.ndarray, np.ndarray]:
    """Each particle's neighbour count within ``radius`` [m] and kernel-weighted moment matrix
    ``sum_j W(|d_ij|) d_ij d_ij^T`` (n, 3, 3), ``d_ij = x_j - x_i``: the core's neighbour search
    (:func:`palpate.neighbours`) and kernel (:func:`palpate.kernel_value`), as the body builds them."""
    ptr, idx = _p.neighbours(pos, radius)
    counts = np.diff(ptr)
    rows = np.repeat(np.arange(len(pos)), counts)
    d = pos[idx] - pos[rows]
    w = _p.kernel_value(KERNELS[kernel], np.linalg.norm(d, axis=1), radius)
    outer = (w[:, None, None] * d[:, :, None] * d[:, None, :]).reshape(-1, 9)
    moments = np.stack([np.bincount(rows, outer[:, c], minlength=len(pos)) for c in range(9)], axis=1)
    return counts, moments.reshape(-1, 3, 3)


def prune(pos: np.ndarray, radius: float, kernel: str, min_ratio: float = 1e-2) -> np.ndarray:
    """Indices of the particles kept after repeatedly removing those whose kernel-weighted
    neighbourhood does not span 3D well (moment-matrix eigenvalue ratio below ``min_ratio``, 100
    times the core's limit): the particles of a sharp rim where a cut meets the surface."""
    keep = np.arange(len(pos))
    while True:
        ev = np.linalg.eigvalsh(neighbourhood_moments(pos[keep], radius, kernel)[1])
        ok = ev[:, 0] > min_ratio * ev[:, 2]
        if ok.all():
            return keep
        keep = keep[ok]


def cluster(n: int, spacing: float, kernel: str = "wendland", support: float = SUPPORT_FACTOR):
    """The benchmark cluster (see the module docs): positions, masses, fixed, probe indices, fill size.

    The ``n`` particles nearest the probe point that survive :func:`prune`: the candidate count
    grows until exactly ``n`` survive.
    """
    pos, m, _ = shell_fill(spacing)
    if n > len(pos):
        raise ValueError(f"N = {n} exceeds the {len(pos)} particles of the LV shell filled at "
                         f"{spacing * 1e3:g} mm; use a smaller --spacing")
    if n < 20:
        raise ValueError(f"N = {n} is too small: at least 20 particles")
    p, _ = probe_point()
    d = np.linalg.norm(pos - p, axis=1)
    rank = np.argsort(d, kind="stable")
    radius = support * spacing
    k, sel = n, None
    for _ in range(100):
        cand = rank[:k]
        sel = cand[prune(pos[cand], radius, kernel)]
        if len(sel) > n:       # overshoot: keep the n nearest survivors if they hold
            sel = sel[:n]
            sel = sel[prune(pos[sel], radius, kernel)]
        if len(sel) == n or k >= len(pos):
            break
        k = min(len(pos), k + max(1, n - len(sel)))
    if len(sel) != n:
        raise ValueError(f"could not cut a cluster of exactly {n} well-connected particles from the fill")
    sel = np.sort(sel)                                  # lattice order
    pos, m, d = pos[sel], m[sel], d[sel]
    by_d = np.argsort(d, kind="stable")
    n_fixed = max(1, int(round(FIXED_FRACTION * n)))
    fixed = np.sort(by_d[n - n_fixed:])
    probe = by_d[:N_PROBE]
    return pos, m, fixed, probe, len(_FILLS[spacing][0])


def run(n: int, spacing: float = SPACING, kernel: str = "wendland", ticks: int = TICKS,
        max_wall_s: Optional[float] = None, support: float = SUPPORT_FACTOR) -> dict:
    """Build the cluster of ``n`` particles and time ``ticks`` ticks of 1 ms; a JSON-able dict."""
    pos, m, fixed, probe, n_fill = cluster(n, spacing, kernel, support)
    material = _p.Material(young=E, poisson=NU, density=RHO)
    t0 = time.perf_counter()
    body = _p.ParticleBody(pos, m, material, support * spacing, kernel=KERNELS[kernel], fixed=fixed)
    build_s = time.perf_counter() - t0
    _, normal = probe_point()
    f = np.zeros((n, 3))
    f[probe] = PROBE_FORCE / len(probe) * normal
    body.set_forces(f)
    r = body.run_timed(ticks, DT, max_wall_s)
    w = np.asarray(r["tick_wall_s"])
    u = body.displacements
    finite = bool(np.isfinite(u).all())
    pairs = body.n_pairs
    flops_tick = r["substeps"] * (FLOPS_PER_PAIR * pairs + FLOPS_PER_PARTICLE * n)
    mhz = cpu_mhz()
    peak = None if mhz is None else mhz * 1e6 * FLOPS_PER_CYCLE
    # Lattice neighbours strictly inside the support: a radius a hair short of it, so that the
    # lattice points at exactly the support radius (support 2.0, 3.0 ...) count as outside, not
    # as whatever their positions' round-off says.
    in_support = float(len(_p.neighbours(pos, support * spacing * (1 - 1e-9))[1]))
    med = float(np.median(w)) if len(w) else None
    rate = flops_tick / med if med else None
    return {
        "n": n,
        "fill_particles": n_fill,
        "spacing_m": spacing,
        "support_radius_m": body.support_radius,
        "kernel": kernel,
        "hot_loop": _p.simd_path(),
        "mean_neighbours": pairs / n,
        "mean_neighbours_in_support": in_support / n,
        "pairs": pairs,
        "fixed": len(fixed),
        "probe_particles": len(probe),
        "probe_force_N": PROBE_FORCE,
        "stable_dt_s": body.stable_dt,
        "substeps": r["substeps"],
        "substep_dt_s": r["substep_dt"],
        "ticks": r["ticks"],
        "tick_median_s": med,
        "tick_min_s": float(w.min()) if len(w) else None,
        "ticks_per_s": 1.0 / med if med else None,
        "ticks_per_s_mean": len(w) / float(w.sum()) if len(w) else None,
        "real_time": bool(med is not None and med <= DT),
        "flops_per_pair": FLOPS_PER_PAIR,
        "flops_per_particle": FLOPS_PER_PARTICLE,
        "flops_per_tick": flops_tick,
        "gflops": rate / 1e9 if rate else None,
        "cpu_mhz": mhz,
        "peak_gflops": peak / 1e9 if peak else None,
        "peak_assumption": f"cpu MHz x {FLOPS_PER_CYCLE} flop/cycle (AVX2 FMA: 2 units x 4 doubles x 2), one core",
        "peak_fraction": rate / peak if rate and peak else None,
        "build_s": build_s,
        "sample_s": shell_fill(spacing)[2],
        "max_disp_m": float(np.linalg.norm(u, axis=1).max()) if finite else None,
        "finite": finite,
        "error": r["error"],
    }
