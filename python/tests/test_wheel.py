"""The release wheel as a user gets it (issue 16, item 2): `make wheel` builds it into dist/
(`make test` does so before pytest); this installs it into a clean venv, on the oldest CPython
the package supports when the machine has it, and runs the demo from outside the source tree.

What a wrong build would do: a manylinux_2_34 or version-specific tag, debug info left in the
extension (13 MB instead of 2), a wheel without the licences, or one that only works beside the
source tree (an import of the in-tree package, a file read relative to the repository, a
dependency on an extra such as matplotlib) fails here."""
import glob
import os
import re
import shutil
import struct
import subprocess
import sys
import zipfile

import pytest

from conftest import REPO

DIST = REPO / "dist"


def _wheel():
    wheels = sorted(DIST.glob("palpate-*.whl"), key=lambda p: p.stat().st_mtime)
    if not wheels:
        pytest.skip("no wheel in dist/: run `make wheel` (make test does)")
    return wheels[-1]


def _elf_sections(data: bytes):
    """Section names of a little-endian ELF64 file (the header fields of the ELF spec)."""
    assert data[:4] == b"\x7fELF" and data[4] == 2 and data[5] == 1
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x3A)
    def header(i):
        name, _type, _flags, _addr, offset, size = struct.unpack_from("<IIQQQQ", data, shoff + i * shentsize)
        return name, offset, size
    _, stroff, strsize = header(shstrndx)
    table = data[stroff:stroff + strsize]
    return {table[n:table.index(b"\0", n)].decode() for n, _, _ in map(header, range(shnum))}


def _oldest_python():
    """CPython 3.9 (the oldest the package supports) if the machine has one that runs, else this one."""
    for cand in [shutil.which("python3.9"), *sorted(glob.glob(os.path.expanduser("~/.pyenv/versions/3.9*/bin/python3.9")))]:
        if cand and subprocess.run([cand, "-c", "import venv"], capture_output=True).returncode == 0:
            return cand
    return sys.executable


def test_wheel_tags_size_and_licences():
    whl = _wheel()
    m = re.match(r"palpate-[^-]+-(cp\d+)-(abi3)-manylinux_2_(\d+)_x86_64\.whl$", whl.name)
    assert m, f"{whl.name}: expected an abi3 manylinux wheel"
    assert m.group(1) == "cp39" and int(m.group(3)) <= 28, whl.name
    with zipfile.ZipFile(whl) as z:
        names = z.namelist()
        so = [n for n in names if n.startswith("palpate/_palpate") and n.endswith(".so")]
        assert len(so) == 1
        ext = z.read(so[0])
        for lic in ("LICENSE-MIT", "LICENSE-APACHE", "NOTICE"):
            assert any(n.endswith(f".dist-info/licenses/{lic}") for n in names), lic
        assert "palpate/py.typed" in names and "palpate/_palpate.pyi" in names
        meta = z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    # Stripped: no DWARF sections, and a few MB (13 MB with the release profile's debug info).
    sections = _elf_sections(ext)
    assert ".text" in sections and not {n for n in sections if n.startswith(".debug")}, sections
    assert ".symtab" not in sections, "symbols not stripped"
    # 5.8 MB since large factorisations are faer's (linalg/supernodal.rs; under 5 MB before).
    assert len(ext) < 8e6, f"extension is {len(ext) / 1e6:.1f} MB"
    assert "License-Expression: MIT OR Apache-2.0" in meta
    requires = [l for l in meta.splitlines() if l.startswith("Requires-Dist:") and "extra ==" not in l]
    assert {r.split()[1].split(">")[0] for r in requires} == {"numpy", "meshio", "tomli"}


def test_wheel_installs_in_a_clean_venv_and_runs_the_demo(tmp_path):
    whl = _wheel()
    python = _oldest_python()
    venv = tmp_path / "venv"
    subprocess.run([python, "-m", "venv", str(venv)], check=True)
    py = venv / "bin" / "python"
    r = subprocess.run([str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check", str(whl)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    run = tmp_path / "elsewhere"
    run.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["MPLBACKEND"] = "Agg"
    if (REPO / "data").is_dir():          # the cached Rodero files: no download in the test
        env["PALPATE_DATA"] = str((REPO / "data").resolve())
    where = subprocess.run([str(py), "-c", "import palpate, sys; print(palpate.__file__); "
                            "print('matplotlib' in sys.modules)"],
                           cwd=run, env=env, capture_output=True, text=True, check=True).stdout.split()
    assert where[0].startswith(str(venv)), where   # the installed package, not the source tree
    r = subprocess.run([str(py), "-m", "palpate.demo", "--steps", "50", "--hybrid-ticks", "0", "--no-plot",
                        "--out", str(run / "out")], cwd=run, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    assert "steps/s" in r.stdout and "Traceback" not in r.stderr
