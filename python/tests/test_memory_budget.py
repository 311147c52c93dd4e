"""Issue 35 item 4: the memory budget follows the real limits of the process (its address-space
limit RLIMIT_AS, its cgroup's memory limit, the memory available; half of the smallest), so an
oversized input ends in a typed palpate.LimitError naming the file and the budget's source,
before anything is allocated: never a signal (SIGABRT from a Rust allocation failure, SIGKILL
from the OOM killer) and never a MemoryError.

The limit is real: each case runs in a child process whose RLIMIT_AS is set to 2 GiB before
Python imports palpate, with PALPATE_MAX_MEMORY unset. The inputs are a few MB at most and
claim (and, for the compressed ones, would truly inflate to) 3 GiB or more.
"""
import io
import json
import os
import resource
import signal
import struct
import subprocess
import sys
import textwrap
import zipfile
import zlib

import numpy as np
import pytest

import palpate
from palpate import _readers

LIMIT = 2 << 30  # the child's RLIMIT_AS [bytes]
BIG = 3 << 30    # what each bomb inflates to [bytes]: over the limit, not only over the budget
BLOCK = 32 << 20  # a VTK compressed block [bytes]; one block compressed, repeated


def _limit_as():
    resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))


def _env(**extra):
    env = {k: v for k, v in os.environ.items() if k != "PALPATE_MAX_MEMORY"}
    env.update(extra)
    return env


def run_child(code: str, limit=True, **env):
    """Run ``code`` in a fresh interpreter (RLIMIT_AS = 2 GiB when ``limit``), which must print
    one JSON line: its outcome. Returns (returncode, outcome or None, stderr)."""
    script = textwrap.dedent("""
        import json, sys, traceback
        import numpy as np
        import palpate
        try:
            value = (lambda: ({code}))()
            out = {{"outcome": "ok", "value": value}}
        except palpate.PalpateError as e:
            out = {{"outcome": "error", "type": type(e).__name__, "message": str(e),
                   "budget": getattr(e, "budget", None), "budget_source": getattr(e, "budget_source", None)}}
        except BaseException as e:
            out = {{"outcome": "untyped", "type": type(e).__name__, "message": str(e)[:2000]}}
        print(json.dumps(out))
    """).format(code=code)
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                       preexec_fn=_limit_as if limit else None, env=_env(**env))
    line = p.stdout.strip().splitlines()[-1] if p.stdout.strip() else ""
    return p.returncode, (json.loads(line) if line.startswith("{") else None), p.stderr


def assert_refused(rc, out, err, name, words=()):
    assert rc == 0, f"killed by signal {-rc} ({signal.Signals(-rc).name})" if rc < 0 else f"exit {rc}: {err[-2000:]}"
    assert out is not None, err[-2000:]
    assert out["outcome"] == "error" and out["type"] == "LimitError", out
    msg = out["message"]
    assert msg.startswith(f"{name}:"), msg
    assert "RLIMIT_AS" in msg and "memory budget" in msg and "PALPATE_MAX_MEMORY" in msg, msg
    assert "RLIMIT_AS" in out["budget_source"] and out["budget"] < LIMIT // 2, out
    for w in words:
        assert w in msg, (w, msg)


# ---------------------------------------------------------------------------------------------
# The budget itself
# ---------------------------------------------------------------------------------------------

def test_memory_budget_reads_this_machine():
    budget, source = palpate.memory_budget()
    assert isinstance(budget, int) and budget > 0 and isinstance(source, str) and source
    if sys.platform.startswith("linux") and "PALPATE_MAX_MEMORY" not in os.environ:
        assert "x 0.5" in source, source
        assert budget <= 0.5 * _mem_available() * 1.05 + (64 << 20), (budget, source)
    assert _readers.max_memory() > 0


def _mem_available():
    with open("/proc/meminfo") as fh:
        for line in fh:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return float("inf")


