"""Mesh files in, VTU time series out.

:func:`load_mesh` reads a tetrahedral mesh from gmsh ``.msh`` (MSH 2.2, 4.0, 4.1), VTK ``.vtk``/``.vtu``,
Medit ``.mesh``, Abaqus ``.inp`` (these four through meshio), TetGen ``.node``/``.ele`` and ``.npz``
(arrays ``points`` and ``tets``), scales it
to metres and validates it in the Rust core. Every defect is raised as :class:`palpate.MeshError`
naming the file, the element (as palpate counts it, 0-based among the file's tetrahedra, and as the
file names it) and the reason.

:class:`VtuSeries` writes one ``.vtu`` per frame plus a ``.pvd`` collection that ParaView opens.
"""
from __future__ import annotations

import contextlib
import os
import re
import warnings
from typing import TYPE_CHECKING, Dict, List, Optional, Sequence, Tuple, Union
from xml.sax.saxutils import quoteattr

import numpy as np

from . import _readers
from ._indices import whole_indices
from ._palpate import MeshError, MeshWarning, ParameterError, TetMesh

if TYPE_CHECKING:
    from ._palpate import Body, HybridModel, ParticleBody

PathLike = Union[str, "os.PathLike[str]"]

#: Length units accepted by :func:`load_mesh`, as metres per unit.
UNITS = {"m": 1.0, "cm": 1.0e-2, "mm": 1.0e-3}

# Formats read through meshio (its format names): .mesh is Medit's, .inp Abaqus's.
_MESHIO_FORMATS = {".vtk": "vtk", ".vtu": "vtu", ".mesh": "medit", ".inp": "abaqus"}


def unit_scale(unit: str) -> float:
    """Metres per ``unit`` (one of ``"m"``, ``"cm"``, ``"mm"``); ``ValueError`` otherwise."""
    try:
        return UNITS[unit]
    except (KeyError, TypeError):
        raise ParameterError(f"unit must be one of {sorted(UNITS)}, got {unit!r}") from None


def _read_meshio(path: str, fmt: str):
    import meshio

    name = os.path.basename(path)
    if _readers.check_input_file(path) == 0:
        raise MeshError(f"{name}: empty file")
    if fmt == "vtu":
        _vtu_precheck(path)
        _readers.vtk_xml_inflated_precheck(path, MeshError)
    if fmt == "vtk":
        _readers.vtk_legacy_precheck(path, MeshError)
    if fmt == "gmsh" and _readers.gmsh_format(path)[1]:
        _readers.gmsh_binary_precheck(path)
    # The format's own reader, not meshio.read: that one prints and calls sys.exit(1) on a ReadError.
    reader = {"vtk": meshio.vtk.read, "vtu": meshio.vtu.read, "gmsh": _meshio_gmsh,
              "medit": meshio.medit.read, "abaqus": _meshio_abaqus}[fmt]
    m = _meshio_read(reader, path, name, fmt)
    return _meshio_arrays(m, name, fmt)


#: meshio's readers drop what they cannot read with a line on stderr (``meshio._common.warn``, not
#: a Python warning) and go on: VTU and legacy VTK 5.1 cells of a type they do not know, a corrupt
#: VTU point data array, Medit sections they do not know, a gmsh section without its end. Such a
#: file loaded without those cells (issue 35 item 6). While palpate reads with them, each of these
#: modules' ``warn`` raises a MeshError instead (a swap of module attributes for the read's
#: duration: a meshio read in another thread at the same time would see it too, and fail rather
#: than drop, which is the promise anyway), but for the messages of :data:`_MESHIO_NOTES` and the
#: Medit sections the caller has named already (``expected``).
_MESHIO_WARNING_MODULES = ("meshio._vtk_common", "meshio.vtu._vtu", "meshio.vtk._vtk_51", "meshio.vtk._vtk_42",
                           "meshio.medit._medit", "meshio.abaqus._abaqus", "meshio.gmsh.common",
                           "meshio.gmsh._gmsh22", "meshio.gmsh._gmsh40", "meshio.gmsh._gmsh41", "meshio._mesh")

#: meshio warnings about data that neither the mesh nor its sets use: a MeshWarning naming the
#: file, after the read. gmsh MSH 2.2 element tags after the physical and the geometrical one
#: (mesh partitions), which meshio's reader drops (``read_mesh_sets`` of a partitioned file).
_MESHIO_NOTES = ("tag data that couldn't be processed",)


@contextlib.contextmanager
def _meshio_warnings_refused(name: str, fmt: str, expected: Sequence[str] = (), notes: Optional[List[str]] = None):
    import importlib

    def refuse(message, highlight=True):
        text = " ".join(str(message).split())
        m = re.search(r"cannot handle \(type (-?\d+)\)", text)
        if m:
            raise MeshError(f"{name}: VTK cell type {m.group(1)} is not one meshio reads (cells of that type would be "
                            "dropped): palpate needs linear tetrahedra (VTK type 10)")
        k = re.search(r"doesn't know keyword (\w+)", text)
        if k and k.group(1) in expected:
            return   # a Medit section medit_precheck checked and the caller's MeshWarning names
        if notes is not None and any(n in text for n in _MESHIO_NOTES):
            notes.append(f"meshio: {text}")
            return
        raise MeshError(f"{name}: cannot read as {fmt.upper()}: {text} (meshio would have dropped it and gone on)")

    saved = []
    for mod_name in _MESHIO_WARNING_MODULES:
        try:
            mod = importlib.import_module(mod_name)
        except ImportError:  # another meshio layout: its warnings stay warnings
            continue
        if hasattr(mod, "warn"):
            saved.append((mod, mod.warn))
            mod.warn = refuse
    try:
        yield
    finally:
        for mod, warn in saved:
            mod.warn = warn


