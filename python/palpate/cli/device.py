"""``palpate device geomagic|forcedimension|haply|hapticmaster``: a vendor device as a separate
process that speaks the bridge protocol to ``palpate haptic MODEL --device bridge:PORT`` (so a
vendor SDK never runs in the servo thread, and its crash cannot take the simulation down). Each
vendor package is an optional extra, imported only here; without it, the command says what to
install (exit code 3: a failed run, see ``_common.EXIT_CODES``). The adapters and their unit and axis mappings: :mod:`palpate.devices`."""
from __future__ import annotations

import math

from ..devices import canonical
from ._common import RunFailed, Usage

ADAPTERS = ("geomagic", "forcedimension", "haply", "hapticmaster")


def add_parser(sub) -> None:
    d = sub.add_parser("device", help="connect a vendor haptic device to a running palpate haptic (bridge) loop",
                       description="Run a vendor device's adapter as a bridge client of `palpate haptic MODEL "
                                   "--device bridge:PORT` (protocol: crates/palpate-haptics/PROTOCOL.md).")
    # `touch`, the Geomagic Touch's former name: still accepted (devices.canonical), not offered.
    d.add_argument("adapter", type=canonical, choices=ADAPTERS,
                   help="the device: geomagic (3D Systems / Geomagic Touch, formerly `touch`), forcedimension, haply, "
                        "hapticmaster")
    d.add_argument("--port", type=int, default=5005, help="the loop's bridge port (default 5005)")
    d.add_argument("--host", default="127.0.0.1", help="the loop's address (default 127.0.0.1)")
    d.add_argument("--key-file", default=None, metavar="FILE",
                   help="the shared key the loop was started with (its --key-file): every packet signed "
                        "(HMAC-SHA256); required by a loop bound beyond 127.0.0.1")
    d.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="exchange rate [Hz] (default 1000)")
    d.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    d.add_argument("--scale", type=float, default=1.0, help="world = scale * device + offset (default 1)")
    d.add_argument("--offset", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                   help="world offset of the device's origin [m] (default 0 0 0)")
    d.add_argument("--address", default=None, help="hapticmaster: IP (default 192.168.0.25); haply: serial port")
    d.set_defaults(func=cmd_device)


def make_adapter(a):
    from ..devices import bridge

    try:
        place = bridge.Placement(a.scale, a.offset)
    except ValueError as e:
        raise Usage(f"palpate device: {e}") from None
    if a.adapter == "geomagic":
        from ..devices.geomagic_touch import TouchAdapter
        return TouchAdapter(place)
    if a.adapter == "forcedimension":
        from ..devices.forcedimension import ForceDimensionAdapter
        return ForceDimensionAdapter(place)
    if a.adapter == "haply":
        from ..devices.haply import HaplyAdapter
        return HaplyAdapter(place, a.address or "")
    from ..devices.hapticmaster import HapticMasterAdapter
    return HapticMasterAdapter(place, a.address or "192.168.0.25")


def cmd_device(a) -> int:
    from .. import HapticsError
    from ..devices import MissingVendor
    from ..devices.bridge import load_key, run_adapter

    if not (a.rate > 0 and math.isfinite(a.rate)):
        raise Usage(f"palpate device: --rate must be positive, got {a.rate}")
    try:
        key = load_key(a.key_file) if a.key_file else None
    except HapticsError as e:
        raise Usage(f"palpate device: {e}") from None
    adapter = make_adapter(a)
    try:
        s = run_adapter(adapter, a.host, a.port, a.rate, a.seconds, lambda line: print(line, flush=True), key=key)
    except (MissingVendor, HapticsError) as e:
        raise RunFailed(f"palpate device {a.adapter}: {e}") from None
    except OSError as e:
        raise RunFailed(f"palpate device {a.adapter}: {e}") from None
    print(f"palpate device {a.adapter}: sent {s['sent']} states, got {s['forces']} forces (max {s['max_force_n']:.3f} N), "
          f"zeroed {s['silences']} times for silence")
    return 0
