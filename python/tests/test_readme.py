"""The README's Python example runs as written (in a temporary directory)."""
import re
import subprocess
import sys

from conftest import REPO


def test_readme_python_example_runs(tmp_path):
    text = (REPO / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "README has no python example"
    script = tmp_path / "example.py"
    script.write_text("\n".join(blocks))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "static tip deflection" in r.stdout


def test_package_docstring_example():
    import doctest

    import palpate

    res = doctest.testmod(palpate, verbose=False)
    assert res.attempted > 0 and res.failed == 0
