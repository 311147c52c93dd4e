"""Kept for old imports: ``palpate bench sweep``'s benchmark now lives in :mod:`palpate.bench.sweep`
(issue 36: the benchmarks in one place). Import from there; this module re-exports its names."""
from ..bench.sweep import *  # noqa: F401,F403
from ..bench.sweep import _bare_two, _half  # noqa: F401
