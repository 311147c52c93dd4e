"""Batch studies (``palpate sweep``, ``palpate fit``): many scenarios of one model, each a task on
Dask ``distributed`` (a ``LocalCluster`` on this machine, or any cluster), their outcomes one tidy
Parquet table.

    import palpate.sweep as ps
    r = ps.sweep("stiffness.toml", "out/stiffness")      # or a dict, or a Spec
    r.table.to_pandas()                                  # one row per scenario

:mod:`~palpate.sweep.spec` says what a study file holds, :mod:`~palpate.sweep.scenario` what a
row holds, :mod:`~palpate.sweep.runner` where it runs and what it writes, :mod:`~palpate.sweep.plot`
what its plot (``results.png``) shows, and
:mod:`~palpate.sweep.fit` how a measured curve gives a material. Needs the ``study`` extra
(the ``study`` extra: dask[distributed], pyarrow), except ``workers=0`` runs, which
need pyarrow only.
"""
from .runner import StudyResult, SweepError, sweep
from .spec import Spec, SweepSpecError, load_spec, spec_from_dict

__all__ = ["sweep", "StudyResult", "SweepError", "Spec", "SweepSpecError", "load_spec", "spec_from_dict"]
