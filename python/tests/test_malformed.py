"""Every file of data/malformed/ fails to load with the error class and message of EXPECTED.toml
(or, for a repairable defect, loads with the expected warning)."""
import sys
from pathlib import Path

import pytest

import palpate

from conftest import check_corpus_entry

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

HERE = Path(__file__).resolve().parent / "data" / "malformed"
EXPECTED = tomllib.loads((HERE / "EXPECTED.toml").read_text())
NOT_CASES = {"EXPECTED.toml", "make_corpus.py"}


def test_corpus_is_complete():
    files = {f.name for f in HERE.iterdir() if f.is_file() and f.name not in NOT_CASES}
    listed = set(EXPECTED)
    assert listed <= files, f"listed but missing: {sorted(listed - files)}"
    stems = {Path(n).stem for n in listed}
    # Unlisted files must be the companion half of a listed TetGen pair.
    orphans = [f for f in files - listed if Path(f).stem not in stems]
    assert not orphans, f"files without an expectation: {orphans}"
    assert len([n for n, e in EXPECTED.items() if "error" in e]) >= 22
    assert any("warning" in e for e in EXPECTED.values())


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_malformed_file(name):
    check_corpus_entry(name, EXPECTED[name], lambda: palpate.load_mesh(HERE / name), palpate.PalpateError)
