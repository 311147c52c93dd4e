"""The ``palpate`` command line (also ``python -m palpate``): one module per command (``run``,
``bench``, ``build``, ``info``, ``touch``, ``haptic``, ``soak``, ``device``, ``devices``, ``view``, ``sweep``, ``fit``, ``validate``), shared helpers in ``_common``.

    palpate run SCENE.toml [--out DIR] [--steps N] [--quiet]
    palpate bench protocol MESH [--force F] [--steps N] [--json] [--integrator NAME] [--newton auto|on|off]
    palpate bench protocol --all [--force F] [--steps N] [--json] [--integrator NAME]
    palpate bench particles N [--spacing S] [--kernel wendland|cubic|lj] [--ticks T] [--json]
    palpate bench particles --all [...]
    palpate bench hybrid MODEL --active N [--ticks T] [--radius M] [--json]
    palpate build INNER OUTER -o MODEL [--unit m|cm|mm] [--quiet] [build options]
    palpate build --tagged SURFACE -o MODEL [--unit m|cm|mm] [--tag-array NAME] [--inner 1,2] [--outer 3]
                  [--base 4,5] [build options]
    palpate build --shape ellipsoids|ventricle|rodero -o MODEL [build options]
        build options: [--projection transmural|radial] [--core-fraction F] [--core-triangles N]
                       [--core-layers N] [--spacing M | --particles N] [--density RHO]
                       [--min-region-particles N] [--field-voxels N]
    palpate info MODEL                  (a palpate model file, written by palpate build)
    palpate info MESH [--unit m|cm|mm]  (a tet mesh file)
    palpate touch MODEL|--shape NAME --script SCRIPT.toml|SCRIPT.csv [--out DIR] [--every K] [--dt S]
                  [--tool-radius M] [--tool-area-stiffness K] [--young E] [--poisson NU] [--density RHO]
                  [--phi P] [--psi P] [--free] [--strict-units] [--quiet]
        (a scripted touch of a hybrid model: force.csv, force.png, touch.pvd; palpate/touch.py)
    palpate haptic MODEL --device scripted:SCRIPT|replay:FILE|bridge:PORT|hand [--rate HZ] [--seconds S]
                   [--record FILE] [--kind KIND] [--max-force N] [--host IP] [--quiet]
        (the haptic loop, headless, with a live status line; palpate/haptics.py)
    palpate soak MODEL --minutes N [--rate HZ] [--seed S] [--json]
    palpate bench haptic MODEL [--seconds S] [--rate HZ] [--no-idle] [--json]
    palpate bench view [MODEL] [--seconds S] [--rate HZ] [--fps HZ] [--json]
    palpate device geomagic|forcedimension|haply|hapticmaster [--port P] [--host IP] [--scale S] [--offset X Y Z]
        (a vendor device as a bridge client; each vendor SDK an optional extra)
    palpate devices [--json]
        (every device palpate can drive, what it needs, whether it is installed, its command)
    palpate view [MODEL] [--host IP] [--port N] [--device hand|bridge] [--bridge-port P] [--preset NAME]
                 [--tool-radius M] [--press-depth M] [--fps HZ] [--seconds S] [--screenshot OUT.png [--press M]]
                 [--token TOKEN] [--require-token]
        (the haptic loop in a browser, viser on 127.0.0.1; palpate/viewer/)
    palpate sweep SPEC.toml [--out DIR] [--workers N | --scheduler ADDRESS] [--resume] [--json] [--quiet]
        (a batch study on Dask: results.parquet, a row per scenario; palpate/sweep/)
    palpate fit SPEC.toml --measured CURVE.csv [--params young,poisson,phi,psi] [--plot PNG] [--workers N]
        (the material that reproduces a measured force-depth curve)
    palpate validate indentation ellipsoids|ventricle|rodero [--model FILE] [--tool-radius M] [--depths M ...] [--levels S:L ...]
                     [--coarse S:L] [--young E] [--poisson NU] [--law neo-hookean|svk] [--out DIR] [--quiet]
        (the hybrid's force and dent against the converged FEM of its wall; palpate/validate.py)

Long work (a model build, a scene run, a touch, a benchmark sweep) shows a progress display on
stderr when it is a terminal, nothing otherwise; ``--quiet`` (run, build, touch, bench protocol,
particles and hybrid) turns it off there too.

Exit codes (the table is ``_common.EXIT_CODES``; ``palpate --help`` prints it): 0 success, 1 bad
input (a file, model, parameter or value palpate refused), 2 usage (the command line as written),
3 a run that failed after its input was accepted (a step diverged, an output could not be
written, ...), 130 Ctrl-C; with one line on stderr and no traceback. A closed stdout ends quietly.
"""
from __future__ import annotations

import argparse
import sys
from typing import List, Optional

from .. import __version__
from . import bench, build, device, devices, fit, haptic, info, run, soak, sweep, touch, validate, view
from ._common import CLOSED_PIPE, EXIT_CODES_HELP, OK, Fail, GuardedStdout, Parser, interrupted, quiet_pipe, run_guarded

#: The commands, in the order of ``palpate --help``: each module adds its parser and handler.
COMMANDS = (run, bench, build, info, touch, haptic, soak, device, devices, view, sweep, fit, validate)


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(prog="palpate", description="Real-time soft-tissue FEM for haptic interaction (SI units).",
                epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"palpate {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for command in COMMANDS:
        command.add_parser(sub)
    return ap


def main(argv: Optional[List[str]] = None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:   # Ctrl-C outside a command (parsing); a command's own is run_guarded's
        return interrupted()


def _main(argv: Optional[List[str]]) -> int:
    ap = build_parser()
    try:
        a = ap.parse_args(argv)
    except SystemExit as e:  # --help / --version print to stdout, which may be a closed pipe
        code = e.code if isinstance(e.code, int) else 0
        return _flushed(code)
    except BrokenPipeError:
        return quiet_pipe()
    if getattr(a, "steps", None) is not None and a.steps <= 0:
        ap.error("--steps must be positive")
    from .. import _progress
    _progress.set_quiet(getattr(a, "quiet", False))   # each call: main may run more than once in a process
    import warnings

    def one_line(message, category, filename, lineno, file=None, line=None):
        # A warning is one line too (`palpate: warning: ...`), not Python's two-line format with
        # the source line.
        print(f"palpate: warning: {' '.join(str(message).split())}", file=sys.stderr)

    # A closed stdout never ends the command's work (issue 35 item 7): its prints are dropped from
    # then on, and a command that otherwise succeeded ends with 141 (128 + SIGPIPE), as Unix tools
    # killed by SIGPIPE do; one that failed keeps its own code.
    out = sys.stdout = GuardedStdout(sys.stdout)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = one_line
            code = _flushed(run_guarded(lambda: a.func(a)))
    finally:
        sys.stdout = out._stream
    return CLOSED_PIPE if out.closed_pipe and code == OK else code


def _flushed(code: int) -> int:
    """Flush stdout now, so that a reader that closed the pipe early (``| head``) ends the
    command quietly here rather than in Python's exit handler with a traceback."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return quiet_pipe()
    return code
