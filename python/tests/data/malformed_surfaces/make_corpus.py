"""Regenerate the malformed-surface corpus beside this script, and its table EXPECTED.toml.

    python make_corpus.py

Each file holds one defect in an otherwise valid closed octahedron (six points, eight outward
triangles, tagged 1 1 1 3 2 2 2 4 in the cell array "surface-id"). The files are committed; this
script documents how they were made. The VTP writer is the hand-rolled one of
python/tests/vtpwrite.py (not palpate's), so that a file can hold what a careful writer refuses.

EXPECTED.toml maps each file to the exception class that ``call`` (``load_surface``, the default,
or ``read_tagged_surface``) must raise with ``unit = "mm"``, and substrings of its message (the
file name is checked by the test itself). A case with ``warning`` instead of ``error`` must load,
with that warning class. Files named ``<stem>_part_definition.json`` are companions of ``<stem>.vtp``.
"""
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))
sys.path.insert(0, os.path.dirname(HERE))
from corpus import entry, write_case, write_expected  # noqa: E402
from vtpwrite import OCTA_POINTS, OCTA_TAGS, OCTA_TRIS, vtp  # noqa: E402

P = [tuple(p) for p in OCTA_POINTS]
T = [tuple(t) for t in OCTA_TRIS]
TAGS = {"surface-id": np.array(OCTA_TAGS, dtype=np.int32)}

CASES = []  # (file name, bytes, expectation dict)


def case(name, content, error=None, contains=(), warning=None, call="load_surface", note=""):
    CASES.append((name, content, dict(error=error, contains=list(contains), warning=warning, call=call, note=note)))


def replace_array(good: bytes, old: bytes, new: bytes) -> bytes:
    assert good.count(old) == 1
    return good.replace(old, new)


