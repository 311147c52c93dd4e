"""Kept for old imports: ``palpate bench view``'s benchmark now lives in :mod:`palpate.bench.view`
(issue 36: the benchmarks in one place). Import from there; this module re-exports its names."""
from ..bench.view import *  # noqa: F401,F403
from ..bench.view import _drive, _p, _pick  # noqa: F401
