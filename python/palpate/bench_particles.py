"""Kept for old imports: ``palpate bench particles``'s benchmark now lives in :mod:`palpate.bench.particles`
(issue 36: the benchmarks in one place). Import from there; this module re-exports its names."""
from .bench.particles import *  # noqa: F401,F403
from .bench.particles import _FILLS, _p  # noqa: F401
