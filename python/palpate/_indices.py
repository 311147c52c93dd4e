"""Index arrays (triangles, tets) given from Python as any numbers: whole values only.

``np.asarray(x, dtype=np.int64)`` truncates a float index toward zero, so that a triangle
``(0, 1.5, 2)`` became ``(0, 1, 2)`` without a word (issue 35 item 6). The binding refuses float
index arrays outright (a ``ParameterTypeError``); the Python helpers, which took floats before
(meshio hands some formats' cells over as floats), take whole floats and refuse the rest, naming
the element.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from ._palpate import ParameterError


def whole_indices(values, what: str, cols: Optional[int] = None, error: Callable[[str], Exception] = ParameterError) -> np.ndarray:
    """``values`` as an int64 array, refused with ``error`` (an exception class, or a function
    making one from the message) naming ``what[row, col]`` if
    any value is not a whole number (1.5, NaN, inf) or, with ``cols``, if the shape is not
    ``(m, cols)``."""
    a = np.asarray(values)
    if cols is not None and a.size == 0:
        return np.zeros((0, cols), dtype=np.int64)
    if cols is not None and (a.ndim != 2 or a.shape[1] != cols):
        raise error(f"{what} must have shape (m, {cols}), got {a.shape}")
    if a.dtype.kind in "iu":
        return a.astype(np.int64)
    if a.dtype.kind == "b" or a.dtype.kind not in "f":
        raise error(f"{what} must hold integer indices, got dtype {a.dtype}")
    bad = np.flatnonzero(~(np.isfinite(a) & (a == np.round(a))).ravel())
    if len(bad):
        where = np.unravel_index(bad[0], a.shape)
        at = ", ".join(str(int(i)) for i in where)
        raise error(f"{what}[{at}] = {float(a[where])!r} is not a whole number: an index must be one "
                    f"({len(bad)} such value{'s' if len(bad) > 1 else ''}; it would have been truncated)")
    return a.astype(np.int64)
