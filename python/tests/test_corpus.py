"""Issue 15: a few hundred malformed or extreme inputs, each in its own process under a memory
limit (RLIMIT_AS 3 GiB, palpate's budget 1 GiB) and a time limit (10 s), must end with a palpate
error or warning (or, where the input is valid after all, a correct result): never a signal, a
panic, a hang or an untyped traceback. Cases: corpus_cases.py; runner: corpus_runner.py.

Set CORPUS_REPORT=path.json to keep the results (RELIABILITY.md's table is made from them by
``python corpus_cases_report.py path.json``).
"""
import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

import corpus_cases

HERE = Path(__file__).resolve().parent
JOBS = 2


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("corpus")
    cases = corpus_cases.make(str(folder))
    procs, outs = [], []
    env = dict(os.environ)
    env.setdefault("CORPUS_TIMEOUT", "10")
    for j in range(JOBS):
        spec = folder / f"cases_{j}.json"
        spec.write_text(json.dumps({"folder": str(folder), "cases": cases[j::JOBS]}))
        out = folder / f"results_{j}.json"
        outs.append(out)
        procs.append(subprocess.Popen([sys.executable, str(HERE / "corpus_runner.py"), str(spec), str(out)], env=env))
    for p in procs:
        assert p.wait(timeout=900) == 0, "the corpus runner itself failed"
    results = {}
    for out in outs:
        results.update(json.loads(out.read_text()))
    report = os.environ.get("CORPUS_REPORT")
    if report:
        Path(report).write_text(json.dumps({"cases": cases, "results": results}, indent=1))
    return cases, results


def verdict(case, r):
    """None when the case ended as it must, else why not."""
    o = r["outcome"]
    if o in ("signal", "hang", "harness"):
        return f"{o} ({r})"
    if o == "untyped":
        return f"untyped {r['type']}: {r['message'][:300]}\n{r.get('traceback', '')[-1500:]}"
    if o == "error" and (r.get("type") == "InternalError" or "InternalError" in r.get("mro", [])):
        # A caught Rust panic is typed, but it is a palpate bug, not a refusal of the input.
        return f"internal error (a caught panic): {r.get('message', '')[:300]}"
    want = case.get("contains")
    want = [want] if isinstance(want, str) else want
    if case["kind"] == "cli":
        lines = [ln for ln in r["stderr"].splitlines() if ln.strip()]
        if "internal error" in r["stderr"].lower():
            return f"the CLI reported an internal error (a caught panic): {r['stderr'][-500:]!r}"
        if want and not any(w in r["stderr"] for w in want):
            return f"stderr does not say any of {want}: {r['stderr'][-500:]!r}"
        if r["code"] not in case["codes"]:
            return f"exit code {r['code']}, expected one of {case['codes']}; stderr {r['stderr'][-500:]!r}"
        if "Traceback" in r["stderr"] or len(lines) != 1 or not lines[0].startswith("palpate"):
            return f"stderr is not one 'palpate...' line: {r['stderr'][-800:]!r}"
        return None
    if o not in case["expect"]:
        return f"outcome {o} ({r.get('type')}: {r.get('message', '')[:300]}), expected {case['expect']}"
    if o == "error" and case.get("types") and r["type"] not in case["types"] and not set(case["types"]) & set(r.get("mro", [])):
        return f"error {r['type']} ({r['message'][:300]}), expected one of {case['types']}"
    if o == "error" and want and not any(w in r["message"] for w in want):
        return f"error {r['type']} ({r['message'][:300]}) does not say any of {want}"
    if o == "error" and "ParameterError" not in [r["type"], *r.get("mro", [])]:  # a bad argument is not about a file
        msg = r["message"]
        files = case.get("names") or [a for a in case.get("code", "").split("'") if "." in a and "/" not in a and " " not in a]
        if "os.path.join(D" in case.get("code", "") and files and not any(f in msg for f in files):
            return f"error message does not name the file {files}: {msg[:300]}"
    if r.get("seconds", 0) > 10:
        return f"took {r['seconds']:.1f} s"
    return None


def test_corpus_is_large_and_covers_every_row(corpus):
    cases, results = corpus
    assert len(cases) >= 200, len(cases)
    assert set(results) == {c["name"] for c in cases}
    rows = Counter(c["klass"] for c in cases)
    for klass in ("abort", "panic", "hang", "bomb", "silent", "output", "untyped", "mutation", "seed"):
        assert rows[klass] >= 3, (klass, rows)
    assert sum(c["kind"] == "cli" for c in cases) >= 20


def test_every_case_ends_typed_within_limits(corpus):
    cases, results = corpus
    bad = {}
    for case in cases:
        why = verdict(case, results[case["name"]])
        if why:
            bad[case["name"]] = why
    assert not bad, f"{len(bad)} of {len(cases)} cases failed:\n" + "\n".join(f"- {k} [{next(c['klass'] for c in cases if c['name'] == k)}]: {v}" for k, v in sorted(bad.items()))


