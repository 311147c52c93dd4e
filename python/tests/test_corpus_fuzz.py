"""Randomised mutation fuzzing of palpate's own Python readers and the readers it wraps (VTU
through meshio, NPZ through numpy) (issue 15, issue 35; cargo-fuzz covers the Rust model-file and
recording loaders, the bridge's decoders and the validators, fuzz/): inputs derived from valid files (truncations,
byte edits, duplicated or dropped lines, inflated, negative or NaN numbers) must load or raise a
palpate error, never another exception, each within 2 s.

Seeded, so a run is reproducible: FUZZ_EXAMPLES (default 150 per target) sets the effort and
FUZZ_SEED the seed, e.g. ``FUZZ_EXAMPLES=5000 FUZZ_SEED=7 pytest python/tests/test_corpus_fuzz.py``
for a longer run on demand; FUZZ_SECONDS instead runs each target for that long and prints the
number of inputs it ran (``FUZZ_SECONDS=600 pytest -s -k vtu ...``: the 10-minute runs of
RELIABILITY.md). A failure prints the input's bytes; it then becomes a case of
corpus_cases.py. (No Hypothesis: it is not among the project's pinned dependencies.)
"""
import os
import random
import struct
import time
import warnings

import numpy as np
import pytest

import palpate
from palpate import _readers
from palpate.vtp import read_vtp, write_vtp

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "150"))
SEED = int(os.environ.get("FUZZ_SEED", "15"))
SECONDS = float(os.environ.get("FUZZ_SECONDS", "0"))

GMSH2 = """$MeshFormat
2.2 0 8
$EndMeshFormat
$Nodes
5
1 0 0 0
2 1 0 0
3 0 1 0
4 0 0 1
5 1 1 1
$EndNodes
$Elements
2
1 4 2 0 1 1 2 3 4
2 4 2 0 1 2 3 4 5
$EndElements
"""
GMSH4 = """$MeshFormat
4.1 0 8
$EndMeshFormat
$Nodes
1 4 1 4
3 1 0 4
1
2
3
4
0 0 0
1 0 0
0 1 0
0 0 1
$EndNodes
$Elements
1 1 1 1
3 1 4 1
1 1 2 3 4
$EndElements
"""
GMSH40 = """$MeshFormat
4 0 8
$EndMeshFormat
$Nodes
2 4
1 0 0 1
1 0 0 0
1 3 0 3
2 1 0 0
3 0 1 0
4 0 0 1
$EndNodes
$Elements
1 1
1 3 4 1
1 1 2 3 4
$EndElements
"""
NODE = "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n"
ELE = "1 4 0\n1 1 2 3 4\n"
OFF = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
PLY = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")


def mutated(rng: random.Random, seed: bytes) -> bytes:
    """``seed`` edited: cut, bytes replaced, a line duplicated or dropped, a number inflated."""
    data = bytearray(seed)
    for _ in range(rng.randint(1, 4)):
        op = rng.choice(["cut", "byte", "dup", "drop", "big", "neg", "nan"])
        if not data:
            break
        i = rng.randrange(len(data))
        if op == "cut":
            del data[i:]
        elif op == "byte":
            data[i] = rng.randrange(256)
        else:
            lines = bytes(data).split(b"\n")
            k = rng.randrange(len(lines))
            if op == "dup":
                lines.insert(k, lines[k])
            elif op == "drop":
                del lines[k]
            else:
                toks = lines[k].split(b" ")
                j = rng.randrange(len(toks))
                toks[j] = {"big": b"100000000000", "neg": b"-7", "nan": b"nan"}[op]
                lines[k] = b" ".join(toks)
            data = bytearray(b"\n".join(lines))
    return bytes(data)


