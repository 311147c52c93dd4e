"""The Python package's two floors (issue 36, item 3), read from the sources with ``ast`` (nothing is
imported): the library below, the applications above it, and imports only downwards. No library
module imports an application module, at module level or inside a function.

Every module under python/palpate is on one floor (a new module must be placed here). A module's
floor is that of the longest name in :data:`LIBRARY` or :data:`APPLICATIONS` that places it (a
subpackage's entry places its modules; the root ``palpate`` only its ``__init__``). Applications
import the library and each other freely.
"""
import ast
from pathlib import Path
from typing import Dict, List, Set, Tuple

from conftest import REPO

PACKAGE = REPO / "python" / "palpate"

#: The library: what a user scripts against, and what the applications stand on.
LIBRARY = {
    "palpate": "the package: the extension's classes and the library's entry points",
    "palpate._palpate": "the compiled core (the extension; no Python source)",
    "palpate._extras": "how to install an optional part",
    "palpate._fields": "field checks of parsed TOML (scenes, touch scripts, study files)",
    "palpate._indices": "index arrays from Python (whole values only)",
    "palpate._pickle": "pickling of the extension's objects",
    "palpate._progress": "progress display for long work",
    "palpate._readers": "I/O: strict gmsh / TetGen / Medit readers",
    "palpate.io": "I/O: mesh files in, VTU series out",
    "palpate.vtp": "I/O: VTK PolyData in",
    "palpate.surfaces": "I/O: triangle surface files in",
    "palpate.scene": "I/O: scene files (a body, its loads and a run) for palpate run and the viewer",
    "palpate.hybrid": "models: hybrid models from files and shapes; load_model, the one resolver of a model name",
    "palpate.probe": "models: the outer surface's normals, the default probe vertex and its press frame",
    "palpate.data": "data sets fetched on first use (Rodero et al.)",
    "palpate.defaults": "every default, read from the Rust core (the default tissue among them)",
}

#: The applications: commands, benchmarks, the viewer, studies, scripted touches, the demo.
APPLICATIONS = {
    "palpate.__main__": "python -m palpate: the command line",
    "palpate.cli": "the palpate command line, one module per command",
    "palpate.bench": "the benchmarks, in one place (palpate bench ...)",
    "palpate.bench_hybrid": "old import path of palpate.bench.hybrid (a re-export)",
    "palpate.bench_particles": "old import path of palpate.bench.particles (a re-export)",
    "palpate.viewer": "palpate view: the browser viewer",
    "palpate.sweep": "palpate sweep / fit: batch studies on Dask",
    "palpate.devices": "palpate device: vendor adapters as bridge processes",
    "palpate.touch": "palpate touch: scripted touches (script format, run, force log)",
    "palpate.haptics": "what palpate haptic, soak, view and bench haptic build on palpate.HapticLoop",
    "palpate.validate": "palpate validate: the hybrid against reference FEM",
    "palpate.demo": "python -m palpate.demo (make demo)",
}

#: Library modules allowed to import an application module, each with its reason: ``(importer,
#: imported): reason``. Empty; an entry here is a debt to pay, not a licence.
ALLOWED: Dict[Tuple[str, str], str] = {}


def covers(entry: str, module: str) -> bool:
    """Does floor entry ``entry`` place ``module``: itself, or a module of its package (the root
    ``palpate`` places only its ``__init__``, so that every other module must be placed by name)."""
    return module == entry or (entry != "palpate" and module.startswith(entry + "."))


def floor(module: str) -> str:
    """``"library"`` or ``"application"`` by the longest entry that places ``module``; ``""`` for none."""
    best, where = "", ""
    for table, name in ((LIBRARY, "library"), (APPLICATIONS, "application")):
        for entry in table:
            if covers(entry, module) and len(entry) > len(best):
                best, where = entry, name
    return where


