"""Small, strict ASCII readers for gmsh MSH 2.2 / 4.1 and TetGen .node/.ele files.

meshio reads these formats too, but it maps unknown gmsh node tags silently (a tag of 0 or -1 wraps
around to the last node, in ASCII and binary files) and its TetGen reader stops at comments without saying where. These
readers report every defect with the file, the line (or byte) and the element, which is what
:func:`palpate.load_mesh` promises. Binary gmsh MSH 2.2 and 4.1 are read here too; MSH 4.0 goes to meshio.

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


def read_gmsh_ascii(path: str, version: str) -> Tuple[np.ndarray, List[CellBlock], List[str]]:
    """Read an ASCII gmsh MSH 2.2 or 4.1 file (nodes and elements; other sections are skipped)."""
    f = _Lines(path, read_text(path))
    v4 = version.startswith("4")
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
                nodes = _gmsh_nodes_v4(f) if v4 else _gmsh_nodes_v2(f)
            elif section == "Elements":
                elements = _gmsh_elements_v4(f) if v4 else _gmsh_elements_v2(f)
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
    """Read a binary gmsh MSH 2.2 or 4.1 file (little-endian; nodes and elements, other sections
    skipped), every element's node tag checked against $Nodes as in the ASCII reader. meshio read
    these before, and mapped an undefined node tag 0 (tag - 1 = -1) to the node with the largest
    tag without a word (issue 35 item 6)."""
    check_input_file(path)
    with open(path, "rb") as fh:
        b = _Bytes(path, fh.read())
    v4 = version.startswith("4")
    b.line("$MeshFormat")
    head = b.line("$MeshFormat").split()
    if v4 and len(head) > 2 and head[2] != b"8":
        raise b.error(f"data-size {head[2].decode('latin-1')!r}: palpate reads binary MSH 4.1 with 8-byte sizes")
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
            nodes = _gmsh_bin_nodes_v4(b) if v4 else _gmsh_bin_nodes_v2(b)
        elif section == "Elements":
            elements = _gmsh_bin_elements_v4(b) if v4 else _gmsh_bin_elements_v2(b)
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
        rows = b.take("<u8", count * (1 + nn), f"{count} gmsh elements of type {etype}").reshape(count, 1 + nn)
        for k, row in enumerate(rows.astype(np.int64).tolist()):
            out.append((etype, row[0], row[1:], f"byte {start + k * 8 * (1 + nn)}"))
    if len(out) != n_elements:
        raise b.error(f"$Elements header announces {n_elements} elements, the blocks hold {len(out)}")
    return out


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
