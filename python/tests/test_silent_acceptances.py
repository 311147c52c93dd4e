"""Issue 35 item 6 ("no silent acceptance") and item 7 (a closed pipe): the inputs that palpate
accepted without a word, each now a typed error naming the file or argument, the element and the
reason. The cases live in the corpus (corpus_cases._silent_cases, klass "silent"), which
test_corpus.py runs with the rest; this file runs them alone, through the same runner (a forked
process under the same limits) and the same verdict, so that they can be checked in seconds.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import corpus_cases
from test_corpus import verdict

HERE = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def silent(tmp_path_factory):
    folder = tmp_path_factory.mktemp("silent")
    c = corpus_cases.Corpus(str(folder))
    corpus_cases._seeds(c)   # seed.palpate, the model the crafted voxel-spacing files start from
    c.cases = []
    corpus_cases._silent_cases(c)
    spec, out = folder / "cases.json", folder / "results.json"
    spec.write_text(json.dumps({"folder": str(folder), "cases": c.cases}))
    env = dict(os.environ)
    env.setdefault("CORPUS_TIMEOUT", "10")
    subprocess.run([sys.executable, str(HERE / "corpus_runner.py"), str(spec), str(out)], env=env, check=True, timeout=600)
    return c.cases, json.loads(out.read_text())


def test_each_silent_acceptance_is_now_reported(silent):
    cases, results = silent
    assert len(cases) >= 30, len(cases)
    bad = {c["name"]: why for c in cases if (why := verdict(c, results[c["name"]]))}
    assert not bad, f"{len(bad)} of {len(cases)} cases failed:\n" + "\n".join(f"- {k}: {v}" for k, v in sorted(bad.items()))


def _build_argv(out):
    return [sys.executable, "-m", "palpate", "build", "--shape", "ellipsoids", "--particles", "300",
            "--field-voxels", "8000", "-o", str(out)]


def test_build_into_a_closed_pipe_still_writes_the_model(tmp_path):
    """Issue 35 item 7: ``palpate build ... | head -c 0``. stdout is a pipe whose reader has gone
    before palpate writes its summary (the first print fails with EPIPE): the model file is
    written all the same and is valid, the command ends quietly with 141 (128 + SIGPIPE)."""
    import palpate
    from palpate.cli import _common

    out = tmp_path / "m.palpate"
    r, w = os.pipe()
    os.close(r)
    try:
        p = subprocess.run(_build_argv(out), stdout=w, stderr=subprocess.PIPE, text=True, timeout=300)
    finally:
        os.close(w)
    assert "Traceback" not in p.stderr and "BrokenPipe" not in p.stderr, p.stderr
    assert p.returncode == _common.CLOSED_PIPE, (p.returncode, p.stderr)
    assert out.exists(), "the closed pipe ended the command before the model was saved"
    m = palpate.HybridModel.load(out)
    assert m.info()["particles"] > 0


def test_build_through_a_shell_pipe_that_closes_at_once(tmp_path):
    """The same through a real shell pipeline, ``| head -c 0`` (the reader exits at once)."""
    import shlex

    import palpate

    out = tmp_path / "m.palpate"
    cmd = " ".join(shlex.quote(a) for a in _build_argv(out)) + " | head -c 0; echo ${PIPESTATUS[0]}"
    p = subprocess.run(["bash", "-c", cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=300)
    assert "Traceback" not in p.stderr, p.stderr
    assert p.stdout.strip() in ("0", "141"), (p.stdout, p.stderr)   # 0 if palpate wrote before head left
    assert palpate.HybridModel.load(out).info()["particles"] > 0
