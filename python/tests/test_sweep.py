"""Batch studies (issue 17): palpate.sweep on Dask and palpate fit.

The cluster's table must equal the in-process one (every column but the timing), a failing
scenario is a row, a killed study resumes without redoing its finished scenarios, a lost worker's
task is re-run, the model reaches each worker once, and a fit recovers a known modulus."""
from __future__ import annotations

import json
import re
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("pyarrow")
import palpate  # noqa: E402
import palpate.sweep as ps  # noqa: E402
from palpate.sweep import runner as sweep_runner  # noqa: E402
from palpate.sweep.fit import FitError, fit  # noqa: E402

distributed = pytest.importorskip("distributed")

HAVE_MATPLOTLIB = __import__("importlib.util").util.find_spec("matplotlib") is not None
PNG = b"\x89PNG\r\n\x1a\n"

#: A small probe study on the generated 192-tet ellipsoid wall: 2 x 2 x 2 = 8 scenarios, one of
#: them (40 N on a soft wall) past the stability limit.
STUDY = {
    "study": {"name": "t"},
    "model": {"mesh": "ellipsoid_192"},
    "loading": {"kind": "probe", "steps": 120},
    "parameters": {"young": {"grid": [2.0e4, 4.0e4], "num": 2, "scale": "log"}, "poisson": [0.3, 0.45],
                   "force": [0.2, 40.0]},
}


def timeless(rows):
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


@pytest.fixture(scope="module")
def sequential(tmp_path_factory):
    return ps.sweep(STUDY, tmp_path_factory.mktemp("seq") / "out", workers=0)


def test_the_spec_expands_in_order_and_its_draws_are_seeded():
    sp = ps.spec_from_dict(STUDY)
    sc = sp.scenarios()
    assert len(sc) == 8 and [s["scenario"] for s in sc] == list(range(8))
    # The last parameter varies fastest; the loading's fixed values fill the rest.
    assert [s["force"] for s in sc[:2]] == [0.2, 40.0] and sc[0]["steps"] == 120 and sc[0]["density"] == 1000.0
    rnd = dict(STUDY, study={"seed": 3, "samples": 4}, parameters={"young": {"random": "loguniform", "low": 1e4, "high": 1e5}})
    a, b = ps.spec_from_dict(rnd).scenarios(), ps.spec_from_dict(rnd).scenarios()
    assert a == b and len({s["young"] for s in a}) == 4 and all(1e4 <= s["young"] <= 1e5 for s in a)
    other = ps.spec_from_dict(dict(rnd, study={"seed": 4, "samples": 4})).scenarios()
    assert [s["young"] for s in other] != [s["young"] for s in a]


@pytest.mark.parametrize("change, key", [
    ({"loading": {"kind": "poke"}}, "loading.kind"),
    ({"parameters": {"young": []}}, "parameters.young"),
    ({"parameters": {"young": {"grid": [1e4], "num": 3}}}, "parameters.young.grid"),
    ({"parameters": {"young": {"grid": [1e4, 2e4]}}}, "parameters.young.num"),
    ({"parameters": {"poisson": [0.3, 0.5]}}, "parameters.poisson[1]"),
    ({"parameters": {"stiffness": [1.0]}}, "parameters.stiffness"),
    ({"parameters": {"young": {"random": "uniform", "low": 1e4, "high": 2e4}}}, "study.samples"),
    ({"parameters": {"young": {"random": "gamma", "low": 1, "high": 2}}}, "parameters.young.random"),
    ({"parameters": {"integrator": ["euler"]}}, "parameters.integrator[0]"),
    ({"model": {"mesh": "no_such_mesh.msh"}}, "model.mesh"),
    ({"model": {"hybrid": "ventricle"}}, "model.hybrid"),
    ({"outputs": {"curve": "yes"}}, "outputs.curve"),
    ({"study": {"seed": -1}}, "study.seed"),
    ({"loading": {"kind": "probe", "dt": 0.0}}, "loading.dt"),
    ({"parameters": {"young": {"grid": [1e4, 2e4], "num": 10**9}}}, "parameters.young.num"),
    ({"parameters": {"young": [1e4] * 1001, "poisson": [0.3] * 1001}}, "more than"),
])
def test_a_bad_spec_names_the_key(change, key):
    doc = dict(STUDY, **change)
    with pytest.raises(ps.SweepSpecError, match=key.replace("[", r"\[").replace("]", r"\]")):
        ps.spec_from_dict(doc, name="spec.toml")


