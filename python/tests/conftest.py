"""Shared fixtures: the repository root and the project's shared folder (bench meshes).

The shared folder is found as $PALPATE_SHARED, else <repo>/../shared; tests that need it are
skipped with a reason when it is absent.
"""
import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
DATA = Path(__file__).resolve().parent / "data"


def find_shared():
    env = os.environ.get("PALPATE_SHARED")
    for c in ([Path(env)] if env else []) + [REPO.parent / "shared"]:
        if (c / "bench" / "meshes").is_dir():
            return c.resolve()
    return None


SHARED = find_shared()
needs_shared = pytest.mark.skipif(
    SHARED is None, reason="shared folder with bench/meshes not found (set PALPATE_SHARED or put it at <repo>/../shared)"
)


@pytest.fixture(scope="session")
def shared():
    if SHARED is None:
        pytest.skip("shared folder with bench/meshes not found (set PALPATE_SHARED or put it at <repo>/../shared)")
    return SHARED


@pytest.fixture
def unit_tet():
    """One right-handed unit tet: points (4, 3) [m], tets (1, 4)."""
    return np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]])


@pytest.fixture
def material():
    import palpate
    return palpate.Material(young=3.0e4, poisson=0.4, density=1000.0)
