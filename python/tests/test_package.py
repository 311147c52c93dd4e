"""What a user installing palpate sees before running it: the licence texts and the data
attribution, the metadata, and a core install of numpy and meshio (plotting and the reference FEM
are extras)."""
import importlib.util
import subprocess
import sys

from conftest import REPO

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

PYPROJECT = tomllib.loads((REPO / "python" / "pyproject.toml").read_text())["project"]
REPOSITORY = "https://github.com/palpate-sim/palpate"


def test_licence_files_and_data_attribution():
    for name in ("LICENSE-MIT", "LICENSE-APACHE", "NOTICE"):
        assert (REPO / name).is_file(), name
        # The wheel takes them from python/ (PEP 639 paths are relative to pyproject.toml).
        assert (REPO / "python" / name).read_text() == (REPO / name).read_text()
    assert "Apache License" in (REPO / "LICENSE-APACHE").read_text()
    notice = (REPO / "NOTICE").read_text()
    for needed in ("CC BY 4.0", "Rodero", "10.1371/journal.pcbi.1008851", "MIT OR Apache-2.0"):
        assert needed in notice, needed


def test_pyproject_metadata():
    assert PYPROJECT["license"] == "MIT OR Apache-2.0"
    assert set(PYPROJECT["license-files"]) == {"LICENSE-MIT", "LICENSE-APACHE", "NOTICE"}
    for key in ("readme", "authors", "classifiers", "requires-python", "description"):
        assert PYPROJECT.get(key), key


def test_core_dependencies_are_numpy_and_meshio():
    core = {d.split(">")[0].split(";")[0].strip() for d in PYPROJECT["dependencies"]}
    assert core == {"numpy", "meshio", "tomli"}   # tomli: Python < 3.11 only
    extras = PYPROJECT["optional-dependencies"]
    assert any(d.startswith("matplotlib") for d in extras["plot"])
    assert any(d.startswith("scikit-fem") for d in extras["test"])
    # "all" (issue 37) is the union of the user-facing extras, nothing missing, nothing else.
    assert set(extras["all"]) == set().union(*(extras[e] for e in ("plot", "view", "validate", "study")))


def test_import_needs_no_extra():
    # A core install has no matplotlib, scikit-fem or the viewer's viser and Playwright: importing
    # palpate and its CLI (palpate view's parser included) must not need them.
    code = ("import sys; import palpate, palpate.cli, palpate.touch, palpate.demo, palpate.io, palpate.viewer; "
            "bad = [m for m in ('matplotlib', 'skfem', 'scipy', 'viser', 'playwright') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_pyproject_urls():
    urls = PYPROJECT["urls"]
    assert set(urls) >= {"Homepage", "Repository", "Documentation", "Issues"}
    assert urls["Repository"] == REPOSITORY and urls["Issues"].startswith(REPOSITORY)


def test_cargo_metadata():
    ws = tomllib.loads((REPO / "Cargo.toml").read_text())["workspace"]["package"]
    assert ws["rust-version"] == "1.89"   # nalgebra 0.35's own rust-version
    for key in ("license", "authors", "readme", "keywords", "categories"):
        assert ws.get(key), key
    assert ws["repository"] == REPOSITORY and ws["homepage"] == REPOSITORY
    for crate in ("crates/palpate-core", "crates/palpate-haptics", "python"):
        pkg = tomllib.loads((REPO / crate / "Cargo.toml").read_text())["package"]
        assert pkg.get("description"), crate
        for key in ("license", "authors", "readme", "keywords", "categories", "rust-version", "repository"):
            assert pkg.get(key) == {"workspace": True}, (crate, key)
    # A published crate carries the licence texts beside its manifest (cargo package takes only
    # files under the crate's folder).
    for crate in ("crates/palpate-core", "crates/palpate-haptics"):
        for name in ("LICENSE-MIT", "LICENSE-APACHE"):
            assert (REPO / crate / name).read_text() == (REPO / name).read_text(), (crate, name)


def test_plots_without_matplotlib_name_the_extra(monkeypatch, capsys, tmp_path):
    # A core install has no matplotlib: the demo and palpate touch say which extra brings the plot.
    import numpy as np

    from palpate import demo, touch

    curves = [("bar", np.arange(3) * 1e-3, np.zeros(3))]
    monkeypatch.setitem(sys.modules, "matplotlib", None)     # `import matplotlib` raises ImportError
    assert demo.plot_probe(curves, str(tmp_path)) is None
    touch.plot_force(np.zeros((0, len(touch.COLUMNS))), str(tmp_path / "force.png"))
    said = capsys.readouterr().out.splitlines()
    assert len(said) == 2 and all("matplotlib not installed" in s and "pip install 'matplotlib" in s and "the plot extra" in s
                                  for s in said), said
    assert not list(tmp_path.iterdir())
    monkeypatch.undo()
    if importlib.util.find_spec("matplotlib") is not None:   # with the extra: the plot
        assert demo.plot_probe(curves, str(tmp_path)) == str(tmp_path / "demo_probe.png")
        assert (tmp_path / "demo_probe.png").stat().st_size > 0


def test_install_hints_name_the_extras_packages_not_pypi():
    # palpate comes from a wheel or a checkout, not PyPI: `pip install 'palpate[plot]'` would look
    # there (issue 37). The hint names the extra's packages from the installed metadata.
    from palpate._extras import extra_packages, install_hint

    assert any(p.startswith("matplotlib") for p in extra_packages("plot"))
    assert {p.split(">")[0].split("[")[0] for p in extra_packages("study")} >= {"dask", "pyarrow", "scipy"}
    hint = install_hint("plot")
    assert hint.startswith("pip install 'matplotlib") and "palpate[" not in hint and "python[plot]" in hint, hint
    assert extra_packages("no-such-extra") == [] and "python[no-such-extra]" in install_hint("no-such-extra")