def _meshio_read(reader, path: str, name: str, fmt: str, warn_skipped: bool = True):
    """``reader(path)`` with meshio's stderr warnings refused (:func:`_meshio_warnings_refused`)
    and its exceptions as MeshErrors. A Medit file's sections are checked first
    (:func:`_readers.medit_precheck`); those meshio reads past are named in one MeshWarning
    (``warn_skipped``) after a successful read, and its vertices and their references are the
    precheck's, parsed from the text in double precision (meshio's are float32 under
    ``MeshVersionFormatted 1``); a file of version 3 or 4 is read by meshio as version 2 (the same
    ASCII text: :func:`_meshio_medit_text`). An Abaqus file's keywords are checked first
    (:func:`_readers.abaqus_precheck`: those that would change the mesh are refused), meshio
    reads its text without the comment lines, its sets are palpate's (:func:`_meshio_abaqus`),
    and the keywords not known are named in one MeshWarning (``warn_skipped``). A reader's own
    notes (``mesh.palpate_notes``: :func:`_gmsh4_groups`) are MeshWarnings too."""
    medit = _readers.medit_precheck(path) if fmt == "medit" else None
    skipped = medit.skipped if medit is not None else []
    unknown: List[str] = []
    read = reader
    if medit is not None and medit.meshio_text is not None:
        read = lambda _path: _meshio_medit_text(medit.meshio_text)  # noqa: E731  (version 3 or 4)
    if fmt == "abaqus":
        abaqus = _readers.abaqus_precheck(path)
        unknown = abaqus.unknown
        read = lambda _path: reader(_path, abaqus)  # noqa: E731
    notes: List[str] = []
    try:
        with warnings.catch_warnings(), _meshio_warnings_refused(name, fmt, [s.split()[0] for s in skipped], notes):
            warnings.simplefilter("ignore")
            mesh = read(path)
    except MeshError:
        raise
    except MemoryError:
        _readers.check_budget("reading the file (the reader ran out of memory)", float("inf"), name)
        raise
    except RecursionError:
        raise MeshError(f"{name}: cannot read as {fmt.upper()}: nested too deeply (corrupt or crafted file)") from None
    except (Exception, SystemExit) as e:  # ReadError, but also ValueError, KeyError, XML errors ...
        reason = str(e).strip() or "malformed or truncated file"
        raise MeshError(f"{name}: cannot read as {fmt.upper()} ({type(e).__name__}: {reason})") from None
    if medit is not None and medit.vertices is not None:
        _medit_exact_vertices(mesh, medit, name)
    notes.extend(getattr(mesh, "palpate_notes", ()))   # a reader's own (_meshio_gmsh)
    if unknown and warn_skipped:
        warnings.warn(f"{name}: Abaqus keywords palpate does not know, read past: {', '.join(unknown)}; palpate takes "
                      "the mesh from *NODE, *ELEMENT, *NSET and *ELSET and reads past the model's other definitions "
                      "(materials, sections, steps, loads, output): if one of these makes, copies or moves nodes or "
                      "elements, the mesh read is not the model's", MeshWarning, stacklevel=2)
    if skipped and warn_skipped:
        warnings.warn(f"{name}: Medit sections read past, not kept: {', '.join(skipped)}; they hold no vertex, cell "
                      "or reference (feature marks, normals, tangents, geometry links), so the mesh and its sets "
                      "are read in full", MeshWarning, stacklevel=2)
    for note in notes:
        warnings.warn(f"{name}: {note}", MeshWarning, stacklevel=2)
    return mesh


def _medit_exact_vertices(mesh, medit: "_readers.MeditCheck", name: str) -> None:
    """Put the Medit precheck's vertices (float64, from the text) and references (int64) in
    place of meshio's: under ``MeshVersionFormatted 0`` or ``1`` meshio reads an ASCII file's
    vertex lines as float32 (0.1234567891 came back as 0.12345679104328156, a reference over
    2**24 rounded to an even one)."""
    points = np.asarray(mesh.points)
    if points.shape != medit.vertices.shape:
        raise MeshError(f"{name}: meshio read vertices of shape {points.shape}, the Vertices section holds "
                        f"{medit.vertices.shape}: not read")
    mesh.points = medit.vertices
    mesh.point_data["medit:ref"] = medit.vertex_refs


def _meshio_medit_text(text: str):
    """meshio's ASCII Medit reader on ``text``: a file of ``MeshVersionFormatted 3`` or ``4``
    with its version line written ``2`` (:class:`_readers.MeditCheck`), which meshio's reader
    takes (it failed on 3 and 4 with a bare ``KeyError: '3'``; the ASCII content is the same).
    That reader parses numbers with ``np.fromfile``, which needs a real file, not a StringIO: the
    text goes through an anonymous temporary file, removed when closed."""
    import tempfile

    from meshio.medit import _medit

    with tempfile.TemporaryFile("w+", encoding="utf-8") as fh:
        fh.write(text)
        fh.seek(0)
        return _medit.read_ascii_buffer(fh)


def _meshio_abaqus(path: str, check: "_readers.AbaqusCheck"):
    """meshio's Abaqus reader on ``check.text`` (:func:`_readers.abaqus_precheck`: the file with
    its comment lines blanked, its keywords checked, its node blocks gathered into one, its set
    definitions taken out), then the sets added up by palpate (:func:`_readers.abaqus_sets`) in
    place of meshio's. The reader runs with its ``_read_nodes`` and ``_read_cells`` wrapped (a
    swap of the module's attributes for the read's duration, as :func:`_meshio_gmsh` does) to
    keep the node and element numbers they map, which meshio's mesh does not hold; an element
    naming a node no *NODE line defines is a MeshError naming its *ELEMENT line (meshio's: a bare
    ``KeyError``)."""
    import io as _io

    from meshio.abaqus import _abaqus

    name = os.path.basename(path)
    read_nodes, read_cells = _abaqus._read_nodes, _abaqus._read_cells
    node_ids: Dict[int, int] = {}
    element_ids: List[Dict[int, int]] = []

    def nodes(f):
        points, point_ids, line = read_nodes(f)
        node_ids.clear()   # one *NODE block (abaqus_precheck gathered them)
        node_ids.update((int(k), int(v)) for k, v in point_ids.items())
        return points, point_ids, line

    def cells(f, params_map, point_ids):
        try:
            out = read_cells(f, params_map, point_ids)
        except KeyError as e:
            k = len(element_ids)
            at = f"line {check.element_lines[k]}: " if k < len(check.element_lines) else ""
            raise MeshError(f"{name}: {at}an element of this *ELEMENT block lists node {e.args[0]}, which no *NODE "
                            "line defines") from None
        element_ids.append({int(k): int(v) for k, v in out[2].items()})
        return out

    _abaqus._read_nodes, _abaqus._read_cells = nodes, cells
    try:
        mesh = _abaqus.read_buffer(_io.StringIO(check.text))
    finally:
        _abaqus._read_nodes, _abaqus._read_cells = read_nodes, read_cells
    if len(mesh.cells) != check.element_blocks:
        raise MeshError(f"{name}: meshio read {len(mesh.cells)} element blocks, the file has "
                        f"{check.element_blocks} *ELEMENT blocks: sets not mapped")
    mesh.point_sets, mesh.cell_sets = _readers.abaqus_sets(
        name, check, len(mesh.points), [np.asarray(cb.data) for cb in mesh.cells], node_ids, element_ids)
    return mesh


