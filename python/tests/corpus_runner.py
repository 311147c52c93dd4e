"""Run corpus cases (test_corpus.py), each in its own forked process under a memory and a time
limit, and write one JSON result per case.

    python corpus_runner.py CASES.json RESULTS.json

This process imports numpy and palpate once and then only forks: it must never run palpate code
itself (a rayon thread pool started before a fork would deadlock the children). Each child

- sets ``RLIMIT_AS`` (address space) to ``CORPUS_MEMORY`` bytes (default 3 GiB) and
  ``PALPATE_MAX_MEMORY`` to 1 GiB (or, for the cases of ``budget=None``, leaves it unset: the
  budget then follows RLIMIT_AS), so an unchecked allocation of a few GB fails (a Rust
  allocation failure aborts: SIGABRT, reported as a signal) while palpate's own budget refuses it
  first with a LimitError;
- arms ``SIGALRM`` after ``CORPUS_TIMEOUT`` seconds (default 10): a hang dies of the alarm;
- runs the case: Python code (``api``) with ``palpate``, ``np`` and ``D`` (the corpus folder) in
  scope, or the command line (``cli``) in process with stdout / stderr captured;
- classifies the end: ``error`` (an exception derived from palpate.PalpateError: its class and
  message), ``untyped`` (any other exception: its class, message and traceback), ``warning``
  (returned normally after a palpate warning), ``ok``; for the CLI also the exit code and stderr.

The parent records a child that dies of a signal as ``signal`` and one that outlives the time
limit (alarm blocked) as ``hang``.
"""
import io
import json
import os
import resource
import signal
import sys
import time
import traceback
import warnings

import numpy as np

import palpate
import palpate.cli

TIMEOUT = float(os.environ.get("CORPUS_TIMEOUT", "10"))
MEMORY = int(os.environ.get("CORPUS_MEMORY", str(3 << 30)))


def classify(exc):
    if isinstance(exc, palpate.PalpateError):
        return {"outcome": "error", "type": type(exc).__name__, "message": str(exc)[:2000],
                "mro": [c.__name__ for c in type(exc).__mro__]}
    return {"outcome": "untyped", "type": type(exc).__name__, "message": str(exc)[:2000],
            "traceback": "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))[-3000:]}


def run_api(case, folder):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            exec(case["code"], {"palpate": palpate, "np": np, "D": folder, "os": os})
        except BaseException as e:  # noqa: BLE001 - the point is to see every kind
            return classify(e)
    ours = [w for w in caught if issubclass(w.category, (palpate.MeshWarning, UserWarning, RuntimeWarning))]
    if ours:
        return {"outcome": "warning", "type": ours[0].category.__name__, "message": str(ours[0].message)[:2000]}
    return {"outcome": "ok"}


def run_cli(case, folder):
    argv = [a.replace("{D}", folder) for a in case["argv"]]
    out, err = io.StringIO(), io.StringIO()
    old = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = out, err
    code = None
    try:
        try:
            code = palpate.cli.main(argv)
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except BaseException as e:  # noqa: BLE001
            sys.stdout, sys.stderr = old
            r = classify(e)
            r["outcome"] = "untyped"  # an exception out of main() is a traceback for the user
            return r
    finally:
        sys.stdout, sys.stderr = old
    return {"outcome": "exit", "code": code, "stderr": err.getvalue()[-3000:], "stdout_bytes": len(out.getvalue())}


def child(case, folder, path):
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))
    budget = case.get("budget", "1G")
    if budget is None:
        # The budget from the limits themselves (issue 35 item 4): half of RLIMIT_AS less what is
        # mapped, about 1.2 GiB here; the case must name RLIMIT_AS in its refusal.
        os.environ.pop("PALPATE_MAX_MEMORY", None)
    else:
        os.environ["PALPATE_MAX_MEMORY"] = budget
    signal.alarm(int(TIMEOUT))
    t0 = time.perf_counter()
    r = run_cli(case, folder) if case["kind"] == "cli" else run_api(case, folder)
    r["seconds"] = time.perf_counter() - t0
    with open(path, "w") as fh:
        json.dump(r, fh)


def main(cases_path, results_path):
    with open(cases_path) as fh:
        spec = json.load(fh)
    folder, cases = spec["folder"], spec["cases"]
    results = {}
    for case in cases:
        out = os.path.join(folder, f".result_{os.getpid()}.json")
        if os.path.exists(out):
            os.remove(out)
        t0 = time.perf_counter()
        pid = os.fork()
        if pid == 0:
            code = 0
            try:
                child(case, folder, out)
            except BaseException:  # noqa: BLE001 - a failure of the harness itself
                traceback.print_exc()
                code = 3
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
        status, killed = None, False
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            if time.perf_counter() - t0 > TIMEOUT + 5:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                killed = True
                break
            time.sleep(0.005)
        wall = time.perf_counter() - t0
        if killed:
            r = {"outcome": "hang", "seconds": wall}
        elif os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            r = {"outcome": "hang" if sig == signal.SIGALRM else "signal", "signal": sig, "seconds": wall}
        elif os.path.exists(out):
            with open(out) as fh:
                r = json.load(fh)
        else:
            r = {"outcome": "harness", "status": os.WEXITSTATUS(status), "seconds": wall}
        results[case["name"]] = r
    if os.path.exists(out):
        os.remove(out)
    with open(results_path, "w") as fh:
        json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
