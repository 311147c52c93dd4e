"""``palpate bench hybrid`` (palpate.bench_hybrid) and the demo's Table 1 hybrid rows (issue 12).

What a wrong implementation would do: report keys missing or of the wrong type (a None where a
number belongs, a numpy scalar JSON cannot write); calibrate a radius whose active count is far
from the target; time more than the step (the count of ticks would not match the script); call
a failed tick stable or exit 0 after one; accept a negative target or an unknown model.

Tolerance of the active count: the count is a step function of the tool radius (a region brings
its whole patch of particles), so the calibrated count is asserted within 25 % of the target or
one region's largest patch (``region_particles_max``), whichever is larger; the timed run's mean
within 50 % (a short script's slide leaves a trail of lingering regions behind the tool).

The small model is the paper's ellipsoids (``palpate.build_shape("ellipsoids")``: a 900-tet core,
~28,000 particles), built once per module; each calibration creates a few HybridSims (~0.6 s each).
"""
import json
import subprocess
import sys

import numpy as np
import pytest

import palpate
from palpate import bench_hybrid as bh
from palpate import demo

from conftest import REPO

TICKS = 120        # a gentle script: 3 mm over 30 ticks, slide 10 mm over 60 (0.17 mm a tick)
TARGET = 300

KEYS = {
    "model": str, "core_tets": int, "particles": int, "active_target": int, "tool_radius_m": float, "tool_area_stiffness": float,
    "active_particles_mean": float, "active_particles_max": int, "ticks": int, "tick_ms_mean": float,
    "tick_ms_p50": float, "tick_ms_p99": float, "tick_ms_max": float, "stable": bool, "max_force_n": float,
    "cpu_count": int, "python_version": str, "palpate_version": str, "date": str,
    "active_particles_calibrated": int, "ticks_per_s": float, "calibration": list,
    "force_ms_mean": float, "force_ms_p50": float, "force_ms_p99": float, "force_ms_max": float,
    "implicit_exchange": bool, "coupling_stiffness": float,
}


@pytest.fixture(scope="module")
def ellipsoids():
    return palpate.build_shape("ellipsoids")


@pytest.fixture(scope="module")
def report(ellipsoids):
    return bh.run(ellipsoids, TARGET, TICKS, name="ellipsoids")


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "palpate", "bench", "hybrid", *map(str, args)],
                          capture_output=True, text=True, cwd=REPO, timeout=300)


def test_report_keys_and_types(report):
    for k, t in KEYS.items():
        assert k in report, k
        assert isinstance(report[k], t), f"{k}: {type(report[k]).__name__}, expected {t.__name__}"
    json.loads(json.dumps(report))           # plain Python types only
    assert report["model"] == "ellipsoids" and 800 <= report["core_tets"] <= 1400
    assert report["ticks"] == TICKS == report["ticks_planned"]
    assert 0 < report["tick_ms_p50"] <= report["tick_ms_p99"] <= report["tick_ms_max"]
    assert report["tick_ms_mean"] <= report["tick_ms_max"]
    # The time to the force is a part of each tick's time.
    assert 0 < report["force_ms_p50"] <= report["force_ms_p99"] <= report["force_ms_max"] <= report["tick_ms_max"]
    assert report["force_ms_mean"] < report["tick_ms_mean"]
    assert report["active_particles_mean"] <= report["active_particles_max"] <= report["particles"]


def test_gentle_run_is_stable_and_touches(report):
    assert report["stable"] is True and report["error"] is None and report["failed_tick"] is None
    assert 0 < report["max_force_n"] < 5.0, "a 3 mm press should push back, gently"


def test_active_count_near_target(ellipsoids, report):
    tol = max(0.25 * TARGET, ellipsoids.info()["region_particles_max"])
    assert abs(report["active_particles_calibrated"] - TARGET) <= tol, report["calibration"]
    assert abs(report["active_particles_mean"] - TARGET) <= 0.5 * TARGET
    assert 5e-4 <= report["tool_radius_m"] <= 2e-2


def test_probe_is_on_the_outer_surface_facing_plus_x(ellipsoids):
    v, p, n_in, t = bh.probe(ellipsoids, "ellipsoids")
    assert np.allclose(p, ellipsoids.outer_points[v])
    assert p[0] > 0.025 and abs(p[2]) < 3e-3          # near the equator at +x (palpate.touch.probe_point)
    assert n_in[0] < -0.9 and abs(np.linalg.norm(n_in) - 1) < 1e-12 and abs(t @ n_in) < 1e-12