def _gmsh40_read_nodes(f, is_ascii: bool, entities: Optional[List[Tuple[int, int]]] = None):
    """meshio's MSH 4.0 ``_read_nodes`` (meshio 5.3, ``gmsh/_gmsh40.py``), with the parametric
    coordinates a node of a parametric entity block carries after x y z (``u [v [w]]``, the
    entity's dimension of them) read past: meshio's own read ``tag x y z`` only and failed on
    them (ASCII: a ValueError; binary: a record of the wrong width). Returns ``(points, tags)`` as
    meshio's does, and appends each node block's entity ``(dim, tag)`` to ``entities``. The file
    was read by palpate's strict 4.0 reader first (``read_mesh_arrays``), so its counts and tags
    are known good here."""
    from meshio.gmsh.common import _fast_forward_to_end_block

    entities = [] if entities is None else entities
    if is_ascii:
        n_blocks, n_nodes = (int(k) for k in f.readline().decode().split())
        points = np.empty((n_nodes, 3), dtype=float)
        tags = np.empty(n_nodes, dtype=int)
        idx = 0
        for _ in range(n_blocks):
            entity, dim, _, count = map(int, f.readline().decode().split())
            entities.append((dim, entity))
            for _ in range(count):
                tok = f.readline().decode().split()
                tags[idx], points[idx] = int(tok[0]), [float(x) for x in tok[1:4]]
                idx += 1
    else:
        n_blocks, _ = np.fromfile(f, count=2, dtype=np.dtype("L"))
        all_points, all_tags = [], []
        for _ in range(int(n_blocks)):
            entity, dim, parametric = (int(x) for x in np.fromfile(f, count=3, dtype=np.dtype("i")))
            entities.append((dim, entity))
            count = int(np.fromfile(f, count=1, dtype=np.dtype("L"))[0])
            per = 3 + (dim if parametric else 0)
            data = np.fromfile(f, count=count, dtype=[("tag", np.dtype("i")), ("x", np.dtype("d"), (per,))])
            all_tags.append(data["tag"])
            all_points.append(data["x"].reshape(count, per)[:, :3])
        tags = np.concatenate(all_tags) if all_tags else np.zeros(0, dtype=int)
        points = np.concatenate(all_points) if all_points else np.zeros((0, 3))
        if f.readline().decode() != "\n":
            raise ValueError("no newline after the binary $Nodes records")
    _fast_forward_to_end_block(f, "Nodes")
    return points, tags


def _gmsh41_read_nodes(f, is_ascii: bool, data_size, entities: Optional[List[Tuple[int, int]]] = None):
    """meshio's MSH 4.1 ``_read_nodes`` (meshio 5.3, ``gmsh/_gmsh41.py``), the same read, which
    also appends each node block's entity ``(dim, tag)`` to ``entities``: meshio gives the entity
    of each node (``gmsh:dim_tags``), so a block of no nodes (gmsh writes one for a surface whose
    nodes all lie on its curves) did not count as declaring its entity, and an element block on
    such an entity was refused where gmsh reads it (:func:`_gmsh4_groups`). The parametric
    coordinates of a parametric block's nodes (``u [v [w]]`` after ``x y z``, the entity's
    dimension of them) are read past: meshio's reader refused them ('parametric nodes not
    implemented'), where palpate's own reader (``load_mesh``) reads the file. Returns ``(points,
    tags, dim_tags)`` as meshio's does."""
    import functools

    from meshio._exceptions import ReadError
    from meshio.gmsh.common import _fast_forward_to_end_block

    entities = [] if entities is None else entities
    fromfile = functools.partial(np.fromfile, sep=" " if is_ascii else "")
    c_size_t = np.dtype(f"u{data_size}")
    n_blocks, n_nodes, _, _ = fromfile(f, c_size_t, 4)
    points = np.empty((n_nodes, 3), dtype=float)
    tags = np.empty(n_nodes, dtype=int)
    dim_tags = np.empty((n_nodes, 2), dtype=int)
    idx = 0
    for _ in range(int(n_blocks)):
        dim, tag, parametric = (int(x) for x in fromfile(f, np.dtype("i"), 3))
        if parametric and not 0 <= dim <= 3:
            raise ReadError(f"a parametric $Nodes block of entity dimension {dim}")
        per = 3 + (dim if parametric else 0)
        count = int(fromfile(f, c_size_t, 1)[0])
        entities.append((dim, tag))
        block = slice(idx, idx + count)
        tags[block] = fromfile(f, c_size_t, count) - 1
        points[block] = fromfile(f, np.dtype("d"), count * per).reshape((count, per))[:, :3]
        dim_tags[block, 0], dim_tags[block, 1] = dim, tag
        idx += count
    _fast_forward_to_end_block(f, "Nodes")
    return points, tags, dim_tags


class _GmshEntities:
    """Stands in for the physical tags meshio's MSH 4.0 / 4.1 reader takes from $Entities (one
    ``{entity tag: [physical tags]}`` per dimension), while its element reader runs: that reader
    looks up ``physical_tags[dim][tag]`` once per element block, in file order; this records the
    ``(dim, tag)`` of each block in ``blocks`` and answers "no physical tag", so that meshio makes
    no physical-group data of its own. The groups are then palpate's (:func:`_gmsh4_groups`),
    from ``physical`` (the $Entities section as meshio read it). meshio's own use of them:

    - an element block on an entity that $Entities does not declare: a bare ``KeyError``;
    - an entity with several physical groups: in 4.0 the first one only (the others lost);
    - an entity in no physical group beside others in one (a file saved with gmsh's
      ``Mesh.SaveAll``): its ``gmsh:physical`` data a block short, ``ValueError: Incompatible cell
      data``;
    - in 4.1, the bounding entities of each entity as a cell set ``gmsh:bounding_entities``,
      which read_mesh_sets took for a set of rows (an IndexError, or a set of unrelated cells),
      and the groups twice (as cell sets and as ``gmsh:physical``: each tet listed twice)."""

    def __init__(self):
        self.physical: Optional[tuple] = None   # $Entities' physical tags, one dict per dimension
        self.blocks: List[Tuple[int, int]] = []   # each element block's entity (dim, tag)
        self.node_blocks: List[Tuple[int, int]] = []   # each node block's entity, empty ones too

    def __getitem__(self, dim):
        return _GmshEntityLookup(self, int(dim))


class _GmshEntityLookup:
    def __init__(self, owner: _GmshEntities, dim: int):
        self.owner, self.dim = owner, dim

    def __getitem__(self, tag):
        self.owner.blocks.append((self.dim, int(tag)))
        return []


def _gmsh_group_label(field_data, dim: int, tag: int) -> str:
    """A gmsh physical group's set name: its $PhysicalNames name, looked up by dimension and tag
    as gmsh does (a surface group 1 and a volume group 1 are two groups), else ``"physical <tag>"``."""
    for name, value in (field_data or {}).items():
        value = np.asarray(value).ravel()
        if len(value) >= 2 and int(value[0]) == tag and int(value[1]) == dim:
            return name
    return f"physical {tag}"


_GMSH_ENTITY_KINDS = ("point", "curve", "surface", "volume")


