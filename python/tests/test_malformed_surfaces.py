"""Every file of data/malformed_surfaces/ fails to load with the error class and message of
EXPECTED.toml (or, for a repairable defect, loads with the expected warning)."""
import sys
from pathlib import Path

import pytest

import palpate

from conftest import check_corpus_entry

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

HERE = Path(__file__).resolve().parent / "data" / "malformed_surfaces"
EXPECTED = tomllib.loads((HERE / "EXPECTED.toml").read_text())
NOT_CASES = {"EXPECTED.toml", "make_corpus.py"}
COMPANION = "_part_definition.json"


def test_corpus_is_complete():
    files = {f.name for f in HERE.iterdir() if f.is_file() and f.name not in NOT_CASES}
    listed = set(EXPECTED)
    assert listed <= files, f"listed but missing: {sorted(listed - files)}"
    stems = {Path(n).stem for n in listed}
    # Unlisted files must be the part definition beside a listed surface.
    orphans = [f for f in files - listed if not (f.endswith(COMPANION) and f[: -len(COMPANION)] in stems)]
    assert not orphans, f"files without an expectation: {orphans}"
    assert len([n for n, e in EXPECTED.items() if "error" in e]) >= 15
    assert any("warning" in e for e in EXPECTED.values())
    assert {e.get("call", "load_surface") for e in EXPECTED.values()} == {"load_surface", "read_tagged_surface"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_malformed_surface(name):
    exp = EXPECTED[name]
    call = getattr(palpate, exp.get("call", "load_surface"))
    check_corpus_entry(name, exp, lambda: call(HERE / name, unit="mm"), palpate.MeshError)
