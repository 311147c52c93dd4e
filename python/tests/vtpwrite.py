"""A hand-rolled VTK XML PolyData writer for the tests (independent of palpate.vtp).

It writes every encoding VTK itself writes, and a few it does not, so that the reader can be
checked on each: ascii; inline base64 (header encoded on its own, as VTK does, or together with
the data); zlib-compressed in one or many blocks; appended raw or base64; UInt32 or UInt64
headers; either byte order. It can also write things a careful writer would refuse (any polygon
sizes, out-of-range indices), which the malformed-surface corpus uses.
"""
import base64
import zlib

import numpy as np

TYPES = {np.dtype(k): v for k, v in [
    (np.int8, "Int8"), (np.uint8, "UInt8"), (np.int16, "Int16"), (np.uint16, "UInt16"),
    (np.int32, "Int32"), (np.uint32, "UInt32"), (np.int64, "Int64"), (np.uint64, "UInt64"),
    (np.float32, "Float32"), (np.float64, "Float64")]}


def vtp(points, polys, cell_data=None, point_data=None, fmt="ascii", compress=False, header_type="UInt32",
        block_size=None, joint=False, big_endian=False, lines=None, verts=None, points_dtype=np.float64):
    """Bytes of a .vtp file.

    polys: list of vertex-index lists (any sizes); lines / verts likewise (cell data then covers
    verts, lines and polys in that order, as in VTK). fmt: "ascii", "binary", "appended" (raw) or
    "appended-base64". block_size: compressed block size in bytes (default: one block).
    joint: uncompressed base64 with header and data encoded together.
    """
    e = ">" if big_endian else "<"
    hdt = np.dtype(np.uint32 if header_type == "UInt32" else np.uint64).newbyteorder(e)
    appended = []
    pos = [0]

    def encode(arr):
        raw = np.ascontiguousarray(arr).astype(arr.dtype.newbyteorder(e)).tobytes()
        if not compress:
            return np.array([len(raw)], hdt).tobytes(), raw
        bs = block_size or max(len(raw), 1)
        blocks = [raw[i:i + bs] for i in range(0, len(raw), bs)] or [b""]
        comp = [zlib.compress(b) for b in blocks]
        last = len(blocks[-1]) if len(blocks[-1]) != bs else 0
        head = np.array([len(blocks), bs, last] + [len(c) for c in comp], hdt).tobytes()
        return head, b"".join(comp)

    def da(arr, name=None, ncomp=1):
        arr = np.asarray(arr)
        attrs = f'type="{TYPES[arr.dtype]}"' + (f' Name="{name}"' if name else "") + f' NumberOfComponents="{ncomp}"'
        if fmt == "ascii":
            body = " ".join(repr(float(x)) if arr.dtype.kind == "f" else str(int(x)) for x in arr.ravel())
            return f'<DataArray {attrs} format="ascii">\n{body}\n</DataArray>'
        head, data = encode(arr.ravel())
        if fmt == "binary":
            if joint and not compress:
                text = base64.b64encode(head + data)
            else:
                text = base64.b64encode(head) + base64.b64encode(data)
            return f'<DataArray {attrs} format="binary">\n{text.decode()}\n</DataArray>'
        if fmt == "appended-base64":
            chunk = base64.b64encode(head + data) if (joint and not compress) else base64.b64encode(head) + base64.b64encode(data)
        else:
            chunk = head + data
        off = pos[0]
        appended.append(chunk)
        pos[0] += len(chunk)
        return f'<DataArray {attrs} format="appended" offset="{off}"/>'

    def cells(tag, lists):
        if not lists:
            return ""
        conn = np.array([i for c in lists for i in c], dtype=np.int64)
        offs = np.cumsum([len(c) for c in lists]).astype(np.int64)
        return f"<{tag}>" + da(conn, "connectivity") + da(offs, "offsets") + f"</{tag}>"

    def section(tag, arrays):
        if not arrays:
            return ""
        out = []
        for k, v in arrays.items():
            v = np.asarray(v)
            out.append(da(v, k, 1 if v.ndim == 1 else v.shape[1]))
        return f"<{tag}>" + "".join(out) + f"</{tag}>"

    points = np.asarray(points, dtype=points_dtype)
    verts, lines = verts or [], lines or []
    body = "\n".join(s for s in [
        section("PointData", point_data), section("CellData", cell_data),
        "<Points>" + da(points, "Points", 3) + "</Points>",
        cells("Verts", verts), cells("Lines", lines), cells("Polys", polys)] if s)
    comp = ' compressor="vtkZLibDataCompressor"' if compress else ""
    order = "BigEndian" if big_endian else "LittleEndian"
    head = (f'<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0" byte_order="{order}" '
            f'header_type="{header_type}"{comp}>\n  <PolyData>\n    <Piece NumberOfPoints="{len(points)}" '
            f'NumberOfVerts="{len(verts)}" NumberOfLines="{len(lines)}" NumberOfStrips="0" '
            f'NumberOfPolys="{len(polys)}">\n{body}\n    </Piece>\n  </PolyData>\n')
    out = head.encode()
    if fmt.startswith("appended"):
        enc = "base64" if fmt == "appended-base64" else "raw"
        out += f'  <AppendedData encoding="{enc}">\n   _'.encode() + b"".join(appended) + b"\n  </AppendedData>\n"
    return out + b"</VTKFile>\n"


# A closed octahedron (outward), tagged: upper half inner (1), lower half outer (2) -- the tags are
# only labels here.
OCTA_POINTS = [(1.0, 0, 0), (-1.0, 0, 0), (0, 1.0, 0), (0, -1.0, 0), (0, 0, 1.0), (0, 0, -1.0)]
OCTA_TRIS = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
OCTA_TAGS = [1, 1, 1, 3, 2, 2, 2, 4]