def test_two_local_workers_give_the_in_process_table(sequential, tmp_path):
    r = ps.sweep(STUDY, tmp_path / "out", workers=2)
    assert r.done == 8 and r.ran == 8
    assert timeless(r.rows()) == timeless(sequential.rows())
    rows = sequential.rows()
    assert [x["status"] for x in rows].count("unstable") >= 1 and [x["status"] for x in rows].count("ok") >= 4
    ok = [x for x in rows if x["status"] == "ok"]
    # Physics the table must show: stiffer walls press in less at the same force.
    soft = [x["final_depth_m"] for x in ok if x["young"] < 3e4 and x["force"] == 0.2 and x["poisson"] == 0.3]
    stiff = [x["final_depth_m"] for x in ok if x["young"] > 3e4 and x["force"] == 0.2 and x["poisson"] == 0.3]
    assert soft[0] > 1.5 * stiff[0]
    assert len(rows[0]["curve_force_n"]) == 120 and rows[0]["curve_force_n"][-1] == pytest.approx(0.2)
    m = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert m["state"] == "complete" and m["scenarios"] == 8 and m["palpate_version"] == palpate.__version__
    assert m["spec_digest"] == ps.spec_from_dict(STUDY).digest() and len(m["model_hash"]) == 16
    assert list((tmp_path / "out" / "parts").glob("part-*.parquet"))


def test_short_scenarios_go_in_batches_that_taper_at_the_tail():
    b = sweep_runner.batch_size
    assert b([], 64, 2) == 1                        # nothing timed yet: one at a time
    assert b([0.1, 0.094, 0.3], 24, 2) == 3         # but four tasks a worker in the tail
    assert b([0.2, 0.25, 0.3], 200, 2) == 4         # 1 s of the median 0.25 s
    assert b([0.1] * 8, 20, 2) == 2                 # every worker keeps four tasks of the tail
    assert b([0.1] * 8, 3, 2) == 1 and b([0.1], 0, 2) == 0
    assert b([30.0], 500, 8) == 1                   # long scenarios: one a task


def test_batched_tasks_give_the_same_table_and_a_lost_batch_is_retried_whole(sequential, tmp_path, monkeypatch):
    from palpate.sweep import scenario
    monkeypatch.setattr(sweep_runner, "batch_size", lambda walls, remaining, n: min(3, remaining))
    marker = tmp_path / "crashed"
    monkeypatch.setenv(scenario.CRASH_ONCE_ENV, str(marker))
    r = ps.sweep(STUDY, tmp_path / "out", workers=2)
    assert marker.exists()   # the first batch's worker killed itself on scenario 0
    assert r.done == 8 and timeless(r.rows()) == timeless(sequential.rows())


def test_a_failing_scenario_is_a_row_not_a_crashed_study(tmp_path):
    # Normal draws of Young's modulus around 0: the negative ones are refused by the material.
    doc = dict(STUDY, study={"seed": 1, "samples": 6}, parameters={"young": {"random": "normal", "mean": 1e4, "std": 3e4}})
    r = ps.sweep(doc, tmp_path / "out", workers=0)
    rows = r.rows()
    bad = [x for x in rows if x["young"] <= 0]
    assert bad and len(bad) < len(rows)
    assert all(x["status"] == "failed" and "MaterialError" in x["error"] for x in bad)
    assert all(x["status"] in ("ok", "unstable") and x["error"] is None or x["status"] == "unstable" for x in rows if x["young"] > 0)
    assert r.failed == len(bad)


def test_a_killed_study_resumes_without_redoing_its_finished_scenarios(sequential, tmp_path, monkeypatch):
    monkeypatch.setattr(sweep_runner, "PART_ROWS", 2)
    real = sweep_runner.run_scenario
    calls = {"n": 0}

    def dies_on_the_sixth(*a, **k):
        calls["n"] += 1
        if calls["n"] == 6:
            raise KeyboardInterrupt   # the user's ^C, or a killed process: rows not in a part are lost
        return real(*a, **k)
    monkeypatch.setattr(sweep_runner, "run_scenario", dies_on_the_sixth)
    with pytest.raises(KeyboardInterrupt):
        ps.sweep(STUDY, tmp_path / "out", workers=0)
    assert json.loads((tmp_path / "out" / "manifest.json").read_text())["state"] == "running"
    with pytest.raises(ps.SweepError, match="--resume"):
        ps.sweep(STUDY, tmp_path / "out", workers=0)
    ran = []
    monkeypatch.setattr(sweep_runner, "run_scenario", lambda p, s, *a, **k: (ran.append(s["scenario"]), real(p, s, *a, **k))[1])
    r = ps.sweep(STUDY, tmp_path / "out", workers=0, resume=True)
    assert sorted(ran) == [4, 5, 6, 7] and r.ran == 4   # two parts of two rows were written before the kill
    assert timeless(r.rows()) == timeless(sequential.rows())
    # Another study in the same folder is refused, even with resume.
    other = dict(STUDY, loading={"kind": "probe", "steps": 100})
    with pytest.raises(ps.SweepError, match="another study"):
        ps.sweep(other, tmp_path / "out", workers=0, resume=True)


