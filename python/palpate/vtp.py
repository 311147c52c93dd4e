"""VTK XML PolyData (``.vtp``) in: :func:`read_vtp`.

meshio does not read ``.vtp``; this is a small reader written with the standard library and numpy
only. It reads every encoding VTK writes: ``format="ascii"``, ``format="binary"`` (base64, raw or
compressed with ``vtkZLibDataCompressor`` / ``vtkLZMADataCompressor``, ``header_type`` UInt32 or
UInt64, one or many compressed blocks) and ``<AppendedData>`` (``encoding="raw"`` or
``"base64"``), in either byte order, with one or several ``<Piece>`` s (concatenated).

What is read: ``Points``, ``Polys`` (``connectivity`` + ``offsets``; every polygon must be a
triangle) and the ``CellData`` / ``PointData`` arrays of the numeric types Int8 ... UInt64,
Float32 / Float64, with any number of components. ``Verts`` and ``Lines`` are ignored (cell data
is restricted to the polygons); triangle strips are an error. String arrays are skipped.

Every defect (not XML, not PolyData, a truncated or corrupt base64 / zlib payload, a size
mismatch, no points, a vertex index out of range, a polygon that is not a triangle ...) raises
:class:`palpate.SurfaceError` (a :class:`palpate.MeshError`) naming the file and the reason,
never a bare traceback from zlib, base64 or the XML parser.
"""
from __future__ import annotations

import base64
import binascii
import lzma
import os
import re
import xml.etree.ElementTree as ET
import zlib
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple, Union

import numpy as np

from . import _readers
from ._indices import whole_indices
from ._palpate import SurfaceError

PathLike = Union[str, "os.PathLike[str]"]

#: VTK XML data-array type names -> numpy dtypes (native order; the byte order is applied per file).
VTK_TYPES = {
    "Int8": np.int8, "UInt8": np.uint8, "Int16": np.int16, "UInt16": np.uint16,
    "Int32": np.int32, "UInt32": np.uint32, "Int64": np.int64, "UInt64": np.uint64,
    "Float32": np.float32, "Float64": np.float64,
    # names written by old VTK versions
    "Char": np.int8, "UnsignedChar": np.uint8, "Short": np.int16, "UnsignedShort": np.uint16,
    "Int": np.int32, "UnsignedInt": np.uint32, "Long": np.int64, "UnsignedLong": np.uint64,
    "Float": np.float32, "Double": np.float64, "IdType": np.int64,
}
_SKIPPED_TYPES = {"String", "Bit"}
_COMPRESSORS = {"vtkZLibDataCompressor": ("zlib", zlib.decompress, zlib.error),
                "vtkLZMADataCompressor": ("LZMA", lzma.decompress, lzma.LZMAError)}


@dataclass
class PolyData:
    """What :func:`read_vtp` returns, in the file's own units (no scaling).

    Attributes
    ----------
    points: ``(n, 3)`` float64.
    triangles: ``(m, 3)`` int64, 0-based, the ``Polys`` of all pieces in file order.
    cell_data: name -> array with one row per triangle (``(m,)`` or ``(m, k)``, the file's dtype).
    point_data: name -> array with one row per point.
    """

    points: np.ndarray
    triangles: np.ndarray
    cell_data: Dict[str, np.ndarray] = field(default_factory=dict)
    point_data: Dict[str, np.ndarray] = field(default_factory=dict)