def _gmsh4_groups(mesh, entities: _GmshEntities, node_entities: set, name: str) -> None:
    """Give ``mesh`` (meshio's MSH 4.x read, with :class:`_GmshEntities` in place of its physical
    tags) its physical groups as cell sets, ``{label: [rows of each cell block]}``
    (:func:`_gmsh_group_label`), every physical group of each element block's entity.

    An element block on an entity that $Entities does not declare: gmsh reads the file when
    $Nodes has a block on that entity (it makes it a discrete entity, with no physical group), and
    refuses it when not (``Unknown entity 6 of dimension 2``). The same here. A file gives its
    physical groups through $Entities only, so such elements are in none: nothing of the file is
    lost, but a mistyped entity tag would take them out of their group without a word, so a
    MeshWarning names them. With no node block on the entity either, a MeshError names it, as
    what the file means is unclear (gmsh's refusal)."""
    if len(entities.blocks) != len(mesh.cells):
        raise MeshError(f"{name}: meshio looked up the entities of {len(entities.blocks)} of its {len(mesh.cells)} "
                        "element blocks ($Entities after $Elements?): physical groups not mapped")
    sets: Dict[str, List[np.ndarray]] = {}
    undeclared: Dict[Tuple[int, int], List[str]] = {}
    for k, ((dim, tag), cb) in enumerate(zip(entities.blocks, mesh.cells)):
        where = f"element block {k + 1} ({len(cb.data)} {cb.type})"
        if not 0 <= dim <= 3:
            raise MeshError(f"{name}: gmsh {where} is on entity {tag} of dimension {dim}: dimensions are 0 to 3")
        if tag not in entities.physical[dim]:
            if (dim, tag) not in node_entities:
                raise MeshError(f"{name}: gmsh {where} is on {_GMSH_ENTITY_KINDS[dim]} {tag} (entity of dimension "
                                f"{dim}, tag {tag}), which neither $Entities nor $Nodes declares: gmsh refuses such "
                                f"a file ('Unknown entity {tag} of dimension {dim}'), and the physical groups of these "
                                "elements are unknown; declare the entity in $Entities, with its physical tags")
            undeclared.setdefault((dim, tag), []).append(where)
            continue
        for physical in dict.fromkeys(int(t) for t in entities.physical[dim][tag]):
            label = _gmsh_group_label(mesh.field_data, dim, physical)
            rows = sets.setdefault(label, [np.zeros(0, dtype=np.int64) for _ in mesh.cells])
            rows[k] = np.arange(len(cb.data), dtype=np.int64)
    mesh.cell_sets = sets
    if undeclared:
        listed = "; ".join(f"{_GMSH_ENTITY_KINDS[d]} {t} (dimension {d}): {', '.join(w)}"
                           for (d, t), w in undeclared.items())
        mesh.palpate_notes = [f"gmsh elements on entities $Entities does not declare, in no physical group: {listed}; "
                              "physical groups are given to the entities $Entities declares, and gmsh reads these as "
                              "entities of their own (from their $Nodes block) without one"]


def _meshio_gmsh(path: str):
    """meshio's gmsh reader, with a ``4`` or ``4.0`` $MeshFormat read as MSH 4.0: gmsh 4.0 writes
    ``4`` (and reads it as 4.0), where ``meshio.gmsh.read`` takes it for 4.1. Its 4.0 reader runs
    with :func:`_gmsh40_read_nodes` in place of its node reader, which failed on parametric nodes
    (the physical groups of such a file were not read); its 4.1 reader with
    :func:`_gmsh41_read_nodes` in place of its node reader (the entity of each node block, an
    empty one too); and its MSH 4.0 and 4.1 readers with
    :class:`_GmshEntities` in place of the physical tags of $Entities, whose use by meshio's
    element readers failed or lost groups (see there): the physical groups of a 4.x file are
    palpate's (:func:`_gmsh4_groups`). Each is a swap of the module's attribute for the read's
    duration, as :func:`_meshio_warnings_refused` swaps ``warn``."""
    import functools

    import meshio
    from meshio.gmsh import _gmsh40, _gmsh41, main

    version, _ = _readers.gmsh_format(path)
    layout = _readers.gmsh_layout(os.path.basename(path), version)
    if layout == "2":
        return meshio.gmsh.read(path)
    entities = _GmshEntities()
    module = _gmsh40 if layout == "4.0" else _gmsh41
    saved = {attr: getattr(module, attr) for attr in ("_read_entities", "_read_elements", "_read_nodes")}

    def read_entities(*args):
        if module is _gmsh40:
            entities.physical = saved["_read_entities"](*args)
            return entities
        entities.physical, _ = saved["_read_entities"](*args)
        return entities, None   # no bounding entities: meshio made them a cell set

    def read_elements_41(f, point_tags, physical_tags, bounding_entities, is_ascii, data_size, field_data):
        # No physical names either: meshio's 4.1 reader looks every block's entity up once per
        # name for the cell sets it makes of them (the groups are palpate's), which would upset
        # the one lookup per block that _GmshEntities counts on.
        return saved["_read_elements"](f, point_tags, physical_tags, bounding_entities, is_ascii, data_size, {})

    module._read_entities = read_entities
    if module is _gmsh40:
        module._read_nodes = functools.partial(_gmsh40_read_nodes, entities=entities.node_blocks)
    else:
        module._read_nodes = functools.partial(_gmsh41_read_nodes, entities=entities.node_blocks)
        module._read_elements = read_elements_41
    try:
        if module is _gmsh40:
            with open(path, "rb") as f:
                f.readline()   # $MeshFormat, the first line (gmsh_format)
                _, data_size, is_ascii = main._read_header(f)
                mesh = _gmsh40.read_buffer(f, is_ascii, data_size)
        else:
            mesh = meshio.gmsh.read(path)
    finally:
        for attr, value in saved.items():
            setattr(module, attr, value)
    if entities.physical is not None:   # without $Entities a 4.x file has no physical groups
        # Each node block's entity, a block of no nodes too (it declares its entity in gmsh).
        _gmsh4_groups(mesh, entities, set(entities.node_blocks), os.path.basename(path))
    return mesh


def _meshio_arrays(m, name: str, fmt: str):
    points = np.asarray(m.points, dtype=np.float64)
    if points.ndim != 2 or (len(points) and points.shape[1] not in (2, 3)):
        raise MeshError(f"{name}: points have shape {points.shape}, expected (n, 3)")
    if points.shape[1] == 2:
        raise MeshError(f"{name}: 2D points: palpate needs a 3D tetrahedral mesh")
    blocks, offset = [], 0
    for cb in m.cells:
        data = np.asarray(cb.data, dtype=np.int64)
        labels = [f"{fmt.upper()} cell {offset + i}" for i in range(len(data))]
        offset += len(data)
        blocks.append(_readers.CellBlock(cb.type, int(cb.dim), data, labels))
    return points, blocks, None