def test_a_lost_worker_is_retried_and_the_model_reaches_each_worker_once(sequential, tmp_path, monkeypatch):
    from distributed import Client, LocalCluster
    from palpate.sweep import scenario

    marker = tmp_path / "crashed"
    monkeypatch.setenv(scenario.CRASH_ONCE_ENV, str(marker))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        r = ps.sweep(STUDY, tmp_path / "out", client=client)
        assert marker.exists()   # scenario 0's first worker killed itself
        assert timeless(r.rows()) == timeless(sequential.rows())
        counts = client.run(lambda: __import__("palpate.sweep.scenario", fromlist=["x"]).UNPICKLED)
    # One copy of the model per worker (a restarted worker gets it again), never one per task.
    assert all(c <= 1 for c in counts.values()), counts


@pytest.mark.parametrize("mesh", ["ellipsoid_192", "190"])
def test_fit_recovers_a_known_modulus_within_its_confidence_interval(tmp_path, mesh, request):
    if mesh != "ellipsoid_192":
        request.getfixturevalue("shared")   # skips without the shared bench meshes
    spec = {"study": {"name": "fit"}, "model": {"mesh": mesh},
            "loading": {"kind": "probe", "steps": 110, "young": 3.0e4}}
    sp = ps.spec_from_dict(spec)
    truth = dict(sp.loading, young=3.7e4, scenario=0)
    with sweep_runner.Runner(sweep_runner.model_payload(sp), workers=0) as run:
        row = run.map([truth])[0]
    d, f = np.array(row["curve_depth_m"]), np.array(row["curve_force_n"])
    k = np.arange(9, 100, 10)
    measured = np.column_stack([d[k], f[k]])
    measured[:, 0] *= 1 + 0.01 * np.random.default_rng(1).standard_normal(len(k))   # 1% noise
    r = fit(sp, measured, ["young"], workers=0, plot=str(tmp_path / "fit.png"))
    assert r.values["young"] == pytest.approx(3.7e4, rel=0.01)
    lo, hi = r.ci95["young"]
    assert lo < 3.7e4 < hi and hi / lo < 1.05
    assert r.coarse_best["young"] != pytest.approx(3.7e4, rel=0.01)   # the refinement did the work
    assert (tmp_path / "fit.png").stat().st_size > 1000
    with pytest.raises(FitError, match="cannot fit"):
        fit(sp, measured, ["density"], workers=0)
    with pytest.raises(FitError, match="m >= 3"):
        fit(sp, measured[:2], ["young"], workers=0)


def test_fields_go_to_the_companion_store(tmp_path):
    doc = dict(STUDY, parameters={"young": [3e4, 4e4]}, outputs={"field": True, "curve": False})
    r = ps.sweep(doc, tmp_path / "out", workers=0)
    assert "curve_force_n" not in r.table.column_names
    u = [np.load(tmp_path / "out" / "fields" / f"{k:07d}.npy") for k in range(2)]
    assert u[0].shape == (54, 3) and np.isfinite(u[0]).all()
    # The stiffer wall moves less; the field is the displacement [m] the row's max_disp_m measures.
    assert np.linalg.norm(u[1], axis=1).max() < np.linalg.norm(u[0], axis=1).max()
    assert np.linalg.norm(u[0], axis=1).max() == pytest.approx(r.rows()[0]["max_disp_m"], rel=0.5)


def test_the_press_loading_runs_on_a_hybrid_model(tmp_path):
    doc = {"study": {"name": "press"}, "model": {"hybrid": "ventricle"},
           "loading": {"kind": "press", "depth": 0.002, "duration": 0.04, "hold": 0.0},
           "parameters": {"young": [2e4, 6e4]}}
    r = ps.sweep(doc, tmp_path / "out", workers=0)
    soft, stiff = r.rows()
    assert soft["status"] == stiff["status"] == "ok", (soft["error"], stiff["error"])
    assert 0 < soft["max_force_n"] < stiff["max_force_n"]
    assert soft["curve_depth_m"][-1] == pytest.approx(0.002, rel=1e-6)