def test_budget_follows_rlimit_as_and_the_variable_overrides():
    rc, out, err = run_child("palpate.memory_budget()")
    assert rc == 0 and out["outcome"] == "ok", (rc, out, err)
    budget, source = out["value"]
    # Half of (2 GiB less what the interpreter has mapped).
    assert "RLIMIT_AS (2.0 GiB)" in source and "already mapped" in source and "x 0.5" in source, source
    assert (LIMIT // 8) < budget < LIMIT // 2, (budget, source)
    rc, out, err = run_child("palpate.memory_budget()", PALPATE_MAX_MEMORY="123M")
    assert rc == 0 and out["value"] == [123 << 20, "PALPATE_MAX_MEMORY=123M"], (rc, out, err)
    # Unreadable: ignored, the limits rule.
    rc, out, err = run_child("palpate.memory_budget()", PALPATE_MAX_MEMORY="lots")
    assert rc == 0 and "RLIMIT_AS" in out["value"][1], (rc, out, err)


# ---------------------------------------------------------------------------------------------
# Compressed VTK XML: a few MB that inflate to 3 GiB, over the child's whole address space
# ---------------------------------------------------------------------------------------------

def _zlib_bomb():
    """(header, body) of a vtkZLibDataCompressor array inflating to BIG bytes (UInt64 header)."""
    comp = zlib.compress(b"\0" * BLOCK, 9)  # ~32 KB
    n = BIG // BLOCK
    header = struct.pack("<QQQ", n, BLOCK, BLOCK) + struct.pack("<Q", len(comp)) * n
    return header, comp * n


def _vtk_bomb(path, kind):
    import base64
    header, body = _zlib_bomb()
    grid, cells = ("UnstructuredGrid", "Cells") if kind == "vtu" else ("PolyData", "Polys")
    ncells = 'NumberOfCells="1"' if kind == "vtu" else 'NumberOfPolys="1"'
    types = '<DataArray type="UInt8" Name="types" format="ascii">10</DataArray>' if kind == "vtu" else ""
    # The VTU: the points appended, raw; the VTP: inline, base64 (the two layouts of the readers).
    if kind == "vtu":
        points = '<DataArray type="Float64" NumberOfComponents="3" format="appended" offset="0"/>'
        tail = b'<AppendedData encoding="raw">_' + header + body + b"</AppendedData>\n"
    else:
        b64 = base64.b64encode(header).decode() + base64.b64encode(body).decode()
        points = f'<DataArray type="Float64" NumberOfComponents="3" format="binary">{b64}</DataArray>'
        tail = b""
    xml = f"""<?xml version="1.0"?>
<VTKFile type="{grid}" version="1.0" byte_order="LittleEndian" header_type="UInt64" compressor="vtkZLibDataCompressor">
<{grid}><Piece NumberOfPoints="{BIG // 24}" {ncells}>
<Points>{points}</Points>
<{cells}><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4</DataArray>{types}</{cells}>
</Piece></{grid}>
"""
    with open(path, "wb") as fh:
        fh.write(xml.encode() + tail + b"</VTKFile>\n")
    assert os.path.getsize(path) < 8 << 20


@pytest.mark.parametrize("kind", ["vtu", "vtp"])
def test_compressed_vtk_over_the_address_space_is_a_limit_error(tmp_path, kind):
    path = tmp_path / f"bomb.{kind}"
    _vtk_bomb(path, kind)
    load = f"palpate.load_mesh({str(path)!r})" if kind == "vtu" else f"palpate.load_surface({str(path)!r}, unit='mm')"
    rc, out, err = run_child(load)
    assert_refused(rc, out, err, f"bomb.{kind}", ["inflates to"])


def test_cli_info_on_a_vtu_bomb_is_a_limit_error(tmp_path):
    path = tmp_path / "bomb.vtu"
    _vtk_bomb(path, "vtu")
    p = subprocess.run([sys.executable, "-m", "palpate", "info", str(path)], capture_output=True, text=True,
                       timeout=300, preexec_fn=_limit_as, env=_env())
    assert p.returncode == 1, (p.returncode, p.stderr[-2000:])
    assert "LimitError" in p.stderr and "bomb.vtu" in p.stderr and "RLIMIT_AS" in p.stderr, p.stderr[-2000:]
    assert "Traceback" not in p.stderr, p.stderr[-2000:]


# ---------------------------------------------------------------------------------------------
# NPZ: the .npy headers are read before numpy allocates from them
# ---------------------------------------------------------------------------------------------

def _npy_header(shape, dtype="<f8"):
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False, "shape": shape})
    return buf.getvalue()


def _npz(path, members):
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)


