"""``palpate view [MODEL]``: the haptic loop in a browser (:mod:`palpate.viewer`): a web page on
127.0.0.1 (``--host`` to serve elsewhere, with a warning) showing the deformed surface, the tool,
the force and a live plot; dragging on the surface moves the simulated hand. ``--screenshot
OUT.png`` renders one frame of a press with the system's headless Chromium and exits.

Only the page's own loopback origin may open the page and its WebSocket, or anything with the
viewer's token (:mod:`palpate.viewer.origin`); beyond loopback, or with ``--require-token``,
nothing without it, and the URL printed carries it (``--token`` or ``$PALPATE_VIEW_TOKEN`` to
choose it; else a random one per run).

MODEL is a hybrid model file (``palpate build``) or a shape name (default ``rodero``; ``ventricle``
and ``ellipsoids`` build in a second without data), or a full-FEM body: a tet mesh file (``.msh``,
``.vtu``, ``.vtk``, ``.npz``, ...; ``--unit`` for its coordinates; the nodes at its lowest z are
held), a scene file (``.toml``, as ``palpate run`` reads: its material is the first preset, its
fixed nodes and gravity are kept) or a protocol mesh name (``ellipsoid_192``, ``lv_1350``, ...). A
full-FEM body is drawn by its boundary faces (the tool meets its boundary nodes) and its tets."""
from __future__ import annotations

import ipaddress
import logging
import math
import os
import sys
import time

from ._common import Fail, RunFailed, Usage, add_physics_rate, load_view_model, num, physics_rate
from .._extras import install_hint
from ..haptics import DEVICE_KINDS, device_kind

#: Status lines on stdout every this many seconds (unless --quiet).
STATUS_EVERY_S = 1.0


