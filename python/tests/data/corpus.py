"""What the two corpus scripts (malformed/make_corpus.py, malformed_surfaces/make_corpus.py)
share: writing a case file, its table in EXPECTED.toml, and the table file itself."""
import json
import os


def write_case(here, name, content):
    """Write the case file ``name`` (bytes or text) beside the script."""
    with open(os.path.join(here, name), "wb" if isinstance(content, bytes) else "w") as fh:
        fh.write(content)


def entry(name, exp, default_call=None):
    """The EXPECTED.toml lines of one case: ``call`` (when not ``default_call``), ``error`` and / or
    ``warning``, ``contains``, ``note``, then a blank line."""
    lines = [f'["{name}"]']
    if default_call is not None and exp["call"] != default_call:
        lines.append(f'call = "{exp["call"]}"')
    if exp["error"]:
        lines.append(f'error = "{exp["error"]}"')
    if exp["warning"]:
        lines.append(f'warning = "{exp["warning"]}"')
    lines.append("contains = [" + ", ".join(json.dumps(c) for c in exp["contains"]) + "]")
    if exp["note"]:
        lines.append(f'note = "{exp["note"]}"')
    lines.append("")
    return lines


def write_expected(here, lines):
    """Write EXPECTED.toml beside the script and say how many cases it lists."""
    with open(os.path.join(here, "EXPECTED.toml"), "w") as fh:
        fh.write("\n".join(lines))
    n = sum(1 for line in lines if line.startswith('["'))
    print(f"wrote {n} cases to {here}")
