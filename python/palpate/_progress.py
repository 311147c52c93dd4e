"""Progress display for long work (downloads, model builds, sweeps, benchmarks): a ``rich``
progress bar (a spinner with the elapsed time when the amount of work is unknown) on stderr when
stderr is a terminal, nothing otherwise (logs, pipes, CI, ``--quiet``). ``rich`` comes with
meshio, a core dependency; without it the display is simply off."""
from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from typing import Callable, Iterator, Optional


#: Set by a command's ``--quiet`` (:func:`set_quiet`): no display in this process, also for work
#: nested in the command (a download inside a model build) that does not know of the flag.
_quiet = False


def set_quiet(quiet: bool) -> None:
    """Silence (or not) every progress display of this process (the CLI's ``--quiet``)."""
    global _quiet
    _quiet = bool(quiet)


def shown(quiet: bool = False) -> bool:
    """Whether progress is displayed: not ``quiet`` (nor :func:`set_quiet`), stderr a terminal, and
    ``TERM`` not ``dumb``."""
    if quiet or _quiet or os.environ.get("TERM") == "dumb":
        return False
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):   # a replaced or closed stderr
        return False


@contextmanager
def task(description: str, total: Optional[int] = None, quiet: bool = False,
         eta: bool = False) -> Iterator[Callable[..., None]]:
    """``with task("building", total=n) as advance: ... advance(1)``: a bar over ``total`` units
    (or a spinner if None) on a terminal; ``advance`` is a no-op otherwise. ``eta``: also the
    estimated time left; ``advance(k, description)`` replaces the description."""
    if not shown(quiet):
        yield lambda k=1, description=None: None
        return
    try:
        from rich.console import Console
        from rich.progress import (BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn,
                                   TimeElapsedColumn, TimeRemainingColumn)
    except ImportError:
        yield lambda k=1, description=None: None
        return
    cols = [SpinnerColumn(), TextColumn("{task.description}")]
    if total is not None:
        cols += [BarColumn(), MofNCompleteColumn()]
    cols.append(TimeElapsedColumn())
    if eta and total is not None:
        cols.append(TimeRemainingColumn())
    with Progress(*cols, console=Console(stderr=True), transient=True) as p:
        t = p.add_task(description, total=total)

        def advance(k: int = 1, description: Optional[str] = None) -> None:
            if description is not None:
                p.update(t, description=description)
            p.advance(t, k)
        yield advance