def add_parser(sub) -> None:
    from ..viewer.app import DEVICES, PRESS_RANGE, TOOL_RADIUS_RANGE

    v = sub.add_parser("view", help="see the haptic loop and touch it in a browser (viser)",
                       description="Serve a web viewer of the haptic loop on MODEL (a palpate model file or a shape "
                                   "name: rodero (default), ventricle, ellipsoids; or a full-FEM body: a tet mesh "
                                   "file, a scene file (.toml) or a protocol mesh name such as ellipsoid_192) and "
                                   "print its URL. Drag on the "
                                   "surface (or move the gizmo) to press with the simulated hand; --device bridge "
                                   "lets a real device drive the view. Stops on Ctrl-C or after --seconds. Needs "
                                   "the view extra (its packages: viser and playwright).")
    v.add_argument("model", nargs="?", default="rodero", metavar="MODEL")
    v.add_argument("--unit", choices=("m", "cm", "mm"), default="m",
                   help="a tet mesh file's coordinate unit (default m; the shared lv_*.msh are in cm)")
    v.add_argument("--host", default="127.0.0.1", metavar="IP",
                   help="address to serve on (default 127.0.0.1; anything else is reachable from the network: the "
                        "page then needs the token in the URL printed, and a warning says that the connection is "
                        "not encrypted)")
    v.add_argument("--token", default=os.environ.get("PALPATE_VIEW_TOKEN") or None, metavar="TOKEN",
                   help="the token that admits a page or WebSocket from anywhere (?token=TOKEN in the URL; 8 or more "
                        "URL-safe characters; default $PALPATE_VIEW_TOKEN, else a random one per run, printed in "
                        "the URL when it is required or given)")
    v.add_argument("--require-token", action="store_true",
                   help="refuse every request without the token, also from this machine's own pages (always so "
                        "beyond loopback)")
    v.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: a free one; a busy one: the next free)")
    v.add_argument("--device", choices=DEVICES, default="hand",
                   help="hand: the page moves a simulated hand (default); bridge: a real device over UDP")
    v.add_argument("--bridge-port", type=int, default=0, metavar="P", help="UDP port of the bridge (default 0: a free one)")
    v.add_argument("--kind", type=device_kind, choices=DEVICE_KINDS, default=None,
                   help="the device's make, for the coupling and safety defaults (as palpate haptic --kind)")
    v.add_argument("--key-file", default=None, metavar="FILE",
                   help="bridge: a shared key (at least 16 bytes) that signs every packet (HMAC-SHA256); required "
                        "with --device bridge beyond 127.0.0.1; the device process gives the same file")
    v.add_argument("--preset", default=None, metavar="NAME",
                   help="material preset (default 'haptic (30 kPa, damped)'; also 'myocardium', 'paper ellipsoids')")
    v.add_argument("--tool-radius", type=float, default=0.005, metavar="M",
                   help=f"tool sphere radius [m] (default 0.005; {num(TOOL_RADIUS_RANGE[0])} to {num(TOOL_RADIUS_RANGE[1])})")
    v.add_argument("--press-depth", type=float, default=0.003, metavar="M",
                   help=f"how deep a drag on the surface presses [m] (default 0.003; up to {num(PRESS_RANGE[1])})")
    v.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="servo rate [Hz] (default 1000; 250 to 4000)")
    add_physics_rate(v)
    v.add_argument("--fps", type=float, default=30.0, metavar="HZ", help="viewer update rate [Hz] (default 30; 1 to 120)")
    v.add_argument("--max-force", type=float, default=None, metavar="N", help="force limit [N] (default 3)")
    v.add_argument("--unsafe-limits", action="store_true",
                   help="allow a --max-force above the device class's rated force (touch 3.3 N, forcedimension 12 N, "
                        "hapticmaster 250 N), logged; refused otherwise")
    v.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    v.add_argument("--screenshot", default=None, metavar="OUT.png",
                   help="render one frame of a press at the probe point in headless Chromium to OUT.png and exit")
    v.add_argument("--press", type=float, default=0.004, metavar="M",
                   help="with --screenshot: the press depth at the probe point [m] (default 0.004)")
    v.add_argument("--show-core", action="store_true",
                   help="draw the FEM core's tets (a full-FEM body's tets) as simulated from the start")
    v.add_argument("--show-particles", action="store_true", help="draw the active shell particles from the start")
    v.add_argument("--realtime", action="store_true",
                   help="run the haptic servo under SCHED_FIFO so that the browser cannot preempt a tick (needs root, "
                        "CAP_SYS_NICE or an rtprio limit)")
    v.add_argument("--quiet", action="store_true", help="no status lines")
    v.set_defaults(func=cmd_view)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _check(a) -> None:
    for flag, v in (("--tool-radius", a.tool_radius), ("--fps", a.fps), ("--seconds", a.seconds),
                    ("--max-force", a.max_force)):
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise Usage(f"palpate view: {flag} must be positive and finite, got {v}")
    if not (a.press >= 0 and math.isfinite(a.press)):
        raise Usage(f"palpate view: --press must be non-negative and finite, got {a.press}")
    if not 250 <= a.rate <= 4000:
        raise Usage(f"palpate view: --rate must be within 250 to 4000 Hz, got {a.rate}")
    if not 0 <= a.port <= 65535 or not 0 <= a.bridge_port <= 65535:
        raise Usage("palpate view: ports must be within 0 to 65535")
    try:
        ipaddress.ip_address(a.host)
    except ValueError:
        if a.host != "localhost":
            raise Usage(f"palpate view: --host {a.host!r} is not an IP address") from None
    if a.token is not None:
        from ..viewer.origin import check_token

        try:
            check_token(a.token)
        except ValueError as e:
            raise Usage(f"palpate view: --token: {e}") from None


def status_line(s: dict, t: float) -> str:
    return (f"t {t:6.1f} s | force {s['force_n']:.3f} N (max {s['max_force_n']:.3f}) | surface {s['surface_mm']:.2f} mm "
            f"(max {s['max_surface_mm']:.2f}) | {s['fps']:.1f} frames/s"
            + (f" | active particles {s['active_particles']}" if s["active_particles"] is not None else "") + f" | drags {s['drags']} | loop ticks "
            f"{s['loop_ticks']} overruns {s['loop_overruns']} | inputs rejected "
            f"{s['inputs']['non_finite'] + s['inputs']['rate_limited']} | messages dropped {s['messages']['dropped']}"
            f" | requests refused {sum(s['requests']['refused'].values())}")


