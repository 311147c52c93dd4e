"""The palpate command line: scenes, the benchmark protocol, error reporting."""
import json
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from palpate.io import read_pvd

from conftest import REPO, SHARED, needs_shared


def palpate_cli(*args, cwd=None, env_extra=None):
    env = dict(os.environ)
    if SHARED is not None:
        env.setdefault("PALPATE_SHARED", str(SHARED))
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-m", "palpate", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or REPO, env=env, timeout=600)


def test_console_script_is_installed():
    script = Path(sys.executable).parent / "palpate"
    assert script.exists(), "the 'palpate' console script is missing from the environment"
    r = subprocess.run([str(script), "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.startswith("palpate ")


def test_run_ellipsoid_scene_writes_readable_series(tmp_path):
    r = palpate_cli("run", REPO / "scenes" / "ellipsoid_probe.toml", "--out", tmp_path / "o", "--steps", 60)
    assert r.returncode == 0, r.stderr
    assert "steps/s" in r.stdout and "max |u|" in r.stdout and "energy" in r.stdout
    frames = read_pvd(tmp_path / "o" / "frame.pvd")
    assert len(frames) == 1 + 3 + 0          # step 0, then every 20 steps of 60
    m = meshio.read(frames[-1][1])
    assert m.cells_dict["tetra"].shape == (192, 4)
    u = m.point_data["displacement"]
    assert u.shape == (54, 3) and np.isfinite(u).all() and np.abs(u).max() > 0
    assert m.point_data["velocity"].shape == (54, 3)


@needs_shared
def test_run_lv_scene(tmp_path):
    scene = REPO / "scenes" / "lv_probe.toml"
    r = palpate_cli("run", scene, "--out", tmp_path / "lv", "--steps", 20)
    assert r.returncode == 0, r.stderr
    frames = read_pvd(tmp_path / "lv" / "frame.pvd")
    assert meshio.read(frames[-1][1]).points.shape == (436, 3)


@pytest.mark.parametrize("body, key", [
    ('[mesh]\ngenerator = "ellipsoid_wall"\n[material]\nyoung = -3e4\npoisson = 0.4\n', "material.young"),
    ('[mesh]\ngenerator = "ellipsoid_wall"\n[material]\nyuong = 3e4\n', "material.yuong"),
    ('[mesh]\ngenerator = "nope"\n[material]\nyoung = 3e4\npoisson = 0.4\n', "mesh.generator"),
    ('[mesh]\nfile = "missing.msh"\n[material]\nyoung = 3e4\npoisson = 0.4\n', "mesh.file"),
    ('[mesh]\ngenerator = "ellipsoid_wall"\n[material]\nyoung = 3e4\npoisson = 0.4\n'
     '[[loads]]\npoint = [0, 0]\nradius = 0.01\nforce = [0, 0, 1]\n', "loads[0].point"),
    ('[mesh]\ngenerator = "ellipsoid_wall"\n[material]\nyoung = 3e4\npoisson = 0.4\n[run]\ndt = -1\n', "run.dt"),
    ('[mesh]\ngenerator = "ellipsoid_wall"\n[material]\nyoung = 3e4\npoisson = 0.4\n[integrator]\ntype = "rk4"\n',
     "integrator.type"),
    ('[mesh\n', "invalid TOML"),
])
def test_scene_errors_are_one_line_exit_1(tmp_path, body, key):
    f = tmp_path / "bad.toml"
    f.write_text(body)
    r = palpate_cli("run", f, "--out", tmp_path / "o")
    assert r.returncode == 1     # bad input: the scene file
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "bad.toml" in lines[0] and key in lines[0]


def _check_bench_row(row):
    keys = {"mesh", "tets", "nodes", "integrator", "force_N", "steps", "wall_s", "steps_per_s", "stable", "max_disp_m",
            "probe_disp_avg_m", "static_probe_disp_m", "rel_L2_vs_static", "rel_L2_vs_newton", "iterations_mean",
            "iterations_max", "inverted_max", "step_us_p50", "step_us_p99", "step_us_max"}
    assert keys <= set(row)
    assert row["steps"] == 50 and row["stable"] is True and row["steps_per_s"] > 0
    assert 0 < row["max_disp_m"] < 0.02
    assert row["static_probe_disp_m"] > 0 and row["rel_L2_vs_static"] >= 0
    assert 0 < row["step_us_p50"] <= row["step_us_p99"] <= row["step_us_max"]
    assert row["iterations_max"] >= 1 and row["iterations_mean"] >= 1


@needs_shared
def test_bench_protocol_firm_press_default_integrator(shared):
    """A 2 N press with the default integrator: finite, bounded by 6 cm, and its mean field within
    a few percent of converged Newton's (a short run: the ramp and the first hold)."""
    r = palpate_cli("bench", "protocol", shared / "bench" / "meshes" / "lv_190.msh", "--steps", 200, "--json",
                    "--force", 2)
    assert r.returncode == 0, r.stderr
    row = json.loads(r.stdout)
    assert row["force_N"] == pytest.approx(2.0) and row["stable_limit_m"] == 0.06
    assert row["stable"] is True and row["integrator"] == "backward-euler"
    assert row["rel_L2_vs_newton"] is not None and row["rel_L2_vs_newton"] < 0.05
    assert row["iterations_mean"] >= 1
    r = palpate_cli("bench", "protocol", shared / "bench" / "meshes" / "lv_190.msh", "--force", -1)
    assert r.returncode == 2 and "--force" in r.stderr


@needs_shared
@pytest.mark.parametrize("ext", [".msh", ".vtu", ".npz"])
def test_bench_protocol_json(shared, ext):
    r = palpate_cli("bench", "protocol", shared / "bench" / "meshes" / f"lv_190{ext}", "--steps", 50, "--json")
    assert r.returncode == 0, r.stderr
    row = json.loads(r.stdout)
    _check_bench_row(row)
    assert row["mesh"] == "lv_190" and row["tets"] == 190 and row["nodes"] == 75
    assert row["loaded_nodes"] == 1 and row["fixed_nodes"] == 20   # PROTOCOL.md: 1 loaded, 20 base nodes


def test_bench_protocol_generated_ellipsoid():
    r = palpate_cli("bench", "protocol", "ellipsoid_192", "--steps", 50, "--json", "--integrator", "semi-implicit")
    assert r.returncode == 0, r.stderr
    row = json.loads(r.stdout)
    _check_bench_row(row)
    assert row["tets"] == 192 and row["integrator"] == "semi-implicit"


def test_bench_protocol_errors(tmp_path):
    r = palpate_cli("bench", "protocol")
    assert r.returncode == 2 and "MESH" in r.stderr         # usage: neither MESH nor --all
    bad = tmp_path / "x.msh"
    bad.write_text("garbage\n")
    r = palpate_cli("bench", "protocol", bad, "--steps", 5)
    assert r.returncode == 1 and "x.msh" in r.stderr and "Traceback" not in r.stderr   # bad input


def test_info(tmp_path):
    r = palpate_cli("info", REPO / "python" / "tests" / "data" / "malformed" / "gmsh2_inverted_tet.msh")
    assert r.returncode == 0 and "2 tets" in r.stdout


def _diverging_scene(tmp_path):
    """The shipped ellipsoid scene with the paper's semi-implicit scheme at 20x its time step: it
    blows up within a few steps (a StepError after the scene was accepted)."""
    text = (REPO / "scenes" / "ellipsoid_probe.toml").read_text()
    text = text.replace('type = "backward_euler"', 'type = "semi_implicit"').replace("dt = 1e-3", "dt = 0.02")
    assert 'type = "semi_implicit"' in text and "dt = 0.02" in text
    f = tmp_path / "diverging.toml"
    f.write_text(text.replace("steps = 1000", "steps = 500"))
    return f


def test_exit_codes_table_each_code_from_a_real_command(tmp_path):
    """The exit-code table (cli/_common.EXIT_CODES, README "Exit codes", palpate --help): for every
    code, real commands that end with it, with one line on stderr (none for 0 and a closed pipe).
    Would catch: a usage error reported as bad input or the reverse, a failed run reported as bad
    input (the contract before: 2 for both usage and input, 1 for failed runs), a code added to
    the table that no command produces, a traceback on Ctrl-C."""
    import signal
    import time

    from palpate.cli import _common as c

    garbage = tmp_path / "x.msh"
    garbage.write_text("garbage\n")
    scene = _diverging_scene(tmp_path)
    (tmp_path / "a_dir.palpate").mkdir()
    import palpate
    box = palpate.box_mesh()
    mesh = tmp_path / "box.npz"
    np.savez(mesh, points=box.points, tets=box.tets)
    commands = {
        c.OK: [("info", mesh)],
        c.INPUT: [("info", tmp_path / "missing.msh"), ("info", garbage),                     # OSError, MeshError
                  ("run", scene, "--out", ".."),                                             # SceneError (the output)
                  ("touch", "--shape", "ventricle", "--script", garbage)],                   # ScriptError
        c.USAGE: [("frobnicate",), ("run",), ("info", mesh, "--unit", "inch"),              # argparse
                  ("bench", "protocol", "ellipsoid_192", "--force", -1),                     # a flag's range
                  ("bench", "protocol", "ellipsoid_192", "--all")],                          # conflicting
        c.FAILED: [("run", scene, "--out", tmp_path / "o"),                                  # StepError
                   ("build", "--shape", "ellipsoids", "-o", tmp_path / "a_dir.palpate",      # a failed write
                    "--particles", 400, "--field-voxels", 20000)],
    }
    for code, cmds in commands.items():
        for args in cmds:
            r = palpate_cli(*args)
            assert r.returncode == code, (args, code, r.returncode, r.stderr)
            assert "Traceback" not in r.stderr
            lines = r.stderr.strip().splitlines()
            assert (lines == []) if code == c.OK else (len(lines) == 1 and lines[0].startswith("palpate") and "error:" in lines[0]), r.stderr

    # Ctrl-C in the middle of a run: one line and 130 (the scene runs ~20 s unless interrupted).
    argv = ["run", REPO / "scenes" / "lv_probe.toml", "--steps", 200000, "--out", tmp_path / "long"]
    # The child gets SIGINT's default disposition: a test runner started in the background by a
    # shell without job control (`make test &` in a script) ignores SIGINT, its children inherit
    # that, and Python then never installs its Ctrl-C handler (the run went on to exit 0).
    p = subprocess.Popen([sys.executable, "-m", "palpate", *map(str, argv)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert p.stdout.readline().startswith("palpate run:")   # past the imports: the command is running
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=120)
    assert p.returncode == c.INTERRUPTED and err == "palpate: interrupted\n", (p.returncode, err)

    # stdout closed by its reader: quiet, 141.
    r, w = os.pipe()
    os.close(r)
    try:
        q = subprocess.run([sys.executable, "-m", "palpate", "info", str(mesh)], stdout=w, stderr=subprocess.PIPE, text=True,
                           timeout=120)
    finally:
        os.close(w)
    assert q.returncode == c.CLOSED_PIPE and q.stderr == "", (q.returncode, q.stderr)

    walked = set(commands) | {c.INTERRUPTED, c.CLOSED_PIPE}
    assert {code for _, code in c.EXIT_CODES} <= walked
    assert walked == {c.OK, c.INPUT, c.USAGE, c.FAILED, c.INTERRUPTED, c.CLOSED_PIPE}
    help_text = palpate_cli("--help").stdout
    assert all(f"\n  {code} " in help_text for code in walked), help_text[-1200:]


def test_every_help_page_reads_as_written():
    """Every command's and subcommand's --help, rendered: no literal '%%' (argparse formats help
    strings, not descriptions: a '%%' in a description is printed as typed; issue 37)."""
    import argparse

    from palpate.cli import build_parser

    def walk(p):
        yield p
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for sub in a.choices.values():
                    yield from walk(sub)

    pages = list(walk(build_parser()))
    assert len(pages) > 10
    for p in pages:
        text = p.format_help()
        assert "%%" not in text and "%(" not in text, f"{p.prog}: {text}"


@pytest.mark.parametrize("argv", [["sweep", "examples/studies/stiffness.toml", "--out", "OUT"],
                                  ["fit", "examples/studies/fit_young.toml", "--measured", "examples/studies/measured_probe.csv"]],
                         ids=["sweep", "fit"])
def test_a_missing_study_extra_is_named_not_an_internal_error(argv, monkeypatch, capsys, tmp_path):
    # Issue 37: without the study extra, sweep and fit printed "internal error ... please report it".
    import sys

    from palpate.cli import main

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    argv = [str(tmp_path / "out") if a == "OUT" else (os.path.join(root, a) if a.startswith("examples/") else a) for a in argv]
    monkeypatch.setitem(sys.modules, "pyarrow", None)   # import pyarrow -> ImportError
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert "the study extra" in err and "'pyarrow>=" in err and "palpate[" not in err and "internal error" not in err, err
    assert not (tmp_path / "out").exists()
