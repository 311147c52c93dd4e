"""The malformed- and extreme-input corpus of issue 15 (test_corpus.py runs it): every reader, the
model file, the generators, the bodies and the command line, each case with its class in the
issue's table and the outcome it must have.

``make(folder)`` writes the input files into ``folder`` and returns the cases, each a dict:

- ``name``, ``klass`` (the issue's row: abort, panic, hang, bomb, silent, output, untyped, or
  ``mutation`` / ``seed`` for the generated reader cases), ``kind`` (``api`` or ``cli``);
- ``code`` (Python run with ``palpate``, ``np``, ``D`` = folder) or ``argv`` (``{D}`` = folder);
- ``expect``: the outcomes allowed: ``error`` (a PalpateError, optionally of ``types``),
  ``warning``, ``ok``; a CLI case expects an exit code in ``codes`` with one line on stderr.

Mutations are deterministic (seeded) truncations, byte flips and count inflations of valid seed
files and of the existing malformed-file corpora (data/malformed, data/malformed_surfaces).
"""
import os
import random
import shutil
import struct
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
TYPED = ["error", "warning", "ok"]
#: What a refusal of an oversized header count says: the readers' pre-checks against the file's
#: size ("the file has N", "more than a file of N bytes can hold") or the memory budget's
#: LimitError. Any other MeshError would mean the count was trusted and something failed later.
PRECHECK = ["the file has", "bytes can hold", "over the memory budget"]
MAGIC_LEN, HEADER = 16, 40