def test_script_phases():
    depth, slide, phase = bh.script(200)
    assert len(depth) == 200 and depth.max() == pytest.approx(bh.DEPTH) and slide.max() == pytest.approx(bh.SLIDE)
    assert list(np.unique(phase)) == [0, 1, 2, 3] and depth[-1] == 0.0
    assert np.abs(np.diff(depth)).max() <= bh.DEPTH / (0.15 * 200) + 1e-12   # the release, the fastest ramp
    with pytest.raises(ValueError):
        bh.script(bh.MIN_TICKS - 1)


def test_a_failed_tick_is_reported(ellipsoids, monkeypatch):
    real = bh._p.HybridSim

    class Failing:
        def __init__(self, *a, **k):
            self.sim, self.n = real(*a, **k), 0

        def step(self, c, dt, **kw):
            self.n += 1
            if self.n == 50:
                raise palpate.StepError("diverged (test)")
            return self.sim.step(c, dt, **kw)

        def __getattr__(self, k):
            return getattr(self.sim, k)

    monkeypatch.setattr(bh._p, "HybridSim", Failing)
    r = bh.run(ellipsoids, TARGET, 100, radius=3e-3, name="ellipsoids")
    assert r["stable"] is False and r["failed_tick"] == 49 and r["failed_phase"] == "slide"   # press 25, hold 10, slide 50, release 15
    assert "diverged (test)" in r["error"] and r["ticks"] == 49


def test_bad_arguments_are_refused(ellipsoids):
    with pytest.raises(ValueError):
        bh.run(ellipsoids, -5, TICKS)
    with pytest.raises(ValueError):
        bh.run("no-such-model", 200, TICKS)
    # Usage (2): the command line as written; bad input (1): a model that is not one.
    for args, code in [(("ellipsoids", "--active", -5), 2), (("ellipsoids", "--active", 0), 2),
                       (("no-such-model", "--active", 200), 1), ((REPO / "README.md", "--active", 200), 1),
                       (("ellipsoids", "--active", 200, "--ticks", 3), 2), (("ellipsoids",), 2)]:
        r = _cli(*args)
        assert r.returncode == code, (args, r.stdout, r.stderr)
        assert "Traceback" not in r.stderr and "error" in r.stderr


def test_cli_json_with_a_given_radius(tmp_path, ellipsoids):
    path = tmp_path / "ell.palpate"
    ellipsoids.save(path)                       # the model-file path of MODEL
    r = _cli(path, "--active", 200, "--radius", 3e-3, "--ticks", bh.MIN_TICKS, "--json")
    assert r.returncode == 0, r.stderr
    row = json.loads(r.stdout)
    assert row["model"] == "ell.palpate" and row["stable"] and row["tool_radius_m"] == 3e-3
    assert row["ticks"] == bh.MIN_TICKS and row["calibration"] == [[3e-3, row["active_particles_calibrated"]]]
    # The contact's default is 12 E*/min(R, 4h) for the bench's tissue; a given one is what runs.
    e_star = bh.material().young / (1 - bh.material().poisson ** 2)
    h = ellipsoids.spacing
    assert row["tool_area_stiffness"] == pytest.approx(12 * e_star / min(3e-3, 4 * h), rel=1e-12)
    r = _cli(path, "--active", 200, "--radius", 3e-3, "--ticks", bh.MIN_TICKS, "--json", "--tool-area-stiffness", 2e7)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["tool_area_stiffness"] == 2e7
    # The exchange: implicit by default (the springs at E h), capped with --explicit-exchange.
    assert row["implicit_exchange"] is True
    assert row["coupling_stiffness"] == pytest.approx(bh.material().young * h, rel=1e-12)
    r = _cli(path, "--active", 200, "--radius", 3e-3, "--ticks", bh.MIN_TICKS, "--json", "--explicit-exchange")
    assert r.returncode == 0, r.stderr
    capped = json.loads(r.stdout)
    assert capped["implicit_exchange"] is False and capped["coupling_stiffness"] < 0.5 * row["coupling_stiffness"]


def test_demo_hybrid_rows_reduced(ellipsoids, capsys):
    rows = demo.hybrid_rows(ellipsoids, shape="ellipsoids", ticks=bh.MIN_TICKS, rows=((TARGET, "average"),))
    out = capsys.readouterr().out
    assert len(rows) == 1 and rows[0]["stable"] and rows[0]["ticks"] == bh.MIN_TICKS
    assert "Table 1, hybrid rows" in out and "330-600 f/s (average)" in out
