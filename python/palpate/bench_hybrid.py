"""Kept for old imports: ``palpate bench hybrid``'s benchmark now lives in :mod:`palpate.bench.hybrid`
(issue 36: the benchmarks in one place). Import from there; this module re-exports its names."""
from .bench.hybrid import *  # noqa: F401,F403
from .bench.hybrid import _defaults, _p, _stats_ms  # noqa: F401