class _Reader:
    def __init__(self, path: str):
        self.path = path
        self.name = os.path.basename(path)

    def error(self, reason: str) -> SurfaceError:
        return SurfaceError(f"{self.name}: {reason}")

    # --- file and XML -------------------------------------------------------------------------

    def load(self) -> PolyData:
        _readers.check_input_file(self.path, SurfaceError)
        _readers.vtk_xml_inflated_precheck(self.path, SurfaceError)
        with open(self.path, "rb") as fh:
            raw = fh.read()
        if not raw.strip():
            raise self.error("empty file")
        xml_bytes, self.appended, self.appended_encoding = self._split_appended(raw)
        try:
            root = ET.fromstring(xml_bytes)
        except ET.ParseError as e:
            if b"<VTKFile" not in raw[:4096]:
                raise self.error(f"not a VTK XML file (XML parse error: {e})") from None
            raise self.error(f"not well-formed XML, the file is truncated or corrupt ({e})") from None
        if root.tag != "VTKFile":
            raise self.error(f"not a VTK XML file (root element <{root.tag}>, expected <VTKFile>)")
        kind = root.get("type")
        if kind != "PolyData":
            raise self.error(f"VTK XML file of type {kind!r}, not 'PolyData': palpate reads triangle "
                             "surfaces from .vtp (PolyData)")
        order = root.get("byte_order", "LittleEndian")
        if order not in ("LittleEndian", "BigEndian"):
            raise self.error(f"unknown byte_order {order!r}")
        self.endian = "<" if order == "LittleEndian" else ">"
        htype = root.get("header_type", "UInt32")
        if htype not in ("UInt32", "UInt64"):
            raise self.error(f"unsupported header_type {htype!r} (expected UInt32 or UInt64)")
        self.header_dtype = np.dtype(VTK_TYPES[htype]).newbyteorder(self.endian)
        comp = root.get("compressor")
        if comp and comp not in _COMPRESSORS:
            raise self.error(f"unsupported compressor {comp!r} (palpate reads "
                             f"{' and '.join(_COMPRESSORS)} or uncompressed data)")
        self.compressor = _COMPRESSORS.get(comp) if comp else None
        poly = root.find("PolyData")
        if poly is None:
            raise self.error("no <PolyData> element")
        pieces = poly.findall("Piece")
        if not pieces:
            raise self.error("no <Piece> in <PolyData>")
        return self._concat([self._piece(p, k, len(pieces)) for k, p in enumerate(pieces)])

    def _split_appended(self, raw: bytes) -> Tuple[bytes, Optional[bytes], Optional[str]]:
        """Cut the <AppendedData> block (raw bytes are not XML) out of the file."""
        i = raw.find(b"<AppendedData")
        if i < 0:
            return raw, None, None
        j = raw.find(b">", i)
        if j < 0:
            raise self.error("truncated <AppendedData> tag")
        tag = raw[i:j + 1]
        if tag.endswith(b"/>"):
            raise self.error("<AppendedData/> is empty")
        m = re.search(rb'encoding\s*=\s*"([^"]*)"', tag)
        encoding = m.group(1).decode("ascii", "replace") if m else "raw"
        if encoding not in ("raw", "base64"):
            raise self.error(f"<AppendedData> encoding {encoding!r} is not 'raw' or 'base64'")
        start = raw.find(b"_", j)
        if start < 0:
            raise self.error("<AppendedData> has no '_' marker before its data (truncated file)")
        start += 1
        end = raw.rfind(b"</AppendedData>")
        if end < start:
            # No closing tag: the file is cut short; the arrays' sizes decide what is missing.
            data = raw[start:]
        else:
            data = raw[start:end]
        if encoding == "base64":
            data = data.rstrip()
        return raw[:i] + b"</VTKFile>", data, encoding

    # --- pieces -------------------------------------------------------------------------------

    def _int_attr(self, elem, attr: str, default: str, where: str, minimum: int) -> int:
        """The integer attribute ``attr`` of ``elem`` (``default`` if absent), at least ``minimum``."""
        v = elem.get(attr, default)
        try:
            n = int(v)
        except ValueError:
            raise self.error(f"{where}: {attr}={v!r} is not an integer") from None
        if n < minimum:
            raise self.error(f"{where}: {attr}={n}" + (" is negative" if minimum == 0 else ""))
        return n

    def _count(self, piece, attr: str, k: int) -> int:
        return self._int_attr(piece, attr, "0", f"piece {k}", 0)

    def _piece(self, piece, k: int, n_pieces: int):
        where = f"piece {k}: " if n_pieces > 1 else ""
        if piece.get("NumberOfPoints") is None:
            raise self.error(f"{where}<Piece> has no NumberOfPoints attribute")
        n_points = self._count(piece, "NumberOfPoints", k)
        n_verts = self._count(piece, "NumberOfVerts", k)
        n_lines = self._count(piece, "NumberOfLines", k)
        n_strips = self._count(piece, "NumberOfStrips", k)
        n_polys = self._count(piece, "NumberOfPolys", k)
        if n_strips:
            raise self.error(f"{where}{n_strips} triangle strip(s) (<Strips>): palpate reads triangles "
                             "stored as <Polys>; triangulate the strips first (vtkTriangleFilter)")
        pts_el = piece.find("Points")
        if n_points == 0:
            raise self.error(f"{where}no points (NumberOfPoints = 0: empty surface)")
        if pts_el is None or pts_el.find("DataArray") is None:
            raise self.error(f"{where}no <Points> (NumberOfPoints = {n_points})")
        pts = self._array(pts_el.find("DataArray"), f"{where}Points", n_points, expect_components=3)
        if not np.issubdtype(pts.dtype, np.number):
            raise self.error(f"{where}Points: non-numeric type")
        pts = pts.astype(np.float64).reshape(n_points, 3)

        tris = np.zeros((0, 3), dtype=np.int64)
        if n_polys:
            polys = piece.find("Polys")
            if polys is None:
                raise self.error(f"{where}NumberOfPolys = {n_polys} but no <Polys> element")
            arrays = {a.get("Name"): a for a in polys.findall("DataArray")}
            for need in ("connectivity", "offsets"):
                if need not in arrays:
                    raise self.error(f"{where}<Polys> has no '{need}' DataArray")
            offsets = self._array(arrays["offsets"], f"{where}Polys offsets", n_polys, integer=True)
            conn = self._array(arrays["connectivity"], f"{where}Polys connectivity", None, integer=True)
            tris = self._triangles(conn, offsets, n_points, n_verts + n_lines, where)

        n_cells = n_verts + n_lines + n_polys
        cell_data = self._data_arrays(piece.find("CellData"), n_cells, f"{where}CellData")
        cell_data = {k_: v[n_verts + n_lines:] for k_, v in cell_data.items()}
        point_data = self._data_arrays(piece.find("PointData"), n_points, f"{where}PointData")
        return pts, tris, cell_data, point_data

    def _triangles(self, conn, offsets, n_points, first_cell, where):
        # Whole values only: a float array's 1.5 was truncated to 1 (issue 35 item 6).
        offsets = whole_indices(offsets, f"{where}Polys offsets", error=self.error).ravel()
        conn = whole_indices(conn, f"{where}Polys connectivity", error=self.error).ravel()
        starts = np.concatenate([[0], offsets[:-1]])
        sizes = offsets - starts
        bad = np.flatnonzero(sizes < 0)
        if len(bad):
            raise self.error(f"{where}Polys offsets decrease at polygon {bad[0]} (corrupt cell array)")
        if offsets[-1] != len(conn):
            raise self.error(f"{where}Polys: the last offset is {offsets[-1]} but the connectivity holds "
                             f"{len(conn)} indices (size mismatch)")
        bad = np.flatnonzero(sizes != 3)
        if len(bad):
            c = int(bad[0])
            raise self.error(f"{where}polygon {c} (VTK cell {first_cell + c}) has {sizes[c]} vertices, not 3: "
                             f"palpate needs a triangle surface ({len(bad)} non-triangle polygon(s); "
                             "triangulate first, e.g. vtkTriangleFilter)")
        tris = conn.reshape(-1, 3)
        bad = np.flatnonzero(((tris < 0) | (tris >= n_points)).any(axis=1))
        if len(bad):
            c = int(bad[0])
            v = int(tris[c][(tris[c] < 0) | (tris[c] >= n_points)][0])
            raise self.error(f"{where}polygon {c} (VTK cell {first_cell + c}): vertex index {v} out of range "
                             f"(the surface has {n_points} points)")
        return tris

    def _data_arrays(self, el, n_tuples: int, where: str) -> Dict[str, np.ndarray]:
        out: Dict[str, np.ndarray] = {}
        if el is None:
            return out
        for k, a in enumerate(el.findall("DataArray")):
            name = a.get("Name") or f"array{k}"
            if a.get("type") in _SKIPPED_TYPES:
                continue
            ncomp = self._ncomp(a, f"{where} array '{name}'")
            arr = self._array(a, f"{where} array '{name}'", n_tuples)
            out[name] = arr.reshape(n_tuples, ncomp) if ncomp > 1 else arr.reshape(n_tuples)
        return out

    def _concat(self, parts) -> PolyData:
        points, tris, offset = [], [], 0
        for pts, t, _, _ in parts:
            points.append(pts)
            tris.append(t + offset)
            offset += len(pts)
        cell_data = self._merge([p[2] for p in parts], "CellData")
        point_data = self._merge([p[3] for p in parts], "PointData")
        tris = np.concatenate(tris, axis=0).astype(np.int64)
        if len(tris) == 0:
            raise self.error("no triangles (no <Polys>: empty surface)")
        return PolyData(np.concatenate(points, axis=0), tris, cell_data, point_data)

    def _merge(self, dicts, what):
        if len(dicts) == 1:
            return dicts[0]
        names = set.intersection(*(set(d) for d in dicts))
        return {n: np.concatenate([d[n] for d in dicts], axis=0) for n in sorted(names)}

    # --- data arrays --------------------------------------------------------------------------

    def _ncomp(self, a, what: str) -> int:
        return self._int_attr(a, "NumberOfComponents", "1", what, 1)

    def _array(self, a, what: str, n_tuples: Optional[int], expect_components: Optional[int] = None,
               integer: bool = False) -> np.ndarray:
        """One <DataArray>, flat, with n_tuples * NumberOfComponents values (when n_tuples is known)."""
        vtype = a.get("type")
        if vtype not in VTK_TYPES:
            raise self.error(f"{what}: unsupported data type {vtype!r}")
        dtype = np.dtype(VTK_TYPES[vtype])
        if integer and dtype.kind not in "iu":
            raise self.error(f"{what}: type {vtype} is not an integer type")
        ncomp = self._ncomp(a, what)
        if expect_components is not None and ncomp != expect_components:
            raise self.error(f"{what}: {ncomp} components, expected {expect_components}")
        fmt = a.get("format", "ascii")
        if fmt == "ascii":
            arr = self._ascii(a.text or "", dtype, what)
        elif fmt == "binary":
            text = re.sub(r"\s+", "", a.text or "")
            arr = self._to_array(self._decode_base64_block(text, what), dtype, what)
        elif fmt == "appended":
            arr = self._appended(a, dtype, what)
        else:
            raise self.error(f"{what}: unknown format {fmt!r} (expected ascii, binary or appended)")
        if n_tuples is not None and arr.size != n_tuples * ncomp:
            raise self.error(f"{what}: holds {arr.size} values, expected {n_tuples * ncomp} "
                             f"({n_tuples} x {ncomp} components): size mismatch")
        return arr

    def _ascii(self, text: str, dtype, what: str) -> np.ndarray:
        tokens = text.split()
        try:
            if dtype.kind == "f":
                return np.array(tokens, dtype=np.float64).astype(dtype)
            return np.array([int(t) for t in tokens], dtype=dtype)
        except (ValueError, OverflowError) as e:
            raise self.error(f"{what}: bad ASCII value ({e})") from None

    def _b64(self, text, what: str) -> bytes:
        try:
            return base64.b64decode(text, validate=True)
        except (binascii.Error, ValueError) as e:
            raise self.error(f"{what}: corrupt base64 data ({e})") from None

    @staticmethod
    def _b64_chars(nbytes: int) -> int:
        return 4 * ((nbytes + 2) // 3)

    def _nblocks(self, buf: bytes, what: str) -> int:
        n = int(self._header_ints(buf, 1, what)[0])
        if n < 0:
            raise self.error(f"{what}: corrupt compressed-data header (block count {n})")
        return n

    def _header_ints(self, buf: bytes, count: int, what: str) -> np.ndarray:
        size = count * self.header_dtype.itemsize
        if len(buf) < size:
            raise self.error(f"{what}: data block header cut short (truncated file)")
        return np.frombuffer(buf[:size], dtype=self.header_dtype).astype(np.int64)

    def _decode_base64_block(self, text: str, what: str) -> bytes:
        """Inline base64: the header and the data are encoded separately (VTK) or together."""
        return self._base64_block(text, what, bounded=False)

    def _base64_block(self, text, what: str, bounded: bool) -> bytes:
        """One base64 data block at the start of ``text`` (str or bytes): ``[nbytes] data``, the header
        encoded on its own (VTK) or with the data, or compressed ``[nblocks, blocksize, lastsize,
        csize_1 .. csize_n]`` (encoded on its own) and the blocks. ``bounded``: the text goes on with
        the next arrays (an appended stream), so only this block's characters are decoded."""
        hs = self.header_dtype.itemsize
        if self.compressor is None:
            hchars = self._b64_chars(hs)
            head = text[:hchars]
            if len(head) < hchars:
                raise self.error(f"{what}: base64 data cut short (truncated file)")
            if head.endswith("=" if isinstance(head, str) else b"="):  # the header encoded on its own
                nbytes = int(self._header_ints(self._b64(head, what), 1, what)[0])
                rest = text[hchars:]
                body = self._b64(rest[:self._b64_chars(nbytes)] if bounded else rest, what)
            else:  # header and data encoded together
                first = self._b64(head if bounded else text, what)
                nbytes = int(self._header_ints(first, 1, what)[0])
                body = (self._b64(text[:self._b64_chars(hs + nbytes)], what) if bounded else first)[hs:]
            return self._take(body, nbytes, what)
        n3 = self._b64_chars(3 * hs)
        first = self._b64(text[:n3], what) if len(text) >= n3 else b""
        nblocks = self._nblocks(first, what)
        hchars = self._b64_chars((3 + nblocks) * hs)
        if len(text) < hchars:
            raise self.error(f"{what}: compressed-data header cut short (truncated file)")
        header = self._header_ints(self._b64(text[:hchars], what), 3 + nblocks, what)
        rest = text[hchars:]
        body = self._b64(rest[:self._b64_chars(int(header[3:].sum()))] if bounded else rest, what)
        return self._inflate(header, body, what)

    def _take(self, body: bytes, nbytes: int, what: str) -> bytes:
        if nbytes < 0 or len(body) < nbytes:
            raise self.error(f"{what}: the block header announces {nbytes} bytes but {len(body)} are present "
                             "(truncated or corrupt data)")
        return body[:nbytes]

    def _inflate(self, header: np.ndarray, body: bytes, what: str) -> bytes:
        label, decompress, err = self.compressor
        nblocks, bsize, last = (int(x) for x in header[:3])
        csizes = header[3:]
        if nblocks < 0 or bsize < 0 or last < 0 or (csizes < 0).any():
            raise self.error(f"{what}: corrupt compressed-data header {header[:3].tolist()}")
        # The inflated size from the header, against the memory budget before any block is
        # inflated (the file-level precheck covers the usual layouts; this covers every one).
        _readers.check_budget(f"{what}: {label} data inflates to {max(nblocks - 1, 0) * bsize + (last or bsize)} bytes",
                              max(nblocks - 1, 0) * bsize + (last or bsize), self.name)
        if int(csizes.sum()) > len(body):
            raise self.error(f"{what}: {label} blocks need {int(csizes.sum())} bytes but {len(body)} are present "
                             "(truncated file)")
        out, pos = [], 0
        for b, cs in enumerate(csizes):
            cs = int(cs)
            try:
                chunk = decompress(body[pos:pos + cs])
            except err as e:
                raise self.error(f"{what}: corrupt {label} data in block {b} of {nblocks} ({e})") from None
            expect = last if (b == nblocks - 1 and last) else bsize
            if len(chunk) != expect:
                raise self.error(f"{what}: {label} block {b} inflates to {len(chunk)} bytes, expected {expect} "
                                 "(corrupt data)")
            out.append(chunk)
            pos += cs
        return b"".join(out)

    def _to_array(self, buf: bytes, dtype, what: str) -> np.ndarray:
        dt = np.dtype(dtype).newbyteorder(self.endian)
        if len(buf) % dt.itemsize:
            raise self.error(f"{what}: {len(buf)} bytes is not a whole number of {dt.name} values (size mismatch)")
        return np.frombuffer(buf, dtype=dt).astype(np.dtype(dtype).newbyteorder("="))

    def _appended(self, a, dtype, what: str) -> np.ndarray:
        if self.appended is None:
            raise self.error(f"{what}: format='appended' but the file has no <AppendedData>")
        v = a.get("offset")
        try:
            off = int(v)
        except (TypeError, ValueError):
            raise self.error(f"{what}: appended array without a valid offset ({v!r})") from None
        data = self.appended
        if off < 0 or off >= len(data):
            raise self.error(f"{what}: offset {off} lies beyond the {len(data)} bytes of <AppendedData> "
                             "(truncated file)")
        if self.appended_encoding == "base64":
            text = data[off:]
            # the stream is cut at the next array's start by the sizes in the headers; take what is needed
            return self._to_array(self._appended_base64(text, what), dtype, what)
        hs = self.header_dtype.itemsize
        if self.compressor is None:
            nbytes = int(self._header_ints(data[off:], 1, what)[0])
            return self._to_array(self._take(data[off + hs:], nbytes, what), dtype, what)
        nblocks = self._nblocks(data[off:], what)
        header = self._header_ints(data[off:], 3 + nblocks, what)
        start = off + (3 + nblocks) * hs
        return self._to_array(self._inflate(header, data[start:start + int(header[3:].sum())], what), dtype, what)

    def _appended_base64(self, text: bytes, what: str) -> bytes:
        """One array at the start of an appended base64 stream (which continues with the next arrays)."""
        return self._base64_block(text, what, bounded=True)

def read_vtp(path: PathLike) -> PolyData:
    """Read a VTK XML PolyData file holding a triangle surface.

    Returns a :class:`PolyData` in the file's units (no scaling, no validation of the surface's
    topology: see :func:`palpate.load_surface` for that).

    Raises
    ------
    SurfaceError
        The file is missing, empty, not XML, not PolyData, truncated, holds corrupt base64 or
        compressed data, arrays of the wrong size, no points, a polygon that is not a triangle or
        a vertex index out of range; the message names the file (and the polygon or array).
    """
    return _Reader(os.fspath(path)).load()


def write_vtp(path: PathLike, points, triangles, cell_data: Optional[Dict[str, np.ndarray]] = None,
              point_data: Optional[Dict[str, np.ndarray]] = None, fmt: str = "binary",
              compress: bool = True, header_type: str = "UInt32") -> None:
    """Write a triangle surface as VTK XML PolyData (for tests and for handing surfaces to ParaView).

    ``fmt`` is ``"ascii"``, ``"binary"`` (inline base64) or ``"appended"`` (raw appended data);
    ``compress`` applies zlib to the binary forms.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    triangles = np.ascontiguousarray(whole_indices(triangles, "triangles", 3))
    if fmt not in ("ascii", "binary", "appended"):
        raise ValueError(f"fmt must be 'ascii', 'binary' or 'appended', got {fmt!r}")
    hdt = np.dtype({"UInt32": np.uint32, "UInt64": np.uint64}[header_type]).newbyteorder("<")
    appended: List[bytes] = []
    pos = [0]

    def block(arr: np.ndarray) -> bytes:
        data = np.ascontiguousarray(arr).astype(arr.dtype.newbyteorder("<")).tobytes()
        if not compress:
            return np.array([len(data)], hdt).tobytes(), data
        c = zlib.compress(data)
        return np.array([1, len(data), len(data), len(c)], hdt).tobytes(), c

    def da(arr: np.ndarray, name: Optional[str]) -> str:
        arr = np.asarray(arr)
        vtype = {np.dtype(v): k for k, v in list(VTK_TYPES.items())[:10]}[arr.dtype.newbyteorder("=")]
        ncomp = 1 if arr.ndim == 1 else arr.shape[1]
        attrs = f'type="{vtype}"' + (f' Name="{name}"' if name else "") + f' NumberOfComponents="{ncomp}"'
        if fmt == "ascii":
            body = " ".join(repr(x) if arr.dtype.kind == "f" else str(x) for x in arr.ravel().tolist())
            return f'<DataArray {attrs} format="ascii">{body}</DataArray>'
        head, data = block(arr)
        if fmt == "binary":
            text = (base64.b64encode(head) + base64.b64encode(data)).decode()
            return f'<DataArray {attrs} format="binary">{text}</DataArray>'
        off = pos[0]
        appended.append(head + data)
        pos[0] += len(head) + len(data)
        return f'<DataArray {attrs} format="appended" offset="{off}"/>'

    def section(tag, arrays):
        if not arrays:
            return ""
        return f"<{tag}>" + "".join(da(np.asarray(v), k) for k, v in arrays.items()) + f"</{tag}>"

    n, m = len(points), len(triangles)
    parts = [section("PointData", point_data), section("CellData", cell_data),
             "<Points>" + da(points, "Points") + "</Points>",
             "<Polys>" + da(triangles.ravel(), "connectivity") + da(np.arange(1, m + 1) * 3, "offsets") + "</Polys>"]
    comp = ' compressor="vtkZLibDataCompressor"' if compress and fmt != "ascii" else ""
    head = (f'<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" '
            f'header_type="{header_type}"{comp}>\n<PolyData>\n<Piece NumberOfPoints="{n}" NumberOfVerts="0" '
            f'NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="{m}">\n' + "\n".join(p for p in parts if p)
            + "\n</Piece>\n</PolyData>\n")
    with open(os.fspath(path), "wb") as fh:
        fh.write(head.encode())
        if appended:
            fh.write(b'<AppendedData encoding="raw">\n_' + b"".join(appended) + b"\n</AppendedData>\n")
        fh.write(b"</VTKFile>\n")