def test_npz_header_claiming_1e10_rows_is_refused_before_numpy(tmp_path):
    # 'points' claims 1e10 x 3 float64 (240 GB) in a member of a few hundred bytes; the zip
    # directory's size (the header's 128 bytes) is honest, so only the header shows it.
    path = tmp_path / "rows.npz"
    _npz(path, {"points.npy": _npy_header((10**10, 3)), "tets.npy": _npy_header((1, 4), "<i8") + b"\0" * 32})
    assert os.path.getsize(path) < 1000
    with pytest.raises(palpate.LimitError) as e:
        palpate.load_mesh(path)
    msg = str(e.value)
    assert msg.startswith("rows.npz:") and "'points.npy'" in msg and "10000000000 x 3" in msg, msg
    assert e.value.budget_source and e.value.budget_source in msg, msg
    # And under a real 2 GiB limit, in a child: the same typed error, not a MemoryError.
    rc, out, err = run_child(f"palpate.load_mesh({str(path)!r})")
    assert_refused(rc, out, err, "rows.npz", ["'points.npy'", "10000000000 x 3"])


def test_npz_header_claiming_more_than_its_member_holds_is_a_mesh_error(tmp_path):
    # Under the budget (1e6 rows, 24 MB) but the member holds 48 bytes: numpy would allocate the
    # 24 MB and then fail; refused from the header with the member and both sizes.
    path = tmp_path / "short.npz"
    _npz(path, {"points.npy": _npy_header((10**6, 3)) + b"\0" * 48, "tets.npy": _npy_header((1, 4), "<i8") + b"\0" * 32})
    with pytest.raises(palpate.MeshError, match=r"short.npz: member 'points.npy'.*1000000 x 3.*holds 48 bytes"):
        palpate.load_mesh(path)


@pytest.mark.parametrize("header", [b"\x93NUMPY\x01\x00\x10\x00{'descr': 'junk'", b"garbage", b"\x93NUMPY\x09\x00"])
def test_npz_garbage_header_is_a_mesh_error(tmp_path, header):
    path = tmp_path / "junk.npz"
    _npz(path, {"points.npy": header, "tets.npy": _npy_header((1, 4), "<i8") + b"\0" * 32})
    with pytest.raises(palpate.MeshError, match=r"junk.npz: "):
        palpate.load_mesh(path)


def test_npz_valid_loads(tmp_path):
    path = tmp_path / "ok.npz"
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    np.savez_compressed(path, points=pts, tets=np.array([[0, 1, 2, 3]]))
    mesh = palpate.load_mesh(path)
    assert mesh.n_nodes == 4


# ---------------------------------------------------------------------------------------------
# Particles: an all-pairs neighbourhood (support radius larger than the body)
# ---------------------------------------------------------------------------------------------

ALL_PAIRS = """(lambda n: palpate.ParticleBody(
    np.stack(np.meshgrid(*[np.arange(n) * 1e-3] * 3, indexing="ij"), -1).reshape(-1, 3),
    np.full(n ** 3, 1e-6), palpate.Material(young=1e4, poisson=0.4, density=1000.0),
    support_radius=1.0).n_pairs)(16)"""


def test_particle_all_pairs_is_a_limit_error_not_sigabrt():
    # 4096 particles 1 mm apart with a 1 m support: 16.8 M pairs, 2.3 GB at 136 bytes a pair,
    # over the child's 2 GiB address space (with the old fixed 8 GiB budget: SIGABRT).
    rc, out, err = run_child(ALL_PAIRS)
    assert rc == 0, f"killed by signal {-rc}" if rc < 0 else err[-2000:]
    assert out["outcome"] == "error" and out["type"] == "LimitError", out
    assert "neighbour pairs of 4096 particles" in out["message"] and "RLIMIT_AS" in out["message"], out


def test_npz_corrupt_member_is_a_mesh_error(tmp_path):
    # A deflated member whose compressed bytes are garbage: zlib.error while reading the header.
    path = tmp_path / "corrupt.npz"
    _npz(path, {"points.npy": _npy_header((4, 3)) + b"\0" * 96, "tets.npy": _npy_header((1, 4), "<i8") + b"\0" * 32})
    raw = bytearray(path.read_bytes())
    start = raw.index(b"points.npy") + len(b"points.npy")  # the local header's name, then the data
    raw[start:start + 40] = b"\xff" * 40
    path.write_bytes(bytes(raw))
    with pytest.raises(palpate.MeshError, match=r"corrupt.npz: member 'points.npy': not a valid .npy header \(error: "):
        palpate.load_mesh(path)
