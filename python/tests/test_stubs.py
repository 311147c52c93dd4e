"""palpate/_palpate.pyi (hand-kept) lists exactly what the extension module defines."""
import ast
from pathlib import Path

import palpate
import palpate._palpate as ext

STUB = Path(palpate.__file__).with_name("_palpate.pyi")
TYPED_DICTS = {"IndentResult", "StepStats", "ProbeRun", "ParticleStepStats", "TimedRun", "RegionField", "HybridInfo", "BodyState",
               "ParticleState", "HybridSimState"}


def test_stub_matches_extension():
    tree = ast.parse(STUB.read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and not node.name.startswith("_") and node.name not in TYPED_DICTS:
            names.add(node.name)
            cls = getattr(ext, node.name)
            stub = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
            stub |= {n.target.id for n in node.body if isinstance(n, ast.AnnAssign)}
            runtime = {a for a in dir(cls) if not a.startswith("_")} - set(dir(Exception))
            assert runtime <= stub, f"{node.name}: not in the stub: {runtime - stub}"
            assert stub - {"__new__", "__len__", "__copy__", "__deepcopy__"} <= runtime, f"{node.name}: stub only: {stub - runtime}"
        elif isinstance(node, ast.FunctionDef):
            names.add(node.name)
            assert hasattr(ext, node.name)
    public = {a for a in dir(ext) if not a.startswith("_")}
    assert public <= names, f"not in the stub: {public - names}"
    assert (STUB.parent / "py.typed").exists()


def test_package_reexports_extension():
    for name in dir(ext):
        if not name.startswith("_"):
            assert getattr(palpate, name) is getattr(ext, name)
    assert set(palpate.__all__) <= set(dir(palpate))
