"""What the commands share: the error that ends a command with an exit code, number formats, and
the description of a hybrid model (``palpate build`` and ``palpate info``)."""
from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Callable, List


class Fail(Exception):
    """Ends a command: one line on stderr (``palpate: error: ...``) and exit ``code`` (2: bad input,
    1: a simulation, build or write that failed)."""

    def __init__(self, msg: str, code: int = 2):
        super().__init__(msg)
        self.code = code


class Parser(argparse.ArgumentParser):
    """argparse with the CLI's one-line errors: ``palpate: error: ...`` and exit 2 (usage),
    instead of argparse's usage block followed by the error."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def run_guarded(func: Callable[[], int]) -> int:
    """Run a command so that whatever it raises ends as one line on stderr and an exit code, never
    a traceback: :class:`Fail` with its code; a palpate error with 1 when a simulation or build
    failed (StepError, SolveError, InternalError) and 2 for bad input (every other PalpateError,
    a missing or unreadable file: OSError); MemoryError 1; anything else is a bug: 1, one line
    saying so (``PALPATE_DEBUG=1`` shows the traceback). A closed stdout (``palpate ... | head``)
    ends quietly."""
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
        print("palpate: interrupted", file=sys.stderr)
        return 130
    except (_p.StepError, _p.SolveError, _p.InternalError) as e:
        return say(f"{type(e).__name__}: {e}", 1)
    except _p.PalpateError as e:
        return say(f"{type(e).__name__}: {e}", 2)
    except OSError as e:
        return say(f"{e.filename + ': ' if getattr(e, 'filename', None) else ''}{e.strerror or e}", 2)
    except MemoryError:
        return say("out of memory (lower the input's size, or see PALPATE_MAX_MEMORY)", 1)
    except Exception as e:  # noqa: BLE001 - the promise is one line, never a traceback
        if os.environ.get("PALPATE_DEBUG"):
            raise
        return say(f"internal error ({type(e).__name__}: {e}); please report it (PALPATE_DEBUG=1 shows the traceback)", 1)


def quiet_pipe() -> int:
    """stdout was closed by the reader (``| head``): point it at /dev/null so that Python's own
    flush at exit does not print a BrokenPipeError, and end with 141 (128 + SIGPIPE), as Unix
    tools killed by SIGPIPE do."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
    return 141


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
    """``(name, model)`` of a hybrid model file or shape name (``bench_hybrid.load_model``), or a
    :class:`Fail` naming ``palpate CMD``: exit 2 for a bad name or file, 1 for data that cannot be
    fetched."""
    from .. import bench_hybrid as bh
    from ..data import DataError

    try:
        return bh.load_model(model_spec)
    except (ValueError, OSError) as e:
        raise Fail(f"palpate {cmd}: {e}") from None
    except DataError as e:
        raise Fail(f"palpate {cmd}: {e}", 1) from None
    except palpate_errors() as e:
        raise Fail(f"palpate {cmd}: {model_spec}: {type(e).__name__}: {e}") from None


def load_view_model(model_spec: str, cmd: str, unit: str = "m"):
    """``(name, model)`` for ``palpate view`` / ``palpate bench view``: a full-FEM
    :class:`palpate.viewer.fem.FemModel` for a protocol mesh name, a scene (.toml) or a tet mesh
    file (coordinates in ``unit``), else a hybrid model (:func:`load_hybrid_model`); a bad one is a
    :class:`Fail` (exit 2) naming the file and the reason."""
    from ..viewer.fem import is_fem_spec, load_fem_model

    if not is_fem_spec(model_spec):
        return load_hybrid_model(model_spec, cmd)
    try:
        return load_fem_model(model_spec, unit)
    except palpate_errors() as e:
        # The readers' and the scene's messages name the file already.
        raise Fail(f"palpate {cmd}: {type(e).__name__}: {e}") from None
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
        f"particles {i['build_particles_s']:.3f}, regions {i['build_regions_s']:.3f})",
    ]
    fb = {k: i[k] for k in ("fallback_particle_outer", "fallback_particle_core", "fallback_skin") if i.get(k)}
    if fb:
        lines.append("  fallbacks: " + ", ".join(f"{k[len('fallback_'):]} {v}" for k, v in fb.items()))
    return lines
