"""Shared fixtures and checks: the repository root and the project's shared folder (bench meshes),
the Rodero LV file, a unit tet, a material; the check of a malformed-file corpus entry and the
measure of how much Python ran during a call (GIL release).

The shared folder is found as $PALPATE_SHARED, else <repo>/../shared; tests that need it are
skipped with a reason when it is absent.
"""
import os
import threading
import time
import warnings
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


@pytest.fixture(scope="session")
def lv_path():
    """The Rodero et al. left ventricle (palpate.data), skipped when not cached and not downloadable."""
    from palpate import data
    try:
        return data.rodero_lv_path()
    except data.DataError as e:
        pytest.skip(f"Rodero LV not cached in {data.data_dir()} and the download failed: {e}")


def python_work_during(call):
    """Run ``call()`` in a thread and count loop iterations of pure Python (which need the GIL)
    meanwhile: ``(count, wall time of the call [s])``. A call that holds the GIL throughout leaves
    the count at a handful."""
    started, done = threading.Event(), {}

    def work():
        started.set()
        t0 = time.perf_counter()
        call()
        done["wall"] = time.perf_counter() - t0

    th = threading.Thread(target=work)
    th.start()
    started.wait()
    count = 0
    while th.is_alive():
        count += 1   # pure Python work: needs the GIL
    th.join()
    return count, done["wall"]


def check_corpus_entry(name, exp, load, base):
    """One entry ``exp`` of a malformed-file corpus (an EXPECTED.toml table): with warnings as
    errors, ``load()`` raises ``exp["error"]`` (a subclass of ``base``) on one line naming the file
    and containing each of ``exp["contains"]``; or it warns ``exp["warning"]`` naming the file (and
    the contents) and returns an object of positive volume."""
    import palpate
    if "error" in exp:
        cls = getattr(palpate, exp["error"])
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(cls) as e:
                load()
        msg = str(e.value)
        assert isinstance(e.value, base)
        assert name in msg, f"message does not name the file: {msg}"
        for part in exp["contains"]:
            assert part in msg, f"{part!r} not in {msg!r}"
        assert "\n" not in msg
    else:
        cls = getattr(palpate, exp["warning"])
        with pytest.warns(cls) as rec:
            m = load()
        assert m.volume > 0
        msg = str(rec[0].message)
        assert name in msg
        for part in exp["contains"]:
            assert part in msg


@pytest.fixture
def chromium():
    """The path of a Chromium that Playwright can drive (the viewer's browser tests), or the test
    skipped with the reason (no Playwright, no browser)."""
    from palpate.viewer.browser import find_chromium, have_playwright

    ok, why = have_playwright()
    if not ok:
        pytest.skip(f"browser test skipped: {why}")
    exe, why = find_chromium()
    if exe is None:
        pytest.skip(f"browser test skipped: {why}")
    return exe


# --- SIGPIPE stays ignored for the whole session -------------------------------------------------
# Python ignores SIGPIPE (a write to a closed pipe or socket raises BrokenPipeError instead), and
# the viewer's and bridge's tests rely on it: they write to sockets whose peer has gone. Two
# clean-clone `.ci/run`s (2026-12-06, 2026-12-07) were killed by SIGPIPE in those tests, at 85%
# and 94% of the suite: something earlier in the process had set the signal's disposition back to
# the default (not Python code: no package here calls signal(SIGPIPE, ...); native code may). So
# each test starts with SIGPIPE ignored, and a test after which the real disposition (read with
# sigaction, which Python's signal.getsignal does not see) is no longer "ignore" is named in a
# warning, for whoever looks for the culprit.
import ctypes
import signal


def _sigpipe_ignored():
    """The real disposition of SIGPIPE is SIG_IGN (None where it cannot be read)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        buf = ctypes.create_string_buffer(256)           # struct sigaction; sa_handler first
        if libc.sigaction(signal.SIGPIPE, None, buf) != 0:
            return None
        return ctypes.c_void_p.from_buffer(buf).value == 1   # SIG_IGN
    except (OSError, AttributeError, ValueError):
        return None


@pytest.fixture(autouse=True)
def _keep_sigpipe_ignored(request):
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    yield
    if _sigpipe_ignored() is False:
        warnings.warn(f"{request.node.nodeid} left SIGPIPE's disposition at the default (reset to ignore)")
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGPIPE, signal.SIG_IGN)