def fuzz(name, make_input, run):
    """EXAMPLES inputs (or as many as FUZZ_SECONDS allows) from ``make_input(rng)`` through
    ``run(input)``: each must return or raise a PalpateError, within 2 s."""
    rng = random.Random(f"{SEED}-{name}")
    start = time.monotonic()
    k = 0
    while (time.monotonic() - start < SECONDS) if SECONDS > 0 else k < EXAMPLES:
        k += 1
        x = make_input(rng)
        t0 = time.perf_counter()
        try:
            _expect_palpate(lambda: run(x))
        except Exception as e:
            raise AssertionError(f"{name} example {k}: {type(e).__name__}: {e}; input {x!r}"[:3000]) from e
        assert time.perf_counter() - t0 < 2.0, f"{name} example {k} took {time.perf_counter() - t0:.1f} s; input {x!r}"[:3000]
    if SECONDS > 0:
        print(f"\nfuzz {name}: {k} inputs in {time.monotonic() - start:.0f} s, seed {SEED}, no failure")


def _expect_palpate(call):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            call()
        except palpate.PalpateError:
            pass


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def test_gmsh_reader(folder):
    seeds = [GMSH2.encode(), GMSH4.encode(), GMSH40.encode()]
    path = str(folder / "f.msh")
    fuzz("gmsh", lambda rng: mutated(rng, rng.choice(seeds)),
         lambda d: (open(path, "wb").write(d), palpate.load_mesh(path)))


def test_gmsh_binary_reader(folder):
    """palpate's binary MSH 2.2 / 4.0 / 4.1 reader (issue 35 item 6: meshio's wrapped node tags)."""
    import corpus_cases

    tets = [(1, 2, 3, 4), (5, 2, 4, 3)]
    seeds = [corpus_cases._gmsh22_binary(corpus_cases._TWO_TETS, tets), corpus_cases._gmsh41_binary(corpus_cases._TWO_TETS, tets),
             corpus_cases._gmsh40_binary(corpus_cases._TWO_TETS, tets)]
    path = str(folder / "b.msh")
    fuzz("gmsh_binary", lambda rng: mutated(rng, rng.choice(seeds)),
         lambda d: (open(path, "wb").write(d), palpate.load_mesh(path)))


def test_tetgen_reader(folder):
    node, ele = str(folder / "t.node"), str(folder / "t.ele")

    def run(pair):
        open(node, "wb").write(pair[0])
        open(ele, "wb").write(pair[1])
        palpate.load_mesh(node)
    fuzz("tetgen", lambda rng: (mutated(rng, NODE.encode()), mutated(rng, ELE.encode())), run)


@pytest.mark.parametrize("ext,seed", [(".off", OFF), (".ply", PLY)])
def test_off_ply_readers(folder, ext, seed):
    path = str(folder / f"s{ext}")
    fuzz(ext, lambda rng: mutated(rng, seed.encode()), lambda d: (open(path, "wb").write(d), palpate.load_surface(path)))