def build():
    import base64
    import zlib

    good = vtp(P, T, cell_data=TAGS, fmt="binary", compress=True)
    case("vtp_truncated.vtp", good[: good.index(b"<Polys>") + 80], "SurfaceError",
         ["not well-formed XML", "truncated"], note="cut inside the polygons")
    app = vtp(P, T, cell_data=TAGS, fmt="appended", compress=True)
    case("vtp_truncated_appended.vtp", app[: app.index(b"_", app.index(b"<AppendedData")) + 120],
         "SurfaceError", ["truncated"], note="raw appended data cut short")
    raw = np.array(P, dtype=np.float64).tobytes()
    c = zlib.compress(raw)
    ok = base64.b64encode(np.array([1, len(raw), 0, len(c)], np.uint32).tobytes()) + base64.b64encode(c)
    bad_c = c[:6] + bytes(8) + c[14:]
    bad = base64.b64encode(np.array([1, len(raw), 0, len(c)], np.uint32).tobytes()) + base64.b64encode(bad_c)
    case("vtp_corrupt_zlib.vtp", replace_array(good, ok, bad), "SurfaceError",
         ["Points", "corrupt zlib data", "block 0"])
    case("vtp_corrupt_base64.vtp", replace_array(good, ok, ok[:30] + b"*#" + ok[32:]), "SurfaceError",
         ["Points", "corrupt base64"])
    case("vtp_size_mismatch.vtp", good.replace(b'NumberOfPoints="6"', b'NumberOfPoints="7"'), "SurfaceError",
         ["holds 18 values, expected 21", "size mismatch"], note="NumberOfPoints says 7, Points hold 6")
    case("vtp_quad_polygon.vtp", vtp(P, T[:2] + [(0, 1, 2, 3)] + T[2:], fmt="ascii"), "SurfaceError",
         ["polygon 2", "4 vertices", "not 3"])
    tris = [list(t) for t in T]
    tris[5][1] = 6
    case("vtp_index_out_of_range.vtp", vtp(P, tris, fmt="appended"), "SurfaceError",
         ["polygon 5", "vertex index 6", "out of range"])
    case("vtp_no_points.vtp", good[: good.index(b"<Points>")] + good[good.index(b"</Points>") + 9:],
         "SurfaceError", ["no <Points>"])
    case("vtp_unstructured_grid.vtp", good.replace(b'type="PolyData"', b'type="UnstructuredGrid"'), "SurfaceError",
         ["'UnstructuredGrid'", "not 'PolyData'"])
    case("vtp_not_xml.vtp", b"solid octahedron\nendsolid octahedron\n", "SurfaceError", ["not a VTK XML file"])
    case("vtp_open_surface.vtp", vtp(P, T[1:], fmt="binary"), "SurfaceError", ["open surface", "edge"])
    case("vtp_flipped_triangle.vtp", vtp(P, T[:3] + [T[3][::-1]] + T[4:], fmt="binary"), "SurfaceError",
         ["inconsistent orientation", "triangle 3"])
    case("vtp_nan_coordinate.vtp", vtp(P[:2] + [(0.0, float("nan"), 0.0)] + P[3:], T, fmt="binary"),
         "SurfaceError", ["vertex 2", "non-finite"])
    # point 6 on the middle of edge (0, 2): triangle (0, 6, 2) has no area
    case("vtp_degenerate_triangle.vtp",
         vtp(P + [(0.5, 0.5, 0.0)], [(0, 6, 4), (6, 2, 4)] + T[1:4] + [(2, 6, 5), (6, 0, 5)] + T[5:]
             + [(0, 6, 2), (0, 2, 6)], fmt="ascii"),
         "SurfaceError", ["degenerate"], note="a zero-area triangle and its twin")
    case("vtp_inward.vtp", vtp(P, [t[::-1] for t in T], fmt="binary", compress=True),
         warning="MeshWarning", contains=["oriented inward", "reversed"], note="loads, with a warning")
    # --- tagged surfaces (read_tagged_surface)
    case("tagged_missing_tag_array.vtp", vtp(P, T, cell_data={"region": TAGS["surface-id"]}, fmt="binary"),
         "SurfaceError", ["missing tag array 'surface-id'", "'region'"], call="read_tagged_surface")
    case("tagged_unmapped_tag.vtp", vtp(P, T, cell_data={"surface-id": np.array([1, 1, 1, 9, 2, 2, 2, 4], np.int32)},
                                        fmt="binary", compress=True),
         "SurfaceError", ["triangle 3", "tag value 9 ('lv-septum')", "not mapped", "tagged_unmapped_tag_part_definition.json"],
         call="read_tagged_surface", note="the part definition beside it maps 1, 2 and 4 only")
    CASES.append(("tagged_unmapped_tag_part_definition.json", json.dumps(
        {"LV": {"id": 1, "enclosed_by_boundaries": {"lv-endocardium": 1, "lv-epicardium": 2,
                                                    "aortic-valve-plane": 4, "lv-septum": 9}}}, indent=1).encode(), None))
    case("tagged_no_outer.vtp", vtp(P, T, cell_data={"surface-id": np.array([1, 1, 1, 3, 1, 1, 1, 4], np.int32)},
                                    fmt="ascii"),
         "SurfaceError", ["no outer triangles", "value(s) [2]", "values present: [1, 3, 4]"], call="read_tagged_surface")
    case("tagged_float_tags.vtp", vtp(P, T, cell_data={"surface-id": np.array(OCTA_TAGS, float) + 0.5}, fmt="ascii"),
         "SurfaceError", ["'surface-id' holds non-integer values"], call="read_tagged_surface")


def main():
    build()
    lines = ["# Expected outcome for each surface file of this folder (made by make_corpus.py).",
             "# call: palpate function run on the file with unit=\"mm\" (default load_surface);",
             "# error: exception class name in palpate; warning: the file must load with this warning class;",
             "# contains: substrings of the message (the file's own name is always required too).", ""]
    for name, content, exp in CASES:
        write_case(HERE, name, content)
        if exp is None:
            continue
        lines += entry(name, exp, default_call="load_surface")
    write_expected(HERE, lines)

if __name__ == "__main__":
    main()