def modules(root: Path = PACKAGE) -> Dict[str, Tuple[Path, bool]]:
    """Every Python module under ``root``: dotted name -> (file, is a package's ``__init__``)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).with_suffix("")
        parts = list(rel.parts)
        is_pkg = parts[-1] == "__init__"
        if is_pkg:
            parts.pop()
        out[".".join(parts)] = (path, is_pkg)
    return out


def imported(module: str, is_pkg: bool, source: str, known: Set[str]) -> List[Tuple[str, int]]:
    """``(palpate module, line)`` of every import of a palpate module in ``source`` (module
    ``module``), anywhere in it: module level, functions, ``if`` blocks, ``importlib.import_module``
    with a literal name. ``from X import name`` counts ``X`` and, where ``X.name`` is a module of
    ``known``, ``X.name`` too."""
    package = module if is_pkg else module.rpartition(".")[0]
    found: List[Tuple[str, int]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append((alias.name, node.lineno))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)] if node.level > 1 else base
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.append((target, node.lineno))
            for alias in node.names:
                if f"{target}.{alias.name}" in known:
                    found.append((f"{target}.{alias.name}", node.lineno))
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)
              and ((isinstance(node.func, ast.Attribute) and node.func.attr == "import_module")
                   or (isinstance(node.func, ast.Name) and node.func.id in ("import_module", "__import__")))):
            found.append((node.args[0].value, node.lineno))
    # ast.walk goes breadth first: in the order of the source instead.
    return sorted(found, key=lambda f: f[1])


def violations(sources: Dict[str, Tuple[str, bool]]) -> List[str]:
    """A line per library module's import of an application module not in :data:`ALLOWED`;
    ``sources``: dotted name -> (source text, is a package)."""
    known = set(sources)
    out = []
    for module, (source, is_pkg) in sorted(sources.items()):
        if floor(module) != "library":
            continue
        for target, line in imported(module, is_pkg, source, known):
            if target.split(".")[0] != "palpate" or floor(target) != "application":
                continue
            if (module, target) not in ALLOWED:
                out.append(f"{module}:{line} imports {target} (an application: {floor_entry(target)})")
    return out


def floor_entry(module: str) -> str:
    entries = [e for e in APPLICATIONS if covers(e, module)]
    return APPLICATIONS[max(entries, key=len)] if entries else "?"


def package_sources() -> Dict[str, Tuple[str, bool]]:
    return {name: (path.read_text(encoding="utf-8"), is_pkg) for name, (path, is_pkg) in modules().items()}


def test_every_module_is_on_one_floor():
    unplaced = [m for m in modules() if not floor(m)]
    assert not unplaced, f"place these modules on a floor in tests/test_floors.py (LIBRARY or APPLICATIONS): {unplaced}"
    assert not set(LIBRARY) & set(APPLICATIONS)
    # Every entry names something that exists (a stale entry would place nothing).
    names = set(modules()) | {"palpate._palpate"}
    assert not [e for e in list(LIBRARY) + list(APPLICATIONS) if e not in names], "stale floor entries"


def test_the_library_imports_no_application():
    found = violations(package_sources())
    assert not found, "the library imports an application module (move the code down, or list it in ALLOWED " \
                      "with its reason):\n" + "\n".join(found)


def test_allowed_exceptions_are_still_needed():
    known = set(modules())
    used = {(m, t) for m, (src, pkg) in package_sources().items() for t, _ in imported(m, pkg, src, known)}
    assert not [k for k in ALLOWED if k not in used], "an ALLOWED exception no longer happens: remove it"


def test_the_checker_flags_a_library_module_that_imports_upwards():
    # The check can fail: a synthetic library module importing applications in each form is flagged,
    # once per form; its imports of the library and an application's imports of anything are not.
    bad = (
        "from . import touch\n"                                # a module by `from . import`
        "from .cli import main\n"                              # relative, a package's name
        "import palpate.viewer.app\n"                          # absolute, a subpackage's module
        "def f():\n"
        "    from .bench.hybrid import probe\n"                # function level
        "    if True:\n"
        "        from palpate.sweep import runner\n"           # nested block, absolute
        "    import importlib\n"
        "    return importlib.import_module('palpate.demo')\n" # importlib with a literal name
        "from . import defaults, io\n"                         # the library: fine
        "from .probe import probe_frame\n"
    )
    sources = package_sources()
    sources["palpate.io"] = (bad, False)
    sources["palpate.cli.extra"] = ("from ..bench import hybrid\nfrom .. import io\n", False)   # app -> anything: fine
    found = violations(sources)
    assert [f.split(" imports ")[1].split(" ")[0] for f in found] == [
        "palpate.touch", "palpate.cli", "palpate.viewer.app", "palpate.bench.hybrid", "palpate.sweep",
        "palpate.sweep.runner", "palpate.demo"], found
    assert all(f.startswith("palpate.io:") for f in found)
    # A package's __init__ resolves `from . import x` against itself, and `..` one level up.
    sources = {"palpate": ("from . import touch\n", True), "palpate.touch": ("", False),
               "palpate.hybrid": ("from .bench import GENERATED\n", False), "palpate.bench": ("", True)}
    assert violations(sources) == [
        f"palpate:1 imports palpate.touch (an application: {APPLICATIONS['palpate.touch']})",
        f"palpate.hybrid:1 imports palpate.bench (an application: {APPLICATIONS['palpate.bench']})"]
    found = imported("palpate.cli", True, "from .. import io\nfrom . import bench\n",
                     {"palpate.io", "palpate.cli.bench"})
    assert found == [("palpate", 1), ("palpate.io", 1), ("palpate.cli", 2), ("palpate.cli.bench", 2)]
    assert floor("palpate.unplaced") == "" and floor("palpate.cli.haptic") == "application"
    assert floor("palpate.bench_hybrid") == "application" and floor("palpate.probe") == "library"