def test_vtp_reader(folder):
    s = palpate.ellipsoid_surface((0.01, 0.01, 0.02), 1)
    seeds = []
    for fmt, comp in (("ascii", False), ("binary", True), ("binary", False), ("appended", True)):
        p = folder / f"seed_{fmt}_{comp}.vtp"
        write_vtp(p, s.points, s.triangles, fmt=fmt, compress=comp)
        seeds.append(p.read_bytes())
    path = str(folder / "s.vtp")

    def make(rng):
        data = bytearray(rng.choice(seeds))
        for _ in range(rng.randint(0, 6)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        return bytes(data[: max(1, int(len(data) * rng.uniform(0.5, 1.0)))])
    fuzz("vtp", make, lambda d: (open(path, "wb").write(d), read_vtp(path)))


def test_binary_stl_count(folder):
    path = str(folder / "s.stl")
    fuzz("stl", lambda rng: b"\0" * 80 + struct.pack("<I", rng.randrange(2**32)) + rng.randbytes(rng.randrange(300)),
         lambda d: (open(path, "wb").write(d), palpate.load_surface(path)))


def test_sizes_parse_like_the_core():
    """PALPATE_MAX_MEMORY is read the same way in Python as in Rust (limits::parse_size)."""
    assert _readers.parse_size("1G") == 1 << 30 and _readers.parse_size("512M") == 512 << 20
    assert _readers.parse_size("2GiB") == 2 << 30 and _readers.parse_size("1e9") == 10**9
    assert _readers.parse_size("-1") is None and _readers.parse_size("lots") is None and _readers.parse_size("") is None


def test_budget_refuses_with_the_numbers(monkeypatch):
    monkeypatch.setenv("PALPATE_MAX_MEMORY", "1M")
    with pytest.raises(palpate.LimitError, match="PALPATE_MAX_MEMORY") as e:
        _readers.check_budget("a test array", 2 << 20, "x.msh")
    assert e.value.requested == 2 << 20 and e.value.budget == 1 << 20 and "x.msh" in str(e.value)
    monkeypatch.setenv("PALPATE_MAX_MEMORY", "2G")
    _readers.check_budget("a test array", 2 << 20, "x.msh")


def test_budget_reaches_the_core(monkeypatch):
    """The Rust core reads the same variable: a 64-particle body's neighbour lists under a
    40-byte budget are refused with a LimitError, and pass under the default."""
    pts = np.mgrid[0:4, 0:4, 0:4].reshape(3, -1).T * 1e-3
    monkeypatch.setenv("PALPATE_MAX_MEMORY", "40")
    with pytest.raises(palpate.LimitError, match="neighbour pairs"):
        palpate.neighbours(pts, 2.5e-3)
    monkeypatch.delenv("PALPATE_MAX_MEMORY")
    palpate.neighbours(pts, 2.5e-3)


def _tet_arrays():
    m = palpate.box_mesh((0.01, 0.01, 0.01), (2, 1, 1))
    return np.asarray(m.points), np.asarray(m.tets)


def _byte_edits(rng, seeds):
    """One of ``seeds`` with up to 6 bytes replaced, then cut to 50-100% of its length."""
    data = bytearray(rng.choice(seeds))
    for _ in range(rng.randint(0, 6)):
        data[rng.randrange(len(data))] = rng.randrange(256)
    return bytes(data[: max(1, int(len(data) * rng.uniform(0.5, 1.0)))])


def test_vtu_reader(folder):
    # meshio's VTU reader behind palpate's checks (issue 35 item 8): ASCII, binary and
    # zlib-compressed binary seeds, byte edits and truncations (a size field inflated, a header cut,
    # a compressed block damaged).
    import meshio

    points, tets = _tet_arrays()
    seeds = []
    for k, kw in enumerate(({"binary": False}, {"binary": True, "compression": None}, {"binary": True, "compression": "zlib"})):
        p = folder / f"seed_{k}.vtu"
        meshio.write(p, meshio.Mesh(points, [("tetra", tets)]), file_format="vtu", **kw)
        seeds.append(p.read_bytes())
        palpate.load_mesh(str(p))                 # the seeds themselves load
    path = str(folder / "s.vtu")
    fuzz("vtu", lambda rng: _byte_edits(rng, seeds) if rng.random() < 0.7 else mutated(rng, rng.choice(seeds)),
         lambda d: (open(path, "wb").write(d), palpate.load_mesh(path)))


def test_npz_reader(folder):
    # palpate's NPZ reader (issue 35 item 8): compressed and stored archives, byte edits and
    # truncations (the zip directory, a member's .npy header, its data).
    points, tets = _tet_arrays()
    seeds = []
    for k, save in enumerate((np.savez, np.savez_compressed)):
        p = folder / f"seed_{k}.npz"
        save(p, points=points, tets=tets)
        seeds.append(p.read_bytes())
        palpate.load_mesh(str(p))
    path = str(folder / "s.npz")
    fuzz("npz", lambda rng: _byte_edits(rng, seeds), lambda d: (open(path, "wb").write(d), palpate.load_mesh(path)))