def run_cli(*args, cwd):
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    return subprocess.run([sys.executable, "-m", "palpate", *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


def test_the_cli_runs_a_study_and_a_fit_and_refuses_a_bad_spec_in_one_line(tmp_path):
    (tmp_path / "s.toml").write_text(
        '[study]\nname = "cli"\n[model]\nmesh = "ellipsoid_192"\n[loading]\nkind = "probe"\nsteps = 110\n'
        '[parameters]\nyoung = [3e4, 3.5e4]\n')
    p = run_cli("sweep", "s.toml", "--out", "o", "--workers", "0", "--json", "--no-plot", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["scenarios"] == 2 and out["failed"] == 0 and (tmp_path / "o" / "results.parquet").exists()
    assert out["plot"] is None and not (tmp_path / "o" / "results.png").exists()
    import pyarrow.parquet as pq
    row = pq.read_table(tmp_path / "o" / "results.parquet").to_pylist()[1]
    with open(tmp_path / "m.csv", "w") as fh:
        fh.write("depth_m,force_n\n")
        for d, f in list(zip(row["curve_depth_m"], row["curve_force_n"]))[9:100:10]:
            fh.write(f"{d!r},{f!r}\n")
    # Without --json: a table of the rows, and a CSV any reader can open (issue 37: one line, and
    # Parquet only, which needs pyarrow or pandas).
    p = run_cli("sweep", "s.toml", "--out", "o2", "--workers", "0", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert re.search(r"scenario +young +status +max_force_n", p.stdout) and "results.csv" in p.stdout, p.stdout
    if HAVE_MATPLOTLIB:   # the plot's path on the line that names the tables (issue 37)
        assert re.search(r"results\.csv .*; the plot: \S*results\.png", p.stdout), p.stdout
        assert (tmp_path / "o2" / "results.png").read_bytes().startswith(PNG)
    import csv
    with open(tmp_path / "o2" / "results.csv") as fh:
        got = list(csv.DictReader(fh))
    assert [float(g["young"]) for g in got] == [3e4, 3.5e4] and "curve_force_n" not in got[0]
    assert float(got[1]["max_force_n"]) == pytest.approx(row["max_force_n"])
    p = run_cli("fit", "s.toml", "--measured", "m.csv", "--workers", "0", "--json", "--plot", "f.png", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["values"]["young"] == pytest.approx(3.5e4, rel=1e-3)
    (tmp_path / "bad.toml").write_text('[model]\nmesh = "ellipsoid_192"\n[loading]\nkind = "probe"\nstep = 3\n')
    p = run_cli("sweep", "bad.toml", "--workers", "0", cwd=tmp_path)
    assert p.returncode == 1 and p.stderr.count("\n") == 1 and "loading.step" in p.stderr, p.stderr


def test_bench_sweep_reports_its_keys(tmp_path):
    from palpate.sweep import bench as sb
    p = run_cli("bench", "sweep", "ellipsoid_192", "--scenarios", "4", "--steps", "20", "--repeat", "2", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert set(sb.KEYS) <= set(r) and r["scenarios"] == 4 and r["repeat"] == 2 and r["worker2_s"] > 0 and r["startup_s"] > 0
    assert r["bare2_s"] > 0 and r["cluster_start_stop_s"] > 0


@pytest.mark.parametrize("make, expect", [
    (lambda d: "missing.toml", "SweepSpecError: missing.toml: no such file"),
    (lambda d: str(d), "is a directory"),
    (lambda d: (d / "bin.toml").write_bytes(bytes(range(256)) * 4) and "bin.toml", "not a text file"),
    (lambda d: (d / "x.toml").write_text("[model\nmesh=1") and "x.toml", "not valid TOML"),
    (lambda d: (d / "y.toml").write_text('[model]\nmesh = "ellipsoid_192"\n[loading]\nkind = "probe"\n'
                                         '[parameters]\nyoung = { grid = [1e4, 2e4], num = 1e9 }\n') and "y.toml",
     "parameters.young.num: must be a whole number"),
])
def test_a_bad_study_file_is_one_line_and_exit_1(tmp_path, make, expect):
    p = run_cli("sweep", make(tmp_path), "--workers", "0", cwd=tmp_path)
    assert p.returncode == 1 and p.stderr.count("\n") == 1 and expect in p.stderr, p.stderr


def test_the_press_can_follow_a_touch_script(tmp_path):
    import shutil
    from pathlib import Path
    src = Path(__file__).resolve().parents[2] / "examples" / "scripts" / "press_release.csv"
    shutil.copy(src, tmp_path / "path.csv")
    doc = {"model": {"hybrid": "ventricle"}, "loading": {"kind": "press", "script": "path.csv"},
           "parameters": {"young": [3e4]}}
    sp = ps.spec_from_dict(doc, base=tmp_path)
    assert "depth" not in sp.loading and sp.script == str((tmp_path / "path.csv").resolve())
    r = ps.sweep(sp, tmp_path / "out", workers=0)
    row, = r.rows()
    assert row["status"] == "ok", row["error"]
    assert row["max_force_n"] > 0 and max(row["curve_depth_m"]) > 0
    with pytest.raises(ps.SweepSpecError, match="loading.depth"):
        ps.spec_from_dict(dict(doc, loading={"kind": "press", "script": "path.csv", "depth": 0.003}), base=tmp_path)
    (tmp_path / "bad.toml").write_text("[[segment]]\nkind = \"poke\"\n")
    with pytest.raises(ps.SweepSpecError, match="loading.script"):
        ps.spec_from_dict(dict(doc, loading={"kind": "press", "script": "bad.toml"}), base=tmp_path)


def test_a_fit_without_matplotlib_keeps_its_values(tmp_path, monkeypatch, capsys):
    # Issue 37: without matplotlib the fit computed, then crashed on its plot and lost the value.
    sp = ps.spec_from_dict({"study": {"name": "fit"}, "model": {"mesh": "ellipsoid_192"},
                            "loading": {"kind": "probe", "steps": 110, "young": 3.0e4}})
    with sweep_runner.Runner(sweep_runner.model_payload(sp), workers=0) as run:
        row = run.map([dict(sp.loading, young=3.7e4, scenario=0)])[0]
    k = np.arange(9, 100, 10)
    measured = np.column_stack([np.array(row["curve_depth_m"])[k], np.array(row["curve_force_n"])[k]])
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # import matplotlib -> ImportError
    r = fit(sp, measured, ["young"], workers=0, plot=str(tmp_path / "fit.png"))
    assert r.values["young"] == pytest.approx(3.7e4, rel=0.01) and r.plot is None
    assert not (tmp_path / "fit.png").exists()
    assert "matplotlib not installed" in capsys.readouterr().err


def test_a_study_plots_its_curves_beside_the_table(sequential, tmp_path):
    # Issue 37: the study's results summarised with a plot, results.png beside results.parquet.
    pytest.importorskip("matplotlib", reason="the plot needs the plot extra")
    from palpate.sweep import plot as sweep_plot
    png = sequential.path.parent / "results.png"
    assert sequential.plot == png and png.read_bytes().startswith(PNG) and png.stat().st_size > 10_000
    assert sweep_plot.label(sequential.rows()[1], ["young", "force"]) == "young = 2e+04 Pa, force = 40 N"
    # Without curves: the main outcome against the first varied parameter; plot=False: none.
    doc = dict(STUDY, parameters={"young": [2e4, 3e4, 4e4]}, loading={"kind": "probe", "steps": 40},
               outputs={"curve": False})
    r = ps.sweep(doc, tmp_path / "flat", workers=0)
    assert r.plot == tmp_path / "flat" / "results.png" and r.plot.read_bytes().startswith(PNG)
    r = ps.sweep(doc, tmp_path / "none", workers=0, plot=False)
    assert r.plot is None and not (tmp_path / "none" / "results.png").exists()
    assert sorted(p.name for p in (tmp_path / "none").iterdir()) == ["manifest.json", "parts", "results.csv", "results.parquet"]


def test_a_study_without_matplotlib_keeps_its_results_and_says_so(tmp_path, monkeypatch, capsys):
    # matplotlib is an extra (plot): the table is written, the plot is not, and a note names the extra.
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # import matplotlib -> ImportError
    doc = dict(STUDY, parameters={"young": [2e4, 4e4]}, loading={"kind": "probe", "steps": 40})
    r = ps.sweep(doc, tmp_path / "out", workers=0)
    assert r.done == 2 and r.plot is None and [x["status"] for x in r.rows()] == ["ok", "ok"]
    assert (tmp_path / "out" / "results.parquet").exists() and (tmp_path / "out" / "results.csv").exists()
    assert not (tmp_path / "out" / "results.png").exists()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "matplotlib not installed: no results.png" in err and "the plot extra" in err, err
