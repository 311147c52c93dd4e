"""RELIABILITY.md's table from a corpus run: ``CORPUS_REPORT=r.json pytest python/tests/test_corpus.py``
then ``python python/tests/corpus_report.py r.json``. Per class of the issue's table: the inputs
tried and how they ended (typed error, warning, accepted correctly, or a failure of the corpus)."""
import json
import sys
from collections import Counter, defaultdict

from test_corpus import verdict

ROWS = ["abort", "panic", "hang", "bomb", "silent", "output", "untyped", "mutation", "seed"]


def main(path):
    d = json.load(open(path))
    cases, results = d["cases"], d["results"]
    rows = defaultdict(Counter)
    types = defaultdict(Counter)
    for c in cases:
        r = results[c["name"]]
        bad = verdict(c, r)
        if bad:
            kind = "FAILED"
        elif c["kind"] == "cli":
            kind = "error" if r["code"] else "ok"
            types[c["klass"]][f"exit {r['code']}"] += 1
        else:
            kind = r["outcome"]
            if kind in ("error", "warning"):
                types[c["klass"]][r["type"]] += 1
        rows[c["klass"]][kind] += 1
        rows[c["klass"]]["cli" if c["kind"] == "cli" else "api"] += 1
    print("| class | inputs (API + CLI) | typed error | warning | accepted correctly | failed | error types |")
    print("|---|---|---|---|---|---|---|")
    tot = Counter()
    for k in ROWS:
        r = rows[k]
        n = r["api"] + r["cli"]
        tot.update({"n": n, "error": r["error"], "warning": r["warning"], "ok": r["ok"], "FAILED": r["FAILED"]})
        ty = ", ".join(f"{t} {v}" for t, v in types[k].most_common())
        print(f"| {k} | {n} ({r['api']} + {r['cli']}) | {r['error']} | {r['warning']} | {r['ok']} | {r['FAILED']} | {ty} |")
    print(f"| **all** | {tot['n']} | {tot['error']} | {tot['warning']} | {tot['ok']} | {tot['FAILED']} | |")
    slow = sorted(((r.get("seconds", 0), n) for n, r in results.items()), reverse=True)[:3]
    print("\nslowest:", ", ".join(f"{n} {s:.1f} s" for s, n in slow))


if __name__ == "__main__":
    main(sys.argv[1])
