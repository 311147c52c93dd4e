"""Small, strict readers for gmsh MSH 2.2 / 4.0 / 4.1 and TetGen .node/.ele files, and the
structure check of Medit .mesh files before meshio reads them.

meshio reads these formats too, but it maps unknown gmsh node tags silently (a tag of 0 or -1 wraps
around to the last node, in ASCII and binary files) and its TetGen reader stops at comments without saying where. These
readers report every defect with the file, the line (or byte) and the element, which is what
:func:`palpate.load_mesh` promises. Binary gmsh MSH 2.2, 4.0 and 4.1 are read here too. MSH 4.0
went to meshio before, whose 4.0 reader maps node tags by index arithmetic as well (an undefined
tag 0 becomes -1, the last node) and fails on parametric nodes.

Each reader returns ``(points, blocks, node_labels)``: ``points`` a float64 ``(n, 3)`` array in
the file's units, ``blocks`` a list of :class:`CellBlock` with 0-based node indices (int64) and, per
cell, a human-readable label (e.g. ``"gmsh element 12, line 40"``), ``node_labels`` the file's name
of each node (e.g. ``"gmsh node 7"``), both for error messages.
"""
from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple, Type

import numpy as np

from ._palpate import LimitError, MeshError, memory_budget

# ---------------------------------------------------------------------------------------------
# Input files and the memory budget (the Rust core's crate::limits, read through the binding)
# ---------------------------------------------------------------------------------------------

#: The budget when no limit of the machine can be read (8 GiB), as ``limits::DEFAULT_MAX_MEMORY``.
DEFAULT_MAX_MEMORY = 8 << 30
_UNITS = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_size(text: str) -> Optional[int]:
    """``"8G"``, ``"512M"``, ``"1e9"`` in bytes (powers of 1024), as the core parses it; None if
    unreadable or not positive."""
    t = text.strip().upper().rstrip("B").rstrip("I")
    mul = 1
    if t and t[-1] in _UNITS:
        t, mul = t[:-1], _UNITS[t[-1]]
    try:
        v = float(t) * mul
    except ValueError:
        return None
    return int(v) if 1 <= v < 1.8e19 else None


def budget() -> Tuple[int, str]:
    """The memory budget [bytes] and its source, from the core (:func:`palpate.memory_budget`):
    one rule for the Rust checks and the Python readers."""
    return memory_budget()


def max_memory() -> int:
    """The memory budget [bytes] (:func:`palpate.memory_budget`)."""
    return budget()[0]


def _human(b: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if b < 1024 or unit == "PiB":
            return f"{b:.0f} B" if unit == "B" else f"{b:.1f} {unit}"
        b /= 1024
    return f"{b}"


def check_budget(what: str, nbytes: float, name: Optional[str] = None) -> None:
    """Refuse ``nbytes`` for ``what`` (prefixed by the file ``name``) over the budget, before
    anything is allocated: a :class:`palpate.LimitError` saying what, how much, the budget and
    how to raise it."""
    budget, source = memory_budget()
    if nbytes <= budget:
        return
    prefix = f"{name}: " if name else ""
    err = LimitError(f"{prefix}{what}: needs {_human(nbytes)}, over the memory budget of {_human(budget)} "
                     f"({source}); set the environment variable PALPATE_MAX_MEMORY to change it (e.g. "
                     "PALPATE_MAX_MEMORY=32G) if the machine has the memory, or check the input")
    err.requested, err.budget, err.budget_source = float(nbytes), budget, source
    raise err


def check_input_file(path: str, error: Type[Exception] = MeshError) -> int:
    """The size of the regular file ``path`` [bytes], after refusing with ``error`` a missing file,
    a directory, and anything that is not a regular file (a FIFO or a device would block the read
    forever or never end), and with a LimitError a file over the memory budget."""
    name = os.path.basename(path) or path
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise error(f"{name}: no such file ({path})") from None
    except OSError as e:
        raise error(f"{name}: cannot open: {e.strerror or e}") from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"{name}: is a directory, not a file ({path})")
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{name}: not a regular file (a FIFO, socket or device): palpate reads regular files only")
    check_budget("reading the file", st.st_size, name)
    return st.st_size

#: gmsh element type code -> (meshio-style name, nodes per element, topological dimension)
GMSH_TYPES: Dict[int, Tuple[str, int, int]] = {
    1: ("line", 2, 1), 2: ("triangle", 3, 2), 3: ("quad", 4, 2), 4: ("tetra", 4, 3),
    5: ("hexahedron", 8, 3), 6: ("wedge", 6, 3), 7: ("pyramid", 5, 3), 8: ("line3", 3, 1),
    9: ("triangle6", 6, 2), 10: ("quad9", 9, 2), 11: ("tetra10", 10, 3), 12: ("hexahedron27", 27, 3),
    13: ("wedge18", 18, 3), 14: ("pyramid14", 14, 3), 15: ("vertex", 1, 0), 16: ("quad8", 8, 2),
    17: ("hexahedron20", 20, 3), 18: ("wedge15", 15, 3), 19: ("pyramid13", 13, 3),
    20: ("triangle9", 9, 2), 21: ("triangle10", 10, 2), 26: ("line4", 4, 1), 29: ("tetra20", 20, 3),
}


@dataclass
class CellBlock:
    """Cells of one type: ``data`` (n_cells, nodes_per_cell) 0-based int64; ``labels`` one per cell."""
    type: str
    dim: int
    data: np.ndarray
    labels: List[str] = field(default_factory=list)


