"""What the commands share: the exit codes and the errors that end a command with one, number
formats, and the description of a hybrid model (``palpate build`` and ``palpate info``)."""
from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Callable, List, Optional, Tuple

# The exit codes: the CLI's contract, kept here only (README "Exit codes", palpate --help's epilog
# and RELIABILITY.md show this table). A command ends with one line on stderr for each code but 0.
OK = 0
#: Bad input: a file, a model, a parameter or a value that palpate refused (every PalpateError
#: from input), or an input file that cannot be read.
INPUT = 1
#: Usage: the command line as written: what argparse refuses (an unknown option, a missing or
#: malformed argument) and the commands' own checks of their flags (conflicting or missing flags,
#: a flag's value outside its documented range), made before any input is read.
USAGE = 2
#: A run that failed after its input was accepted: a step diverged, a solve failed, a tick of a
#: touch failed, a haptic device was lost (faults), an output could not be written, a data set
#: could not be fetched, an optional package or a browser is missing, or a palpate bug.
FAILED = 3
#: Ctrl-C (128 + SIGINT): one line, ``palpate: interrupted``.
INTERRUPTED = 130
#: stdout closed by its reader (``palpate ... | head``): quiet, 128 + SIGPIPE as Unix tools.
CLOSED_PIPE = 141

#: The exit code of each kind of error that ends a command: (class, code), the first match wins.
#: Names only, resolved on first use (the parser must build without importing the extension).
EXIT_CODES: Tuple[Tuple[str, int], ...] = (
    ("palpate.StepError", FAILED),          # a step went non-finite or diverged
    ("palpate.SolveError", FAILED),         # a static solve that did not converge
    ("palpate.touch.TouchFailed", FAILED),  # a tick of a scripted touch failed
    ("palpate.data.DataError", FAILED),     # a data set that could not be fetched
    ("palpate.InternalError", FAILED),      # a palpate bug caught at the binding
    ("palpate.PalpateError", INPUT),        # every other palpate error: the input was refused
    ("builtins.OSError", INPUT),            # an input file that cannot be read (writes: RunFailed)
    ("builtins.MemoryError", FAILED),       # out of memory past the budget's checks
)

#: The table as ``palpate --help`` and the README show it.
EXIT_CODES_HELP = f"""\
exit codes:
  {OK}    success
  {INPUT}    bad input: a file, model, parameter or value palpate refused
       (MeshError, ModelFileError, MaterialError, ParameterError, LimitError,
       SceneError, ...), or an input file that cannot be read
  {USAGE}    usage: an unknown option, a missing or malformed argument,
       conflicting flags, a flag's value outside its documented range
  {FAILED}    the run failed after its input was accepted: a step diverged
       (StepError), a solve failed (SolveError), a touch's tick failed,
       haptic faults (a device lost), an output could not be written, a data
       set could not be fetched, an optional package is missing, a palpate bug
  {INTERRUPTED}  interrupted (Ctrl-C)
  {CLOSED_PIPE}  stdout closed by its reader (palpate ... | head), quietly
every failure is one line on stderr (palpate: error: ...), never a traceback."""


def _resolve(name: str) -> type:
    import importlib

    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def exit_code(e: BaseException) -> Optional[int]:
    """The exit code of ``e`` by :data:`EXIT_CODES` (a :class:`Fail` carries its own), or None for
    an exception the table does not know (a bug: the caller reports it as an internal error)."""
    if isinstance(e, Fail):
        return e.code
    for name, code in EXIT_CODES:
        if isinstance(e, _resolve(name)):
            return code
    return None


class Fail(Exception):
    """Ends a command: one line on stderr (``palpate: error: ...``) and exit :data:`INPUT` (bad
    input); with ``cause`` (the library error it reports), the code :data:`EXIT_CODES` gives that
    error, where the table knows it."""

    code = INPUT

    def __init__(self, msg: str, cause: Optional[BaseException] = None):
        super().__init__(msg)
        code = None if cause is None else exit_code(cause)
        if code is not None:
            self.code = code