def test_verdict_can_fail():
    """The checks themselves reject what the issue forbids."""
    api = {"kind": "api", "expect": ["error"], "types": ["MeshError"], "code": ""}
    assert verdict(api, {"outcome": "signal", "signal": 6})
    assert verdict(api, {"outcome": "hang"})
    assert verdict(api, {"outcome": "untyped", "type": "PanicException", "message": "x"})
    assert verdict(api, {"outcome": "ok"})
    assert verdict(api, {"outcome": "error", "type": "ModelError", "message": "x", "mro": ["ModelError", "PalpateError"]})
    assert verdict(api, {"outcome": "error", "type": "MeshError", "message": "x", "mro": ["MeshError"]}) is None
    # A caught panic is a PalpateError (InternalError), but never an accepted end, even where any
    # palpate error is allowed.
    anyerr = {"kind": "api", "expect": ["error"], "types": None, "code": ""}
    assert verdict(anyerr, {"outcome": "error", "type": "InternalError", "message": "x", "mro": ["InternalError", "PalpateError"]})
    assert verdict(anyerr, {"outcome": "error", "type": "ParameterError", "message": "x", "mro": ["ParameterError", "PalpateError"]}) is None
    # A case that names its check: the same type from another check (after building) fails.
    pre = {"kind": "api", "expect": ["error"], "types": ["MeshError"], "code": "", "contains": "refused before building"}
    assert verdict(pre, {"outcome": "error", "type": "MeshError", "message": "g: fails validation", "mro": ["MeshError"]})
    assert verdict(pre, {"outcome": "error", "type": "MeshError", "message": "g: refused before building: x", "mro": ["MeshError"]}) is None
    # A bomb or oversized header refused by some later MeshError (the pre-check lost) fails.
    bomb = {"kind": "api", "expect": ["error"], "types": ["LimitError"], "code": ""}
    assert verdict(bomb, {"outcome": "error", "type": "MeshError", "message": "x.vtu: cannot read as VTU", "mro": ["MeshError", "PalpateError"]})
    header = {"kind": "api", "expect": ["error"], "types": ["MeshError", "LimitError"], "code": "", "contains": corpus_cases.PRECHECK}
    assert verdict(header, {"outcome": "error", "type": "MeshError", "message": "x.vtk: cannot read as VTK (ValueError: cannot reshape)", "mro": ["MeshError"]})
    assert verdict(header, {"outcome": "error", "type": "MeshError", "message": "x.vtk: byte 9: POINTS announces 9; the file has 90", "mro": ["MeshError"]}) is None
    assert verdict({"kind": "cli", "codes": [1], "contains": "LimitError"}, {"outcome": "exit", "code": 1, "stderr": "palpate: error: MeshError: x\n"})
    cli = {"kind": "cli", "codes": [1]}
    assert verdict(cli, {"outcome": "exit", "code": 2, "stderr": "palpate: error: x\n"})   # usage where input was due
    assert verdict(cli, {"outcome": "exit", "code": 3, "stderr": "palpate: error: x\n"})   # a failed run where input was due
    assert verdict(cli, {"outcome": "exit", "code": 1, "stderr": "Traceback (most recent call last):\n...\n"})
    assert verdict(cli, {"outcome": "exit", "code": 1, "stderr": "palpate: error: x\n"}) is None
    assert verdict({"kind": "cli", "codes": [1, 3]}, {"outcome": "exit", "code": 3, "stderr":
                   "palpate: error: box_mesh: internal error (a palpate bug; please report it with the input): x\n"})


@pytest.mark.parametrize("args", [["--version"], ["--help"], ["info", str(HERE / "data" / "malformed" / "gmsh2_inverted_tet.msh")]])
def test_cli_is_quiet_on_a_closed_pipe(args):
    """`palpate ... | head`: the reader has gone before palpate writes. stdout here is a pipe whose
    read end is already closed, so the first write fails (EPIPE): no BrokenPipeError traceback,
    no "Exception ignored" message, nothing on stderr."""
    r, w = os.pipe()
    os.close(r)
    try:
        p = subprocess.run([sys.executable, "-m", "palpate", *args], stdout=w, stderr=subprocess.PIPE, text=True,
                           env=dict(os.environ), timeout=120)
    finally:
        os.close(w)
    assert p.stderr.strip() == "" or (p.stderr.count("\n") <= 1 and "Traceback" not in p.stderr
                                      and "BrokenPipe" not in p.stderr and "Exception ignored" not in p.stderr), p.stderr
    assert "Traceback" not in p.stderr and "BrokenPipe" not in p.stderr, p.stderr


def test_python_errors_are_palpate_errors():
    """The Python modules' own errors are in the one tree (issue 15), keeping the base that
    callers caught before as a second one."""
    import palpate
    import palpate.data
    import palpate.scene
    import palpate.touch

    for cls, old in ((palpate.touch.ScriptError, ValueError), (palpate.touch.TouchFailed, RuntimeError),
                     (palpate.data.DataError, RuntimeError), (palpate.scene.SceneError, ValueError),
                     (palpate.ParameterError, ValueError)):
        assert issubclass(cls, palpate.PalpateError) and issubclass(cls, old), cls
    with pytest.raises(palpate.ParameterError):
        palpate.build_shape("cube")
    with pytest.raises(palpate.ParameterError):
        palpate.repair_surface(np.zeros((4, 2)), [[0, 1, 2]])
