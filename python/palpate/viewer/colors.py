"""The displacement colours: seven bands of the viridis map (sampled at 0, 1/6, ..., 1), the first
for displacements below one sixth of the colour scale (the organ at rest), the last for the scale
and above; the colour bar image and its labels in millimetres."""
from __future__ import annotations

import numpy as np

#: Band colours, RGB 0-255 (viridis at 0, 1/6, ..., 1).
BANDS = ((68, 1, 84), (68, 57, 131), (49, 104, 142), (33, 145, 140), (53, 183, 121), (144, 215, 67), (253, 231, 37))


def edges(scale_mm: float) -> np.ndarray:
    """The band edges [mm] for a colour scale of ``scale_mm``: band k holds ``edges[k-1] <= d <
    edges[k]`` (band 0 below ``edges[0]``, the last band from ``edges[-1]`` on)."""
    n = len(BANDS) - 1
    return scale_mm * np.arange(1, n + 1) / n


def band_of(d_mm: np.ndarray, scale_mm: float) -> np.ndarray:
    """The band index of each displacement ``d_mm`` [mm]."""
    return np.searchsorted(edges(scale_mm), np.asarray(d_mm), side="right")


def bar_image(width: int = 280, height: int = 18) -> np.ndarray:
    """The colour bar, (height, width, 3) uint8: the bands left to right, equal widths."""
    k = np.minimum((np.arange(width) * len(BANDS)) // width, len(BANDS) - 1)
    row = np.asarray(BANDS, dtype=np.uint8)[k]
    return np.repeat(row[None], height, axis=0)


def bar_labels(scale_mm: float) -> str:
    """The bar's band edges as one line of markdown [mm]."""
    e = edges(scale_mm)
    return "0 | " + " | ".join(f"{x:.3g}" for x in e[:-1]) + f" | >= {e[-1]:.3g} mm"