def cmd_view(a) -> int:
    _check(a)
    try:
        import viser  # noqa: F401
    except ImportError:
        raise RunFailed(f"palpate view: needs viser: {install_hint('view')}") from None
    from ..viewer.app import PRESS_RANGE

    if a.screenshot:
        from ..viewer.browser import find_chromium, have_playwright

        ok, why = have_playwright()
        exe, why2 = find_chromium()
        if not ok or exe is None:
            raise RunFailed(f"palpate view: --screenshot needs a browser: {why or why2}")
        if a.press > PRESS_RANGE[1] + a.tool_radius:
            raise Usage(f"palpate view: --press {a.press} m is deeper than the viewer allows")
    name, model = load_view_model(a.model, "view", a.unit)
    if not is_loopback(a.host):
        print(f"palpate: warning: serving on {a.host}: anyone who can reach port {a.port} can try; only the token in "
              "the URL printed lets a page in, and it travels unencrypted (no TLS): use 127.0.0.1 and an SSH tunnel "
              "instead", file=sys.stderr)
    hz = physics_rate(a, "view")
    # The viewer's refusals (the first of each reason) as the command's warnings.
    log = logging.getLogger("palpate.viewer")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("palpate: warning: %(message)s"))
    log.addHandler(handler)
    propagate, log.propagate = log.propagate, False
    try:
        return _serve(a, name, model, hz)
    finally:
        log.removeHandler(handler)
        log.propagate = propagate


def _serve(a, name, model, hz) -> int:
    from .. import _palpate as _p
    from ..viewer import OriginCheckUnavailable, Viewer

    from .. import HapticsError
    from ..devices.bridge import load_key
    from ..haptics import loop_rates

    try:
        key = load_key(a.key_file) if a.key_file else None
    except HapticsError as e:
        raise Usage(f"palpate view: {e}") from None
    try:
        viewer = Viewer(model, name, host=a.host, port=a.port, device=a.device, bridge_port=a.bridge_port,
                        bridge_host=a.host if a.device == "bridge" else "127.0.0.1", preset=a.preset,
                        tool_radius=a.tool_radius, press_depth=a.press_depth, rate_hz=a.rate, fps=a.fps,
                        max_force=a.max_force, show_core=a.show_core, show_particles=a.show_particles,
                        realtime=a.realtime, **loop_rates(hz),
                        unsafe_limits=a.unsafe_limits, token=a.token, require_token=a.require_token, bridge_key=key,
                        kind=a.kind)
    except _p.ParameterError as e:
        raise Fail(f"palpate view: {e}") from None
    except OriginCheckUnavailable as e:
        raise RunFailed(f"palpate view: {e}") from None
    except OSError as e:
        raise RunFailed(f"palpate view: cannot serve on {a.host}:{a.port}: {e}") from None
    if viewer.bounds_warning:
        print(f"palpate: warning: {viewer.bounds_warning}", file=sys.stderr)
    try:
        if not viewer.wait_ready(60.0):
            raise RunFailed(f"palpate view: the loop did not start: {viewer.loop_error or 'timeout'}")
        where = f", bridge on udp://{viewer.bridge_address}" if viewer.bridge_address else ""
        print(f"palpate view: {name} on {viewer.url} (device {a.device}{where}; Ctrl-C stops)", flush=True)
        if a.screenshot:
            return _screenshot(a, viewer)
        t0 = time.monotonic()
        next_line = t0 + STATUS_EVERY_S
        while a.seconds is None or time.monotonic() - t0 < a.seconds:
            time.sleep(0.05)
            if not a.quiet and time.monotonic() >= next_line:
                next_line += STATUS_EVERY_S
                print(status_line(viewer.status(), time.monotonic() - t0), flush=True)
    finally:
        report = viewer.close()
    if report is not None and not a.quiet:
        print(f"  loop: {report['ticks']} ticks, period p99 {report['period_us_p99']:.0f} us, overruns "
              f"{report['overruns']}, max force {report['max_force_n']:.3f} N, faults {report['n_faults']}", flush=True)
    return 0


def _screenshot(a, viewer) -> int:
    from ..viewer.browser import screenshot

    # The gizmo would hide the dimple: off for the picture.
    viewer.g_gizmo.value = False
    viewer.gizmo.visible = False
    t0 = viewer.loop.snapshot()["time"]
    viewer.set_target(viewer.press_target(a.press))
    # The hand reaches the press and the organ's swing settles: 3 s of the loop's time (more wall
    # time where the loop runs slower than real time), at most 60 s.
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and viewer.loop.snapshot()["time"] - t0 < 3.0:
        time.sleep(0.1)
    try:
        n = screenshot(viewer.url, a.screenshot)
    except RuntimeError as e:
        raise RunFailed(f"palpate view: {e}") from None
    except OSError as e:
        raise RunFailed(f"palpate view: cannot write {a.screenshot}: {e}") from None
    s = viewer.status()
    print(f"palpate view: wrote {a.screenshot} ({n / 1e3:.0f} kB): force {s['force_n']:.3f} N, surface "
          f"{s['surface_mm']:.2f} mm", flush=True)
    return 0
