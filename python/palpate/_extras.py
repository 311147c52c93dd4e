"""How to install an optional part of palpate (an *extra*), said so that it works.

palpate is installed from a wheel or a source checkout, not from PyPI, so the usual
``pip install 'palpate[plot]'`` would look for another package there. The installed
distribution's metadata lists each extra's packages; the hint names them as pip reads them
(``pip install 'matplotlib>=3.8'``), and the extra for a checkout (``pip install -e 'python[plot]'``).
"""
from __future__ import annotations

import re
from typing import List


def extra_packages(extra: str) -> List[str]:
    """The requirements of ``extra`` in the installed palpate's metadata (``[]`` if none or no
    metadata), e.g. ``["matplotlib>=3.8"]`` for ``"plot"``."""
    try:
        from importlib.metadata import PackageNotFoundError, requires
    except ImportError:  # pragma: no cover (Python >= 3.8 has it)
        return []
    try:
        reqs = requires("palpate") or []
    except PackageNotFoundError:
        return []
    out = []
    for r in reqs:
        spec, _, marker = r.partition(";")
        if re.search(r"""extra\s*==\s*['"]%s['"]""" % re.escape(extra), marker):
            out.append(spec.strip().replace(" ", ""))
    return out


def install_hint(extra: str) -> str:
    """The command that installs ``extra``: ``pip install 'PKG' ...`` (the ``EXTRA`` extra; from a
    source checkout: ``pip install -e 'python[EXTRA]'``)."""
    pkgs = extra_packages(extra)
    checkout = f"pip install -e 'python[{extra}]'"
    if not pkgs:
        return f"{checkout} from a source checkout, or install the wheel with [{extra}]"
    return "pip install " + " ".join(f"'{p}'" for p in pkgs) + f" (the {extra} extra; from a source checkout: {checkout})"