class _Lines:
    """Line iterator with 1-based line numbers and a helpful end-of-file error."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.name = os.path.basename(path)
        self.lines = text.splitlines()
        self.i = 0  # index of the next line

    @property
    def lineno(self) -> int:
        """1-based number of the line returned last."""
        return self.i

    def next(self, context: str) -> str:
        while self.i < len(self.lines):
            line = self.lines[self.i]
            self.i += 1
            if line.strip():
                return line.strip()
        raise MeshError(f"{self.name}: unexpected end of file (truncated?) while reading {context}")

    def error(self, msg: str) -> MeshError:
        return MeshError(f"{self.name}: line {self.lineno}: {msg}")

    def ints(self, line: str, context: str) -> List[int]:
        try:
            return [int(t) for t in line.split()]
        except ValueError:
            raise self.error(f"expected integers in {context}, got {line[:60]!r}") from None

    def floats(self, tokens: List[str], context: str) -> List[float]:
        try:
            return [float(t) for t in tokens]
        except ValueError:
            raise self.error(f"expected numbers in {context}, got {' '.join(tokens)[:60]!r}") from None


def read_text(path: str, error: Type[Exception] = MeshError) -> str:
    """The file as text; a clear ``error`` (a MeshError by default) for a missing, empty or binary
    file."""
    name = os.path.basename(path)
    check_input_file(path, error)
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as e:
        raise error(f"{name}: cannot read: {e.strerror or e}") from None
    if not raw.strip():
        raise error(f"{name}: empty file")
    if b"\x00" in raw:
        raise error(f"{name}: not a text file (contains NUL bytes: binary or garbage)")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise error(f"{name}: not a text file (invalid UTF-8 at byte {e.start}: binary or garbage)") from None


def vtk_xml_inflated_precheck(path: str, error: Type[Exception] = MeshError) -> None:
    """The bytes a compressed VTK XML file (.vtu, .vtp) inflates to, summed from its block headers
    (``[nblocks, blocksize, lastsize, ...]`` before each array), against the memory budget before
    any block is inflated: a 3 MB file of zlib streams can inflate to 3 GB and more."""
    import base64
    import binascii
    import re
    import struct

    name = os.path.basename(path)
    with open(path, "rb") as fh:
        raw = fh.read()
    head = raw[:4096]
    if b"compressor=" not in head:
        return
    m = re.search(rb'header_type\s*=\s*"(UInt32|UInt64)"', head)
    big_endian = b'byte_order="BigEndian"' in head
    fmt, hs = ("Q", 8) if m and m.group(1) == b"UInt64" else ("I", 4)
    fmt3 = (">" if big_endian else "<") + fmt * 3
    total = 0

    def add(header: bytes, where: str) -> None:
        nonlocal total
        if len(header) < 3 * hs:
            return  # a cut-short header is the reader's error to name
        nblocks, bsize, last = struct.unpack(fmt3, header[:3 * hs])
        total += max(nblocks - 1, 0) * bsize + (last or bsize if nblocks else 0)
        if total > max_memory():
            check_budget(f"compressed data inflates to at least {total} bytes (at {where})", total, name)

    def b64_head(text: bytes) -> bytes:
        chars = 4 * ((3 * hs + 2) // 3)
        try:
            return base64.b64decode(text[:chars] + b"=" * (-len(text[:chars]) % 4))
        except (binascii.Error, ValueError):
            return b""

    app = raw.find(b"<AppendedData")
    xml = raw if app < 0 else raw[:app]
    for k, mm in enumerate(re.finditer(rb"<DataArray([^>]*)>\s*([A-Za-z0-9+/=]{8,})", xml)):
        if b'format="binary"' in mm.group(1):
            add(b64_head(mm.group(2)), f"inline array {k}, byte {mm.start(2)}")
    if app >= 0:
        enc = re.search(rb'encoding\s*=\s*"(raw|base64)"', raw[app:app + 200])
        start = raw.find(b"_", app) + 1
        for k, mm in enumerate(re.finditer(rb"<DataArray([^>]*)>", xml)):
            attrs = mm.group(1)
            off = re.search(rb'offset\s*=\s*"\s*(\d+)\s*"', attrs)
            if b'format="appended"' not in attrs or off is None or start <= 0:
                continue
            pos = start + int(off.group(1))
            header = raw[pos:pos + 3 * hs] if enc is None or enc.group(1) == b"raw" else b64_head(raw[pos:pos + 64])
            add(header, f"appended array {k}, byte {pos}")


def npz_precheck(path: str, error: Type[Exception] = MeshError) -> None:
    """Each member of the NPZ ``path`` against the memory budget before numpy allocates it: the
    zip directory's uncompressed size (a 3 MB file can hold a 3 GB array of zeros) and the shape
    x dtype its ``.npy`` header claims (numpy allocates the whole array from the header before it
    reads a byte: a 300-byte member claiming 1e10 rows asks for 240 GB). A header claiming more
    bytes than its member holds is refused with ``error`` (a lie numpy would still allocate for).
    Only headers are read (a few hundred bytes a member); nothing is inflated."""
    import zipfile

    name = os.path.basename(path)
    try:
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                member = info.filename
                check_budget(f"zip member {member!r} inflates to {info.file_size} bytes", info.file_size, name)
                if not member.endswith(".npy"):
                    continue
                with z.open(info) as fp:
                    shape, dtype, header_end = _npy_header(fp, f"{name}: member {member!r}", error)
                count = float(np.prod([float(d) for d in shape])) if shape else 1.0
                nbytes = count * dtype.itemsize
                dims = " x ".join(str(d) for d in shape) or "scalar"
                check_budget(f"member {member!r}: its .npy header claims a {dims} array of {dtype} "
                             f"({nbytes:.3e} bytes)", nbytes, name)
                if not dtype.hasobject and nbytes > info.file_size - header_end:
                    raise error(f"{name}: member {member!r}: its .npy header claims a {dims} array of {dtype} "
                                f"({nbytes:.0f} bytes) but the member holds {max(info.file_size - header_end, 0)} "
                                "bytes of data (truncated or corrupt)")
    except (LimitError, error):
        raise
    except zipfile.BadZipFile as e:
        raise error(f"{name}: cannot read as NPZ (not a zip archive: {e})") from None
    except Exception as e:  # noqa: BLE001 - untrusted bytes: zlib.error, an unsupported method,
        # an encrypted member, a bad offset... each a refusal of the file, not a traceback
        raise error(f"{name}: cannot read as NPZ ({type(e).__name__}: {e})") from None


def _npy_header(fp, where: str, error: Type[Exception]):
    """``(shape, dtype, header_end)`` of the .npy stream ``fp`` (numpy's own header readers,
    which parse with ``ast.literal_eval`` and bound the header's length)."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fp)
        if version == (1, 0):
            shape, _fortran, dtype = fmt.read_array_header_1_0(fp)
        elif version == (2, 0):
            shape, _fortran, dtype = fmt.read_array_header_2_0(fp)
        else:  # (3, 0): a UTF-8 header, read by the same private helper numpy.load uses
            shape, _fortran, dtype = fmt._read_array_header(fp, version)
    except Exception as e:  # noqa: BLE001 - untrusted bytes: numpy's parser raises ValueError,
        # SyntaxError, tokenize.TokenError, UnicodeDecodeError... all mean "not a header"
        raise error(f"{where}: not a valid .npy header ({type(e).__name__}: {e})") from None
    if any(not isinstance(d, int) or d < 0 for d in shape):
        raise error(f"{where}: invalid .npy shape {shape}")
    return shape, np.dtype(dtype), fp.tell()


# ---------------------------------------------------------------------------------------------
# gmsh
# ---------------------------------------------------------------------------------------------

def gmsh_format(path: str) -> Tuple[str, bool]:
    """(version string, is_binary) from a gmsh file's $MeshFormat header."""
    name = os.path.basename(path)
    check_input_file(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(256)
    except OSError as e:
        raise MeshError(f"{name}: cannot read: {e.strerror or e}") from None
    if not head.strip():
        raise MeshError(f"{name}: empty file")
    lines = head.split(b"\n")
    first = lines[0].strip()
    if first != b"$MeshFormat":
        shown = first[:40].decode("utf-8", "replace")
        raise MeshError(f"{name}: line 1: not a gmsh MSH file: expected '$MeshFormat', got {shown!r}")
    if len(lines) < 2:
        raise MeshError(f"{name}: unexpected end of file (truncated?) in $MeshFormat")
    parts = lines[1].split()
    if len(parts) < 3:
        raise MeshError(f"{name}: line 2: malformed $MeshFormat line {lines[1][:40]!r}: "
                        "expected 'version file-type data-size'")
    version = parts[0].decode("utf-8", "replace")
    try:
        binary = int(parts[1]) == 1
    except ValueError:
        raise MeshError(f"{name}: line 2: malformed $MeshFormat file-type {parts[1][:10]!r}") from None
    if version.split(".")[0] not in ("2", "4"):
        raise MeshError(f"{name}: line 2: unsupported gmsh MSH version {version!r} (palpate reads 2.x and 4.x)")
    return version, binary


#: How to rewrite a gmsh file in a layout palpate reads (gmsh's own command line).
GMSH_CONVERT = "gmsh IN.msh -format msh41 -save -o OUT.msh (or -format msh22)"


def gmsh_layout(name: str, version: str) -> str:
    """The $Nodes / $Elements layout of a gmsh file with $MeshFormat ``version``: ``"2"`` (2.x),
    ``"4.0"`` (``4`` or ``4.0``: gmsh 4.0 writes ``4``, and gmsh reads a ``4`` file as 4.0, where
    meshio takes it for 4.1, meshio issue 797) or ``"4.1"``; a MeshError for any other 4.x."""
    if version.startswith("2"):
        return "2"
    if version.startswith("4.1"):
        return "4.1"
    try:
        if float(version) == 4.0:
            return "4.0"
    except ValueError:
        pass
    raise MeshError(f"{name}: line 2: unsupported gmsh MSH version {version!r}: palpate reads MSH 2.2, 4.0 "
                    f"and 4.1; convert with {GMSH_CONVERT}")


def gmsh_binary_precheck(path: str) -> None:
    """A binary gmsh file's $Nodes / $Elements counts against the file's size and the budget,
    before meshio allocates them (a 200-byte file claiming 1e8 nodes made it allocate 2.4 GB)."""
    name = os.path.basename(path)
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        raw = fh.read(min(size, 1 << 16)) if size > (1 << 16) else fh.read()
    for section, per_item in ((b"$Nodes\n", 3 * 8), (b"$Elements\n", 4 * 4)):
        i = raw.find(section)
        if i < 0:
            continue
        j = i + len(section)
        line_end = raw.find(b"\n", j)
        line = raw[j:line_end if line_end >= 0 else None]
        counts = []
        try:
            counts = [int(t) for t in line.split()]
        except ValueError:
            counts = []
        if len(counts) not in (1, 4) and len(raw) >= j + 16:  # MSH 4.1 binary: size_t numbers
            import struct
            counts = list(struct.unpack("<QQ", raw[j:j + 16]))
        if not counts:
            continue
        n = counts[1] if len(counts) >= 2 else counts[0]
        what = section.strip().decode()
        if n * per_item > size:
            raise MeshError(f"{name}: byte {j}: {what} announces {n} entries, which need at least {n * per_item} "
                            f"bytes; the file has {size} (truncated or corrupt header)")
        check_budget(f"{what} of {n} entries", n * 64.0, name)


# ---------------------------------------------------------------------------------------------
# VTK legacy (read by meshio)
# ---------------------------------------------------------------------------------------------

_VTK_SIZES = {"bit": 1, "unsigned_char": 1, "char": 1, "unsigned_short": 2, "short": 2, "unsigned_int": 4,
              "int": 4, "unsigned_long": 8, "long": 8, "vtktypeint64": 8, "vtktypeuint64": 8, "float": 4,
              "double": 8}


def vtk_legacy_precheck(path: str, error: Type[Exception] = MeshError) -> None:
    """A legacy VTK file's POINTS and CELLS counts against the file's size and the budget, before
    meshio trusts them: its binary reader asks numpy for the announced count up front (a 200-byte
    file announcing 4e8 points asked for 9.6 GB). Binary data takes the type's size per number,
    ASCII at least 2 bytes (a digit and a separator)."""
    name = os.path.basename(path)
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    lines = head.split(b"\n")
    binary = any(line.strip().upper() == b"BINARY" for line in lines[:4])
    offset = 0
    for line in lines:
        t = line.split()
        offset += len(line) + 1
        if not t or t[0].upper() not in (b"POINTS", b"CELLS"):
            continue
        key = t[0].upper().decode()
        try:
            n = int(t[1])
            if key == "POINTS":
                numbers, per = 3 * n, _VTK_SIZES.get(t[2].decode("latin-1").lower(), 8) if len(t) > 2 else 8
            else:  # CELLS n size (VTK 4) or CELLS n_offsets n_connectivity (VTK 5): ints, or int64
                numbers, per = int(t[2]) if len(t) > 2 else n, 4
        except (ValueError, IndexError):
            continue  # meshio's own error names a malformed line
        need = numbers * (per if binary else 2)
        if n < 0 or numbers < 0 or need > size:
            raise error(f"{name}: byte {offset - len(line) - 1}: {key} announces {n} "
                        f"{'points' if key == 'POINTS' else 'cells'} ({numbers} numbers), which need at least "
                        f"{need} bytes; the file has {size} (truncated or corrupt header)")
        check_budget(f"{key} of {n} entries", numbers * 8.0 * 3, name)


# ---------------------------------------------------------------------------------------------
# Medit (read by meshio)
# ---------------------------------------------------------------------------------------------

#: Sections of an ASCII Medit file that meshio's reader (meshio 5.3, ``medit/_medit.py``) keeps,
#: and the numbers per entry ("d": the dimension): vertices and cells, each with its reference
#: (the cells' references are :func:`palpate.read_mesh_sets`' ``"ref <k>"`` sets).
_MEDIT_KEPT = {"Vertices": "d+1", "Edges": 3, "Triangles": 4, "Quadrilaterals": 5, "Tetrahedra": 5,
               "Prisms": 7, "Pyramids": 6, "Hexahedra": 9, "Hexaedra": 9}

#: Sections meshio reads past and drops: with a line on stderr ("Meshio doesn't know keyword ...
#: Skipping.") for RequiredVertices, Ridges, Tangents and TangentAtVertices, without a word for
#: the others. None of them holds a vertex, a cell or a reference: the tetrahedra palpate builds,
#: and the sets, are the same with or without them, so the file is read and a MeshWarning names
#: them (what they hold, and why palpate can do without it, by group):
_MEDIT_DROPPED = {
    # feature marks for a remesher (mmg, Medit): vertex and edge numbers, no coordinates;
    # palpate does not remesh
    "Corners": 1, "RequiredVertices": 1, "Ridges": 1,
    # normals and tangents of the boundary: palpate computes the normals it uses (contact,
    # palpation) from the surface triangles
    "Normals": "d", "NormalAtVertices": 2, "Tangents": "d", "TangentAtVertices": 2,
    # links from the mesh to a CAD geometry (FreeFem, bamg): palpate simulates the mesh alone
    "SubDomainFromMesh": 4, "VertexOnGeometricVertex": 2, "VertexOnGeometricEdge": 3, "EdgeOnGeometricEdge": 2,
}
#: Of those, the ones meshio reads past by skipping ``count`` lines, not ``count`` entries: one
#: entry a line, or it skips into (and drops) the next section without a word (a Triangles
#: section after a RequiredVertices one written several numbers a line was lost that way).
_MEDIT_BY_LINE = ("RequiredVertices", "Ridges", "Tangents", "TangentAtVertices")
#: One line after the keyword that meshio skips, whatever it holds: a title, a geometry file's name.
_MEDIT_ONE_LINE = ("Identifier", "Geometry")
#: Any other keyword stops meshio's reader (ReadError "Unknown keyword"): solution fields
#: (SolAtVertices, ...), RequiredEdges, RequiredTriangles, ... are refused here by name, before
#: it runs. Binary Medit (.meshb) is not read (``load_mesh`` takes ``.mesh`` only).


def _medit_keyword_line(line: str) -> bool:
    """A line meshio's reader takes for a keyword: its first word is alphabetic (and not nan or inf,
    which are numbers in a section's data)."""
    t = line.split(None, 1)
    if not t or not t[0].isalpha():
        return False
    try:
        float(t[0])
        return False
    except ValueError:
        return True


def _n(k: int, one: str, many: str) -> str:
    return f"{k} {one if k == 1 else many}"


#: The ``MeshVersionFormatted`` values of an ASCII Medit file. In libMeshb (Medit's library) the
#: version says how a *binary* .meshb stores its numbers: 1 float32 reals, 2 float64 reals, 3 also
#: 64-bit file positions, 4 also 64-bit integers; an ASCII file's text is the same whatever it says
#: (numbers written out in full, any number of digits). meshio's ASCII reader takes 0 to 2 only
#: (the float type it parses the vertices with) and failed on 3 and 4 with a bare ``KeyError:
#: '3'``; palpate parses the vertices itself, in double precision, so every version reads alike.
_MEDIT_VERSIONS = ("0", "1", "2", "3", "4")


@dataclass
class MeditCheck:
    """What :func:`medit_precheck` found: ``skipped``, the sections read past (``"<keyword>
    (<count> entries, line <n>)"``, for the caller's MeshWarning); ``vertices``, the Vertices
    section's coordinates ``(n, dim)`` parsed from the text in double precision, and
    ``vertex_refs``, their references ``(n,)`` int64 (both None without a Vertices section);
    ``meshio_text``, for a file of version 3 or 4 only, its text with the version line written
    ``MeshVersionFormatted 2`` (the same ASCII content under a version meshio's reader takes)."""
    skipped: List[str]
    vertices: Optional[np.ndarray] = None
    vertex_refs: Optional[np.ndarray] = None
    meshio_text: Optional[str] = None


def _medit_vertices(name: str, lines: List[str], start: int, end: int, count: int, dim: int):
    """The Vertices entries of ``lines[start:end]`` (comment lines left out; their count checked
    already), as float64 coordinates ``(count, dim)`` and int64 references ``(count,)``. meshio
    reads them as float32 under ``MeshVersionFormatted 0`` or ``1`` (the version says how a binary
    .meshb stores its reals, not how many digits an ASCII file holds): 0.1234567891 came back as
    0.12345679104328156, and a reference over 2**24 was rounded to an even one."""
    tokens: List[str] = []
    for k in range(start, end):
        if not lines[k].lstrip().startswith("#"):
            tokens.extend(lines[k].split())
    try:
        values = np.array(tokens, dtype=np.float64).reshape(count, dim + 1)
    except ValueError:
        for k in range(start, end):
            for t in lines[k].split() if not lines[k].lstrip().startswith("#") else []:
                try:
                    float(t)
                except ValueError:
                    raise MeshError(f"{name}: line {k + 1}: expected numbers in Vertices, got {t[:40]!r}") from None
        raise
    coords = values[:, :dim].copy()
    try:
        # As integers, exactly: a version 4 file's references are 64-bit (over 2**53 a float64
        # would round them).
        return coords, np.array(tokens[dim::dim + 1], dtype=np.int64)
    except (ValueError, OverflowError):
        pass
    # Written otherwise ("2.0", "1e3"): whole numbers within float64's exact integers only.
    refs = values[:, dim]
    bad = np.flatnonzero(~np.isfinite(refs) | (refs != np.round(refs)) | (np.abs(refs) >= 2.0 ** 53))
    if len(bad):
        raise MeshError(f"{name}: Vertices: vertex {bad[0] + 1} (as Medit numbers them, from 1) has reference "
                        f"{tokens[bad[0] * (dim + 1) + dim]!r}: a reference is a whole number ({len(bad)} such "
                        f"vertex{'' if len(bad) == 1 else 'es'})")
    return coords, refs.astype(np.int64)


def medit_precheck(path: str) -> MeditCheck:
    """Check the sections of an ASCII Medit file before meshio reads it, and name the ones it
    would drop. Every section's count must match the numbers that follow it up to the next
    keyword (a wrong count is refused with the line; meshio reads numbers by count across line
    ends and would misread the rest), a keyword meshio does not know is refused by name, and the
    sections meshio skips line by line must hold one entry a line, and ``MeshVersionFormatted``
    must be one of :data:`_MEDIT_VERSIONS`. Returns a :class:`MeditCheck`:
    for the sections that are read past (:data:`_MEDIT_DROPPED`, :data:`_MEDIT_ONE_LINE`),
    ``"<keyword> (<count> entries, line <n>)"`` (the keyword's line), for the caller's
    MeshWarning, and the vertices and their references as the text gives them (the caller puts
    them in place of meshio's, which may be float32: :func:`_medit_vertices`)."""
    name = os.path.basename(path)
    lines = read_text(path).splitlines()
    dim: Optional[int] = None
    skipped: List[str] = []
    out = MeditCheck(skipped)
    meshio_lines: Optional[List[str]] = None   # the text for meshio, if a version line is rewritten
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        i += 1
        if not line or line.startswith("#"):
            continue
        tok = line.split()
        kw = tok[0]
        if not _medit_keyword_line(line):
            raise MeshError(f"{name}: line {i}: expected a Medit keyword (Vertices, Tetrahedra, ...), got "
                            f"{line[:40]!r} (a wrong count in the section before?)")
        if kw == "End":
            continue
        if kw == "MeshVersionFormatted":
            if len(tok) < 2:
                raise MeshError(f"{name}: line {i}: expected the version on the 'MeshVersionFormatted' line")
            if tok[1] not in _MEDIT_VERSIONS:
                raise MeshError(f"{name}: line {i}: MeshVersionFormatted {tok[1][:20]!r} is not a Medit version: "
                                "palpate reads ASCII Medit files of versions 0 to 4 (the version says how a binary "
                                ".meshb stores its numbers; an ASCII file reads alike under any of them)")
            if tok[1] in ("3", "4"):
                # Versions 3 and 4 (64-bit positions, 64-bit integers) differ from 2 in the binary
                # format only: meshio reads the text as version 2 (see _MEDIT_VERSIONS).
                meshio_lines = meshio_lines or list(lines)
                meshio_lines[i - 1] = "MeshVersionFormatted 2"
            continue
        if kw == "Dimension":
            value = tok[1] if len(tok) > 1 else (lines[i].strip() if i < len(lines) else "")
            i += 0 if len(tok) > 1 else 1
            try:
                dim = int(value)
            except ValueError:
                raise MeshError(f"{name}: line {i}: expected the dimension after 'Dimension', "
                                f"got {value[:40]!r}") from None
            continue
        if kw in _MEDIT_ONE_LINE:
            if i < len(lines) and _medit_keyword_line(lines[i]):
                raise MeshError(f"{name}: line {i + 1}: {kw} at line {i} has no value line: meshio skips the line "
                                f"after it, here the keyword {lines[i].split()[0]!r} (and that section's data would "
                                "be misread)")
            skipped.append(f"{kw} (line {i})")
            i += 1
            continue
        per = _MEDIT_KEPT.get(kw, _MEDIT_DROPPED.get(kw))
        if per is None:
            raise MeshError(f"{name}: line {i}: Medit keyword {kw!r} is not one palpate can read past (meshio's "
                            f"Medit reader stops at it): palpate reads {', '.join(_MEDIT_KEPT)}, and skips with a "
                            f"warning {', '.join(list(_MEDIT_DROPPED) + list(_MEDIT_ONE_LINE))}; remove the "
                            f"{kw} section to load the mesh")
        if isinstance(per, str):
            if dim is None:
                raise MeshError(f"{name}: line {i}: {kw} before Dimension (its entries have 'Dimension' numbers)")
            per = dim + (1 if per == "d+1" else 0)
        at = i
        count_text = lines[i].strip() if i < len(lines) else ""
        try:
            count = int(count_text)
        except ValueError:
            raise MeshError(f"{name}: line {at + 1}: expected the number of {kw} entries alone on the line after "
                            f"'{kw}', got {count_text[:40]!r}") from None
        if count < 0:
            raise MeshError(f"{name}: line {at + 1}: {kw}: negative count {count}")
        i += 1
        start, numbers = i, 0
        while i < len(lines) and not _medit_keyword_line(lines[i]):
            if not lines[i].lstrip().startswith("#"):
                numbers += len(lines[i].split())
            i += 1
        if numbers != count * per:
            raise MeshError(f"{name}: line {at + 1}: {kw} announces {_n(count, 'entry', 'entries')} of "
                            f"{_n(per, 'number', 'numbers')} ({count * per}), lines {start + 1}..{i} hold {numbers} "
                            "(a wrong count, or a truncated or malformed entry)")
        if kw == "Vertices":
            out.vertices, out.vertex_refs = _medit_vertices(name, lines, start, i, count, per - 1)
        if kw in _MEDIT_BY_LINE:
            for k in range(start, start + count):
                if len(lines[k].split()) != per:
                    raise MeshError(f"{name}: line {k + 1}: {kw} entries must be one a line "
                                    f"({_n(per, 'number', 'numbers')}), got {len(lines[k].split())}: meshio reads "
                                    f"past {kw} by skipping {count} lines, and would skip into the next section and "
                                    "drop it")
        if kw in _MEDIT_DROPPED:
            skipped.append(f"{kw} ({_n(count, 'entry', 'entries')}, line {at})")
    if meshio_lines is not None:
        out.meshio_text = "\n".join(meshio_lines) + "\n"
    return out


# ---------------------------------------------------------------------------------------------
# Abaqus (read by meshio)
# ---------------------------------------------------------------------------------------------

#: Keywords meshio's Abaqus reader (meshio 5.3, ``abaqus/_abaqus.py``) reads: the mesh and its sets.
_ABAQUS_READ = ("NODE", "ELEMENT", "NSET", "ELSET")

#: Keywords that neither make, copy nor move a node or an element: the model's other definitions,
#: which palpate does not take from an .inp file (a scene gives the material, the fixed nodes and
#: the loads). meshio reads past them, and so does palpate, without a word. Compared without
#: blanks (``*SOLID SECTION`` and ``*SOLIDSECTION`` alike). *TRANSFORM turns the directions of a
#: node's degrees of freedom (for boundary conditions and loads), not its coordinates; *ORIENTATION
#: the material's axes. *INSTANCE is checked apart (:func:`abaqus_precheck`).
_ABAQUS_IGNORED = frozenset(k.replace(" ", "") for k in (
    # the file, the model's structure
    "HEADING", "PREPRINT", "PHYSICAL CONSTANTS", "RESTART", "FILE FORMAT", "PART", "END PART", "ASSEMBLY",
    "END ASSEMBLY", "END INSTANCE", "ORIENTATION", "TRANSFORM",
    # materials and sections
    "MATERIAL", "ELASTIC", "HYPERELASTIC", "HYPERFOAM", "VISCOELASTIC", "PLASTIC", "DENSITY", "DAMPING",
    "EXPANSION", "CONDUCTIVITY", "SPECIFIC HEAT", "USER MATERIAL", "DEPVAR", "SOLID SECTION", "SHELL SECTION",
    "MEMBRANE SECTION", "BEAM SECTION", "SECTION CONTROLS",
    # surfaces, constraints and contact
    "SURFACE", "SURFACE INTERACTION", "SURFACE BEHAVIOR", "FRICTION", "CONTACT", "CONTACT PAIR",
    "CONTACT INCLUSIONS", "CONTACT PROPERTY ASSIGNMENT", "TIE", "COUPLING", "KINEMATIC", "DISTRIBUTING",
    "EQUATION", "MPC", "RIGID BODY",
    # steps, procedures, boundary conditions, loads
    "STEP", "END STEP", "STATIC", "DYNAMIC", "VISCO", "FREQUENCY", "HEAT TRANSFER", "CONTROLS",
    "SOLUTION TECHNIQUE", "BOUNDARY", "CLOAD", "DLOAD", "DSLOAD", "AMPLITUDE", "INITIAL CONDITIONS",
    "TEMPERATURE", "FIELD",
    # output
    "OUTPUT", "NODE OUTPUT", "ELEMENT OUTPUT", "CONTACT OUTPUT", "ENERGY OUTPUT", "NODE PRINT", "EL PRINT",
    "NODE FILE", "EL FILE", "ENERGY PRINT", "ENERGY FILE", "MONITOR", "PRINT", "DIAGNOSTICS"))

#: Keywords that make, copy or move nodes or elements, or change how later lines read, which
#: meshio skips without a word (the mesh read would not be the model's): refused, with what the
#: keyword does and what to write instead.
_ABAQUS_REFUSED = {
    "NGEN": ("generates nodes along a line or curve", "write the nodes it makes as *NODE lines"),
    "NFILL": ("fills a region with nodes between two node sets", "write the nodes it makes as *NODE lines"),
    "NCOPY": ("copies nodes (and may shift, rotate or reflect them)", "write the nodes it makes as *NODE lines"),
    "NMAP": ("maps (moves) nodes from another coordinate system", "write the nodes' final coordinates"),
    "SYSTEM": ("sets a local coordinate system in which the *NODE lines after it are given",
               "write the nodes' global coordinates"),
    "ELGEN": ("generates elements from a master element", "write the elements it makes as *ELEMENT lines"),
    "ELCOPY": ("copies elements", "write the elements it makes as *ELEMENT lines"),
    "INCLUDE": ("reads lines from another file", "paste the included lines in its place"),
    "PARAMETER": ("defines parameters that later lines use in place of numbers", "write the numbers out"),
    "IMPORT": ("imports the mesh of an earlier analysis", "export the mesh itself"),
}


def _abaqus_params(line: str) -> Dict[str, str]:
    """A keyword line's parameters, ``{"NAME": value}`` (uppercase names; ``""`` for a flag)."""
    out: Dict[str, str] = {}
    for part in line.split(",")[1:]:
        key, _, value = part.partition("=")
        if key.strip():
            out[key.strip().upper().replace(" ", "")] = value.strip()
    return out


def _abaqus_name(label: str) -> str:
    """A set's label as Abaqus reads it: without the double quotes a label is written in when it
    holds blanks or other characters (``NSET="my set"`` names the set ``my set``)."""
    t = label.strip()
    if len(t) >= 2 and t[0] == t[-1] == '"':
        return t[1:-1]
    return t


@dataclass
class AbaqusSetPiece:
    """One definition that adds members to an Abaqus node set (``kind`` ``"node"``) or element
    set (``"element"``), as :func:`abaqus_precheck` found it; :func:`abaqus_sets` adds them up in
    file order. Abaqus sets are additive: a name defined again (``*NSET, NSET=BASE`` twice, or a
    ``*NODE, NSET=BASE`` and an ``*NSET, NSET=BASE``) gets the members of every definition.

    ``block``: every node of node block ``block`` (``*NODE, NSET=``) or every element of element
    block ``block`` (``*ELEMENT, ELSET=``), each counted from 0 in file order (meshio's cell
    blocks); ``numbers``: the node / element numbers an ``*NSET`` / ``*ELSET`` lists, one array
    per data line with the line (``GENERATE`` ranges expanded: ``generate``), which palpate maps
    (:func:`abaqus_sets`); ``refs``: the sets its data lines name (``(name, line)``);
    ``elset``: ``*NSET, ELSET=<name>``, the nodes of that element set's elements. Names are
    without their quotes (:func:`_abaqus_name`)."""
    kind: str
    name: str
    line: int
    block: Optional[int] = None
    numbers: List[Tuple[np.ndarray, int]] = field(default_factory=list)
    generate: bool = False
    refs: List[Tuple[str, int]] = field(default_factory=list)
    elset: Optional[str] = None


@dataclass
class AbaqusCheck:
    """What :func:`abaqus_precheck` found: ``text``, the file's text for meshio's reader (comment
    lines blanked, the *NODE blocks gathered into the first, set definitions taken out: see
    there); ``unknown``, ``"*<keyword> (<line n>)"`` for each keyword not known here (for the
    caller's MeshWarning); ``sets``, the set definitions in file order; ``element_blocks``, the
    number of *ELEMENT blocks (``element_lines``: the line of each); ``node_blocks``, the number
    of nodes of each *NODE block, in file order (meshio reads them as one block, in that order)."""
    text: str
    unknown: List[str]
    sets: List[AbaqusSetPiece]
    element_blocks: int
    node_blocks: List[int] = field(default_factory=list)
    element_lines: List[int] = field(default_factory=list)


def _abaqus_label(item: str) -> bool:
    """A data line item that names a set rather than giving a number: Abaqus labels begin with a
    letter (Abaqus/CAE's internal sets with ``_``), or are quoted."""
    return bool(item) and (item[0].isalpha() or item[0] in '_"')


#: Keywords that open or close a part, the assembly or an instance: a *NODE block after one of
#: these is not in the first block's part (:func:`abaqus_precheck`).
_ABAQUS_SCOPES = ("PART", "ENDPART", "ASSEMBLY", "ENDASSEMBLY", "INSTANCE", "ENDINSTANCE")


def _abaqus_set_numbers(name: str, i: int, piece: AbaqusSetPiece, items: List[str]) -> np.ndarray:
    """The numbers of one data line of an *NSET / *ELSET (``items``, its set names left out), as
    Abaqus reads them: numbers, or with ``GENERATE`` ``first, last[, increment]`` (increment 1 by
    default; the line's members are first, first + increment, ... up to last)."""
    what = "node" if piece.kind == "node" else "element"
    values = []
    for t in items:
        try:
            values.append(int(t))
        except ValueError:
            raise MeshError(f"{name}: line {i}: the {what} set {piece.name!r} lists {t[:40]!r}, which is neither a "
                            f"{what} number nor a set name") from None
    if not piece.generate:
        return np.array(values, dtype=np.int64)
    if len(values) not in (2, 3):
        raise MeshError(f"{name}: line {i}: the {what} set {piece.name!r} has GENERATE, whose data lines give "
                        f"'first, last, increment' (the increment 1 if left out); got {len(values)} numbers")
    first, last, step = values[0], values[1], values[2] if len(values) == 3 else 1
    if step <= 0 or last < first:
        raise MeshError(f"{name}: line {i}: the {what} set {piece.name!r} has GENERATE from {first} to {last} by "
                        f"{step}: the last number is at least the first, and the increment positive")
    check_budget(f"line {i}: the GENERATE range {first}..{last} of the {what} set {piece.name!r}",
                 ((last - first) // step + 1) * 8.0, name)
    return np.arange(first, last + 1, step, dtype=np.int64)


def abaqus_precheck(path: str) -> AbaqusCheck:
    """Check the keywords of an Abaqus .inp file before meshio reads it; meshio's reader reads
    *NODE, *ELEMENT, *NSET and *ELSET and skips every other line without a word. The rule:

    - a keyword of :data:`_ABAQUS_IGNORED` (materials, sections, steps, boundary conditions,
      loads, output, parts and assembly) is read past, as meshio does;
    - a keyword that makes, copies or moves nodes or elements, or changes how later lines read
      (:data:`_ABAQUS_REFUSED`: *NGEN, *NFILL, *NCOPY, *NMAP, *SYSTEM, *ELGEN, *ELCOPY, *INCLUDE,
      *PARAMETER, *IMPORT), any keyword with an ``INPUT=`` file, *NODE with ``SYSTEM=C`` or
      ``S``, a *NODE block in another part, in the assembly or in an instance than the first
      block (each numbers its nodes apart), more than one *INSTANCE (the part placed several
      times, meshio reads it once), an *INSTANCE with a translation or rotation, a keyword
      meshio reads written in a way it does not recognise (``* NODE``), and a data line meshio
      takes for a keyword (a set named ``NODE`` on a *BOUNDARY line) are a MeshError naming the
      file, the line and the keyword;
    - any other keyword is read past, and named in the caller's MeshWarning.

    The *NODE blocks of one part are one set of nodes, as Abaqus reads them: meshio's reader
    replaces the nodes read before at each *NODE (the elements read before would point at the
    new ones), so the text it reads has every node line under the first *NODE line, in file
    order; a node number defined twice (in one block or two) is a MeshError naming the number
    and both lines (meshio kept both nodes and mapped the number to the second: the first was
    used by no element).

    The sets are palpate's to add up (:func:`abaqus_sets`), because meshio's reader gets several
    of them wrong: it ignores ``*NODE, NSET=`` (no set), maps ``*ELEMENT, ELSET=`` onto the wrong
    cell block when an element block without ELSET comes before (an IndexError, or another
    block's cells), replaces a set defined twice instead of adding to it, drops the set names an
    *NSET data line lists and nests those of an *ELSET line, leaves ``*NSET, ELSET=`` empty,
    drops an *ELSET number that names no element and fails on an *NSET one (``KeyError``), and
    keeps a quoted label's quotes. So *NSET and *ELSET are taken out of the text meshio reads,
    their numbers parsed here (:func:`_abaqus_set_numbers`) and mapped by palpate, and
    ``ELSET=`` removed from *ELEMENT lines; every definition is an :class:`AbaqusSetPiece`.

    Comment lines (``**``) are blanked in that text: meshio's reader ends a *NODE or *ELEMENT
    block at a comment line and skipped the lines after it as unknown keywords (the rest of the
    block was lost)."""
    name = os.path.basename(path)
    lines = read_text(path).splitlines()
    unknown: List[str] = []
    sets: List[AbaqusSetPiece] = []
    piece: Optional[AbaqusSetPiece] = None   # the *NSET / *ELSET whose data lines follow
    current: Optional[str] = None   # the keyword whose data lines follow
    node_line = instance_line = part_line = scope_line = 0
    scope_kw = ""
    element_lines: List[int] = []
    node_blocks: List[int] = []   # nodes per *NODE block
    node_data: List[str] = []   # every node line, in file order (meshio reads them under the first *NODE)
    node_defined: Dict[int, int] = {}   # node number -> its line

    def refuse(i: int, shown: str, why: str) -> MeshError:
        return MeshError(f"{name}: line {i}: Abaqus keyword *{shown} {why}")

    for i, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("**"):
            lines[i - 1] = ""
            continue
        head = line.partition(",")[0]
        meshio_kw = head.strip().replace("*", "").upper()   # what meshio's reader compares
        if not line.startswith("*"):
            if current == "NODE":
                node_data.append(line)
                node_blocks[-1] += 1
                lines[i - 1] = ""
                try:
                    number = int(head)
                except ValueError:
                    continue   # meshio's reader refuses it (ValueError), as before
                if number in node_defined:
                    raise MeshError(f"{name}: line {i}: node {number} is defined again (first at line "
                                    f"{node_defined[number]}): a node number names one node in a part; meshio's "
                                    "reader would keep both and map the number to the second (the first used by "
                                    "no element)")
                node_defined[number] = i
            elif current == "INSTANCE":
                try:
                    moved = any(float(t) != 0.0 for t in line.split(",") if t.strip())
                except ValueError:
                    moved = True
                if moved:
                    raise refuse(instance_line, "INSTANCE", f"moves its part by a translation or rotation (line {i}: "
                                 f"{line[:60]!r}), which meshio's reader skips: the nodes would be read where the "
                                 "part defines them; write the part's nodes where the instance puts them")
            elif piece is not None:
                # The set's data lines are palpate's (abaqus_sets): set names and numbers.
                items = [t.strip() for t in line.split(",")]
                named = [t for t in items if _abaqus_label(t)]
                if named and piece.generate:
                    raise MeshError(f"{name}: line {i}: the {piece.kind} set {piece.name!r} has GENERATE, whose data "
                                    f"lines give numbers, not set names ({named[0][:40]!r})")
                piece.refs.extend((_abaqus_name(t), i) for t in named)
                numbers = [t for t in items if t and not _abaqus_label(t)]
                if numbers:
                    piece.numbers.append((_abaqus_set_numbers(name, i, piece, numbers), i))
                lines[i - 1] = ""
            elif current not in _ABAQUS_READ and meshio_kw in _ABAQUS_READ + ("INCLUDE",):
                raise MeshError(f"{name}: line {i}: the data line {line[:60]!r} of *{current or '(none)'} begins "
                                f"with {head.strip()!r}, which meshio's Abaqus reader takes for the keyword "
                                f"*{meshio_kw} (it does not look for the '*'): rename the set")
            continue
        shown = " ".join(head[1:].split()).upper()
        kw = shown.replace(" ", "")
        params = _abaqus_params(line)
        current, piece = kw, None
        if kw in _ABAQUS_REFUSED:
            what, fix = _ABAQUS_REFUSED[kw]
            meshio_does = ("follows its own way (it merges that file's nodes without their numbers, and opens it "
                           "without palpate's checks on an input file)" if kw == "INCLUDE" else "skips without a word")
            raise refuse(i, shown, f"{what}, which meshio's reader {meshio_does} (the mesh read would not be the "
                         f"model's): palpate refuses it; {fix}")
        if "INPUT" in params:
            raise refuse(i, shown, f"reads its data from the file {params['INPUT']!r} (INPUT=), which meshio's "
                         "reader does not open: palpate reads one file; paste that file's lines in its place")
        if kw in _ABAQUS_READ + ("INCLUDE",) and meshio_kw != kw:
            raise refuse(i, shown, f"is written {head.strip()!r}, which meshio's reader does not recognise (it "
                         f"would skip the block): write it *{kw}")
        if kw in _ABAQUS_SCOPES:
            scope_line, scope_kw = i, shown
        if kw == "NODE":
            if node_line and part_line > node_line:
                raise refuse(i, shown, f"opens the node block of a second part (*PART at line {part_line}; the first "
                             f"part's nodes at line {node_line}): each part numbers its nodes apart, and meshio's "
                             "reader keeps the last block's nodes only; palpate reads .inp files with one part, "
                             "placed by at most one *INSTANCE: export each part to a file of its own, or merge "
                             "them into one part")
            if node_line and scope_line > node_line:
                raise refuse(i, shown, f"opens a node block after *{scope_kw} (line {scope_line}), outside the part "
                             f"whose nodes begin at line {node_line}: nodes of the assembly (a reference point) or of "
                             "an instance number apart from the part's, and would be read as the part's; palpate "
                             "reads the nodes of one part (its *NODE blocks): leave these nodes out, or merge them "
                             "into the part with numbers of their own")
            if not node_line:
                node_line = i
                lines[i - 1] = raw.rstrip()   # every node line goes under it (below)
            else:
                lines[i - 1] = ""
            node_blocks.append(0)
            system = params.get("SYSTEM", "R").upper()
            if system not in ("R", ""):
                kind = {"C": "cylindrical", "S": "spherical"}.get(system, "non-rectangular")
                raise refuse(i, shown, f"gives its nodes in {kind} coordinates (SYSTEM={params['SYSTEM']}), which "
                             "meshio's reader takes for x, y, z: write them in rectangular coordinates")
            if params.get("NSET"):
                # The block's nodes form that set (meshio's reader ignores the parameter).
                sets.append(AbaqusSetPiece("node", _abaqus_name(params["NSET"]), i, block=len(node_blocks) - 1))
        elif kw == "ELEMENT":
            if params.get("ELSET"):
                # The block's elements form that set; taken out of meshio's text, whose reader
                # puts it on the wrong cell block when a block without ELSET comes before.
                sets.append(AbaqusSetPiece("element", _abaqus_name(params["ELSET"]), i, block=len(element_lines)))
                keyword, *rest = raw.split(",")
                lines[i - 1] = ",".join([keyword] + [t for t in rest if t.partition("=")[0].strip().upper() != "ELSET"])
            element_lines.append(i)
        elif kw in ("NSET", "ELSET"):
            if not params.get(kw):
                raise refuse(i, shown, f"has no {kw}= parameter: the set's name is given as {kw}=<name>")
            elset = _abaqus_name(params["ELSET"]) if kw == "NSET" and params.get("ELSET") else None
            piece = AbaqusSetPiece("node" if kw == "NSET" else "element", _abaqus_name(params[kw]), i,
                                   generate="GENERATE" in params, elset=elset)
            sets.append(piece)
            lines[i - 1] = ""   # palpate reads the set (its data lines too), not meshio
        elif kw == "PART":
            part_line = i
        elif kw == "INSTANCE":
            if instance_line:
                raise refuse(i, shown, f"places a second instance (the first at line {instance_line}): meshio's "
                             "reader reads each part's nodes once, where the part defines them; palpate reads "
                             ".inp files with one instance")
            instance_line = i
        elif kw not in _ABAQUS_READ and kw not in _ABAQUS_IGNORED:
            unknown.append(f"*{shown} (line {i})")
    if node_line and node_data:
        lines[node_line - 1] += "\n" + "\n".join(node_data)
    return AbaqusCheck("\n".join(lines) + "\n", unknown, sets, len(element_lines), node_blocks, element_lines)


def _abaqus_lookup(numbers: Dict[int, int]):
    """``lookup(values) -> (indices, found)`` for the number -> index map ``numbers`` (meshio's
    node or element numbering), vectorised: a GENERATE range may list many."""
    keys = np.fromiter(numbers.keys(), dtype=np.int64, count=len(numbers))
    values = np.fromiter(numbers.values(), dtype=np.int64, count=len(numbers))
    order = np.argsort(keys, kind="stable")
    keys, values = keys[order], values[order]

    def lookup(wanted: np.ndarray):
        if not len(keys):
            return np.zeros(len(wanted), dtype=np.int64), np.zeros(len(wanted), dtype=bool)
        pos = np.clip(np.searchsorted(keys, wanted), 0, len(keys) - 1)
        return values[pos], keys[pos] == wanted

    return lookup


def abaqus_sets(name: str, check: AbaqusCheck, n_nodes: int, blocks: List[np.ndarray],
                node_ids: Dict[int, int], element_ids: List[Dict[int, int]]):
    """The node and element sets of an Abaqus file, as meshio's ``(point_sets, cell_sets)``
    (``{name: node indices}``, ``{name: [row indices of each cell block]}``): the definitions
    of ``check.sets`` added up in file order (:class:`AbaqusSetPiece`), over the mesh meshio read
    (``n_nodes`` nodes, numbered as ``node_ids`` maps them; ``blocks`` the cells of each *ELEMENT
    block, ``element_ids`` the element numbers of each). Set names are compared in upper case,
    as Abaqus compares labels, and kept as first written (without quotes). A set named on a data
    line that no definition before it gives, and a number that names no node or element, are a
    MeshError naming the set, the number and the line (meshio dropped such an *ELSET number
    without a word, and failed on an *NSET one with a bare ``KeyError``)."""
    empty = np.zeros(0, dtype=np.int64)
    nodes: Dict[str, np.ndarray] = {}
    elements: Dict[str, List[np.ndarray]] = {}
    spelled: Dict[Tuple[str, str], str] = {}
    if sum(check.node_blocks) != n_nodes or len(element_ids) != len(blocks):
        raise MeshError(f"{name}: meshio read {n_nodes} nodes and {len(blocks)} element blocks, the file's *NODE "
                        f"blocks hold {sum(check.node_blocks)} nodes and it has {len(element_ids)} *ELEMENT blocks: "
                        "sets not mapped")
    starts = np.cumsum([0] + list(check.node_blocks))
    node_lookup = _abaqus_lookup(node_ids)
    element_lookups = [_abaqus_lookup(ids) for ids in element_ids]

    def defined(table: Dict, kind: str, ref: str, line: int, piece: AbaqusSetPiece):
        if ref.upper() not in table:
            raise MeshError(f"{name}: line {line}: the {piece.kind} set {piece.name!r} lists the {kind} set {ref!r}, "
                            f"which no definition before it gives (no *{'NSET' if kind == 'node' else 'ELSET'} or "
                            f"*{'NODE' if kind == 'node' else 'ELEMENT'} line names it): its members are unknown")
        return table[ref.upper()]

    def missing(piece: AbaqusSetPiece, line: int, numbers: np.ndarray, found: np.ndarray) -> MeshError:
        kind, keyword = (("node", "*NODE") if piece.kind == "node" else ("element", "*ELEMENT"))
        bad = numbers[~found]
        more = f" ({len(bad)} numbers of the line name none)" if len(bad) > 1 else ""
        how = " (GENERATE)" if piece.generate else ""
        return MeshError(f"{name}: line {line}: the {kind} set {piece.name!r} lists {kind} {int(bad[0])}{how}, which "
                         f"no {keyword} line defines{more}: the set's members are unknown")

    for piece in check.sets:
        key = piece.name.upper()
        spelled.setdefault((piece.kind, key), piece.name)
        if piece.kind == "node":
            parts = [nodes.get(key, empty)]
            if piece.block is not None:
                parts.append(np.arange(starts[piece.block], starts[piece.block + 1], dtype=np.int64))
            for numbers, line in piece.numbers:
                index, found = node_lookup(numbers)
                if not found.all():
                    raise missing(piece, line, numbers, found)
                parts.append(index)
            parts.extend(defined(nodes, "node", ref, line, piece) for ref, line in piece.refs)
            if piece.elset:
                rows = defined(elements, "element", piece.elset, piece.line, piece)
                parts.extend(np.asarray(blocks[k], dtype=np.int64)[r].ravel() for k, r in enumerate(rows))
            nodes[key] = np.unique(np.concatenate(parts))
        else:
            per_block = [[rows] for rows in elements.get(key, [empty] * len(blocks))]
            if piece.block is not None:
                per_block[piece.block].append(np.arange(len(blocks[piece.block]), dtype=np.int64))
            for numbers, line in piece.numbers:
                anywhere = np.zeros(len(numbers), dtype=bool)
                for k, lookup in enumerate(element_lookups):
                    rows, found = lookup(numbers)
                    per_block[k].append(rows[found])
                    anywhere |= found
                if not anywhere.all():
                    raise missing(piece, line, numbers, anywhere)
            for ref, line in piece.refs:
                for k, rows in enumerate(defined(elements, "element", ref, line, piece)):
                    per_block[k].append(rows)
            elements[key] = [np.unique(np.concatenate(p)) for p in per_block]
    return ({spelled["node", k]: v for k, v in nodes.items()},
            {spelled["element", k]: v for k, v in elements.items()})


def read_gmsh_ascii(path: str, version: str) -> Tuple[np.ndarray, List[CellBlock], List[str]]:
    """Read an ASCII gmsh MSH 2.2, 4.0 or 4.1 file (nodes and elements; other sections are skipped)."""
    f = _Lines(path, read_text(path))
    layout = gmsh_layout(f.name, version)
    read_nodes = {"2": _gmsh_nodes_v2, "4.0": _gmsh_nodes_v40, "4.1": _gmsh_nodes_v4}[layout]
    read_elements = {"2": _gmsh_elements_v2, "4.0": _gmsh_elements_v40, "4.1": _gmsh_elements_v4}[layout]
    nodes: Optional[Tuple[List[int], List[List[float]]]] = None
    elements = None
    while True:
        try:
            line = f.next("sections")
        except MeshError:
            break  # end of file between sections
        if not line.startswith("$"):
            raise f.error(f"expected a section header like '$Nodes', got {line[:60]!r}")
        section = line[1:]
        try:
            if section == "Nodes":
                nodes = read_nodes(f)
            elif section == "Elements":
                elements = read_elements(f)
            else:
                _skip_section(f, section)
                continue
        except MeshError as e:
            # A malformed last line of the file is a cut-off file, and is best reported as that.
            if f.i >= len(f.lines) and "end of file" not in str(e):
                reason = str(e).split(": ", 1)[-1]
                raise MeshError(f"{f.name}: unexpected end of file (truncated?) in ${section} "
                                f"at line {f.lineno}: {reason}") from None
            raise
        end = f.next(f"$End{section}")
        if end != f"$End{section}":
            raise f.error(f"expected '$End{section}', got {end[:60]!r} (wrong count in the section header?)")
    if nodes is None:
        raise MeshError(f"{f.name}: no $Nodes section (no points)")
    if elements is None:
        raise MeshError(f"{f.name}: no $Elements section (no cells)")
    tags, coords = nodes
    return _gmsh_assemble(f.name, tags, np.array(coords, dtype=np.float64).reshape(-1, 3),
                          [(etype, etag, node_tags, f"line {lineno}") for etype, etag, node_tags, lineno in elements])


def _gmsh_assemble(name: str, tags: List[int], points: np.ndarray, elements) -> Tuple[np.ndarray, List[CellBlock], List[str]]:
    """Nodes and elements by tag, as the file gives them, to points and 0-based cell blocks: every
    element's node tag must be one that $Nodes defines (``elements``: (type, tag, node tags,
    where in the file))."""
    index = {t: i for i, t in enumerate(tags)}
    if len(index) != len(tags):
        seen = set()
        for t in tags:
            if t in seen:
                raise MeshError(f"{name}: node tag {t} is defined twice in $Nodes")
            seen.add(t)
    rows: Dict[str, List[List[int]]] = {}
    labels: Dict[str, List[str]] = {}
    for etype, etag, node_tags, where in elements:
        cell = GMSH_TYPES[etype][0]
        conn = []
        for t in node_tags:
            i = index.get(t)
            if i is None:
                raise MeshError(f"{name}: {where}: gmsh element {etag} ({cell}) references node tag {t}, "
                                f"which is not defined in $Nodes ({len(tags)} nodes"
                                + (f", tags {min(tags)}..{max(tags)})" if tags else ")"))
            conn.append(i)
        rows.setdefault(cell, []).append(conn)
        labels.setdefault(cell, []).append(f"gmsh element {etag}, {where}")
    dims = {cell: dim for cell, _, dim in GMSH_TYPES.values()}
    blocks = [CellBlock(cell, dims[cell], np.array(r, dtype=np.int64), labels[cell]) for cell, r in rows.items()]
    return points, blocks, [f"gmsh node {t}" for t in tags]


class _Bytes:
    """A binary gmsh file read front to back, with the byte offset of every error."""

    def __init__(self, path: str, data: bytes):
        self.name = os.path.basename(path)
        self.data = data
        self.pos = 0

    def error(self, msg: str, at: Optional[int] = None) -> MeshError:
        return MeshError(f"{self.name}: byte {self.pos if at is None else at}: {msg}")

    def line(self, context: str) -> bytes:
        """The next line (the sections' headers and counts are ASCII lines), without its newline."""
        end = self.data.find(b"\n", self.pos)
        if end < 0:
            raise MeshError(f"{self.name}: unexpected end of file (truncated?) while reading {context}")
        out, self.pos = self.data[self.pos:end].rstrip(b"\r"), end + 1
        return out

    def take(self, fmt: str, count: int, context: str) -> np.ndarray:
        """``count`` little-endian numbers of numpy type ``fmt`` ('<i4', '<u8', '<f8')."""
        dt = np.dtype(fmt)
        need = count * dt.itemsize
        if count < 0 or self.pos + need > len(self.data):
            raise MeshError(f"{self.name}: byte {self.pos}: unexpected end of file (truncated?) while reading {context}: "
                            f"{count} numbers need {need} bytes, {len(self.data) - self.pos} are left")
        out = np.frombuffer(self.data, dtype=dt, count=count, offset=self.pos)
        self.pos += need
        return out

    def end(self, section: str) -> None:
        """``$End<section>``, after the newline that closes the binary data."""
        if self.data[self.pos:self.pos + 1] == b"\n":
            self.pos += 1
        at = self.pos
        line = self.line(f"$End{section}")
        if line.strip() != f"$End{section}".encode():
            raise self.error(f"expected '$End{section}', got {line[:40]!r} (a wrong count in the section?)", at)


def read_gmsh_binary(path: str, version: str) -> Tuple[np.ndarray, List[CellBlock], List[str]]:
    """Read a binary gmsh MSH 2.2, 4.0 or 4.1 file (little-endian; nodes and elements, other
    sections skipped), every element's node tag checked against $Nodes as in the ASCII reader.
    meshio read these before, and mapped an undefined node tag 0 (tag - 1 = -1) to the node with
    the largest tag without a word (issue 35 item 6). MSH 4.0 writes its counts as C ``unsigned
    long``: 8 bytes as gmsh writes them on 64-bit Linux and macOS, which is what is read here (a
    file with 4-byte ones, from gmsh 4.0 on Windows or a 32-bit system, is refused at its $Nodes
    header)."""
    check_input_file(path)
    with open(path, "rb") as fh:
        b = _Bytes(path, fh.read())
    layout = gmsh_layout(b.name, version)
    b.line("$MeshFormat")
    head = b.line("$MeshFormat").split()
    if layout != "2" and len(head) > 2 and head[2] != b"8":
        raise b.error(f"data-size {head[2].decode('latin-1')!r}: palpate reads binary MSH {layout} with 8-byte "
                      f"sizes; convert with {GMSH_CONVERT}")
    read_nodes = {"2": _gmsh_bin_nodes_v2, "4.0": _gmsh_bin_nodes_v40, "4.1": _gmsh_bin_nodes_v4}[layout]
    read_elements = {"2": _gmsh_bin_elements_v2, "4.0": _gmsh_bin_elements_v40, "4.1": _gmsh_bin_elements_v4}[layout]
    one = int(b.take("<i4", 1, "the endianness check")[0])
    if one != 1:
        raise b.error(f"the endianness check reads {one}, not 1: a big-endian file (palpate reads little-endian ones)")
    b.end("MeshFormat")
    nodes = elements = None
    while b.pos < len(b.data):
        at = b.pos
        line = b.line("sections").strip()
        if not line:
            continue
        if not line.startswith(b"$"):
            raise b.error(f"expected a section header like '$Nodes', got {line[:40]!r}", at)
        section = line[1:].decode("latin-1")
        if section == "Nodes":
            nodes = read_nodes(b)
        elif section == "Elements":
            elements = read_elements(b)
        else:
            end = b.data.find(f"$End{section}".encode(), b.pos)
            if end < 0:
                raise b.error(f"${section} is not closed by $End{section}", at)
            b.pos = end
            b.line(f"$End{section}")
            continue
        b.end(section)
    if nodes is None:
        raise MeshError(f"{b.name}: no $Nodes section (no points)")
    if elements is None:
        raise MeshError(f"{b.name}: no $Elements section (no cells)")
    tags, points = nodes
    return _gmsh_assemble(b.name, tags, points, elements)


def _gmsh_count(b: _Bytes, what: str) -> int:
    at = b.pos
    t = b.line(what).split()
    try:
        n = int(t[0]) if len(t) == 1 else -1
    except ValueError:
        n = -1
    if n < 0:
        raise b.error(f"expected the number of {what}, got {b' '.join(t)[:40]!r}", at)
    return n


def _gmsh_bin_nodes_v2(b: _Bytes):
    n = _gmsh_count(b, "nodes")
    check_budget(f"$Nodes of {n} entries", n * 64.0, b.name)
    rec = b.take("<u1", n * 28, "$Nodes")   # per node: int32 tag, 3 float64
    recs = np.frombuffer(rec.tobytes(), dtype=np.dtype([("tag", "<i4"), ("xyz", "<f8", 3)]), count=n)
    return recs["tag"].astype(np.int64).tolist(), recs["xyz"].astype(np.float64)


def _gmsh_bin_elements_v2(b: _Bytes):
    n = _gmsh_count(b, "elements")
    check_budget(f"$Elements of {n} entries", n * 64.0, b.name)
    out = []
    while len(out) < n:
        at = b.pos
        etype, count, ntags = (int(x) for x in b.take("<i4", 3, "an $Elements block header"))
        if etype not in GMSH_TYPES:
            raise b.error(f"unknown gmsh element type {etype}", at)
        if count <= 0 or ntags < 0 or len(out) + count > n:
            raise b.error(f"an $Elements block of {count} elements with {ntags} tags after {len(out)} of {n} elements", at)
        nn = GMSH_TYPES[etype][1]
        start = b.pos
        rows = b.take("<i4", count * (1 + ntags + nn), f"{count} gmsh elements of type {etype}").reshape(count, -1)
        size = 4 * (1 + ntags + nn)
        for k, row in enumerate(rows.tolist()):
            out.append((etype, row[0], row[1 + ntags:], f"byte {start + k * size}"))
    return out


def _gmsh_bin_nodes_v4(b: _Bytes):
    n_blocks, n_nodes, _, _ = (int(x) for x in b.take("<u8", 4, "the $Nodes header"))
    check_budget(f"$Nodes of {n_nodes} entries", n_nodes * 64.0, b.name)
    tags: List[int] = []
    coords = []
    for _ in range(n_blocks):
        at = b.pos
        dim, _, parametric = (int(x) for x in b.take("<i4", 3, "a $Nodes entity block header"))
        count = int(b.take("<u8", 1, "a $Nodes entity block header")[0])
        if count > n_nodes - len(tags):
            raise b.error(f"a $Nodes block of {count} nodes after {len(tags)} of {n_nodes}", at)
        tags.extend(b.take("<u8", count, "$Nodes (node tags)").astype(np.int64).tolist())
        per = 3 + (dim if parametric else 0)
        coords.append(b.take("<f8", count * per, "$Nodes (coordinates)").reshape(count, per)[:, :3])
    if len(tags) != n_nodes:
        raise b.error(f"$Nodes header announces {n_nodes} nodes, the blocks hold {len(tags)}")
    return tags, (np.concatenate(coords) if coords else np.zeros((0, 3)))


def _gmsh_bin_elements_v4(b: _Bytes):
    n_blocks, n_elements, _, _ = (int(x) for x in b.take("<u8", 4, "the $Elements header"))
    check_budget(f"$Elements of {n_elements} entries", n_elements * 64.0, b.name)
    return _gmsh_bin_element_blocks(b, n_blocks, n_elements, "<u8")


def _gmsh_bin_element_blocks(b: _Bytes, n_blocks: int, n_elements: int, tag_type: str):
    """The $Elements entity blocks of binary MSH 4.x after the section header: per block
    tagEntity dimEntity typeEle (int) numElements (unsigned long), then per element its tag and
    node tags, each ``tag_type`` (``"<u8"`` in 4.1, ``"<i4"`` in 4.0)."""
    width = np.dtype(tag_type).itemsize
    out = []
    for _ in range(n_blocks):
        at = b.pos
        _, _, etype = (int(x) for x in b.take("<i4", 3, "an $Elements entity block header"))
        count = int(b.take("<u8", 1, "an $Elements entity block header")[0])
        if etype not in GMSH_TYPES:
            raise b.error(f"unknown gmsh element type {etype}", at)
        if count > n_elements - len(out):
            raise b.error(f"an $Elements block of {count} elements after {len(out)} of {n_elements}", at)
        nn = GMSH_TYPES[etype][1]
        start = b.pos
        rows = b.take(tag_type, count * (1 + nn), f"{count} gmsh elements of type {etype}").reshape(count, 1 + nn)
        for k, row in enumerate(rows.astype(np.int64).tolist()):
            out.append((etype, row[0], row[1:], f"byte {start + k * width * (1 + nn)}"))
    if len(out) != n_elements:
        raise b.error(f"$Elements header announces {n_elements} elements, the blocks hold {len(out)}")
    return out


def _gmsh_bin_header_v40(b: _Bytes, section: str, what: str, per_item: int, per_block: int) -> Tuple[int, int]:
    """An MSH 4.0 binary section header: ``numEntityBlocks numItems`` (unsigned long, 8 bytes),
    both checked against the bytes left before anything is sized by them."""
    at = b.pos
    n_blocks, n_items = (int(x) for x in b.take("<u8", 2, f"the ${section} header"))
    left = len(b.data) - b.pos
    if n_items * per_item + n_blocks * per_block > left:
        raise b.error(f"the ${section} header announces {n_blocks} entity blocks of {n_items} {what} in all, "
                      f"which need at least {n_items * per_item + n_blocks * per_block} bytes; {left} are left "
                      "(truncated, or written with 4-byte unsigned long counts, as gmsh 4.0 on Windows or a 32-bit "
                      f"system does: palpate reads 8-byte ones; convert with {GMSH_CONVERT})", at)
    check_budget(f"${section} of {n_items} entries", n_items * 64.0, b.name)
    return n_blocks, n_items


def _gmsh_bin_nodes_v40(b: _Bytes):
    # Block: tagEntity dimEntity parametric (int) numNodes (unsigned long); then per node
    # tag (int) x y z (double) [u [v [w]]] (double, dimEntity of them if parametric).
    n_blocks, n_nodes = _gmsh_bin_header_v40(b, "Nodes", "nodes", 4 + 24, 20)
    tags: List[int] = []
    coords = []
    for _ in range(n_blocks):
        at = b.pos
        _, dim, parametric = (int(x) for x in b.take("<i4", 3, "a $Nodes entity block header"))
        count = int(b.take("<u8", 1, "a $Nodes entity block header")[0])
        if count > n_nodes - len(tags):
            raise b.error(f"a $Nodes block of {count} nodes after {len(tags)} of {n_nodes}", at)
        if parametric and not 0 <= dim <= 3:
            raise b.error(f"a $Nodes block of entity dimension {dim} with parametric coordinates", at)
        per = 3 + (dim if parametric else 0)
        raw = b.take("<u1", count * (4 + 8 * per), "$Nodes (node records)")
        recs = np.frombuffer(raw.tobytes(), dtype=np.dtype([("tag", "<i4"), ("xyz", "<f8", per)]), count=count)
        tags.extend(recs["tag"].astype(np.int64).tolist())
        coords.append(recs["xyz"].reshape(count, per)[:, :3].astype(np.float64))
    if len(tags) != n_nodes:
        raise b.error(f"$Nodes header announces {n_nodes} nodes, the blocks hold {len(tags)}")
    return tags, (np.concatenate(coords) if coords else np.zeros((0, 3)))


def _gmsh_bin_elements_v40(b: _Bytes):
    # The header's counts are unsigned long; the element and node tags int.
    n_blocks, n_elements = _gmsh_bin_header_v40(b, "Elements", "elements", 8, 20)
    return _gmsh_bin_element_blocks(b, n_blocks, n_elements, "<i4")


def _skip_section(f: _Lines, section: str) -> None:
    end = f"$End{section}"
    while True:
        line = f.next(f"${section}")
        if line == end:
            return


def _coords(f: _Lines, tokens: List[str], tag: int) -> List[float]:
    xyz = f.floats(tokens, f"the coordinates of node {tag}")
    return xyz


def _gmsh_nodes_v2(f: _Lines):
    n = f.ints(f.next("$Nodes"), "the $Nodes count")
    if len(n) != 1 or n[0] < 0:
        raise f.error("expected the number of nodes")
    tags, coords = [], []
    for k in range(n[0]):
        tok = f.next(f"$Nodes (node {k + 1} of {n[0]})").split()
        if len(tok) != 4:
            raise f.error(f"expected 'tag x y z', got {' '.join(tok)[:60]!r}")
        tags.append(f.ints(tok[0], "a node tag")[0])
        coords.append(_coords(f, tok[1:], tags[-1]))
    return tags, coords


def _gmsh_nodes_v4(f: _Lines):
    head = f.ints(f.next("$Nodes"), "the $Nodes header")
    if len(head) != 4:
        raise f.error("expected 'numEntityBlocks numNodes minNodeTag maxNodeTag'")
    n_blocks, n_nodes = head[0], head[1]
    tags, coords = [], []
    for _ in range(n_blocks):
        bh = f.ints(f.next("a $Nodes entity block header"), "a $Nodes entity block header")
        if len(bh) != 4:
            raise f.error("expected 'entityDim entityTag parametric numNodesInBlock'")
        parametric, count = bh[2], bh[3]
        block_tags = [f.ints(f.next("$Nodes (node tags)"), "a node tag")[0] for _ in range(count)]
        for t in block_tags:
            tok = f.next(f"$Nodes (coordinates of node {t})").split()
            if len(tok) < 3 or (not parametric and len(tok) != 3):
                raise f.error(f"expected 'x y z' for node {t}, got {' '.join(tok)[:60]!r}")
            coords.append(_coords(f, tok[:3], t))
        tags.extend(block_tags)
    if len(tags) != n_nodes:
        raise f.error(f"$Nodes header announces {n_nodes} nodes, the blocks hold {len(tags)}")
    return tags, coords


def _element(f: _Lines, etype: int, nodes: List[int], etag: int):
    if etype not in GMSH_TYPES:
        raise f.error(f"gmsh element {etag} has unknown element type {etype}")
    name, nn, _ = GMSH_TYPES[etype]
    if len(nodes) != nn:
        raise f.error(f"gmsh element {etag} ({name}) has {len(nodes)} nodes, expected {nn}")
    return (etype, etag, nodes, f.lineno)


def _gmsh_elements_v2(f: _Lines):
    n = f.ints(f.next("$Elements"), "the $Elements count")
    if len(n) != 1 or n[0] < 0:
        raise f.error("expected the number of elements")
    out = []
    for k in range(n[0]):
        v = f.ints(f.next(f"$Elements (element {k + 1} of {n[0]})"), "an element line")
        if len(v) < 3 or len(v) < 3 + v[2]:
            raise f.error("expected 'tag type ntags tags... nodes...'")
        out.append(_element(f, v[1], v[3 + v[2]:], v[0]))
    return out


def _gmsh_elements_v4(f: _Lines):
    head = f.ints(f.next("$Elements"), "the $Elements header")
    if len(head) != 4:
        raise f.error("expected 'numEntityBlocks numElements minElementTag maxElementTag'")
    out = []
    for _ in range(head[0]):
        bh = f.ints(f.next("an $Elements entity block header"), "an $Elements entity block header")
        if len(bh) != 4:
            raise f.error("expected 'entityDim entityTag elementType numElementsInBlock'")
        etype, count = bh[2], bh[3]
        if etype not in GMSH_TYPES:
            raise f.error(f"unknown gmsh element type {etype}")
        for _ in range(count):
            v = f.ints(f.next("$Elements"), "an element line")
            out.append(_element(f, etype, v[1:], v[0]))
    if len(out) != head[1]:
        raise f.error(f"$Elements header announces {head[1]} elements, the blocks hold {len(out)}")
    return out


def _gmsh_nodes_v40(f: _Lines):
    """MSH 4.0 $Nodes: ``numEntityBlocks numNodes``; per block ``tagEntity dimEntity parametric
    numNodes``, then one line per node, ``tag x y z`` (and ``u [v [w]]``, dimEntity of them, if
    parametric). 4.1 adds the min / max tags to the header, puts the entity's dimension first and
    lists the block's tags before its coordinates."""
    head = f.ints(f.next("$Nodes"), "the $Nodes header")
    if len(head) != 2 or min(head) < 0:
        hint = " (4 numbers are an MSH 4.1 header, but $MeshFormat says 4.0)" if len(head) == 4 else ""
        raise f.error(f"expected 'numEntityBlocks numNodes' (MSH 4.0), got {len(head)} numbers{hint}")
    n_blocks, n_nodes = head
    tags, coords = [], []
    for _ in range(n_blocks):
        bh = f.ints(f.next("a $Nodes entity block header"), "a $Nodes entity block header")
        if len(bh) != 4:
            raise f.error("expected 'tagEntity dimEntity parametric numNodes' (MSH 4.0)")
        dim, parametric, count = bh[1], bh[2], bh[3]
        if count < 0 or count > n_nodes - len(tags):
            raise f.error(f"a $Nodes block of {count} nodes after {len(tags)} of {n_nodes}")
        extra = dim if parametric else 0
        for k in range(count):
            tok = f.next(f"$Nodes (node {len(tags) + 1} of {n_nodes})").split()
            if len(tok) != 4 + extra:
                layout = "tag x y z" + ("", " u", " u v", " u v w")[extra if 0 <= extra <= 3 else 0]
                raise f.error(f"expected '{layout}' (MSH 4.0, entity dimension {dim}, parametric {parametric}), "
                              f"got {' '.join(tok)[:60]!r}")
            tags.append(f.ints(tok[0], "a node tag")[0])
            coords.append(_coords(f, tok[1:4], tags[-1]))
    if len(tags) != n_nodes:
        raise f.error(f"$Nodes header announces {n_nodes} nodes, the blocks hold {len(tags)}")
    return tags, coords


def _gmsh_elements_v40(f: _Lines):
    """MSH 4.0 $Elements: ``numEntityBlocks numElements``; per block ``tagEntity dimEntity
    typeEle numElements``, then ``tag node-tags...`` per element (as 4.1, whose header adds the
    min / max tags and whose blocks put the entity's dimension first)."""
    head = f.ints(f.next("$Elements"), "the $Elements header")
    if len(head) != 2 or min(head) < 0:
        hint = " (4 numbers are an MSH 4.1 header, but $MeshFormat says 4.0)" if len(head) == 4 else ""
        raise f.error(f"expected 'numEntityBlocks numElements' (MSH 4.0), got {len(head)} numbers{hint}")
    out = []
    for _ in range(head[0]):
        bh = f.ints(f.next("an $Elements entity block header"), "an $Elements entity block header")
        if len(bh) != 4:
            raise f.error("expected 'tagEntity dimEntity typeEle numElements' (MSH 4.0)")
        etype, count = bh[2], bh[3]
        if etype not in GMSH_TYPES:
            raise f.error(f"unknown gmsh element type {etype}")
        if count < 0 or count > head[1] - len(out):
            raise f.error(f"an $Elements block of {count} elements after {len(out)} of {head[1]}")
        for _ in range(count):
            v = f.ints(f.next("$Elements"), "an element line")
            out.append(_element(f, etype, v[1:], v[0]))
    if len(out) != head[1]:
        raise f.error(f"$Elements header announces {head[1]} elements, the blocks hold {len(out)}")
    return out


# ---------------------------------------------------------------------------------------------
# TetGen
# ---------------------------------------------------------------------------------------------

def _tetgen_rows(f: _Lines, what: str):
    """Yield the non-comment token lists of a TetGen file ('#' starts a comment anywhere)."""
    while f.i < len(f.lines):
        line = f.lines[f.i].split("#", 1)[0].strip()
        f.i += 1
        if line:
            yield line.split()



def _tetgen_header(path, what: str, usage: str):
    """Open a TetGen file: its line reader, the row iterator past the header, and the header's
    integers (at least two)."""
    f = _Lines(path, read_text(path))
    rows = _tetgen_rows(f, what)
    head = next(rows, None)
    if head is None:
        raise MeshError(f"{f.name}: no header line")
    ext = ".node" if what == "node" else ".ele"
    h = f.ints(" ".join(head), f"the {ext} header")
    if len(h) < 2:
        raise f.error(f"expected {usage}")
    return f, rows, h

def read_tetgen(path: str) -> Tuple[np.ndarray, List[CellBlock], List[str]]:
    """Read a TetGen mesh given as ``NAME.node`` or ``NAME.ele`` (the other file must sit beside it)."""
    stem, ext = os.path.splitext(path)
    node_path, ele_path = stem + ".node", stem + ".ele"
    given = os.path.basename(path)
    for p, kind in ((node_path, ".node"), (ele_path, ".ele")):
        if not os.path.exists(p):
            raise MeshError(f"{given}: the TetGen {kind} file {os.path.basename(p)!r} is missing "
                            f"(a TetGen mesh needs both NAME.node and NAME.ele)")
    # --- nodes
    f, rows, h = _tetgen_header(node_path, "node", "'<#points> <dimension> [<#attributes> <#boundary markers>]'")
    n, dim = h[0], h[1]
    n_attr = h[2] if len(h) > 2 else 0
    n_mark = h[3] if len(h) > 3 else 0
    if dim != 3:
        raise f.error(f"dimension {dim}: palpate needs 3D points")
    if n <= 0:
        raise MeshError(f"{f.name}: no points (header announces {n})")
    first_index = None
    coords = []
    for k in range(n):
        tok = next(rows, None)
        if tok is None:
            raise MeshError(f"{f.name}: unexpected end of file (truncated?): header announces {n} points, found {k}")
        if len(tok) != 4 + n_attr + n_mark:
            raise f.error(f"point {k}: expected {4 + n_attr + n_mark} values (index x y z"
                          f"{' attributes' if n_attr else ''}{' marker' if n_mark else ''}), got {len(tok)}")
        idx = f.ints(tok[0], "a point index")[0]
        if first_index is None:
            first_index = idx
            if idx not in (0, 1):
                raise f.error(f"first point index is {idx}; TetGen numbers from 0 or 1")
        if idx != first_index + k:
            raise f.error(f"point index {idx} out of sequence (expected {first_index + k})")
        coords.append(f.floats(tok[1:4], f"point {idx}"))
    if next(rows, None) is not None:
        raise f.error(f"more point lines than the {n} the header announces")
    points = np.array(coords, dtype=np.float64)
    # --- tets
    g, rows, h = _tetgen_header(ele_path, "tet", "'<#tetrahedra> <nodes per tet> [<#attributes>]'")
    m, npt = h[0], h[1]
    n_attr = h[2] if len(h) > 2 else 0
    if npt == 10:
        raise g.error("quadratic (10-node) tetrahedra are not supported: palpate uses linear tets")
    if npt != 4:
        raise g.error(f"{npt} nodes per element: palpate reads 4-node tetrahedra")
    if m <= 0:
        raise MeshError(f"{g.name}: no tetrahedra (header announces {m})")
    conn, labels = [], []
    for k in range(m):
        tok = next(rows, None)
        if tok is None:
            raise MeshError(f"{g.name}: unexpected end of file (truncated?): header announces {m} tets, found {k}")
        if len(tok) != 5 + n_attr:
            raise g.error(f"tet {k}: expected {5 + n_attr} values (index n1 n2 n3 n4"
                          f"{' attributes' if n_attr else ''}), got {len(tok)}")
        v = g.ints(" ".join(tok[:5]), "a tet line")
        for i in v[1:5]:
            if not first_index <= i < first_index + n:
                raise g.error(f"TetGen element {v[0]}: node index {i} out of range "
                              f"({os.path.basename(node_path)} numbers its {n} points "
                              f"{first_index}..{first_index + n - 1})")
        conn.append([i - first_index for i in v[1:5]])
        labels.append(f"TetGen element {v[0]}, {g.name} line {g.lineno}")
    if next(rows, None) is not None:
        raise g.error(f"more tet lines than the {m} the header announces")
    node_labels = [f"TetGen point {first_index + k}" for k in range(n)]
    return points, [CellBlock("tetra", 3, np.array(conn, dtype=np.int64), labels)], node_labels
