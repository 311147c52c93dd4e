"""What the commands share: the error that ends a command with an exit code, number formats, and
the description of a hybrid model (``palpate build`` and ``palpate info``)."""
from __future__ import annotations

import math
from typing import List


class Fail(Exception):
    """Ends a command: one line on stderr (``palpate: error: ...``) and exit ``code`` (2: bad input,
    1: a simulation, build or write that failed)."""

    def __init__(self, msg: str, code: int = 2):
        super().__init__(msg)
        self.code = code


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