class Usage(Fail):
    """A command line that cannot run as written (a command's own check of its flags): exit
    :data:`USAGE`, as argparse's own errors."""

    code = USAGE


class RunFailed(Fail):
    """A run that failed after its input was accepted (an output that cannot be written, a missing
    optional package, faults): exit :data:`FAILED`."""

    code = FAILED


class Parser(argparse.ArgumentParser):
    """argparse with the CLI's one-line errors: ``palpate: error: ...`` and exit 2 (usage),
    instead of argparse's usage block followed by the error."""

    def error(self, message: str):
        self.exit(USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def run_guarded(func: Callable[[], int]) -> int:
    """Run a command so that whatever it raises ends as one line on stderr and an exit code by
    :data:`EXIT_CODES`, never a traceback: :class:`Fail` with its code, a palpate error, an
    unreadable file (OSError) or MemoryError by the table; Ctrl-C 130; anything else is a bug:
    :data:`FAILED`, one line saying so (``PALPATE_DEBUG=1`` shows the traceback). A closed stdout
    (``palpate ... | head``) ends quietly."""
    from .. import _palpate as _p

    def say(msg: str, code: int) -> int:
        print(f"palpate: error: {' '.join(str(msg).split())}", file=sys.stderr)
        return code

    try:
        return func()
    except Fail as e:
        return say(str(e), e.code)
    except BrokenPipeError:
        return quiet_pipe()
    except KeyboardInterrupt:
        return interrupted()
    except _p.PalpateError as e:
        return say(f"{type(e).__name__}: {e}", exit_code(e))
    except OSError as e:
        return say(f"{e.filename + ': ' if getattr(e, 'filename', None) else ''}{e.strerror or e}", exit_code(e))
    except MemoryError as e:
        return say("out of memory (lower the input's size, or see PALPATE_MAX_MEMORY)", exit_code(e))
    except Exception as e:  # noqa: BLE001 - the promise is one line, never a traceback
        if os.environ.get("PALPATE_DEBUG"):
            raise
        return say(f"internal error ({type(e).__name__}: {e}); please report it (PALPATE_DEBUG=1 shows the traceback)", FAILED)


def interrupted() -> int:
    """Ctrl-C: one line on stderr and :data:`INTERRUPTED`, no traceback."""
    try:
        print("palpate: interrupted", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass
    return INTERRUPTED


class GuardedStdout:
    """``sys.stdout`` while a command runs: a write or flush that finds the reader gone (EPIPE:
    ``palpate build ... | head -c 0``) points stdout at /dev/null, as Python's documentation on
    SIGPIPE recommends, and the command goes on with its real work (the files it writes) instead of
    ending at its first print (issue 35 item 7). :attr:`closed_pipe` tells the caller to end with
    :data:`CLOSED_PIPE`. Everything else is the wrapped stream's."""

    def __init__(self, stream):
        self._stream = stream
        self.closed_pipe = False

    def _closed(self) -> None:
        self.closed_pipe = True
        quiet_pipe()

    def write(self, text: str) -> int:
        if not self.closed_pipe:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._closed()
        return len(text)   # the reader has gone: the text is dropped with it

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._closed()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def quiet_pipe() -> int:
    """stdout was closed by the reader (``| head``): point it at /dev/null so that Python's own
    flush at exit does not print a BrokenPipeError, and end with 141 (128 + SIGPIPE), as Unix
    tools killed by SIGPIPE do."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
    return CLOSED_PIPE


#: The physics thread's rate [Hz] of the commands' haptic loops (``palpate haptic``, ``view``,
#: ``soak``, ``bench haptic``): the multirate loop, whose servo never waits for the physics. On the
#: Rodero palpation on the project's 2-core VM (BENCHMARKS.md, 2026-12-06) the single-rate loop
#: missed 32,832 of 60,000 periods a minute at 1 kHz, the multirate loop 15 (the idle loop 1).
DEFAULT_PHYSICS_RATE_HZ = 1000.0


def add_physics_rate(parser) -> None:
    """``--physics-rate HZ`` and ``--single-rate`` (see :func:`physics_rate`)."""
    g = parser.add_mutually_exclusive_group()
    g.add_argument("--physics-rate", type=float, default=None, metavar="HZ",
                   help=f"the physics thread's rate (default {DEFAULT_PHYSICS_RATE_HZ:g} Hz, or --rate if lower; 100 to "
                        "--rate): the servo renders every period from the local model (force and stiffness at the "
                        "tool) the physics publishes after each tick, and never waits for it")
    g.add_argument("--single-rate", action="store_true",
                   help="one physics tick inside every servo period instead (a slow tick is a missed period; for "
                        "comparison)")


def physics_rate(a, cmd: str) -> Optional[float]:
    """The :class:`palpate.HapticLoop` ``physics_rate`` of parsed arguments ``a`` (with ``rate``,
    ``physics_rate``, ``single_rate``): None for ``--single-rate``."""
    if a.single_rate:
        return None
    hz = a.physics_rate if a.physics_rate is not None else min(DEFAULT_PHYSICS_RATE_HZ, a.rate)
    if not (math.isfinite(hz) and 100 <= hz <= a.rate):
        raise Usage(f"palpate {cmd}: --physics-rate must be within 100 Hz and --rate ({a.rate:g} Hz), got {hz}")
    return hz


def add_quiet(parser) -> None:
    """``--quiet``: no progress display (the display is drawn only on a terminal anyway)."""
    parser.add_argument("--quiet", action="store_true", help="no progress display (shown on a terminal only)")


def fmt_mm(v) -> str:
    """A length [m] in millimetres, ``-`` for None / NaN."""
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{1e3 * v:.4f}"


def num(x: float) -> str:
    """A default for a help string: ``%g``, or ``9e-4`` for values under 1e-3."""
    if x != 0 and abs(x) < 1e-3:
        m, e = f"{x:e}".split("e")
        return f"{m.rstrip('0').rstrip('.')}e{int(e)}"
    return f"{x:g}"


def mb(nbytes: int) -> str:
    return f"{nbytes / 1e6:.2f} MB"


def ml(m3: float) -> str:
    return f"{m3 * 1e6:.3f} mL"


def palpate_errors():
    """The exceptions palpate's core raises (imported late: the parser must build without them)."""
    from .. import _palpate as _p
    return (_p.PalpateError,)


def load_hybrid_model(model_spec: str, cmd: str):
    """``(name, model)`` of a hybrid model file or shape name (:func:`palpate.hybrid.load_model`), or a
    :class:`Fail` naming ``palpate CMD``, its code by :data:`EXIT_CODES` (a bad name or file:
    input; data that cannot be fetched: a failed run)."""
    from ..data import DataError
    from ..hybrid import load_model

    try:
        return load_model(model_spec)
    except (ValueError, OSError) as e:
        raise Fail(f"palpate {cmd}: {e}") from None
    except DataError as e:
        raise Fail(f"palpate {cmd}: {e}", cause=e) from None
    except palpate_errors() as e:
        raise Fail(f"palpate {cmd}: {model_spec}: {type(e).__name__}: {e}", cause=e) from None


def load_view_model(model_spec: str, cmd: str, unit: str = "m"):
    """``(name, model)`` for ``palpate view`` / ``palpate bench view``: a full-FEM
    :class:`palpate.viewer.fem.FemModel` for a protocol mesh name, a scene (.toml) or a tet mesh
    file (coordinates in ``unit``), else a hybrid model (:func:`load_hybrid_model`); a bad one is a
    :class:`Fail` naming the file and the reason (bad input, or by :data:`EXIT_CODES`)."""
    from ..viewer.fem import is_fem_spec, load_fem_model

    if not is_fem_spec(model_spec):
        return load_hybrid_model(model_spec, cmd)
    try:
        return load_fem_model(model_spec, unit)
    except palpate_errors() as e:
        # The readers' and the scene's messages name the file already.
        raise Fail(f"palpate {cmd}: {type(e).__name__}: {e}", cause=e) from None
    except (ValueError, OSError) as e:
        raise Fail(f"palpate {cmd}: {model_spec}: {e}") from None


def model_lines(info: dict) -> List[str]:
    """The description of a hybrid model's info() dict, shared by build and info."""
    i = info
    closure = (i["core_volume_m3"] + i["shell_volume_m3"]) / i["wall_volume_m3"] if i["wall_volume_m3"] > 0 else math.nan
    lines = [
        f"  core: {i['core_tets']} tets, {i['core_nodes']} nodes, {i['core_faces']} faces towards the shell, "
        f"{i['core_base_nodes']} base nodes; min dihedral {i['core_min_dihedral_deg']:.2f} deg, "
        f"tet volume ratio min/max {i['core_volume_ratio']:.3g}",
        f"  shell: {i['particles']} particles at {i['spacing_m'] * 1e3:.3f} mm spacing",
        f"  regions: {i['regions']} (one per outer vertex; {i['outer_triangles']} outer triangles), "
        f"particles per region min {i['region_particles_min']}, median {i['region_particles_median']}, "
        f"max {i['region_particles_max']}",
        f"  volumes: wall {ml(i['wall_volume_m3'])}, core {ml(i['core_volume_m3'])}, "
        f"shell {ml(i['shell_volume_m3'])} (core + shell = {100 * closure:.2f} % of the wall)",
        f"  transmural field: {i['voxels']} voxels of {i['voxel_m'] * 1e3:.3f} mm, {i['field_cg_iterations']} CG iterations",
        f"  build time: {i['build_s']:.3f} s (field {i['build_field_s']:.3f}, core {i['build_core_s']:.3f}, "
        f"particles {i['build_particles_s']:.3f}, regions {i['build_regions_s']:.3f}, "
        f"homogenisation {i.get('build_homogenise_s', 0.0):.3f})",
    ]
    if i.get("homogenised"):
        lines.insert(1, f"  core stiffness: {i['core_stiffening']:.2f}x the tissue's away from the active shell (at nu = "
                        f"0.4; per probe {i['core_stiffening_min']:.2f}-{i['core_stiffening_max']:.2f}), homogenised "
                        f"against the whole wall in {i['homogenise_reference_tets']} quadratic tets")
        if i.get("homogenise_region_tets"):
            lines.insert(2, f"  core stiffness under the active shell: {i['core_active_stiffening']:.2f}x the tissue's (per "
                            f"probe {i['core_active_stiffening_min']:.2f}-{i['core_active_stiffening_max']:.2f}), against the "
                            f"wall's inner part in {i['homogenise_region_tets']} quadratic tets")
    else:
        lines.insert(1, "  core stiffness: the tissue's (not homogenised: the paper's core)")
    fb = {k: i[k] for k in ("fallback_particle_outer", "fallback_particle_core", "fallback_skin") if i.get(k)}
    if fb:
        lines.append("  fallbacks: " + ", ".join(f"{k[len('fallback_'):]} {v}" for k, v in fb.items()))
    return lines


def require_extra(command: str, extra: str, modules: Tuple[str, ...]) -> None:
    """Ends ``palpate COMMAND`` with :class:`RunFailed` naming the extra to install when any of
    ``modules`` (the extra's packages) cannot be imported, before any work: without it, the
    first import deep in the run was reported as an internal error."""
    import importlib

    missing = []
    for m in modules:
        try:
            importlib.import_module(m)
        except ImportError:
            missing.append(m)
    if missing:
        from .._extras import install_hint

        raise RunFailed(f"palpate {command}: needs the {extra} extra ({', '.join(missing)} not installed): "
                        f"{install_hint(extra)}")
