"""``palpate devices``: every device palpate can drive, what each needs, whether this machine has
its Python package, and the command that runs it (docs/devices.md has the set-up of each).

The vendor packages are looked up without being imported (an SDK's import can open hardware or
print); "installed" means Python can find the package, not that the vendor's driver or device
is present.
"""
from __future__ import annotations

import json
from typing import Any, Dict, List

#: The built-in devices of ``palpate haptic --device``: name, what it is, the command.
BUILT_IN = (
    ("hand", "the simulated hand: a palpation cycle on the model, no hardware",
     "palpate haptic MODEL --device hand"),
    ("scripted", "a scripted tool trajectory (a .toml or .csv script, as palpate touch)",
     "palpate haptic MODEL --device scripted:SCRIPT"),
    ("replay", "a recording made with --record, replayed bit for bit",
     "palpate haptic MODEL --device replay:FILE"),
    ("bridge", "any device process speaking the bridge protocol over UDP (crates/palpate-haptics/PROTOCOL.md)",
     "palpate haptic MODEL --device bridge:PORT"),
)

#: The vendor adapters of ``palpate device NAME`` (see :data:`palpate.devices.VENDORS`): the devices each drives.
VENDOR_DEVICES = {
    "geomagic": "3D Systems / Geomagic Touch (OpenHaptics; formerly `touch`)",
    "forcedimension": "Force Dimension omega / delta / sigma, Novint Falcon (Force Dimension SDK)",
    "haply": "Haply Inverse3 (serial port)",
    "hapticmaster": "Moog HapticMaster (TCP)",
}


def device_table() -> List[Dict[str, Any]]:
    """One dict per device: ``name``, ``kind`` (``"built-in"`` or ``"vendor"``), ``what``,
    ``needs`` (what to install besides palpate), ``installed`` (the vendor's Python package is
    importable; None for the built-in ones), ``command`` (the command or commands that run it)."""
    from ..devices import VENDORS, missing_vendor

    rows: List[Dict[str, Any]] = [dict(name=n, kind="built-in", what=w, needs="", installed=None, command=c)
                                  for n, w, c in BUILT_IN]
    for name, (module, package, extra, other) in VENDORS.items():
        found = missing_vendor(name) is None
        rows.append(dict(name=name, kind="vendor", what=VENDOR_DEVICES.get(name, name),
                         needs=f"pip install {package} (the {extra} extra), plus {other}", installed=found,
                         command=f"palpate haptic MODEL --device {name} --offset X Y Z   (or two processes: "
                                 f"palpate haptic MODEL --device bridge:5005 --kind {name}, and palpate device {name} "
                                 f"--port 5005)"))
    return rows


def add_parser(sub) -> None:
    d = sub.add_parser("devices", help="list the haptic devices palpate can drive and how to run each",
                       description="List every device palpate can drive: the built-in ones (no hardware) and the "
                                   "vendor adapters, with what each needs, whether its Python package is installed "
                                   "here (looked up, not imported), and the command that runs it. docs/devices.md "
                                   "has each one's set-up.")
    d.add_argument("--json", action="store_true", help="one JSON list instead of the table")
    d.set_defaults(func=cmd_devices)


def cmd_devices(a) -> int:
    rows = device_table()
    if a.json:
        print(json.dumps(rows))
        return 0
    for r in rows:
        state = "" if r["installed"] is None else ("  [package installed]" if r["installed"] else "  [package not installed]")
        print(f"{r['name']} ({r['kind']}): {r['what']}{state}")
        if r["needs"]:
            print(f"    needs:   {r['needs']}")
        print(f"    run:     {r['command']}")
    print("The bridge's devices run as their own process; docs/devices.md has the set-up of each.")
    return 0