def _vtu_precheck(path: str) -> None:
    """Name the defects meshio's VTU reader reports obscurely (an empty piece)."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    counts = [int(v) for v in re.findall(rb'NumberOfPoints="\s*(\d+)\s*"', head)]
    if counts and not any(counts):
        raise MeshError(f"{os.path.basename(path)}: no points (NumberOfPoints = 0: empty mesh)")


def _read_npz(path: str):
    name = os.path.basename(path)
    _readers.check_input_file(path)
    # Every member's zip size and .npy header against the budget before numpy allocates.
    _readers.npz_precheck(path)
    try:
        with np.load(path, allow_pickle=False) as d:
            missing = [k for k in ("points", "tets") if k not in d.files]
            if missing:
                raise MeshError(f"{name}: missing array(s) {missing} (an .npz mesh holds 'points' (n, 3) "
                                f"and 'tets' (m, 4)); found {d.files}")
            points, tets = d["points"], d["tets"]
    except MeshError:
        raise
    except Exception as e:
        raise MeshError(f"{name}: cannot read as NPZ ({type(e).__name__}: {e})") from None
    if points.ndim != 2 or points.shape[1] != 3 or not np.issubdtype(points.dtype, np.number):
        raise MeshError(f"{name}: 'points' must be a numeric (n, 3) array, got {points.dtype} {points.shape}")
    if tets.ndim != 2 or tets.shape[1] != 4 or not np.issubdtype(tets.dtype, np.integer):
        raise MeshError(f"{name}: 'tets' must be an integer (m, 4) array, got {tets.dtype} {tets.shape}")
    labels = [f"row {i} of 'tets'" for i in range(len(tets))]
    return points.astype(np.float64), [_readers.CellBlock("tetra", 3, tets.astype(np.int64), labels)], None


def read_mesh_arrays(path: PathLike, unit: str = "m") -> Tuple[np.ndarray, np.ndarray, List[str], Optional[List[str]]]:
    """Read a mesh file without validating it in the core.

    Returns ``(points, tets, tet_labels, node_labels)``: points ``(n, 3)`` float64 in metres, tets
    ``(m, 4)`` int64 0-based, how the file names each tet and each node (``node_labels`` may be
    ``None``). Non-tetrahedral 3D cells are an error; lower-dimensional cells (vertices, lines,
    triangles, quads: e.g. gmsh's boundary and physical-group elements) are ignored when the file
    also holds tetrahedra.
    """
    path = os.fspath(path)
    scale = unit_scale(unit)
    name = os.path.basename(path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".msh":
        version, binary = _readers.gmsh_format(path)
        layout = _readers.gmsh_layout(name, version)   # MSH 2.2, 4.0 or 4.1, each read by palpate
        if binary:
            if layout != "4.0":   # the 4.0 reader checks its counts itself, with the 4-byte count hint
                _readers.gmsh_binary_precheck(path)
            points, blocks, node_labels = _readers.read_gmsh_binary(path, version)
        else:
            points, blocks, node_labels = _readers.read_gmsh_ascii(path, version)
    elif ext in _MESHIO_FORMATS:
        points, blocks, node_labels = _read_meshio(path, _MESHIO_FORMATS[ext])
    elif ext in (".node", ".ele"):
        points, blocks, node_labels = _readers.read_tetgen(path)
    elif ext == ".npz":
        points, blocks, node_labels = _read_npz(path)
    else:
        raise MeshError(f"{name}: unsupported mesh format {ext or '(no extension)'!r}; "
                        "palpate reads .msh (gmsh 2.2, 4.0, 4.1), .vtk, .vtu, .mesh (Medit), .inp (Abaqus), "
                        ".node/.ele (TetGen) and .npz")
    if len(points) == 0:
        raise MeshError(f"{name}: no points (empty mesh)")
    blocks = [b for b in blocks if len(b.data)]
    if not blocks:
        raise MeshError(f"{name}: no cells (empty mesh): palpate needs tetrahedra")
    bad = [b for b in blocks if b.type != "tetra" and b.dim >= 3]
    if bad:
        b = bad[0]
        if b.type.startswith("tetra"):
            why = "quadratic/high-order tetrahedra are not supported: palpate uses linear (4-node) tets"
        else:
            why = "palpate needs a mesh of linear tetrahedra"
        raise MeshError(f"{name}: {b.labels[0]}: cells of type '{b.type}' ({len(b.data)} of them) are not "
                        f"tetrahedra: {why}")
    tet_blocks = [b for b in blocks if b.type == "tetra"]
    if not tet_blocks:
        kinds = ", ".join(f"'{b.type}' ({len(b.data)})" for b in blocks)
        raise MeshError(f"{name}: no tetrahedra: the file holds only {kinds} cells; palpate needs a "
                        "tetrahedral volume mesh")
    tets = np.concatenate([b.data for b in tet_blocks], axis=0)
    labels = [lab for b in tet_blocks for lab in b.labels]
    return points * scale, tets, labels, node_labels


def read_mesh_sets(path: PathLike) -> Tuple[Dict[str, np.ndarray], Dict[str, np.ndarray]]:
    """The named node and element sets of a mesh file, read by meshio: ``(node_sets, tet_sets)``,
    each ``{name: int64 indices, ascending}`` into the nodes and tets of :func:`load_mesh` /
    :func:`read_mesh_arrays` of the same file (a scene can fix or load a set by name).

    gmsh (``.msh``): one set per physical group, named by ``$PhysicalNames`` (looked up by the
    group's dimension and tag, as gmsh does; ``"physical <tag>"`` if unnamed): its tets, and the
    nodes of all its elements (e.g. a clamped face's triangles). In MSH 2.2 a physical tag 0 is
    no group (gmsh's ``Mesh.SaveAll`` writes it): such elements are in no set. In MSH 4.0 / 4.1
    an element is in every physical group of its entity, as ``$Entities`` gives them; elements on
    an entity that ``$Entities`` does not declare are in none, with a :class:`palpate.MeshWarning`
    (gmsh reads them so when ``$Nodes`` has a block on that entity, one of no nodes too), and the
    file is a MeshError when ``$Nodes`` has no block on it either (gmsh refuses such a file).
    Medit (``.mesh``): one set per element reference, ``"ref <k>"``, and one node set per non-zero
    vertex reference, ``"vertex ref <k>"``. Abaqus (``.inp``): its node and element sets, by name,
    from *NSET and *ELSET and the ``NSET=`` / ``ELSET=`` of a *NODE / *ELEMENT line (that
    block's nodes / elements); as in Abaqus, a set defined twice has the members of both, a
    set's data lines may name other sets, ``*NSET, ELSET=<set>`` holds the nodes of that element
    set, and names compare in upper case (a set keeps its name as first written, without the
    double quotes of a quoted label); a number that names no node or element is a MeshError
    naming the set, the number and the line. Any other
    format meshio gives point / cell sets for: those, by name. The file is read by
    :func:`read_mesh_arrays` first (its errors and warnings), then by meshio for the sets. Raises
    :class:`MeshError` for an unreadable file, one that meshio would read with a loss it reports
    only on stderr, or one whose tets meshio orders differently from palpate's reader.
    """
    import meshio

    path = os.fspath(path)
    name = os.path.basename(path)
    ext = os.path.splitext(path)[1].lower()
    fmt = "gmsh" if ext == ".msh" else _MESHIO_FORMATS.get(ext)
    if fmt is None:
        raise MeshError(f"{name}: named sets are read from .msh, .vtk, .vtu, .mesh and .inp files, not {ext!r}")
    if not os.path.exists(path):
        raise MeshError(f"{name}: no such file ({path})")
    _, tets, _, _ = read_mesh_arrays(path)   # palpate's reader first: its errors name the element
    reader = {"vtk": meshio.vtk.read, "vtu": meshio.vtu.read, "gmsh": _meshio_gmsh,
              "medit": meshio.medit.read, "abaqus": _meshio_abaqus}[fmt]
    m = _meshio_read(reader, path, name, fmt, warn_skipped=False)   # read_mesh_arrays warned
    # Empty blocks left out, as read_mesh_arrays leaves them (meshio gives an empty Abaqus block shape (0,)).
    tet_blocks = [k for k, cb in enumerate(m.cells) if cb.type == "tetra" and len(cb.data)]
    mesh_tets = np.concatenate([np.asarray(m.cells[k].data, dtype=np.int64) for k in tet_blocks]) if tet_blocks \
        else np.zeros((0, 4), dtype=np.int64)
    if not np.array_equal(mesh_tets, tets):
        raise MeshError(f"{name}: meshio orders the tets differently from palpate's reader: sets not mapped")
    # Offsets of each tetra block in the concatenated tets.
    offsets, k0 = {}, 0
    for k in tet_blocks:
        offsets[k] = k0
        k0 += len(m.cells[k].data)
    node_sets: Dict[str, set] = {}
    tet_sets: Dict[str, set] = {}   # sets: a tet given a label twice (two sources of one group) counts once

    def add(label: str, k: int, rows: np.ndarray) -> None:
        cb = m.cells[k]
        node_sets.setdefault(label, set()).update(np.asarray(cb.data)[rows].ravel().tolist())
        if k in offsets:
            tet_sets.setdefault(label, set()).update((offsets[k] + rows).tolist())

    tags = {"gmsh": "gmsh:physical", "medit": "medit:ref"}.get(fmt)
    if fmt == "medit":
        # Vertex references (the Vertices section's last column; 0 is "none"), as the precheck
        # parsed them: node sets of their own, "vertex ref <k>", apart from the element
        # references' "ref <k>" (a Medit file numbers the two independently: mmg keeps a boundary
        # vertex's reference, which need not be its faces').
        refs = np.asarray(m.point_data.get("medit:ref", np.zeros(0)), dtype=np.int64)
        for ref in np.unique(refs[refs != 0]):
            node_sets[f"vertex ref {int(ref)}"] = set(np.flatnonzero(refs == ref).tolist())
    if tags and tags in m.cell_data:   # gmsh MSH 2.2 (a 4.x file's groups are cell sets: _gmsh4_groups)
        for k, values in enumerate(m.cell_data[tags]):
            values = np.asarray(values)
            for tag in np.unique(values):
                if fmt == "gmsh" and tag == 0:
                    continue   # physical tag 0: in no physical group (gmsh's Mesh.SaveAll writes it)
                label = (_gmsh_group_label(m.field_data, m.cells[k].dim, int(tag)) if fmt == "gmsh"
                         else f"ref {int(tag)}")
                add(label, k, np.flatnonzero(values == tag))
    for label, per_block in (m.cell_sets or {}).items():
        for k, rows in enumerate(per_block):
            if rows is not None and len(rows):
                add(label, k, np.asarray(rows, dtype=np.int64))
    for label, nodes in (m.point_sets or {}).items():
        node_sets.setdefault(label, set()).update(np.asarray(nodes).ravel().tolist())
    as_array = lambda s: np.array(sorted(s), dtype=np.int64)  # noqa: E731
    return ({n: as_array(s) for n, s in node_sets.items()}, {n: as_array(s) for n, s in tet_sets.items()})


def _with_label(msg: str, kind: str, index: Optional[int], labels: Optional[Sequence[str]]) -> str:
    """Insert how the file names element ``index`` after the first ``"<kind> <index>"`` in ``msg``."""
    if index is None or labels is None or not 0 <= index < len(labels):
        return msg
    pat = re.compile(rf"\b{kind} {index}\b")
    if pat.search(msg):
        return pat.sub(f"{kind} {index} ({labels[index]})", msg, count=1)
    return f"{msg} [{kind} {index} is {labels[index]}]"


def load_mesh(path: PathLike, unit: str = "m") -> TetMesh:
    """Load and validate a tetrahedral mesh file.

    Parameters
    ----------
    path:
        ``.msh`` (gmsh MSH 2.2, 4.0 and 4.1, ASCII or binary, read by palpate; another version is a
        MeshError saying how to convert it), ``.vtk``, ``.vtu``, ``.mesh`` (Medit), ``.inp``
        (Abaqus) (these four by meshio; a loss meshio reports only on stderr is a MeshError),
        ``.node`` or ``.ele`` (TetGen; the other file must sit beside it), ``.npz`` (arrays
        ``points`` (n, 3) and ``tets`` (m, 4)). A Medit file's sections are checked before meshio
        reads it: a section that holds no vertex, cell or reference (Corners, Ridges,
        RequiredVertices, Normals, Tangents, ...) is read past with a :class:`palpate.MeshWarning`
        naming it; a keyword meshio cannot read past, or a count that does not match its data, is a
        MeshError naming the keyword and line; the vertices are read in double precision whatever
        the file's MeshVersionFormatted (0 to 4: the version says how a binary .meshb stores its
        numbers, and an ASCII file reads alike under any). An Abaqus file's keywords are checked
        before meshio reads it: the mesh is taken from *NODE, *ELEMENT, *NSET and *ELSET; one that
        makes, copies or moves nodes or elements, which meshio would skip (*NGEN, *ELGEN, *NCOPY,
        *NFILL, *INCLUDE, *PARAMETER, *SYSTEM, a second *NODE block or part, a placed *INSTANCE,
        ...), is a MeshError naming the keyword and line; a keyword palpate does not know is read
        past with a MeshWarning.
    unit:
        Length unit of the file's coordinates: ``"m"``, ``"cm"`` or ``"mm"``. Points are scaled to
        metres.

    Returns
    -------
    TetMesh
        Validated mesh in metres. Inverted tets are reoriented with a :class:`palpate.MeshWarning`.

    Warns
    -----
    MeshWarning
        Inverted tets reoriented; Medit sections read past and not kept (named with their line);
        Abaqus keywords palpate does not know (named with their line).

    Raises
    ------
    MeshError
        The file is missing, unreadable, truncated, not a tetrahedral mesh, or a tet or node is
        invalid. The message names the file, the element and the reason.
    ValueError
        ``unit`` is not one of the above.
    """
    path = os.fspath(path)
    name = os.path.basename(path)
    points, tets, labels, node_labels = read_mesh_arrays(path, unit)
    try:
        return TetMesh(points, tets, source=name)
    except MeshError as e:
        msg = str(e)
        msg = _with_label(msg, "tet", getattr(e, "tet", None), labels)
        msg = _with_label(msg, "node", getattr(e, "node", None), node_labels)
        err = MeshError(msg)
        err.tet, err.node = getattr(e, "tet", None), getattr(e, "node", None)
        raise err from None


class VtuSeries:
    """Write frames of a body as ``<stem>_<k>.vtu`` plus ``<stem>.pvd`` (ParaView collection).

    Point data written per frame: ``displacement`` [m] and ``velocity`` [m/s], both (n, 3), and
    whatever ``point_data`` / ``cell_data`` :meth:`write` is given; :meth:`write_body` writes
    everything a ParaView user plots (see there). Points are the deformed positions [m]; cells
    are the mesh's tets: ``tets`` (m, 4), or (m, 10) quadratic tets in VTK's node order (the
    vertices, then the edges (0,1) (1,2) (0,2) (0,3) (1,3) (2,3), palpate's own). A quadratic
    :class:`~palpate.Body` (``order=2``) given the mesh's (m, 4) tets is written with its (m, 10)
    cells (:func:`quadratic_cells`), so ParaView draws its curved elements.
    """

    def __init__(self, outdir: PathLike, tets: np.ndarray, stem: str = "frame"):
        self.outdir = os.fspath(outdir)
        self.stem = stem
        a = np.asarray(tets)
        self.tets = whole_indices(tets, "tets", 10 if a.ndim == 2 and a.shape[1] == 10 else 4)
        self.entries: List[Tuple[float, str]] = []
        os.makedirs(self.outdir, exist_ok=True)
        remove_frames(self.outdir, [stem])

    @property
    def pvd_path(self) -> str:
        return os.path.join(self.outdir, f"{self.stem}.pvd")

    def __repr__(self) -> str:
        n = len(self.entries)
        span = f", t = {self.entries[0][0]:g} to {self.entries[-1][0]:g} s" if n else ""
        return f"<palpate.VtuSeries: {n} frame{'' if n == 1 else 's'} of {len(self.tets)} tets{span}; {self.pvd_path}>"

    def write(self, time: float, positions: np.ndarray, displacement: np.ndarray, velocity: np.ndarray,
              point_data: Optional[Dict[str, np.ndarray]] = None,
              cell_data: Optional[Dict[str, np.ndarray]] = None) -> str:
        """Write one frame at simulated ``time`` [s]; returns the .vtu path. Rewrites the .pvd.
        ``point_data``: extra arrays (n, ...) per node; ``cell_data``: arrays (m, ...) per tet."""
        import meshio

        fname = f"{self.stem}_{len(self.entries):05d}.vtu"
        pts = np.asarray(positions, dtype=np.float64)
        pd = {"displacement": np.asarray(displacement, dtype=np.float64),
              "velocity": np.asarray(velocity, dtype=np.float64)}
        extra = {k: np.asarray(v) for k, v in (point_data or {}).items()}
        cd = {k: np.asarray(v) for k, v in (cell_data or {}).items()}
        self._check_frame(fname, pts, list(pd.items()) + [(f"point_data[{k!r}]", v) for k, v in extra.items()],
                          [(f"cell_data[{k!r}]", v) for k, v in cd.items()])
        pd.update(extra)
        mesh = meshio.Mesh(
            pts,
            [("tetra10" if self.tets.shape[1] == 10 else "tetra", self.tets)],
            point_data=pd,
            cell_data={k: [v] for k, v in cd.items()},
        )
        path = os.path.join(self.outdir, fname)
        meshio.write(path, mesh, file_format="vtu")  # binary, zlib-compressed: ParaView reads it
        self.entries.append((float(time), fname))
        self._write_pvd()
        return path

    def _check_frame(self, fname: str, pts: np.ndarray, pd: List[Tuple[str, np.ndarray]], cd: List[Tuple[str, np.ndarray]]) -> None:
        """One row per mesh node in the positions and every point data array, one per tet in every
        cell data array, before the file is written: a frame with fewer points than the tets use,
        or a short array, was written and only ParaView failed on it later (issue 35 item 6)."""
        where = os.path.join(self.outdir, fname)
        need = int(self.tets.max()) + 1 if len(self.tets) else 0
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < need or (len(self.tets) and self.tets.min() < 0):
            raise ParameterError(f"{where}: positions have shape {pts.shape}; the series' tets use nodes 0..{need - 1}, "
                                 f"so (n >= {need}, 3) are needed (frame not written)")
        for name, a in pd:
            if a.ndim == 0 or len(a) != len(pts):
                raise ParameterError(f"{where}: {name} has {a.shape[0] if a.ndim else 'no'} rows (shape {a.shape}), "
                                     f"the frame has {len(pts)} points: one row per point (frame not written)")
        for name, a in cd:
            if a.ndim == 0 or len(a) != len(self.tets):
                raise ParameterError(f"{where}: {name} has {a.shape[0] if a.ndim else 'no'} rows (shape {a.shape}), "
                                     f"the mesh has {len(self.tets)} tets: one row per tet (frame not written)")

    def write_body(self, body: "Body", loaded: Optional[np.ndarray] = None) -> str:
        """Write one frame of a :class:`~palpate.Body` at its time: point data ``displacement``
        [m] and ``velocity`` [m/s] (n, 3), ``fixed`` and ``loaded`` (n,) uint8 flags (``loaded``:
        the given node indices, else the nodes carrying a non-zero external force); cell data
        ``von_mises`` [Pa] and ``energy_density`` [J/m^3] (``Body.element_fields``), ``det_f``
        [-] and ``inverted`` (m,) uint8 (det F <= 0)."""
        if getattr(body, "order", 1) == 2 and self.tets.shape[1] == 4:
            self.tets = quadratic_cells(self.tets, body.edges, body.mesh.n_nodes)
        n = body.n_nodes
        fixed = np.zeros(n, dtype=np.uint8)
        fixed[body.fixed] = 1
        load = np.zeros(n, dtype=np.uint8)
        if loaded is None:
            load[np.any(body.forces != 0.0, axis=1)] = 1
        else:
            load[np.asarray(loaded, dtype=np.int64)] = 1
        ef = body.element_fields()
        return self.write(body.time, body.positions, body.displacements, body.velocities,
                          point_data={"fixed": fixed, "loaded": load},
                          cell_data={"von_mises": ef["von_mises"], "energy_density": ef["energy_density"],
                                     "det_f": ef["det_f"], "inverted": (ef["det_f"] <= 0.0).astype(np.uint8)})

    def _write_pvd(self) -> None:
        write_pvd(self.pvd_path, [(t, f, 0, None) for t, f in self.entries])


def quadratic_cells(tets: np.ndarray, edges: np.ndarray, n_vertices: int) -> np.ndarray:
    """The (m, 10) cells of a quadratic body: each tet's four vertices, then the nodes of its
    edges (0,1) (1,2) (0,2) (0,3) (1,3) (2,3) (VTK's ``tetra10`` order, and palpate's), edge node
    ``k`` being node ``n_vertices + k`` of ``edges[k]`` (:attr:`palpate.Body.edges`)."""
    tets = np.asarray(tets, dtype=np.int64)
    edges = np.sort(np.asarray(edges, dtype=np.int64), axis=1)
    key = edges[:, 0] * (n_vertices + 1) + edges[:, 1]
    order = np.argsort(key)
    out = np.empty((len(tets), 10), dtype=np.int64)
    out[:, :4] = tets
    for j, (a, b) in enumerate(((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))):
        lo, hi = np.minimum(tets[:, a], tets[:, b]), np.maximum(tets[:, a], tets[:, b])
        k = lo * (n_vertices + 1) + hi
        pos = np.searchsorted(key, k, sorter=order)
        found = order[np.minimum(pos, len(order) - 1)]
        if len(key) == 0 or not np.array_equal(key[found], k):
            raise ParameterError("quadratic_cells: a tet's edge is not among the body's edges")
        out[:, 4 + j] = n_vertices + found
    return out


def remove_frames(outdir: PathLike, stems: Sequence[str]) -> None:
    """Remove ``<stem>_<5 digits>.vtu`` files of an earlier run from ``outdir``: they would not
    match the new ``.pvd``."""
    stale = re.compile(rf"({'|'.join(re.escape(s) for s in stems)})_\d{{5}}\.vtu")
    for f in os.listdir(outdir):
        if stale.fullmatch(f):
            os.remove(os.path.join(os.fspath(outdir), f))


def write_pvd(path: PathLike, datasets: Sequence[Tuple[float, str, int, Optional[str]]]) -> None:
    """Write a ParaView collection (``.pvd``) listing ``(time [s], file, part, name)`` (``name``
    ``None``: no name attribute), replacing the file atomically (a reader never sees half of it)."""
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
             "  <Collection>"]
    for t, f, part, name in datasets:
        named = f" name={quoteattr(name)}" if name is not None else ""
        lines.append(f'    <DataSet timestep="{t!r}" group="" part="{part}"{named} file={quoteattr(f)}/>')
    lines += ["  </Collection>", "</VTKFile>", ""]
    path = os.fspath(path)
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write("\n".join(lines))
    os.replace(tmp, path)


def read_pvd(path: PathLike) -> List[Tuple[float, str]]:
    """``[(time [s], absolute .vtu path), ...]`` from a ``.pvd`` collection."""
    import xml.etree.ElementTree as ET

    path = os.fspath(path)
    root = ET.parse(path).getroot()
    base = os.path.dirname(os.path.abspath(path))
    return [(float(ds.get("timestep")), os.path.join(base, ds.get("file")))
            for ds in root.iter("DataSet")]


def write_particles(path: PathLike, body: "ParticleBody") -> str:
    """Write a :class:`~palpate.ParticleBody` as a VTU of vertex cells at its current positions
    [m]: point data ``displacement`` [m] and ``velocity`` [m/s] (n, 3), ``mass`` [kg] (n,),
    ``fixed`` and ``active`` (n,) uint8 flags. Returns the path."""
    import meshio

    n = body.n_particles
    fixed = np.zeros(n, dtype=np.uint8)
    fixed[body.fixed] = 1
    active = np.zeros(n, dtype=np.uint8)
    active[body.active] = 1
    mesh = meshio.Mesh(body.positions, [("vertex", np.arange(n, dtype=np.int64)[:, None])],
                       point_data={"displacement": body.displacements, "velocity": body.velocities,
                                   "mass": body.masses, "fixed": fixed, "active": active})
    path = os.fspath(path)
    meshio.write(path, mesh, file_format="vtu")
    return path


def write_hybrid_model(outdir: PathLike, model: "HybridModel", stem: str = "hybrid") -> str:
    """Write the parts of a :class:`~palpate.HybridModel` at rest for ParaView, into ``outdir``:
    ``<stem>_core.vtu`` (the FEM core's tets; point data ``fixed``: the base nodes),
    ``<stem>_shell.vtu`` (the particles as vertex cells; point data ``mass`` [kg],
    ``outer_triangle`` and ``core_face``: the outer triangle above and the core face below each
    particle, which key its activation regions), ``<stem>_skin.vtu`` (the outer surface's
    triangles; point data ``region``: the activation region of each outer vertex, whose index is
    the vertex's), and ``<stem>.pvd`` naming the three parts. Positions [m]. Returns the .pvd path."""
    import meshio

    outdir = os.fspath(outdir)
    os.makedirs(outdir, exist_ok=True)
    core_pts = model.core_points
    base = np.zeros(len(core_pts), dtype=np.uint8)
    base[model.core_base_nodes] = 1
    p = model.particles
    skin_pts = model.outer_points
    parts = {
        "core": meshio.Mesh(core_pts, [("tetra", model.core_tets)], point_data={"fixed": base}),
        "shell": meshio.Mesh(p, [("vertex", np.arange(len(p), dtype=np.int64)[:, None])],
                             point_data={"mass": model.particle_masses,
                                         "outer_triangle": model.particle_outer_triangle,
                                         "core_face": model.particle_core_face}),
        "skin": meshio.Mesh(skin_pts, [("triangle", model.outer_triangles)],
                            point_data={"region": np.arange(len(skin_pts), dtype=np.int64)}),
    }
    entries = []
    for k, (name, mesh) in enumerate(parts.items()):
        fname = f"{stem}_{name}.vtu"
        meshio.write(os.path.join(outdir, fname), mesh, file_format="vtu")
        entries.append((0.0, fname, k, name))
    pvd = os.path.join(outdir, f"{stem}.pvd")
    write_pvd(pvd, entries)
    return pvd
