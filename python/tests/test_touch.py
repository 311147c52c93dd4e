"""``palpate touch`` and :mod:`palpate.touch`: scripted touches of a hybrid model.

What a wrong implementation would do: accept a script with a typo, a negative duration, a
non-finite number or nothing in it (or fail with a traceback instead of one line, exit 1); put
the tool sphere's centre on the surface instead of tangent to it at depth 0; log a force before
contact or one that pulls the tool in; write a VTU series ParaView or meshio cannot read, or a
.pvd that misses frames; lose the ticks done before a failed one.
"""
import csv
import math

import meshio
import numpy as np
import pytest

import palpate
from palpate import touch
from palpate.cli import main
from palpate.io import read_pvd

from conftest import REPO

SCRIPTS = REPO / "examples" / "scripts"


@pytest.fixture(scope="module")
def ventricle_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "ventricle.palpate"
    palpate.build_shape("ventricle").save(str(path))
    return path


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


# ------------------------------------------------------------------------------------- parsing

def test_example_toml_parses_and_resolves_to_the_protocol_probe():
    s = touch.parse_script(SCRIPTS / "press_hold_slide.toml")
    assert s.kind == "toml" and [g.kind for g in s.segments] == ["press", "hold", "slide", "hold", "release"]
    assert s.duration == pytest.approx(2.3) and s.point is None and s.gap == 0.002
    assert [g.kind for g in touch.default_script().segments] == [g.kind for g in s.segments]
    # A flat square surface z = 0 (normal +z): the tool sphere is tangent at depth 0.
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]], float) * 0.1
    tris = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    tr = touch.parse_script_text('[probe]\npoint = [0.05, 0.05, 0]\n[[segment]]\nkind = "press"\ndepth = 0.004\n'
                                 'duration = 0.1\n[[segment]]\nkind = "slide"\ndirection = [1, 0, 1]\ndistance = 0.01\n'
                                 'duration = 0.1\n[[segment]]\nkind = "release"\nduration = 0.1\n', "flat.toml", "toml"
                                 ).resolve(pts, tris, 0.005)
    np.testing.assert_allclose(tr.normal, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(tr.knots, [[0.05, 0.05, 0.007], [0.05, 0.05, 0.001], [0.06, 0.05, 0.001],
                                          [0.06, 0.05, 0.007]], atol=1e-12)
    np.testing.assert_allclose(tr.depth(tr.knots), [-0.002, 0.004, 0.004, -0.002], atol=1e-12)
    t, c = tr.positions(1e-3)
    assert len(t) == 300 and t[-1] == pytest.approx(0.3)
    np.testing.assert_allclose(c[49], [0.05, 0.05, 0.004], atol=1e-12)   # half-way down the press


def test_default_probe_on_the_ventricle_is_the_protocols():
    m = palpate.build_shape("ventricle")
    pts, tris = m.outer_points, m.outer_triangles
    v = touch.probe_point(pts, tris)
    target = np.array([pts[:, 0].max(), 0.0, 0.02])
    assert np.linalg.norm(pts[v] - target) == pytest.approx(np.linalg.norm(pts - target, axis=1).min())
    n = touch.vertex_normals(pts, tris)[v]
    radial = np.array([pts[v, 0], pts[v, 1], 0.0]) / np.hypot(pts[v, 0], pts[v, 1])
    assert n @ radial > 0.9, f"the normal {n} should point outward"


def test_example_csv_parses():
    s = touch.parse_script(SCRIPTS / "press_release.csv")
    assert s.kind == "csv" and s.knots.shape == (6, 3) and s.duration == pytest.approx(1.0)
    assert np.all(np.diff(s.times) > 0)


GOOD = '[probe]\nvertex = "probe"\n[[segment]]\nkind = "press"\ndepth = 0.003\nduration = 0.2\n'


@pytest.mark.parametrize("name, text, where", [
    ("typo.toml", GOOD.replace("depth", "dpeth"), "segment[1].dpeth"),
    ("top.toml", GOOD + "[extra]\na = 1\n", "extra"),
    ("probekey.toml", GOOD.replace('vertex = "probe"', 'vertex = "probe"\nnormall = [1, 0, 0]'), "probe.normall"),
    ("neg.toml", GOOD.replace("duration = 0.2", "duration = -0.2"), "segment[1].duration"),
    ("zero.toml", GOOD.replace("duration = 0.2", "duration = 0"), "segment[1].duration"),
    ("nan.toml", GOOD.replace("depth = 0.003", "depth = nan"), "segment[1].depth"),
    ("inf.toml", GOOD.replace('vertex = "probe"', "point = [0.0, inf, 0.0]"), "probe.point"),
    ("kind.toml", GOOD.replace('"press"', '"poke"'), "segment[1].kind"),
    ("missing.toml", GOOD.replace("depth = 0.003\n", ""), "segment[1].depth"),
    ("empty.toml", '[probe]\nvertex = "probe"\n', "segment"),
    ("both.toml", GOOD.replace('vertex = "probe"', 'vertex = "probe"\npoint = [0, 0, 0]'), "probe"),
    ("vertex.toml", GOOD.replace('"probe"\n', '"apex"\n'), "probe.vertex"),
    ("slide.toml", GOOD + '[[segment]]\nkind = "slide"\ndistance = 0.01\nduration = 1\n', "segment[2].direction"),
    ("zeronormal.toml", GOOD.replace('vertex = "probe"', 'vertex = "probe"\nnormal = [0, 0, 0]'), "probe.normal"),
    ("syntax.toml", "[probe\n", "invalid TOML"),
    ("header.csv", "time,x,y,z\n0,0,0,0\n1,0,0,0\n", "line 1"),
    ("nan.csv", "t,x,y,z\n0,0,0,0\n1,nan,0,0\n", "line 3: x"),
    ("back.csv", "t,x,y,z\n0,0,0,0\n1,0,0,0\n0.5,0,0,0\n", "line 4: t"),
    ("cols.csv", "t,x,y,z\n0,0,0\n", "line 2"),
    ("word.csv", "t,x,y,z\n0,0,0,0\n1,0,zero,0\n", "line 3: y"),
    ("empty.csv", "t,x,y,z\n# nothing\n", "empty script"),
    ("one.csv", "t,x,y,z\n0,0,0,0\n", "line 2"),
    ("script.txt", GOOD, ".toml"),
])
def test_bad_scripts_are_one_line_exit_1(tmp_path, capsys, name, text, where):
    p = _write(tmp_path, name, text)
    with pytest.raises(touch.ScriptError) as e:
        touch.parse_script(p)
    msg = str(e.value)
    assert name in msg and where in msg and "\n" not in msg, msg
    # The CLI: the same line on stderr, exit 1 (bad input), before any model is built.
    rc = main(["touch", "--shape", "ventricle", "--script", str(p), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith("palpate: error:") and where in err and err.count("\n") == 1, err
    assert "Traceback" not in err and not (tmp_path / "o").exists()


def test_slide_along_the_normal_is_refused(tmp_path):
    s = touch.parse_script_text('[probe]\npoint = [0, 0, 0]\nnormal = [0, 0, 1]\n[[segment]]\nkind = "slide"\n'
                                'direction = [0, 0, -1]\ndistance = 0.01\nduration = 1\n', "s.toml", "toml")
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    with pytest.raises(touch.ScriptError, match=r"s\.toml: segment\[1\]\.direction"):
        s.resolve(pts, np.array([[0, 1, 2]]), 0.005)


@pytest.mark.parametrize("args, what, code", [
    # usage (2): a flag's value outside its documented range, checked by the command
    (["--dt", "0"], "--dt", 2), (["--dt", "nan"], "--dt", 2), (["--tool-radius", "-1"], "--tool-radius", 2),
    (["--every", "0"], "--every", 2), (["--young", "-3"], "--young", 2),
    # bad input (1): a value palpate's Material refuses (MaterialError)
    (["--poisson", "0.7"], "material", 1),
    # bad input (1): a value most likely in the wrong unit, refused with --strict-units (issue 37)
    (["--young", "30", "--strict-units"], "typed in kPa? 30 kPa is 30000 Pa", 1),
    (["--tool-radius", "5", "--strict-units"], "5 mm is 0.005 m", 1),
])
def test_bad_options_exit_2_or_1(tmp_path, capsys, args, what, code):
    rc = main(["touch", "--shape", "ventricle", "--script", str(SCRIPTS / "press_release.csv"),
               "--out", str(tmp_path / "o"), *args])
    err = capsys.readouterr().err
    assert rc == code and what in err and err.count("\n") == 1, err


def test_model_or_shape_exactly_one(tmp_path, capsys, ventricle_file):
    csv_script = str(SCRIPTS / "press_release.csv")
    assert main(["touch", "--script", csv_script]) == 2                                        # usage
    assert main(["touch", str(ventricle_file), "--shape", "ventricle", "--script", csv_script]) == 2   # usage
    bad = _write(tmp_path, "bad.palpate", "not a model")
    assert main(["touch", str(bad), "--script", csv_script]) == 1                              # bad input
    assert "bad.palpate" in capsys.readouterr().err


# ----------------------------------------------------------------------------------------- runs

def _read_csv(path):
    with open(path) as fh:
        r = csv.reader(fh)
        header = next(r)
        rows = np.array([[float(v) for v in row] for row in r])
    return header, rows


def test_press_on_the_ventricle_writes_force_plot_and_series(tmp_path, capsys, ventricle_file):
    """A 3 mm press (CSV knots) on the ventricle, 300 ticks: the tissue pushes back once in contact."""
    script = _write(tmp_path, "press.csv", "t,x,y,z\n")
    m = palpate.HybridModel.load(str(ventricle_file))
    v = touch.probe_point(m.outer_points, m.outer_triangles)
    p, n = m.outer_points[v], touch.vertex_normals(m.outer_points, m.outer_triangles)[v]
    with open(script, "a") as fh:
        for t, depth in [(0.0, -0.002), (0.1, 0.0), (0.25, 0.003), (0.3, 0.003)]:
            c = p + n * (0.005 - depth)
            fh.write(f"{t}," + ",".join(repr(float(x)) for x in c) + "\n")
    out = tmp_path / "out"
    rc = main(["touch", str(ventricle_file), "--script", str(script), "--out", str(out), "--every", "50"])
    stdout = capsys.readouterr().out
    assert rc == 0, stdout
    assert "300 ticks" in stdout and "ticks/s" in stdout
    header, rows = _read_csv(out / "force.csv")
    assert tuple(header) == touch.COLUMNS
    assert rows.shape == (300, len(touch.COLUMNS))
    c = {k: i for i, k in enumerate(header)}
    np.testing.assert_allclose(rows[:, c["t"]], 1e-3 * np.arange(1, 301), rtol=1e-9)
    before = rows[:, c["depth"]] < -2e-4
    assert before.sum() > 50 and np.all(rows[before, c["f"]] == 0.0), "no force before contact"
    assert np.all(rows[before, c["contacts"]] == 0)
    deep = rows[:, c["depth"]] > 2.5e-3
    assert deep.sum() > 50
    assert np.all(rows[deep, c["fn"]] > 0.02), "the tissue must push the tool back out along the normal"
    assert np.all(rows[deep, c["fn"]] > 0.9 * rows[deep, c["f"]]), "the force should be mostly normal"
    assert rows[-1, c["depth"]] == pytest.approx(0.003, abs=1e-6)
    assert np.all(rows[deep, c["active"]] > 0) and np.all(rows[deep, c["contacts"]] > 0)
    np.testing.assert_allclose(rows[:, c["f"]], np.linalg.norm(rows[:, [c["fx"], c["fy"], c["fz"]]], axis=1),
                               rtol=1e-6, atol=1e-12)
    assert np.all(rows[:, c["tick_ms"]] > 0)
    assert (out / "force.png").stat().st_size > 10_000

    frames = read_pvd(out / "touch.pvd")
    times = sorted({t for t, _ in frames})
    assert times == pytest.approx([0.0] + [0.05 * k for k in range(1, 7)])
    n_active = [int(rows[round(t * 1e3) - 1, c["active"]]) if t > 0 else 0 for t in times]
    assert len(frames) == 3 * len(times) + sum(k > 0 for k in n_active)   # no active file while none is
    by_part = {}
    for t, f in frames:
        by_part.setdefault(f.rsplit("/", 1)[-1].split("_")[0], []).append(f)
    assert set(by_part) == {"surface", "core", "active", "tool"}
    surf = meshio.read(by_part["surface"][-1])
    assert surf.cells_dict["triangle"].shape == m.outer_triangles.shape
    assert np.abs(surf.point_data["displacement"]).max() > 1e-3, "the surface under the tool should move"
    assert meshio.read(by_part["core"][-1]).cells_dict["tetra"].shape[1] == 4
    act = meshio.read(by_part["active"][-1])
    assert act.cells_dict["vertex"].shape == (rows[-1, c["active"]], 1)
    assert len(by_part["active"]) == sum(k > 0 for k in n_active) and n_active[0] == 0
    tool = meshio.read(by_part["tool"][-1])
    np.testing.assert_allclose(tool.points[0], rows[-1, [c["x"], c["y"], c["z"]]], atol=1e-9)


class _Failing:
    """A HybridSim stand-in whose step raises StepError at tick ``fail_at``."""

    def __init__(self, sim, fail_at):
        self._sim, self._fail_at = sim, fail_at

    def step(self, c, dt=1e-3):
        if self._sim.ticks + 1 == self._fail_at:
            raise palpate.StepError("non-finite particle position (injected)")
        return self._sim.step(c, dt)

    def __getattr__(self, k):
        return getattr(self._sim, k)

    def __repr__(self):
        return repr(self._sim)


def test_step_error_exits_3_with_the_ticks_done(tmp_path, capsys, monkeypatch, ventricle_file):
    real = palpate._palpate.HybridSim
    monkeypatch.setattr(palpate._palpate, "HybridSim", lambda *a, **k: _Failing(real(*a, **k), 40))
    out = tmp_path / "out"
    rc = main(["touch", str(ventricle_file), "--script", str(SCRIPTS / "press_release.csv"), "--out", str(out)])
    cap = capsys.readouterr()
    assert rc == 3     # a run that failed after its input was accepted
    assert "tick 40" in cap.err and "injected" in cap.err and cap.err.count("\n") == 1
    header, rows = _read_csv(out / "force.csv")
    assert rows.shape == (39, len(touch.COLUMNS)) and rows[-1, 0] == pytest.approx(0.039)
    assert (out / "force.png").exists()
    assert read_pvd(out / "touch.pvd")     # the frame at t = 0 at least


def test_run_touch_api_on_tick_and_failure(tmp_path, ventricle_file):
    m = palpate.HybridModel.load(str(ventricle_file))
    mat = palpate.Material(young=3e4, poisson=0.4, density=1000.0)
    s = touch.parse_script_text('[probe]\nvertex = "probe"\ngap = 0.001\n[[segment]]\nkind = "press"\n'
                                'depth = 0.001\nduration = 0.05\n', "p.toml", "toml")
    seen = []
    summary = touch.run_touch(palpate.HybridSim(m, mat), s, tmp_path / "a", every=10, plot=False,
                              on_tick=lambda k, t, c, f: seen.append((k, t)))
    assert summary["ticks"] == 50 and summary["frames"] == 6 and summary["error"] is None
    assert seen[0] == (1, pytest.approx(1e-3)) and seen[-1][0] == 50
    assert summary["max_depth_m"] == pytest.approx(0.001) and math.isfinite(summary["ticks_per_s"])
    with pytest.raises(touch.TouchFailed) as e:
        touch.run_touch(_Failing(palpate.HybridSim(m, mat), 5), s, tmp_path / "b", plot=False)
    assert e.value.tick == 5 and e.value.summary["ticks"] == 4


def test_no_plot_is_claimed_without_matplotlib(tmp_path, ventricle_file, monkeypatch, capsys):
    # Issue 37: without matplotlib (an extra) the run wrote no force.png but said it had.
    import sys

    m = palpate.HybridModel.load(str(ventricle_file))
    mat = palpate.Material(young=3e4, poisson=0.4, density=1000.0)
    s = touch.parse_script_text('[probe]\nvertex = "probe"\ngap = 0.001\n[[segment]]\nkind = "press"\n'
                                'depth = 0.001\nduration = 0.01\n', "p.toml", "toml")
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # import matplotlib -> ImportError
    summary = touch.run_touch(palpate.HybridSim(m, mat), s, tmp_path, every=10)
    assert summary["png"] is None and not (tmp_path / "force.png").exists()
    assert "matplotlib not installed" in capsys.readouterr().out


def test_the_demos_touch_writes_a_preview_not_a_recording(tmp_path, ventricle_file, capsys):
    # Issue 37: make demo wrote 172 MB of VTU (100 frames of Rodero's skin); now 20 frames, and a
    # p99 over the 1 ms tick is said to be so.
    import argparse

    from palpate import demo

    models = {"ventricle": palpate.HybridModel.load(str(ventricle_file))}
    demo._touch(models, argparse.Namespace(out=str(tmp_path), no_plot=True))
    out = capsys.readouterr().out
    pvd = read_pvd(tmp_path / "touch_ventricle" / "touch.pvd")
    frames = len({t for t, _ in pvd})   # one entry per part of each frame
    assert demo.DEMO_FRAMES <= frames <= demo.DEMO_FRAMES + 1, frames
    p99 = float(out.split("p99 ")[1].split(" ms")[0])
    assert ("over the 1 ms tick" in out) == (p99 > 1.0), out