def _fnv(b):
    h = 0xcbf29ce484222325
    for x in b:
        h = ((h ^ x) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
    return h


def refresh_checksum(data: bytes) -> bytes:
    """A model file's bytes with the payload length and checksum made consistent again: a
    crafted file, which the checksum does not stop."""
    payload = data[HEADER:]
    return data[:24] + struct.pack("<QQ", len(payload), _fnv(payload)) + payload


class Corpus:
    def __init__(self, folder):
        self.folder = folder
        self.cases = []

    def path(self, name):
        return os.path.join(self.folder, name)

    def write(self, name, content):
        with open(self.path(name), "wb" if isinstance(content, bytes) else "w") as fh:
            fh.write(content)
        return name

    def api(self, name, klass, code, expect=("error",), types=None, budget="1G", names=None, contains=None):
        # contains: words the error message must hold (a string, or a list of which one will do),
        # where the type alone would not show that the right check refused: a pre-check before
        # building or before allocating, not a failure after it.
        self.cases.append({"name": name, "klass": klass, "kind": "api", "code": code, "expect": list(expect),
                           "types": types, "budget": budget, "names": names, "contains": contains})

    def cli(self, name, klass, argv, codes=(1,), expect_stdout=None, contains=None, budget="1G"):
        self.cases.append({"name": name, "klass": klass, "kind": "cli", "argv": list(argv), "codes": list(codes),
                           "expect_stdout": expect_stdout, "budget": budget, "contains": contains})


# ---------------------------------------------------------------------------------------------
# seeds: small valid files of every format
# ---------------------------------------------------------------------------------------------

def _seeds(c: Corpus):
    import meshio

    import palpate
    from palpate.vtp import write_vtp

    box = palpate.box_mesh((0.01, 0.01, 0.01), (2, 2, 2))
    pts, tets = box.points, box.tets
    mesh = meshio.Mesh(pts, [("tetra", tets)])
    seeds_mesh = {}
    meshio.write(c.path("seed.vtk"), mesh, binary=False)
    meshio.write(c.path("seed_bin.vtk"), mesh, binary=True)
    meshio.write(c.path("seed.vtu"), mesh)  # zlib-compressed binary
    meshio.write(c.path("seed22.msh"), mesh, file_format="gmsh22", binary=False)
    meshio.write(c.path("seed41.msh"), mesh, file_format="gmsh", binary=False)
    meshio.write(c.path("seed41_bin.msh"), mesh, file_format="gmsh", binary=True)
    np.savez(c.path("seed.npz"), points=pts, tets=tets)
    for n in ("seed.vtk", "seed_bin.vtk", "seed.vtu", "seed22.msh", "seed41.msh", "seed41_bin.msh", "seed.npz"):
        seeds_mesh[n] = "mesh"
    surf = palpate.ellipsoid_surface((0.01, 0.01, 0.02), 2)
    sm = meshio.Mesh(surf.points * 1e3, [("triangle", surf.triangles)])
    seeds_surf = {}
    for n, kw in (("seed.obj", {}), ("seed.stl", {"binary": False}), ("seed_bin.stl", {"binary": True}),
                  ("seed.ply", {"binary": False}), ("seed_bin.ply", {"binary": True}), ("seed.off", {}),
                  ("seed_surf.vtk", {"binary": False})):
        meshio.write(c.path(n), sm, **kw)
        seeds_surf[n] = "surface"
    write_vtp(c.path("seed.vtp"), surf.points * 1e3, surf.triangles)
    write_vtp(c.path("seed_app.vtp"), surf.points * 1e3, surf.triangles, fmt="appended")
    seeds_surf["seed.vtp"] = seeds_surf["seed_app.vtp"] = "surface"
    model = palpate.build_shape("ellipsoids", particles=400, field_voxels=20000)
    model.save(c.path("seed.palpate"))
    return seeds_mesh, seeds_surf


def _loader(kind, name):
    if kind == "mesh":
        return f"palpate.load_mesh(os.path.join(D, {name!r}))"
    if kind == "surface":
        return f"palpate.load_surface(os.path.join(D, {name!r}), unit='mm')"
    return f"palpate.HybridModel.load(os.path.join(D, {name!r}))"


def _mutations(c: Corpus, name, kind, rng, n_trunc=3, n_flip=3):
    data = open(c.path(name), "rb").read()
    stem, ext = os.path.splitext(name)
    if ext in (".node", ".ele") or len(data) < 16:
        return  # a TetGen pair is mutated through its .node half below
    load = lambda n: _loader(kind, n)  # noqa: E731
    for k in range(n_trunc):
        cut = int(len(data) * (k + 1) / (n_trunc + 1)) if k < n_trunc - 1 else max(1, len(data) - rng.randrange(1, 12))
        n = c.write(f"mut_{stem}_trunc{k}{ext}", data[:cut])
        c.api(n, "mutation", load(n), TYPED)
    for k in range(n_flip):
        b = bytearray(data)
        for _ in range(1 + k * 4):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
        n = c.write(f"mut_{stem}_flip{k}{ext}", bytes(b))
        c.api(n, "mutation", load(n), TYPED)


# ---------------------------------------------------------------------------------------------
# the cases
# ---------------------------------------------------------------------------------------------

def make(folder):
    c = Corpus(folder)
    rng = random.Random(15)
    seeds_mesh, seeds_surf = _seeds(c)
    for n, kind in list(seeds_mesh.items()) + list(seeds_surf.items()):
        c.api(n, "seed", _loader(kind, n), ["ok", "warning"])
        _mutations(c, n, kind, rng)

    # The earlier corpora, copied and mutated (their own tests check their exact messages).
    for sub, kind in (("malformed", "mesh"), ("malformed_surfaces", "surface")):
        src = os.path.join(HERE, "data", sub)
        for f in sorted(os.listdir(src)):
            if f in ("EXPECTED.toml", "make_corpus.py") or f.endswith(".json"):
                continue
            shutil.copy(os.path.join(src, f), c.path(f"old_{f}"))
            for comp in (f[: -len(".vtp")] + "_part_definition.json",) if f.endswith(".vtp") else ():
                if os.path.exists(os.path.join(src, comp)):
                    shutil.copy(os.path.join(src, comp), c.path("old_" + comp))
            if f.endswith(".ele") or f.endswith(".node") and not os.path.exists(os.path.join(src, f[:-5] + ".ele")):
                continue
            _mutations(c, f"old_{f}", kind, rng, n_trunc=1, n_flip=1)

    _model_file_cases(c, rng)
    _silent_cases(c)
    _reader_cases(c)
    _generator_cases(c)
    _body_cases(c)
    _binding_cases(c)
    _cli_cases(c)
    return c.cases


def _model_file_cases(c: Corpus, rng):
    data = open(c.path("seed.palpate"), "rb").read()
    c.api("seed.palpate", "seed", _loader("model", "seed.palpate"), ["ok"])
    # Truncations and flips (the checksum catches flips: corrupted, not crafted).
    for k, cut in enumerate([0, 8, 16, 39, 40, 41, 100, len(data) // 2, len(data) - 1]):
        n = c.write(f"model_trunc{k}.palpate", data[:cut])
        c.api(n, "mutation", _loader("model", n), ["error"], ["ModelFileError"])
    for k in range(6):
        b = bytearray(data)
        i = rng.randrange(HEADER, len(b))
        b[i] ^= 0x10
        n = c.write(f"model_flip{k}.palpate", bytes(b))
        c.api(n, "mutation", _loader("model", n), ["error"], ["ModelFileError"])
    # Crafted: bytes changed and the checksum made right again (a file written on purpose).
    for k in range(30):
        b = bytearray(data)
        for _ in range(1 + k % 4):
            i = rng.randrange(HEADER, len(b))
            b[i] = rng.randrange(256)
        n = c.write(f"model_crafted{k}.palpate", refresh_checksum(bytes(b)))
        c.api(n, "mutation", _loader("model", n), TYPED)
    # Crafted: a field's value replaced by NaN / inf / a negative (found by its bytes: the
    # format is packed, not aligned): options, wall volume, masses, skin, points.
    import palpate
    m = palpate.HybridModel.load(c.path("seed.palpate"))
    info = m.info()
    fields = {"core_fraction": info["core_fraction"], "wall_volume": m.wall_volume, "mass": float(m.particle_masses[0]),
              "skin_bary": float(m.skin_barycentric[0, 0]), "skin_offset": float(m.skin_offsets[0, 0]),
              "core_point": float(m.core_points[0, 0]), "particle": float(m.particles[0, 0]),
              "outer_point": float(m.outer_points[0, 0])}
    for fname, value in fields.items():
        i = data.find(struct.pack("<d", value), HEADER)
        assert i > 0, fname
        for tag, bad in (("nan", float("nan")), ("inf", float("inf")), ("neg", -abs(value) - 1.0)):
            if tag == "neg" and fname in ("skin_offset", "core_point", "particle", "outer_point"):
                continue  # a negative coordinate is a valid coordinate
            b = data[:i] + struct.pack("<d", bad) + data[i + 8:]
            n = c.write(f"model_{tag}_{fname}.palpate", refresh_checksum(b))
            c.api(n, "silent", _loader("model", n), ["error"], ["ModelFileError"])
    nan = struct.pack("<d", float("nan"))
    # NaN in the last f64s: the build statistics (palpate info printed "nan" with exit 0).
    b = data[:-72] + nan + data[-64:]
    n = c.write("model_nan_stats.palpate", refresh_checksum(b))
    c.api(n, "silent", _loader("model", n), ["error"], ["ModelFileError"])
    c.cli("cli_info_nan_model", "silent", ["info", "{D}/model_nan_stats.palpate"], codes=(1,))
    # Counts inflated to 1e8 / 2^63 (checksum fixed).
    for k, off in enumerate(range(HEADER, HEADER + 400, 8)):
        (v,) = struct.unpack("<Q", data[off:off + 8])
        if 0 < v < 10_000_000:
            for j, big in enumerate((100_000_000, 1 << 63)):
                b = data[:off] + struct.pack("<Q", big) + data[off + 8:]
                n = c.write(f"model_count{k}_{j}.palpate", refresh_checksum(b))
                # Some of these words are option values, not counts: loading is then fine.
                c.api(n, "abort", _loader("model", n), ["error", "ok"], ["ModelFileError", "LimitError"])
    c.write("model_magic_only.palpate", b"PALPATE\0HYBRID\0\0")
    c.api("model_magic_only.palpate", "mutation", _loader("model", "model_magic_only.palpate"), ["error"], ["ModelFileError"])
    c.write("model_version.palpate", data[:16] + struct.pack("<I", 99) + data[20:])
    c.api("model_version.palpate", "mutation", _loader("model", "model_version.palpate"), ["error"], ["ModelFileError"])
    os.makedirs(c.path("a_directory.palpate"), exist_ok=True)
    c.api("model_directory", "untyped", _loader("model", "a_directory.palpate"), ["error"], ["ModelFileIOError"])
    c.api("model_missing", "untyped", _loader("model", "no_such.palpate"), ["error"], ["ModelFileIOError"])
    fifo = c.path("a_fifo.palpate")
    if not os.path.exists(fifo):
        os.mkfifo(fifo)
    c.api("model_fifo", "hang", _loader("model", "a_fifo.palpate"), ["error"], ["ModelFileIOError"])
    # Swapped tags on one closed wall (inner tagged outer and the reverse): detected.
    c.api("build_tagged_swapped", "silent",
          "v, t, part = palpate.ventricle_surface(48, 12); part = np.where(part == 2, 2, 1 - part)\n"
          "palpate.HybridModel.build_tagged(v, t, part, particles=400, field_voxels=20000)", ["error"], ["ModelError"])
    c.api("build_tagged_correct", "seed",
          "v, t, part = palpate.ventricle_surface(48, 12)\n"
          "palpate.HybridModel.build_tagged(v, t, part, particles=400, field_voxels=20000, homogenise=False)", ["ok"])
    # Swapped surfaces (inner given as outer): detected.
    c.api("build_swapped_surfaces", "silent",
          "a = palpate.ellipsoid_surface((0.02, 0.02, 0.035), 3); b = palpate.ellipsoid_surface((0.026, 0.026, 0.042), 3)\n"
          "palpate.HybridModel.build_nested(b, a)", ["error"])


def _reader_cases(c: Corpus):
    fifo_names = []
    for ext in (".msh", ".vtk", ".vtu", ".node", ".npz"):
        n = f"fifo{ext}"
        if not os.path.exists(c.path(n)):
            os.mkfifo(c.path(n))
        c.api(f"mesh_{n}", "hang", _loader("mesh", n), ["error"], ["MeshError"])
        fifo_names.append(n)
    for ext in (".obj", ".stl", ".ply", ".off", ".vtp"):
        n = f"fifo{ext}"
        if not os.path.exists(c.path(n)):
            os.mkfifo(c.path(n))
        c.api(f"surface_{n}", "hang", _loader("surface", n), ["error"], ["SurfaceError"])
    for ext in (".msh", ".vtk", ".vtu", ".npz", ".node"):
        d = c.path(f"dir{ext}")
        os.makedirs(d, exist_ok=True)
        c.api(f"mesh_dir{ext}", "untyped", _loader("mesh", f"dir{ext}"), ["error"], ["MeshError"])
    for ext in (".obj", ".ply", ".off", ".vtp", ".stl"):
        d = c.path(f"dir{ext}")
        os.makedirs(d, exist_ok=True)
        c.api(f"surface_dir{ext}", "untyped", _loader("surface", f"dir{ext}"), ["error"], ["SurfaceError"])
    # OFF and PLY with a truncated header (meshio's reader looped forever).
    for k, text in enumerate(["OFF\n", "OFF\n# only a comment\n", "OFF\n8 12", "OFF\n3 1 0\n0 0 0\n"]):
        n = c.write(f"off_header{k}.off", text)
        c.api(n, "hang", _loader("surface", n), ["error"], ["SurfaceError"])
    for k, text in enumerate(["ply\n", "ply\nformat ascii 1.0\n", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n",
                              "ply\nformat binary_little_endian 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n"]):
        n = c.write(f"ply_header{k}.ply", text)
        c.api(n, "hang", _loader("surface", n), ["error"], ["SurfaceError", "LimitError"], contains=PRECHECK if k == 3 else None)
    # Oversized counts in headers.
    n = c.write("off_huge.off", "OFF\n100000000 200000000 0\n0 0 0\n")
    c.api(n, "abort", _loader("surface", n), ["error"], ["SurfaceError", "LimitError"], contains=PRECHECK)
    n = c.write("stl_bin_huge.stl", b"\0" * 80 + struct.pack("<I", 100_000_000) + b"\0" * 100)
    c.api(n, "abort", _loader("surface", n), ["error"], ["SurfaceError", "LimitError"], contains=PRECHECK)
    # palpate's own ASCII readers (gmsh, TetGen) grow their arrays line by line and never trust a
    # count: the file ends first.
    n = c.write("gmsh2_huge_nodes.msh", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n100000000\n1 0 0 0\n$EndNodes\n")
    c.api(n, "abort", _loader("mesh", n), ["error"], ["MeshError", "LimitError"], contains="unexpected end of file")
    head = b"$MeshFormat\n4.1 1 8\n" + struct.pack("<i", 1) + b"\n$EndMeshFormat\n$Nodes\n"
    n = c.write("gmsh4_bin_1e8_nodes.msh", head + struct.pack("<QQQQ", 1, 100_000_000, 1, 100_000_000)
                + struct.pack("<iiiQ", 3, 1, 0, 100_000_000) + b"\0" * 64)
    c.api(n, "abort", _loader("mesh", n), ["error"], ["MeshError", "LimitError"], contains=PRECHECK)
    head2 = b"$MeshFormat\n2.2 1 8\n" + struct.pack("<i", 1) + b"\n$EndMeshFormat\n$Nodes\n100000000\n"
    n = c.write("gmsh2_bin_1e8_nodes.msh", head2 + b"\0" * 64)
    c.api(n, "abort", _loader("mesh", n), ["error"], ["MeshError", "LimitError"], contains=PRECHECK)
    n = c.write("tetgen_huge.node", "100000000 3 0 0\n1 0 0 0\n")
    c.write("tetgen_huge.ele", "1 4 0\n1 1 1 1 1\n")
    c.api(n, "abort", _loader("mesh", n), ["error"], ["MeshError", "LimitError"], contains="unexpected end of file")
    n = c.write("vtk_huge_points.vtk", "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 100000000 double\n0 0 0\n")
    c.api(n, "abort", _loader("mesh", n), ["error"], ["MeshError", "LimitError"], contains=PRECHECK)
    n = c.write("vtk_bin_huge_points.vtk", b"# vtk DataFile Version 4.2\nx\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 400000000 double\n" + b"\0" * 48)
    c.api(n, "abort", _loader("mesh", n), ["error"], ["MeshError", "LimitError"], contains=PRECHECK)
    n = c.write("vtk_bin_huge_cells.vtk", b"# vtk DataFile Version 4.2\nx\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n"
                + struct.pack(">12d", 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1) + b"\nCELLS 100000000 500000000\n" + b"\0" * 48)
    c.api(n, "abort", _loader("mesh", n), ["error"], ["MeshError", "LimitError"], contains=PRECHECK)
    n = c.write("vtk_surf_huge_points.vtk", "# vtk DataFile Version 4.2\nx\nASCII\nDATASET POLYDATA\nPOINTS 100000000 float\n0 0 0\n")
    c.api(n, "abort", _loader("surface", n), ["error"], ["SurfaceError", "LimitError"], contains=PRECHECK)
    # VTK cells of an unknown type (meshio dropped them with a warning we suppressed).
    txt = ("# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 5 double\n0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\n"
           "CELLS 2 10\n4 0 1 2 3\n4 1 2 3 4\nCELL_TYPES 2\n10\n99\n")
    n = c.write("vtk_unknown_cell_type.vtk", txt)
    c.api(n, "silent", _loader("mesh", n), ["error", "warning"])
    # Bombs: zlib streams that inflate to 3 GB (a VTU and a VTP), a zip (npz) that does.
    _bombs(c)
    # Bad text: invalid UTF-8, NUL bytes, deep nesting.
    n = c.write("bad_utf8.msh", b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 \xff\xfe\n$EndNodes\n")
    c.api(n, "untyped", _loader("mesh", n), ["error"], ["MeshError"])
    n = c.write("bad_utf8.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n\xff\xfe f 1 2 3\n")
    c.api(n, "untyped", _loader("surface", n), ["error"], ["SurfaceError"])
    n = c.write("scene_bad_utf8.toml", b"[mesh]\ngenerator = \"\xff\xfe\"\n")
    c.api("scene_bad_utf8", "untyped", f"import palpate.scene as s; s.load_scene(os.path.join(D, {n!r}))", ["error"])
    n = c.write("scene_deep.toml", "a = " + "[" * 5000 + "]" * 5000 + "\n")
    c.api("scene_deep", "untyped", f"import palpate.scene as s; s.load_scene(os.path.join(D, {n!r}))", ["error"])
    n = c.write("tagged_deep_part_definition.json", "[" * 100000 + "]" * 100000)
    c.write("tagged_deep.vtp", open(c.path("old_tagged_unmapped_tag.vtp"), "rb").read())
    c.api("part_definition_deep", "untyped",
          "palpate.read_tagged_surface(os.path.join(D, 'tagged_deep.vtp'), unit='mm')", ["error"], ["SurfaceError"],
          names=["tagged_deep_part_definition.json"])
    n = c.write("scene_garbage.toml", b"\x00\x01\x02 not toml")
    c.api("scene_garbage", "untyped", f"import palpate.scene as s; s.load_scene(os.path.join(D, {n!r}))", ["error"])
    c.api("scene_missing", "untyped", "import palpate.scene as s; s.load_scene(os.path.join(D, 'none.toml'))", ["error"])
    c.api("scene_directory", "untyped", "import palpate.scene as s; s.load_scene(os.path.join(D, 'dir.msh'))", ["error"])
    c.api("load_mesh_unit_bad", "untyped", "palpate.load_mesh(os.path.join(D, 'seed.vtk'), unit='furlong')", ["error"])


def _bombs(c: Corpus):
    import base64

    big = 3 << 30
    block = 1 << 30
    comp = zlib.compress(b"\0" * block, 9)  # ~1 MB for 1 GiB of zeros
    nblocks = big // block
    header = struct.pack("<QQQ", nblocks, block, block) + struct.pack("<Q", len(comp)) * nblocks
    b64 = base64.b64encode(header).decode() + base64.b64encode(comp * nblocks).decode()
    vtu = f"""<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64" compressor="vtkZLibDataCompressor">
<UnstructuredGrid><Piece NumberOfPoints="134217728" NumberOfCells="1">
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">{b64}</DataArray></Points>
<Cells><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10</DataArray></Cells>
</Piece></UnstructuredGrid></VTKFile>
"""
    c.write("bomb.vtu", vtu)
    # LimitError only: a MeshError here would mean the inflated-size pre-check was lost and the
    # reader failed on its own later (after inflating, or after running out of address space).
    c.api("bomb.vtu", "bomb", _loader("mesh", "bomb.vtu"), ["error"], ["LimitError"])
    vtp = vtu.replace("UnstructuredGrid", "PolyData").replace('NumberOfCells="1"', 'NumberOfPolys="1"').replace("<Cells>", "<Polys>").replace("</Cells>", "</Polys>")
    c.write("bomb.vtp", vtp)
    c.api("bomb.vtp", "bomb", _loader("surface", "bomb.vtp"), ["error"], ["LimitError"])
    import zipfile
    with zipfile.ZipFile(c.path("bomb.npz"), "w", compression=zipfile.ZIP_DEFLATED) as z:
        hdr = np.lib.format.header_data_from_array_1_0(np.zeros((1, 3)))
        hdr["shape"] = (big // 24, 3)
        import io
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, hdr)
        with z.open("points.npy", "w", force_zip64=True) as fh:
            fh.write(buf.getvalue())
            chunk = b"\0" * (64 << 20)
            for _ in range(big // len(chunk)):
                fh.write(chunk)
        z.writestr("tets.npy", b"")
    c.api("bomb.npz", "bomb", _loader("mesh", "bomb.npz"), ["error"], ["LimitError"])
    # Issue 35 item 4: the same bombs with no PALPATE_MAX_MEMORY: the budget follows RLIMIT_AS
    # (3 GiB in the child), and the refusal names it.
    for name, kind in (("bomb.vtu", "mesh"), ("bomb.vtp", "surface"), ("bomb.npz", "mesh")):
        c.api(name.replace(".", "_") + "_rlimit", "bomb", _loader(kind, name), ["error"], ["LimitError"], budget=None,
              names=[name], contains="RLIMIT_AS")
    # An .npy header claiming 1e10 x 3 float64 (240 GB) in a member of ~130 bytes: the zip
    # directory is honest, only the header lies; refused from the header before numpy allocates.
    with zipfile.ZipFile(c.path("rows_1e10.npz"), "w") as z:
        for member, shape, descr in (("points.npy", (10**10, 3), "<f8"), ("tets.npy", (1, 4), "<i8")):
            buf = io.BytesIO()
            np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False, "shape": shape})
            z.writestr(member, buf.getvalue() + (b"\0" * 32 if member == "tets.npy" else b""))
    c.api("npz_header_1e10_rows", "bomb", _loader("mesh", "rows_1e10.npz"), ["error"], ["LimitError"], contains="'points.npy'")
    c.api("npz_header_1e10_rows_rlimit", "bomb", _loader("mesh", "rows_1e10.npz"), ["error"], ["LimitError"], budget=None,
          names=["rows_1e10.npz"], contains="RLIMIT_AS")


def _generator_cases(c: Corpus):
    g = [
        ("box_thin", "panic", "palpate.box_mesh(size=(1, 1, 1e-12), cells=(2, 2, 2))", ["MeshError"]),
        ("box_thin_cells", "panic", "palpate.box_mesh(size=(0.1, 0.1, 0.1), cells=(1, 1, 200000))", ["MeshError", "LimitError"]),
        ("box_thin_but_valid", "panic", "palpate.box_mesh(size=(0.1, 0.1, 0.1), cells=(1, 1, 20000))", ["ok"]),
        ("box_huge_cells", "panic", "palpate.box_mesh(size=(1, 1, 1), cells=(100000, 100000, 100000))", None),
        ("box_huge_size", "panic", "palpate.box_mesh(size=(1e300, 1e300, 1e300), cells=(2, 2, 2))", None),
        ("box_tiny_size", "panic", "palpate.box_mesh(size=(1e-300, 1e-300, 1e-300), cells=(2, 2, 2))", None),
        ("box_nan", "panic", "palpate.box_mesh(size=(float('nan'), 1, 1), cells=(2, 2, 2))", None),
        ("box_negative_cells", "untyped", "palpate.box_mesh(size=(1, 1, 1), cells=(-1, 2, 2))", None),
        ("box_zero_cells", "panic", "palpate.box_mesh(size=(1, 1, 1), cells=(0, 2, 2))", None),
        # Inside the documented ranges, but too fine at the apex: refused before the mesh is built.
        ("ventricle_96_600", "panic", "palpate.ventricle_surface(96, 600)", ["MeshError"], "refused before building"),
        ("ventricle_3_4096", "panic", "palpate.ventricle_surface(3, 4096)", ["MeshError"], "refused before building"),
        ("ventricle_512_512", "panic", "palpate.ventricle_surface(512, 512)", ["MeshError"], "refused before building"),
        ("ventricle_4096_4096", "abort", "palpate.ventricle_surface(4096, 4096)", None),
        ("ventricle_negative", "untyped", "palpate.ventricle_surface(-3, 10)", None),
        ("ellipsoid_wall_subdiv_40", "abort", "palpate.ellipsoid_wall(subdivisions=40)", None),
        ("ellipsoid_wall_thin", "panic", "palpate.ellipsoid_wall(inner=(0.02, 0.02, 0.035), outer=(0.0200000001, 0.0200000001, 0.0350000001))", ["MeshError"], "refused before building"),
        ("truncated_wall_apex", "panic", "palpate.truncated_ellipsoid_wall(circumferential=96, longitudinal=600, layers=1)", ["MeshError"], "refused before building"),
        ("ellipsoid_wall_swapped", "panic", "palpate.ellipsoid_wall(inner=(0.026, 0.026, 0.042), outer=(0.02, 0.02, 0.035))", None),
        ("truncated_wall_zcut", "panic", "palpate.truncated_ellipsoid_wall(z_cut=0.0349999)", None),
        ("truncated_wall_huge", "abort", "palpate.truncated_ellipsoid_wall(circumferential=100000, longitudinal=100000, layers=100)", None),
        ("ellipsoid_surface_subdiv_30", "abort", "palpate.ellipsoid_surface((0.01, 0.01, 0.01), 30)", None),
        ("ellipsoid_surface_flat", "panic", "palpate.ellipsoid_surface((0.01, 0.01, 1e-300), 3)", None),
        ("sample_inside_tiny_spacing", "abort", "palpate.sample_inside(palpate.ellipsoid_surface((0.01, 0.01, 0.01), 2), 1e-7, 1000.0)", None),
        ("sample_inside_nan_spacing", "panic", "palpate.sample_inside(palpate.ellipsoid_surface((0.01, 0.01, 0.01), 2), float('nan'), 1000.0)", None),
        ("build_thin_wall", "abort", "a = palpate.ellipsoid_surface((0.02, 0.02, 0.035), 3); b = palpate.ellipsoid_surface((0.02002, 0.02002, 0.03502), 3)\n"
                                      "palpate.HybridModel.build_nested(a, b)", None),
        ("build_field_voxels_huge", "abort", "palpate.build_shape('ellipsoids', field_voxels=10**12)", None),
        ("build_particles_huge", "abort", "palpate.build_shape('ellipsoids', particles=50_000_000)", None),
        ("build_spacing_tiny", "abort", "palpate.build_shape('ellipsoids', spacing=1e-7)", None),
        ("neighbours_tiny_radius", "abort", "palpate.neighbours(np.random.default_rng(0).random((1000, 3)) * 0.1, 1e-9)", ["error", "ok"]),
        ("neighbours_huge_radius", "abort", "palpate.neighbours(np.random.default_rng(0).random((40000, 3)), 10.0)", None),
    ]
    for name, klass, code, types, *contains in g:
        if types and types[0] in ("error", "ok", "warning"):
            c.api(name, klass, code, types)
        else:
            c.api(name, klass, code, ["error"], types, contains=contains[0] if contains else None)


_PB = ("pts = np.mgrid[0:4, 0:4, 0:4].reshape(3, -1).T * 0.001\n"
       "def pb(young=3e4, mass=1e-6, radius=0.0025, n=None, **kw):\n"
       "    p = pts if n is None else n\n"
       "    return palpate.ParticleBody(p, np.full(len(p), mass), palpate.Material(young=young, poisson=0.4, density=1000.0), support_radius=radius, **kw)\n")
_BODY = ("mesh = palpate.box_mesh((0.1, 0.02, 0.02), (10, 2, 2))\n"
         "def body(young=3e4, **kw):\n"
         "    return palpate.Body(mesh, palpate.Material(young=young, poisson=0.4, density=1000.0), fixed=np.flatnonzero(mesh.points[:, 0] == 0), **kw)\n")
_UNCHANGED = ("x0, v0, t0 = b.positions.copy(), b.velocities.copy(), b.time\n"
              "try:\n    {call}\nexcept palpate.PalpateError:\n"
              "    assert (b.positions == x0).all() and (b.velocities == v0).all() and b.time == t0, 'state changed by a rejected step'\n    raise\n")


def _body_cases(c: Corpus):
    vent = "v, t, part = palpate.ventricle_surface(); s = palpate.TriSurface(v, t); ps = palpate.sample_inside(s, 0.0015, 1000.0)\n"
    cases = [
        ("pb_support_1e-8", "panic", _PB + "pb(radius=1e-8)", ["error"]),
        ("pb_support_1e-5_ventricle", "abort", _PB + vent + "pb(radius=1e-5, n=ps.positions if hasattr(ps, 'positions') else ps[0])", ["error"]),
        ("pb_support_huge", "abort", _PB + "p = np.random.default_rng(1).random((30000, 3)) * 0.01\npb(radius=1.0, n=p)", ["error"]),
        ("pb_mass_1e-150", "panic", _PB + "pb(mass=1e-150)", ["error"]),
        ("pb_mass_1e150", "panic", _PB + "b = pb(mass=1e150); b.step(1)", ["error", "ok"]),
        ("pb_young_1e150", "hang", _PB + "b = pb(young=1e150); b.step(1)", ["error"]),
        ("pb_young_1e-300", "hang", _PB + "b = pb(young=1e-300); b.step(1)", ["error", "ok"]),
        ("pb_dt_1e3", "hang", _PB + "b = pb()\n" + _UNCHANGED.format(call="b.step(1, dt=1e3)"), ["error"], ["StepError"]),
        ("pb_dt_nan", "hang", _PB + "b = pb()\n" + _UNCHANGED.format(call="b.step(1, dt=float('nan'))"), ["error"], ["StepError"]),
        ("pb_negative_steps", "untyped", _PB + "b = pb(); b.step(-1)", ["error"], ["ParameterError"]),
        ("pb_run_timed_1e11", "abort", _PB + "b = pb(); r = b.run_timed(10**11, max_wall_s=0.5); assert r['error'] and 'cap' in r['error'], r['error']", ["ok"]),
        ("pb_run_timed_negative", "untyped", _PB + "b = pb(); b.run_timed(-5)", ["error"], ["ParameterError"]),
        ("pb_nan_force", "silent", _PB + "b = pb(); f = np.zeros((64, 3)); f[3, 0] = np.nan; b.set_forces(f)\n" + _UNCHANGED.format(call="b.step(1)"), ["error"]),
        ("pb_huge_force", "silent", _PB + "b = pb(); f = np.zeros((64, 3)); f[3, 0] = 1e300; b.set_forces(f)\n" + _UNCHANGED.format(call="b.step(1)"), ["error"]),
        ("pb_positions_nan", "silent", _PB + "p = pts.copy(); p[0, 0] = np.inf; pb(n=p)", ["error"]),
        ("pb_duplicate_points", "panic", _PB + "p = np.zeros((64, 3)); pb(n=p)", ["error"]),
        ("pb_fixed_out_of_range", "panic", _PB + "pb(fixed=[10**9])", ["error"]),
        ("pb_fixed_negative", "untyped", _PB + "pb(fixed=[-1])", ["error"]),
        ("body_run_probe_1e11", "abort", _BODY + "b = body(); r = b.run_probe([20], (0, 0, -1e-3), 0.1, 10**11, max_wall_s=0.5); assert r['steps'] < 10**11", ["ok"]),
        ("body_run_loads_1e11", "abort", _BODY + "b = body(); r = b.run_loads([([20], (0, 0, -1e-3), 0.1)], 10**11, max_wall_s=0.5); assert r['steps'] < 10**11", ["ok"]),
        ("body_negative_steps", "untyped", _BODY + "b = body(); b.step(-1)", ["error"]),
        ("body_dt_1e3", "hang", _BODY + "b = body()\n" + _UNCHANGED.format(call="b.step(1, dt=1e3)"), TYPED),
        ("body_young_1e150", "hang", _BODY + "b = body(young=1e150); b.step(5)", TYPED),
        ("body_mass_tiny_density", "panic", "mesh = palpate.box_mesh(); palpate.Body(mesh, palpate.Material(young=3e4, poisson=0.4, density=1e-300)).step(1)", TYPED),
        ("body_nan_force", "silent", _BODY + "b = body(); f = np.zeros((b.n_nodes, 3)); f[5, 2] = np.nan\n" + _UNCHANGED.format(call="b.set_forces(f); b.step(1)"), ["error"]),
        ("body_inf_force", "silent", _BODY + "b = body(); f = np.zeros((b.n_nodes, 3)); f[5, 2] = 1e308\n" + _UNCHANGED.format(call="b.set_forces(f); b.step(3)"), ["error", "ok", "warning"]),
        ("body_load_on_fixed", "silent", _BODY + "b = body(); f = np.zeros((b.n_nodes, 3)); f[0, 2] = -1.0; b.set_forces(f); b.step(1)", ["warning", "error"]),
        ("body_probe_on_fixed", "silent", _BODY + "b = body(); b.run_probe([0, 20], (0, 0, -1e-3), 0.1, 5)", ["warning", "error"]),
        ("tetmesh_inverted", "silent", "p = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]); palpate.TetMesh(p, [[0, 2, 1, 3]])", ["warning"]),
        ("tetmesh_flat", "panic", "p = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]); palpate.TetMesh(p, [[0, 1, 2, 3]])", ["error"]),
        ("tetmesh_huge_coords", "panic", "p = np.array([[0., 0, 0], [1e300, 0, 0], [0, 1e300, 0], [0, 0, 1e300]]); palpate.TetMesh(p, [[0, 1, 2, 3]])", TYPED),
        ("tetmesh_tiny_coords", "panic", "p = np.array([[0., 0, 0], [1e-300, 0, 0], [0, 1e-300, 0], [0, 0, 1e-300]]); palpate.TetMesh(p, [[0, 1, 2, 3]])", TYPED),
        ("tetmesh_index_huge", "panic", "p = np.zeros((4, 3)); palpate.TetMesh(p, [[0, 1, 2, 2**62]])", ["error"]),
        ("trisurface_index_negative", "panic", "p = np.eye(3); palpate.TriSurface(p, [[0, 1, -2]])", ["error"]),
        ("hybrid_sim_nan_tool", "silent",
         "m = palpate.build_shape('ellipsoids', particles=400, field_voxels=20000, homogenise=False); s = palpate.HybridSim(m, palpate.Material.myocardium()); s.step((float('nan'), 0, 0))", ["error"]),
    ]
    for entry in cases:
        name, klass, code, expect = entry[:4]
        types = entry[4] if len(entry) > 4 else None
        c.api(name, klass, code, expect, types)
    # Issue 35 item 4: an all-pairs neighbourhood (4096 particles 1 mm apart, a 1 m support:
    # 16.8 M pairs, 2.3 GB) with no PALPATE_MAX_MEMORY, under RLIMIT_AS 3 GiB: refused from the
    # budget that follows RLIMIT_AS (with the old fixed 8 GiB: SIGABRT).
    c.api("pb_all_pairs_rlimit", "abort", _PB + "p = np.mgrid[0:16, 0:16, 0:16].reshape(3, -1).T * 1e-3\npb(radius=1.0, n=p)",
          ["error"], ["LimitError"], budget=None, contains="RLIMIT_AS")
    # Long runs with no wall-clock cap under a small memory budget: the per-step records stop
    # growing at the budget (the run ends with the steps it took and says why), rather than
    # growing until the process aborts.
    c.api("body_run_probe_records_budget", "abort", _BODY + "b = body(); r = b.run_probe([20], (0, 0, -1e-3), 0.1, 10**11); "
          "assert r['steps'] == 65536 and 'memory budget' in r['error'], (r['steps'], r['error'])", ["ok"], budget="1M")
    c.api("pb_run_timed_records_budget", "abort", _PB + "b = pb(); r = b.run_timed(10**11); "
          "assert r['ticks'] == 65536 and 'memory budget' in r['error'], (r['ticks'], r['error'])", ["ok"], budget="600K")
    # Divergence reported when it starts (issue 15, item 4), not at overflow: the step that passes
    # the speed bound fails with the state restored and every value still finite.
    diverging = ("    x0, v0, t0 = b.positions.copy(), b.velocities.copy(), b.time\n"
                 "    try:\n        b.step(1)\n    except palpate.StepError:\n"
                 "        assert (b.positions == x0).all() and (b.velocities == v0).all() and b.time == t0, 'state changed'\n"
                 "        assert np.isfinite(b.positions).all() and np.isfinite(b.velocities).all()\n        raise\n")
    c.api("body_semi_implicit_diverging", "silent",
          "mesh = palpate.truncated_ellipsoid_wall(); p = mesh.points; free = np.abs(p[:, 2]) > 1e-9\n"
          "b = palpate.Body(mesh, palpate.Material(young=3e4, poisson=0.4, density=1000.0), fixed=np.flatnonzero(~free), integrator=palpate.SemiImplicit(palpate.Filter.PAPER))\n"
          "b.set_positions(p + np.random.default_rng(1).uniform(-1e-9, 1e-9, p.shape) * free[:, None])\n"
          "for k in range(300):\n" + diverging, ["error"], ["StepError"], contains="diverging")
    c.api("hybrid_sim_under_stepped_diverging", "silent",
          "m = palpate.build_shape('ellipsoids', particles=400, field_voxels=20000, homogenise=False)\n"
          "s = palpate.HybridSim(m, palpate.Material.myocardium(), max_substeps=1, shell_fallback=False)\n"
          "o = s.surface; p = o[np.argmax(o[:, 0])]; r = s.tool_radius\n"
          "for k in range(500):\n"
          "    x0 = s.core_positions.copy()\n"
          "    try:\n        s.step(p + np.array([r - min(3e-3, 3e-5 * (k + 1)), 0, 0]))\n"
          "    except palpate.StepError:\n        assert (s.core_positions == x0).all() and np.isfinite(s.particle_positions()).all()\n        raise\n",
          ["error"], ["StepError"], contains="diverging")


_MODEL = "m = palpate.HybridModel.load(os.path.join(D, 'seed.palpate'))\n"


def _binding_cases(c: Corpus):
    """The binding's other entries: crafted model bytes through ``from_bytes`` and through a
    pickle (loads as ``HybridModel.load`` does, under the panic guard), negative counts and
    indices (pyo3 raised OverflowError for an argument typed ``usize``), and the Python modules'
    own errors (ParameterError, ScriptError: PalpateErrors)."""
    crafted = sorted(n for n in os.listdir(c.folder) if n.startswith(("model_crafted", "model_count", "model_nan_", "model_trunc")))
    for n in crafted[::4]:
        read = f"data = open(os.path.join(D, {n!r}), 'rb').read()\n"
        c.api(f"from_bytes_{n}", "mutation", read + "palpate.HybridModel.from_bytes(data)", TYPED, ["ModelFileError", "LimitError"], names=["<bytes>"])
        # A pickle of the seed model with its file bytes swapped for the crafted ones.
        c.api(f"pickle_{n}", "mutation", read + "import pickle\nclass Crafted:\n    def __reduce__(self):\n"
              "        return (palpate.HybridModel.from_bytes, (data,))\npickle.loads(pickle.dumps(Crafted()))",
              TYPED, ["ModelFileError", "LimitError"], names=["<bytes>"])
    c.api("from_bytes_empty", "mutation", "palpate.HybridModel.from_bytes(b'')", ["error"], ["ModelFileError"], names=["<bytes>"])
    c.api("pickle_seed", "seed", _MODEL + "import pickle\nassert pickle.loads(pickle.dumps(m)).to_bytes() == m.to_bytes()", ["ok"])
    par = ["ParameterError"]
    negative = [
        ("neg_ellipsoid_surface", "palpate.ellipsoid_surface((0.01, 0.01, 0.01), -1)"),
        ("neg_ellipsoid_wall_subdivisions", "palpate.ellipsoid_wall(subdivisions=-1)"),
        ("neg_ellipsoid_wall_layers", "palpate.ellipsoid_wall(layers=-2)"),
        ("neg_truncated_wall_circumferential", "palpate.truncated_ellipsoid_wall(circumferential=-3)"),
        ("neg_truncated_wall_longitudinal", "palpate.truncated_ellipsoid_wall(longitudinal=-1)"),
        ("neg_truncated_wall_layers", "palpate.truncated_ellipsoid_wall(layers=-1)"),
        ("neg_static_solve_iterations", _BODY + "body().static_solve(max_iterations=-1)"),
        ("neg_static_solve_load_steps", _BODY + "body().static_solve(load_steps=-1)"),
        ("neg_backward_euler_iterations", "palpate.BackwardEuler(max_iterations=-1)"),
        ("neg_backward_euler_history", "palpate.BackwardEuler(history=-1)"),
        ("neg_hybrid_sim_substeps", _MODEL + "palpate.HybridSim(m, palpate.Material.myocardium(), max_substeps=-1)"),
        ("neg_hybrid_sim_linger", _MODEL + "palpate.HybridSim(m, palpate.Material.myocardium(), linger=-1.0)"),
        ("neg_region_particles", _MODEL + "m.region_particles(-1)"),
        ("neg_region_field", _MODEL + "m.region_field(-2)"),
        ("neg_region_curve", _MODEL + "m.region_curve(-(2**62))"),
        ("neg_particle_neighbours", _PB + "pb().neighbours(-1)"),
        ("particle_neighbours_past_end", _PB + "pb().neighbours(64)"),
        ("neg_build_particles", "palpate.build_shape('ellipsoids', particles=-5)"),
        ("neg_build_field_voxels", "palpate.build_shape('ellipsoids', field_voxels=-1)"),
        ("neg_record_ticks", _MODEL + "palpate.HapticLoop(m, palpate.Material.myocardium(), 'scripted', times=[0, 1], knots=[[0, 0, 0.05], [0, 0, 0.06]], record_ticks=-1)"),
        ("neg_max_ticks", _MODEL + "palpate.HapticLoop(m, palpate.Material.myocardium(), 'scripted', times=[0, 1], knots=[[0, 0, 0.05], [0, 0, 0.06]], max_ticks=-1)"),
        ("bridge_port_out_of_range", _MODEL + "palpate.HapticLoop(m, palpate.Material.myocardium(), 'bridge', port=70000)"),
        ("haptic_device_unknown", _MODEL + "palpate.HapticLoop(m, palpate.Material.myocardium(), 'nothing')"),
        ("build_shape_unknown", "palpate.build_shape('cube')"),
        ("bench_hybrid_unknown_model", "import palpate.bench_hybrid as b; b.load_model('no such model')"),
        ("repair_surface_bad_shape", "palpate.repair_surface(np.zeros((4, 2)), [[0, 1, 2]])"),
    ]
    for name, code in negative:
        c.api(name, "untyped", code, ["error"], par)
    # Integers beyond 64 bits (pyo3's i64 conversion raised OverflowError), indices past the end
    # (a bare IndexError), wrong dtypes and state dicts without a key (bare TypeError, KeyError):
    # ParameterErrors that keep the builtin class (ParameterIndexError is an IndexError, ...).
    huge = [
        ("big_neg_body_steps", _BODY + "body().step(-(2**70))", par),
        ("big_body_steps", _BODY + "body().step(2**70)", par),
        ("big_box_cells", "palpate.box_mesh(cells=(2**70, 2, 2))", par),
        ("big_neg_box_cells", "palpate.box_mesh(cells=(10, -(2**70), 2))", par),
        ("big_ellipsoid_surface", "palpate.ellipsoid_surface((0.01, 0.01, 0.01), 2**70)", par),
        ("big_neg_ellipsoid_wall_layers", "palpate.ellipsoid_wall(layers=-(2**70))", par),
        ("big_truncated_wall_circumferential", "palpate.truncated_ellipsoid_wall(circumferential=2**70)", par),
        ("big_ventricle_surface", "palpate.ventricle_surface(2**70, 24)", par),
        ("big_run_probe_steps", _BODY + "body().run_probe([20], (0, 0, -1e-3), 0.1, 2**70)", par),
        ("big_neg_run_loads_steps", _BODY + "body().run_loads([([20], (0, 0, -1e-3), 0.1)], -(2**70))", par),
        ("big_static_solve_iterations", _BODY + "body().static_solve(max_iterations=2**70)", par),
        ("big_backward_euler_history", "palpate.BackwardEuler(history=-(2**70))", par),
        ("big_pb_steps", _PB + "pb().step(2**70)", par),
        ("big_neg_pb_run_timed", _PB + "pb().run_timed(-(2**70))", par),
        ("big_particle_neighbours", _PB + "pb().neighbours(2**70)", ["ParameterIndexError"]),
        ("big_neg_particle_neighbours", _PB + "pb().neighbours(-(2**70))", par),
        ("big_build_particles", "palpate.build_shape('ellipsoids', particles=2**70)", par),
        ("big_hybrid_sim_substeps", _MODEL + "palpate.HybridSim(m, palpate.Material.myocardium(), max_substeps=2**70)", par),
        ("big_region_particles", _MODEL + "m.region_particles(2**70)", ["ParameterIndexError"]),
        ("big_neg_region_curve", _MODEL + "m.region_curve(-(2**70))", par),
        ("big_record_ticks", _MODEL + "palpate.HapticLoop(m, palpate.Material.myocardium(), 'scripted', times=[0, 1], knots=[[0, 0, 0.05], [0, 0, 0.06]], record_ticks=2**70)", par),
        ("big_bridge_port", _MODEL + "palpate.HapticLoop(m, palpate.Material.myocardium(), 'bridge', port=-(2**70))", par),
        ("region_particles_past_end", _MODEL + "m.region_particles(m.n_regions)", ["ParameterIndexError"]),
        ("region_field_past_end", _MODEL + "m.region_field(10**9)", ["ParameterIndexError"]),
        ("region_triangles_past_end", _MODEL + "m.region_triangles(m.n_regions)", ["ParameterIndexError"]),
        ("region_core_faces_past_end", _MODEL + "m.region_core_faces(m.n_regions + 5)", ["ParameterIndexError"]),
        ("region_curve_past_end", _MODEL + "m.region_curve(m.n_regions)", ["ParameterIndexError"]),
        ("tets_float_dtype", "palpate.TetMesh(np.eye(4, 3), np.zeros((1, 4)))", ["ParameterTypeError"]),
        ("points_strings", "palpate.TetMesh([['a', 'b', 'c']] * 4, [[0, 1, 2, 3]])", ["ParameterTypeError"]),
        ("integrator_string", _BODY + "body(integrator='semi_implicit')", ["ParameterTypeError"]),
        ("build_option_unknown", "palpate.build_shape('ellipsoids', core_fractoin=0.5)", ["ParameterTypeError"]),
        # Arguments pyo3 converts (conv::arg): a wrong type was pyo3's bare TypeError.
        ("material_young_str", "palpate.Material(young='abc', poisson=0.4)", ["ParameterTypeError"]),
        ("material_density_none", "palpate.Material(young=3e4, poisson=0.4, density=None)", ["ParameterTypeError"]),
        ("material_law_str", "palpate.Material(young=3e4, poisson=0.4, law='neo-hookean')", ["ParameterTypeError"]),
        ("body_mesh_str", "palpate.Body('mesh.msh', palpate.Material.myocardium())", ["ParameterTypeError"]),
        ("body_step_dt_list", _BODY + "body().step(1, dt=['1e-3'])", ["ParameterTypeError"]),
        ("body_step_n_str", _BODY + "body().step('10')", ["ParameterTypeError"]),
        ("box_mesh_size_dict", "palpate.box_mesh(size={'x': 0.1})", ["ParameterTypeError"]),
        ("box_mesh_cells_strs", "palpate.box_mesh(cells=['a', 'b', 'c'])", ["ParameterTypeError"]),
        ("simd_enabled_str", "palpate.set_simd_enabled('yes')", ["ParameterTypeError"]),
        ("model_load_none", "palpate.HybridModel.load(None)", ["ParameterTypeError"]),
        ("model_from_bytes_str", "palpate.HybridModel.from_bytes('PALPATE')", ["ParameterTypeError"]),
        ("hybrid_sim_hold_str", _MODEL + "palpate.HybridSim(m, palpate.Material.myocardium(), hold='no')", ["ParameterTypeError"]),
        ("body_set_state_time_str", _BODY + "b = body()\ns = b.get_state()\ns['time'] = 'now'\nb.set_state(s)", ["ParameterTypeError"]),
        ("mesh_points_dict", "palpate.TetMesh({'a': 1}, [[0, 1, 2, 3]])", ["ParameterTypeError"]),
        ("body_set_state_empty", _BODY + "body().set_state({})", ["ParameterKeyError"]),
        ("pb_set_state_empty", _PB + "pb().set_state({})", ["ParameterKeyError"]),
    ]
    builtin = {"ParameterIndexError": "IndexError", "ParameterTypeError": "TypeError", "ParameterKeyError": "KeyError"}
    for name, code, types in huge:
        if types[0] in builtin:
            # Still the builtin class an `except IndexError` (TypeError, KeyError) caller expects.
            *setup, call = code.rstrip("\n").split("\n")
            code = "\n".join(setup + ["try:", f"    {call}", "except palpate.PalpateError as e:",
                                       f"    assert isinstance(e, {builtin[types[0]]}), type(e).__mro__", "    raise"])
        c.api(name, "untyped", code, ["error"], types)
    n = c.write("touch_garbage.toml", "[[segment]]\nkind = 'press'\ndepth = -1\n")
    c.api("touch_script_bad", "untyped", f"import palpate.touch as t; t.parse_script(os.path.join(D, {n!r}))", ["error"], ["ScriptError"])


def _cli_cases(c: Corpus):
    c.write("scene_ok.toml", open(os.path.join(HERE, "..", "..", "scenes", "ellipsoid_probe.toml")).read())
    # Exit codes (palpate/cli/_common.py, EXIT_CODES): 2 usage (the command line as written), 1 bad
    # input, 3 a run that failed after its input was accepted (here: the model could not be written).
    cases = [
        ("cli_no_args", "untyped", [], (2,)),
        ("cli_unknown_command", "untyped", ["frobnicate"], (2,)),
        ("cli_info_missing", "untyped", ["info", "{D}/nothing.msh"], (1,)),
        ("cli_info_directory", "untyped", ["info", "{D}/a_directory.palpate"], (1,)),
        ("cli_info_fifo", "hang", ["info", "{D}/a_fifo.palpate"], (1,)),
        ("cli_info_fifo_mesh", "hang", ["info", "{D}/fifo.msh"], (1,)),
        ("cli_info_garbage_model", "untyped", ["info", "{D}/model_flip0.palpate"], (1,)),
        ("cli_info_bomb", "bomb", ["info", "{D}/bomb.vtu"], (1,)),
        ("cli_info_bad_utf8", "untyped", ["info", "{D}/bad_utf8.msh"], (1,)),
        ("cli_run_out_dotdot", "output", ["run", "{D}/scene_ok.toml", "--out", "..", "--steps", "2"], (1,)),
        ("cli_run_out_file", "output", ["run", "{D}/scene_ok.toml", "--out", "{D}/seed.vtk", "--steps", "2"], (1,)),
        ("cli_run_out_empty", "output", ["run", "{D}/scene_ok.toml", "--out", "", "--steps", "2"], (1,)),
        ("cli_run_negative_steps", "untyped", ["run", "{D}/scene_ok.toml", "--steps", "-5"], (2,)),
        ("cli_run_huge_steps", "abort", ["run", "{D}/scene_bad_utf8.toml", "--steps", "100000000000"], (1,)),
        ("cli_run_scene_bad_utf8", "untyped", ["run", "{D}/scene_bad_utf8.toml"], (1,)),
        ("cli_run_scene_deep", "untyped", ["run", "{D}/scene_deep.toml"], (1,)),
        ("cli_run_scene_directory", "untyped", ["run", "{D}/dir.msh"], (1,)),
        ("cli_bench_not_ventricle", "untyped", ["bench", "protocol", "{D}/seed.vtk", "--steps", "2"], (1,)),
        ("cli_bench_bomb", "bomb", ["bench", "protocol", "{D}/bomb.vtu"], (1,)),
        ("cli_build_out_dir", "output", ["build", "--shape", "ellipsoids", "-o", "{D}/a_directory.palpate", "--particles", "400", "--field-voxels", "20000"], (3,)),
        ("cli_build_out_dotdot", "output", ["build", "--shape", "ellipsoids", "-o", "..", "--particles", "400", "--field-voxels", "20000"], (3,)),
        ("cli_build_thin_surfaces", "abort", ["build", "{D}/seed.obj", "{D}/seed.obj", "-o", "{D}/out.palpate", "--unit", "mm"], (1,)),
        ("cli_build_swapped", "silent", ["build", "{D}/outer.vtp", "{D}/inner.vtp", "-o", "{D}/out2.palpate", "--unit", "mm"], (1,)),
        ("cli_build_field_voxels", "abort", ["build", "--shape", "ellipsoids", "-o", "{D}/out3.palpate", "--field-voxels", "1000000000000"], (1,)),
    ]
    import palpate
    from palpate.vtp import write_vtp
    a = palpate.ellipsoid_surface((0.02, 0.02, 0.035), 3)
    b = palpate.ellipsoid_surface((0.026, 0.026, 0.042), 3)
    write_vtp(c.path("inner.vtp"), a.points * 1e3, a.triangles)
    write_vtp(c.path("outer.vtp"), b.points * 1e3, b.triangles)
    for name, klass, argv, codes in cases:
        # The bombs are refused by the inflated-size pre-check: a LimitError, not any input error.
        c.cli(name, klass, argv, codes, contains="LimitError" if "bomb" in name else None)
    # Issue 35 item 4: with no PALPATE_MAX_MEMORY the budget follows RLIMIT_AS, and says so.
    c.cli("cli_info_bomb_vtu_rlimit", "bomb", ["info", "{D}/bomb.vtu"], (1,), contains="RLIMIT_AS", budget=None)
    c.cli("cli_info_npz_1e10_rows_rlimit", "bomb", ["info", "{D}/rows_1e10.npz"], (1,), contains="RLIMIT_AS", budget=None)


# ---------------------------------------------------------------------------------------------
# Issue 35 item 6: silent acceptances, each now a typed error naming the file or argument, the
# element and the reason (test_silent_acceptances.py runs these cases alone)
# ---------------------------------------------------------------------------------------------

def _gmsh22_binary(nodes, tets):
    """A binary MSH 2.2 file: ``nodes`` [(tag, x, y, z)], ``tets`` [(node tag, ...) x 4], as gmsh
    writes it (counts in ASCII, records in native little-endian binary)."""
    out = b"$MeshFormat\n2.2 1 8\n" + struct.pack("<i", 1) + b"\n$EndMeshFormat\n"
    out += b"$Nodes\n%d\n" % len(nodes) + b"".join(struct.pack("<i3d", *n) for n in nodes) + b"\n$EndNodes\n"
    # One block of tets (type 4), two tags (physical, geometrical) each.
    out += b"$Elements\n%d\n" % len(tets) + struct.pack("<3i", 4, len(tets), 2)
    out += b"".join(struct.pack("<7i", k + 1, 1, 1, *t) for k, t in enumerate(tets)) + b"\n$EndElements\n"
    return out


def _gmsh41_binary(nodes, tets):
    """A binary MSH 4.1 file (one node block, one element block; size_t = 8 bytes)."""
    out = b"$MeshFormat\n4.1 1 8\n" + struct.pack("<i", 1) + b"\n$EndMeshFormat\n"
    tags = [n[0] for n in nodes]
    out += b"$Nodes\n" + struct.pack("<4Q", 1, len(nodes), min(tags), max(tags))
    out += struct.pack("<3iQ", 3, 1, 0, len(nodes)) + b"".join(struct.pack("<Q", t) for t in tags)
    out += b"".join(struct.pack("<3d", *n[1:]) for n in nodes) + b"\n$EndNodes\n"
    out += b"$Elements\n" + struct.pack("<4Q", 1, len(tets), 1, len(tets)) + struct.pack("<3iQ", 3, 1, 4, len(tets))
    out += b"".join(struct.pack("<5Q", k + 1, *t) for k, t in enumerate(tets)) + b"\n$EndElements\n"
    return out


def _gmsh40_binary(nodes, tets, ulong="Q"):
    """A binary MSH 4.0 file as gmsh 4.0 writes it (version ``4``; tags int32, counts unsigned
    long: ``ulong`` "Q", 8 bytes, on Linux and macOS, "I", 4 bytes, on Windows)."""
    out = b"$MeshFormat\n4 1 8\n" + struct.pack("<i", 1) + b"\n$EndMeshFormat\n"
    out += b"$Nodes\n" + struct.pack(f"<2{ulong}", 1, len(nodes)) + struct.pack(f"<3i{ulong}", 1, 3, 0, len(nodes))
    out += b"".join(struct.pack("<i3d", *n) for n in nodes) + b"\n$EndNodes\n"
    out += b"$Elements\n" + struct.pack(f"<2{ulong}", 1, len(tets)) + struct.pack(f"<3i{ulong}", 1, 3, 4, len(tets))
    out += b"".join(struct.pack("<5i", k + 1, *t) for k, t in enumerate(tets)) + b"\n$EndElements\n"
    return out


#: Two tets sharing a face: nodes 1..5 (node 5 beyond the face 2-3-4 from node 1).
_TWO_TETS = [(1, 0.0, 0.0, 0.0), (2, 1.0, 0.0, 0.0), (3, 0.0, 1.0, 0.0), (4, 0.0, 0.0, 1.0), (5, 1.0, 1.0, 1.0)]

_VTU_UNKNOWN = """<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
<UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="2">
<Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0 0 0 1</DataArray></Points>
<Cells>
<DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3 0 1 2</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4 7</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10 99</DataArray>
</Cells></Piece></UnstructuredGrid></VTKFile>
"""


def _silent_cases(c: Corpus):
    one_tet = "p = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])\n"
    # 1. VTK cells of an unknown type, every node used by the tet: meshio's VTU and VTK 5.1
    # readers dropped the cell (a warning printed on stderr) and the mesh loaded without it.
    n = c.write("s35_vtu_unknown_cell_type.vtu", _VTU_UNKNOWN)
    c.api("s35_vtu_unknown_cell_type", "silent", _loader("mesh", n), ["error"], ["MeshError"], contains="VTK cell type 99")
    n = c.write("s35_vtk51_unknown_cell_type.vtk",
                "# vtk DataFile Version 5.1\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n0 0 0 1 0 0 0 1 0 0 0 1\n"
                "CELLS 3 7\nOFFSETS vtktypeint64\n0 4 7\nCONNECTIVITY vtktypeint64\n0 1 2 3 0 1 2\nCELL_TYPES 2\n10\n99\n")
    c.api("s35_vtk51_unknown_cell_type", "silent", _loader("mesh", n), ["error"], ["MeshError"], contains="VTK cell type 99")
    n = c.write("s35_vtk42_unknown_cell_type.vtk",
                "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n0 0 0 1 0 0 0 1 0 0 0 1\n"
                "CELLS 2 9\n4 0 1 2 3\n3 0 1 2\nCELL_TYPES 2\n10\n99\n")
    c.api("s35_vtk42_unknown_cell_type", "silent", _loader("mesh", n), ["error"], ["MeshError"], contains="99")
    # 2. Binary gmsh: an element's node tag 0 (gmsh tags start at 1) wrapped around to the node
    # with the largest tag (meshio's index arithmetic: tag - 1 = -1), so that the tet (0, 2, 4, 3)
    # silently became (5, 2, 4, 3).
    for ver, make in (("22", _gmsh22_binary), ("41", _gmsh41_binary)):
        n = c.write(f"s35_gmsh{ver}_bin_tag0.msh", make(_TWO_TETS, [(1, 2, 3, 4), (0, 2, 4, 3)]))
        c.api(f"s35_gmsh{ver}_bin_tag0", "silent", _loader("mesh", n), ["error"], ["MeshError"],
              contains="references node tag 0, which is not defined")
        # The same file with tag 5 where 0 was: valid, and read as written.
        n = c.write(f"s35_gmsh{ver}_bin_ok.msh", make(_TWO_TETS, [(1, 2, 3, 4), (5, 2, 4, 3)]))
        c.api(f"s35_gmsh{ver}_bin_ok", "seed", f"m = {_loader('mesh', n)}\n"
              "assert m.n_tets == 2 and abs(m.volume - 1 / 6 - 1 / 3) < 1e-12, m.volume", ["ok"])
    # 3. A tet repeated on duplicated nodes (same corners, other node numbers): twice the volume
    # and mass there. Same node numbers were refused already (DuplicateTet).
    c.api("s35_tetmesh_duplicate_on_copied_nodes", "silent", one_tet + "palpate.TetMesh(np.vstack([p, p]), [[0, 1, 2, 3], [4, 5, 6, 7]])",
          ["error"], ["MeshError"], contains="tet 1: duplicate of tet 0")
    c.api("s35_tetmesh_duplicate_same_nodes", "silent", one_tet + "palpate.TetMesh(p, [[0, 1, 2, 3], [1, 0, 3, 2]])",
          ["error"], ["MeshError"], contains="tet 1: duplicate of tet 0")
    np.savez(c.path("s35_duplicate_tet.npz"), points=np.vstack([np.eye(4, 3)[[3, 0, 1, 2]]] * 2),
             tets=np.array([[0, 1, 2, 3], [4, 5, 6, 7]]))
    c.api("s35_npz_duplicate_tet", "silent", _loader("mesh", "s35_duplicate_tet.npz"), ["error"], ["MeshError"],
          contains="duplicate of tet 0")
    # 4. Fractional triangle indices in a float array: numpy's astype(int64) truncated 1.5 to 1.
    tri = "v, t, part = palpate.ventricle_surface(24, 8); tf = t.astype(np.float64); tf[3, 1] += 0.5\n"
    for fn, call in (("orient", "palpate.orient_consistently(v, tf)"), ("repair", "palpate.repair_surface(v, tf)"),
                     ("write_vtp", "from palpate.vtp import write_vtp; write_vtp(os.path.join(D, 's35_frac.vtp'), v, tf)"),
                     ("vertex_normals", "from palpate.touch import vertex_normals; vertex_normals(v, tf)")):
        c.api(f"s35_fractional_triangles_{fn}", "silent", tri + call, ["error"], ["ParameterError"], contains="triangles[3, 1]")
    c.api("s35_fractional_triangles_trisurface", "silent", tri + "palpate.TriSurface(v, tf)", ["error"], ["ParameterTypeError"],
          contains="must be an integer array")
    c.api("s35_fractional_tets_vtu_series", "silent", one_tet + "palpate.VtuSeries(os.path.join(D, 's35_series'), [[0, 1, 2.5, 3]])",
          ["error"], ["ParameterError"], contains="tets[0, 2]")
    # 5. A model file whose particle lattice spacing is negative, zero or NaN (checksum refreshed:
    # a crafted file): it loaded, with a negative shell volume, and failed at the first tick. The
    # voxel grid's spacing was refused already, as "voxel grid inconsistent": now named.
    import palpate
    data = open(c.path("seed.palpate"), "rb").read()
    info = palpate.HybridModel.load(c.path("seed.palpate")).info()
    for field, key, says in (("spacing", "spacing_m", "particle lattice spacing"), ("voxel", "voxel_m", "voxel grid spacing")):
        h = info[key]
        i = data.find(struct.pack("<d", h), HEADER)
        assert i > 0 and data.count(struct.pack("<d", h)) == 1, f"the {key} bytes"
        for tag, bad in (("neg", -h), ("zero", 0.0), ("nan", float("nan"))):
            n = c.write(f"s35_model_{field}_{tag}.palpate", refresh_checksum(data[:i] + struct.pack("<d", bad) + data[i + 8:]))
            c.api(f"s35_model_{field}_{tag}", "silent", _loader("model", n), ["error"], ["ModelFileError"], contains=says)
    # 6. A force of 1e300 N: refused where it enters (the bound: finite, |f| <= 1e6 N).
    for name, code in (("set_forces", "b = body(); f = np.zeros((b.n_nodes, 3)); f[5, 2] = 1e300\n" + _UNCHANGED.format(call="b.set_forces(f)")),
                       ("static_solve", "b = body(); f = np.zeros((b.n_nodes, 3)); f[5, 2] = 1e300; b.static_solve(f)"),
                       ("run_probe", "b = body(); b.run_probe([20], (0, 0, -1e300), 0.1, 5)"),
                       ("run_loads", "b = body(); b.run_loads([([20], (0, 0, 1e300), 0.1)], 5)"),
                       ("set_state", "b = body(); s = b.get_state(); s['forces'][5, 2] = 1e300; b.set_state(s)")):
        c.api(f"s35_body_force_1e300_{name}", "silent", _BODY + code, ["error"], ["ParameterError"], contains="over the bound of 1e6 N")
    c.api("s35_pb_force_1e300", "silent", _PB + "b = pb(); f = np.zeros((64, 3)); f[3, 0] = 1e300; b.set_forces(f)",
          ["error"], ["ParameterError"], contains="over the bound of 1e6 N")
    c.api("s35_body_force_1e5_ok", "seed", _BODY + "b = body(); f = np.zeros((b.n_nodes, 3)); f[5, 2] = 1e5; b.set_forces(f)", ["ok"])
    # 7. static_solve(load_steps=0): taken as 1 without a word.
    c.api("s35_static_solve_load_steps_0", "silent", _BODY + "b = body(); b.static_solve(load_steps=0)",
          ["error"], ["ParameterError"], contains="load_steps")
    # 8. NaN max_wall_s (never reached: no cap) and stable_limit (every run "unstable").
    for name, code in (("run_probe_max_wall_nan", "b = body(); b.run_probe([20], (0, 0, -1e-3), 0.1, 5, max_wall_s=float('nan'))"),
                       ("run_probe_stable_nan", "b = body(); b.run_probe([20], (0, 0, -1e-3), 0.1, 5, stable_limit=float('nan'))"),
                       ("run_loads_max_wall_nan", "b = body(); b.run_loads([([20], (0, 0, -1e-3), 0.1)], 5, max_wall_s=float('nan'))"),
                       ("run_loads_stable_nan", "b = body(); b.run_loads([([20], (0, 0, -1e-3), 0.1)], 5, stable_limit=float('nan'))"),
                       ("run_probe_max_wall_negative", "b = body(); b.run_probe([20], (0, 0, -1e-3), 0.1, 5, max_wall_s=-1.0)")):
        c.api(f"s35_body_{name}", "silent", _BODY + code, ["error"], ["ParameterError"],
              contains="max_wall_s" if "wall" in name else "stable_limit")
    c.api("s35_pb_run_timed_max_wall_nan", "silent", _PB + "b = pb(); b.run_timed(5, max_wall_s=float('nan'))",
          ["error"], ["ParameterError"], contains="max_wall_s")
    # 9. A VTU series frame with fewer points, or point data shorter than the points: the files
    # were written and ParaView failed on them later.
    series = _BODY + "b = body(); s = palpate.VtuSeries(os.path.join(D, 's35_series9'), mesh.tets)\n"
    c.api("s35_vtu_series_short_positions", "silent", series + "s.write(0.0, b.positions[:-3], b.displacements[:-3], b.velocities[:-3])",
          ["error"], ["ParameterError"], contains="positions")
    c.api("s35_vtu_series_short_point_data", "silent",
          series + "s.write(0.0, b.positions, b.displacements[:-1], b.velocities)", ["error"], ["ParameterError"], contains="displacement")
    c.api("s35_vtu_series_short_extra", "silent",
          series + "s.write(0.0, b.positions, b.displacements, b.velocities, point_data={'p': np.zeros(5)})",
          ["error"], ["ParameterError"], contains="point_data['p']")
    c.api("s35_vtu_series_short_cell_data", "silent",
          series + "s.write(0.0, b.positions, b.displacements, b.velocities, cell_data={'e': np.zeros(2)})",
          ["error"], ["ParameterError"], contains="cell_data['e']")
