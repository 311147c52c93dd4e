"""Devices for the haptic loop that run as separate processes and speak the bridge protocol
(``crates/palpate-haptics/PROTOCOL.md``) to ``palpate haptic MODEL --device bridge:PORT``.

- :mod:`.bridge`: the reference bridge client (pure Python: ``socket`` + ``struct``), and
  :func:`run_adapter`, the loop that ties a vendor adapter to it;
- vendor adapters, each an optional extra imported only when used (``palpate device NAME``):
  :mod:`.touch` (3D Systems / Geomagic Touch through ``pyopenhaptics``), :mod:`.forcedimension`
  (Force Dimension and Novint Falcon through ``forcedimension-core``), :mod:`.haply` (Haply
  Inverse3 through ``HaplyHardwareAPI``), :mod:`.hapticmaster` (Moog HapticMaster over TCP
  through ``haptic-master``).

Every adapter maps its device's native units and axes to the model's world frame (metres; x to
the user's right, y away from the user, z up), documented in its module, then applies
``world = scale * mapped + offset`` (``palpate device --scale --offset``: the device's workspace
placed over the organ). Forces come back in newtons in the world frame and are mapped back by the
inverse (the scale does not apply to forces).
"""
from __future__ import annotations

import importlib
import importlib.util
from typing import Any, Optional

#: Adapter name -> (module, the PyPI package, the pip extra of palpate, what else to install).
VENDORS = {
    "geomagic": ("pyOpenHaptics", "pyopenhaptics", "geomagic", "the OpenHaptics SDK and the Touch device driver"),
    "forcedimension": ("forcedimension_core", "forcedimension-core", "forcedimension",
                       "the Force Dimension SDK (also drives the Novint Falcon) and its udev rules"),
    "haply": ("HaplyHardwareAPI", "HaplyHardwareAPI", "haply", "the Inverse3 on a serial port you may open"),
    "hapticmaster": ("haptic_master", "haptic-master", "hapticmaster", "a HapticMaster reachable over TCP"),
}


#: Former adapter names, still accepted: ``touch`` for the Geomagic Touch (``touch`` now names only
#: ``palpate touch``, the scripted touches).
ALIASES = {"touch": "geomagic"}


def canonical(name: str) -> str:
    """The adapter's name for ``name`` (itself, or what a former name became)."""
    return ALIASES.get(name, name)


class MissingVendor(ImportError):
    """A vendor adapter's SDK package is not installed; the message says what to install."""


def missing_vendor(name: str) -> Optional[str]:
    """What to install for adapter ``name``, or None when its vendor module is found (looked up,
    not imported: an SDK may touch the hardware when imported)."""
    name = canonical(name)
    module, package, extra, other = VENDORS[name]
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        found = False
    if found:
        return None
    return (f"palpate device {name} needs the Python package {package!r} (module {module}), which is not installed: "
            f"pip install {package} (the {extra} extra), plus {other}")


def import_vendor(name: str) -> Any:
    """Imports the vendor module of adapter ``name`` (only now: adapters are import-free until
    used), or raises :class:`MissingVendor` naming what to install."""
    name = canonical(name)
    module, package, extra, other = VENDORS[name]
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise MissingVendor(
            f"palpate device {name} needs the Python package {package!r} (module {module}), which is not installed "
            f"({e}): pip install {package} (the {extra} extra), plus {other}") from None
