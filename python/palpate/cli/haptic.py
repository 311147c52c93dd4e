"""``palpate haptic MODEL --device scripted:SCRIPT|replay:FILE|bridge:PORT|hand|VENDOR``: the haptic
loop (a native servo thread, :class:`palpate.HapticLoop`) on a hybrid model, headless, with a
live status line (rate, period, force, overruns). ``--record FILE`` writes the interaction for
``--device replay:FILE``, which gives the same forces bit for bit.

``--device geomagic|forcedimension|haply|hapticmaster`` is the common case in one command: the loop
opens a bridge on a free loopback port with a fresh random key, and starts ``palpate device
VENDOR`` as a child process on it (the vendor SDK never runs in the servo's process); the loop
stops when the child does, and the child when the loop does. The two-process form (``--device
bridge:PORT`` and ``palpate device``) stays for a device on another machine.

The recording's buffer is allocated when the loop starts (the servo thread never allocates), 144
bytes a tick: with ``--seconds S``, S seconds of ticks (the loop then stops itself after that
many); without, the device's length (a script's, a replay's) up to :data:`DEFAULT_RECORD_TICKS`
(5 minutes at 1 kHz, 43 MB; a bridge or a hand, which have no end, get that). Ticks past the
buffer are not recorded: the command says how many, in one warning line on stderr."""
from __future__ import annotations

import math
import os
import secrets
import subprocess
import sys
import tempfile

from ..haptics import DEVICE_KINDS, device_kind
from .device import ADAPTERS as VENDOR_ADAPTERS
from ._common import FAILED, INTERRUPTED, Fail, RunFailed, Usage, add_physics_rate, load_hybrid_model, palpate_errors, physics_rate

DEVICES = "scripted:SCRIPT.toml|SCRIPT.csv, replay:FILE, bridge:PORT, hand, geomagic|forcedimension|haply|hapticmaster"
#: The recording buffer without ``--seconds`` [ticks]: 5 min at 1 kHz, 75 s at 4 kHz (43 MB).
DEFAULT_RECORD_TICKS = 300_000
#: The fastest a loop (and so a recording to replay) runs [Hz].
MAX_RATE_HZ = 4000.0


def add_parser(sub) -> None:
    h = sub.add_parser("haptic", help="run the haptic loop on a hybrid model with a device, headless",
                       description="Run the haptic servo loop (250-4000 Hz) on MODEL (a palpate model file or a shape "
                                   "name: ellipsoids, ventricle, rodero) with a device: " + DEVICES + ". Prints a live "
                                   "status line; stops at the device's end, after --seconds, or on Ctrl-C.")
    h.add_argument("model", metavar="MODEL")
    h.add_argument("--device", required=True, metavar="DEVICE", help=DEVICES)
    h.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="servo rate [Hz] (default 1000; 250 to 4000)")
    add_physics_rate(h)
    h.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds (default: the device's end; "
                   "for bridge and hand, Ctrl-C)")
    h.add_argument("--record", default=None, metavar="FILE",
                   help="record the interaction (inputs, forces, model identity); the buffer holds --seconds S of ticks, "
                        f"else the device's length up to {DEFAULT_RECORD_TICKS:,} ticks (5 min at 1 kHz; 144 bytes a tick): "
                        "ticks past it are not recorded, and a warning says how many")
    h.add_argument("--host", default="127.0.0.1",
                   help="bridge address to bind (default 127.0.0.1; any other needs --key-file)")
    h.add_argument("--key-file", default=None, metavar="FILE",
                   help="bridge: a shared key (at least 16 bytes) that signs every packet (HMAC-SHA256, PROTOCOL.md); "
                        "the device process gives the same file to `palpate device --key-file`")
    h.add_argument("--kind", type=device_kind, choices=DEVICE_KINDS, default=None, help="the device's make, for the coupling and safety defaults "
                   "(a vendor --device sets its own)")
    h.add_argument("--scale", type=float, default=1.0,
                   help="a vendor --device: world = scale * device + offset (default 1, as palpate device)")
    h.add_argument("--offset", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="a vendor --device: the world position [m] of the device's origin (default: the centre of the "
                        "organ's bounding box)")
    h.add_argument("--address", default=None, help="a vendor --device: hapticmaster's IP, haply's serial port (as palpate device)")
    h.add_argument("--max-force", type=float, default=None, metavar="N", help="force limit [N] (default 3)")
    h.add_argument("--unsafe-limits", action="store_true",
                   help="allow a --max-force above the device class's rated force (geomagic 3.3 N, forcedimension 12 N, "
                        "hapticmaster 250 N), logged; refused otherwise")
    h.add_argument("--tool-radius", type=float, default=0.005, metavar="M", help="tool sphere radius [m] (default 0.005)")
    h.add_argument("--realtime", action="store_true",
                   help="run the servo under SCHED_FIFO so that other work cannot preempt a tick (needs root, "
                        "CAP_SYS_NICE or an rtprio limit; refused otherwise, with a warning)")
    h.add_argument("--threads", type=int, default=1, metavar="N",
                   help="threads a tick's particle passes run on, 1 to 8 (default 1): the servo's and N-1 helpers "
                        "that spin while the loop runs; the same forces bit for bit, sooner only where the helpers "
                        "have idle cores (on a 2-core machine they did not help: BENCHMARKS.md)")
    w = h.add_mutually_exclusive_group()
    w.add_argument("--busy-wait", action="store_true",
                   help="the servo spins through each period instead of sleeping (the default of --single-rate "
                        "without --realtime; the default two-rate loop sleeps to its deadlines, leaving the cores to "
                        "the physics): a core kept busy, a shorter compute tail and fewer overruns for the single-rate "
                        "loop (measured on a 2-core machine: docs/history/benchmarks-log.md); not with --realtime")
    w.add_argument("--sleep", action="store_true",
                   help="the servo sleeps through each wait but its last 200 us, leaving its core to other work "
                        "(more overruns on a busy or virtual machine)")
    h.add_argument("--quiet", action="store_true", help="no status line")
    h.set_defaults(func=cmd_haptic)


def _positive(cmd: str, flag: str, v) -> None:
    if v is not None and not (v > 0 and math.isfinite(v)):
        raise Usage(f"palpate {cmd}: {flag} must be positive and finite, got {v}")


def record_ticks(a) -> int:
    """The recording buffer for ``a`` [ticks] (0 without ``--record``; see the module)."""
    if not a.record:
        return 0
    if a.seconds is None:
        return DEFAULT_RECORD_TICKS         # the loop cuts it to a script's or a replay's length
    # A replay runs at its recording's rate, whatever --rate says (the loop cuts the buffer to
    # the recording's length).
    rate = MAX_RATE_HZ if a.device.startswith("replay:") else a.rate
    return int(math.ceil(a.seconds * rate)) + 1


def make_loop(a, model, record_ticks: int):
    """The :class:`palpate.HapticLoop` for ``a.device``; with ``--seconds S`` (but for a replay,
    whose rate is the recording's), the loop stops itself after S seconds of ticks, which the
    recording buffer holds (stopped from here, it would run on until the next status line)."""
    from .. import _palpate as _p
    from .. import haptics
    from ..touch import ScriptError

    kind, _, arg = a.device.partition(":")
    common = dict(rate_hz=a.rate, record_ticks=record_ticks, max_force=a.max_force, tool_radius=a.tool_radius,
                  realtime=a.realtime, threads=a.threads, unsafe_limits=a.unsafe_limits, **haptics.loop_rates(a.physics_hz))
    if a.busy_wait:
        common["spin"] = haptics.BUSY_SPIN
    elif a.sleep:
        common["spin"] = haptics.SLEEP_SPIN
    if a.kind is not None:
        common["kind"] = a.kind
    if a.seconds is not None and kind != "replay":
        common["max_ticks"] = int(math.ceil(a.seconds * a.rate))
    mat = haptics.material()
    if kind in VENDOR_ADAPTERS:
        from ..devices import missing_vendor

        why = missing_vendor(kind)
        if why is not None:
            raise RunFailed(f"palpate haptic: {why}")
        common.setdefault("kind", kind)
        # Loopback, a free port and a key only this process and its child know.
        return _p.HapticLoop(model, mat, "bridge", port=0, host="127.0.0.1", bridge_key=a.vendor_key, **common)
    try:
        if kind == "scripted":
            if not arg:
                raise Usage("palpate haptic: --device scripted:SCRIPT needs a script (.toml or .csv, as palpate touch)")
            try:
                t, k = haptics.script_trajectory(model, arg, a.tool_radius)
            except ScriptError as e:
                raise Fail(f"palpate haptic: {e}") from None
            except OSError as e:
                raise Fail(f"palpate haptic: {e}") from None
            return _p.HapticLoop(model, mat, "scripted", times=t, knots=k, **common)
        if kind == "replay":
            common.pop("rate_hz")
            common.pop("physics_rate")
            common.pop("single_rate")
            return _p.HapticLoop(model, mat, "replay", recording=arg, **common)
        if kind == "bridge":
            try:
                port = int(arg)
            except ValueError:
                raise Usage(f"palpate haptic: --device bridge:PORT needs a port number, got {arg!r}") from None
            if not 0 <= port <= 65535:
                raise Usage(f"palpate haptic: port {port} out of range")
            from ..devices.bridge import load_key
            key = load_key(a.key_file) if a.key_file else None
            beyond = a.host not in ("127.0.0.1", "localhost") and not a.host.startswith("127.")
            if key is None and beyond:
                raise Usage(f"palpate haptic: --host {a.host} makes the bridge reachable from other machines: "
                            "give a shared key with --key-file FILE (every packet is then signed), or bind 127.0.0.1")
            if beyond:
                print(f"palpate haptic: warning: the bridge on {a.host} is reachable from other machines; its packets "
                      "are signed with the key but not encrypted (positions and forces can be read on the network)",
                      file=sys.stderr)
            return _p.HapticLoop(model, mat, "bridge", port=port, host=a.host, bridge_key=key, **common)
        if kind == "hand":
            import numpy as np
            t, k = haptics.palpation_cycle(model, a.tool_radius)
            return _p.HapticLoop(model, mat, "hand", hand_start=np.asarray(k[0]), **common)
    except ValueError as e:
        raise Fail(f"palpate haptic: {e}") from None
    except _p.HapticsError as e:
        raise Fail(f"palpate haptic: {e}") from None
    except palpate_errors() as e:
        raise Fail(f"palpate haptic: {type(e).__name__}: {e}", cause=e) from None
    raise Usage(f"palpate haptic: unknown device {a.device!r}; expected {DEVICES}")


def start_vendor(a, loop, model) -> "subprocess.Popen":
    """``palpate device VENDOR`` as a child process on the loop's bridge, its key in a file only
    the user can read (removed once the child has read it: see :func:`cmd_haptic`), the device's
    origin placed at ``--offset`` (default: the centre of the organ's bounding box)."""
    import numpy as np

    port = loop.bridge_address.rsplit(":", 1)[1]
    fd, path = tempfile.mkstemp(prefix="palpate-bridge-", suffix=".key")
    with os.fdopen(fd, "wb") as f:
        f.write(a.vendor_key)
    a.vendor_key_file = path
    pts = np.asarray(model.outer_points)
    offset = a.offset if a.offset is not None else 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    cmd = [sys.executable, "-m", "palpate", "device", a.device, "--port", port, "--host", "127.0.0.1",
           "--key-file", path, "--scale", repr(float(a.scale)), "--offset", *(repr(float(v)) for v in offset)]
    if a.address:
        cmd += ["--address", a.address]
    print(f"palpate haptic: starting palpate device {a.device} on port {port} (device origin at "
          f"{', '.join(f'{v:.4f}' for v in offset)} m, scale {a.scale:g})", flush=True)
    try:
        out = sys.stderr.fileno()  # the child's lines beside the loop's events, not in its status
    except (AttributeError, OSError, ValueError):
        out = None  # a captured stderr (no file descriptor): the child's own stdout
    return subprocess.Popen(cmd, stdout=out)


def stop_vendor(a, child) -> int:
    """Ends the child (Ctrl-C as a user would, then a kill after 3 s) and removes the key file;
    returns its exit code."""
    if child.poll() is None:
        child.send_signal(2)  # SIGINT: the adapter zeroes the device's force and closes it
        try:
            child.wait(3.0)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
    if getattr(a, "vendor_key_file", None):
        try:
            os.unlink(a.vendor_key_file)
        except OSError:
            pass
    return child.returncode


def cmd_haptic(a) -> int:
    from .. import haptics

    a.device = device_kind(a.device)   # `touch`, the Geomagic Touch's former name

    if not 250 <= a.rate <= 4000:
        raise Usage(f"palpate haptic: --rate must be within 250 to 4000 Hz, got {a.rate}")
    _positive("haptic", "--seconds", a.seconds)
    _positive("haptic", "--max-force", a.max_force)
    _positive("haptic", "--tool-radius", a.tool_radius)
    if not 1 <= a.threads <= 8:
        raise Usage(f"palpate haptic: --threads must be 1 to 8, got {a.threads}")
    a.physics_hz = physics_rate(a, "haptic")
    if a.busy_wait and a.realtime:
        raise Usage("palpate haptic: --busy-wait and --realtime together: a real-time thread that never sleeps "
                    "meets the kernel's real-time throttling (50 ms without the CPU every second)")
    if not (a.scale > 0 and math.isfinite(a.scale)):
        raise Usage(f"palpate haptic: --scale must be positive, got {a.scale}")
    vendor = a.device in VENDOR_ADAPTERS
    a.vendor_key = secrets.token_hex(32).encode() if vendor else None
    name, model = load_hybrid_model(a.model, "haptic")
    loop = make_loop(a, model, record_ticks(a))
    child = start_vendor(a, loop, model) if vendor else None
    try:
        return _run(a, loop, name, child)
    finally:
        if child is not None:
            code = stop_vendor(a, child)
            if code not in (0, None, -2, 130):
                print(f"palpate haptic: palpate device {a.device} ended with exit code {code}", file=sys.stderr)


def _run(a, loop, name: str, child) -> int:
    from .. import haptics

    where = f" on {loop.bridge_address}" if loop.bridge_address else ""
    phys = f", physics {loop.physics_rate_hz:g} Hz (multirate)" if loop.physics_rate_hz else ""
    print(f"palpate haptic: {name}, device {a.device}{where}, {loop.rate_hz:g} Hz{phys}", flush=True)
    if a.device.startswith("replay:") and loop.physics_rate_hz:
        # A multirate recording replays from its recorded schedule, bit for bit, without a clock.
        r = loop.run()
        print(f"  replayed {r['ticks']} servo ticks offline (multirate: the physics from its recorded inputs); "
              f"max force {r['max_force_n']:.3f} N; faults {r['n_faults']}")
        return FAILED if r["n_faults"] else 0
    tty = sys.stdout.isatty()

    def show(line: str) -> None:
        if not a.quiet:
            print(("\r" + line) if tty else line, end="" if tty else "\n", flush=True)

    def event(line: str) -> None:
        print(("\r" if tty and not a.quiet else "") + "palpate haptic: " + line, file=sys.stderr, flush=True)

    until = (lambda: child.poll() is not None) if child is not None else None
    r = haptics.run_live(loop, a.seconds, show, on_event=event, until=until)
    # The vendor's adapter ended before the loop did: the loop stopped with it (the device no
    # longer sends, and no force reaches it); a failed adapter fails the run.
    adapter_failed = False
    if child is not None and child.poll() is not None and not r["interrupted"]:
        adapter_failed = child.returncode != 0
        print(f"palpate haptic: palpate device {a.device} stopped (exit code {child.returncode}) after "
              f"{r['elapsed_s']:.2f} s: the loop stopped with it", file=sys.stderr)
    if tty and not a.quiet:
        print()
    if r["interrupted"]:
        print("palpate haptic: interrupted (Ctrl-C): the loop stopped; its summary and recording follow", file=sys.stderr)
    print(f"  {r['ticks']} ticks in {r['elapsed_s']:.2f} s ({r['achieved_hz']:.1f} Hz): period p50 {r['period_us_p50']:.0f} us, "
          f"p99 {r['period_us_p99']:.0f} us, max {r['period_us_max']:.0f} us; compute p99 {r['compute_us_p99']:.0f} us; "
          f"overruns {r['overruns']} (own {r['overruns_own']}, the machine's {r['overruns_machine']}); max force {r['max_force_n']:.3f} N; faults {r['n_faults']}")
    p = r.get("physics")
    if p:
        print(f"  physics: {p['ticks']} ticks ({p['achieved_hz']:.1f} of {p['rate_hz']:g} Hz): compute p50 {p['compute_us_p50']:.0f} us, "
              f"p99 {p['compute_us_p99']:.0f} us; lag p99 {p['lag_us_p99']:.0f} us, max {p['lag_us_max']:.0f} us; "
              f"late {p['late']}, skipped {p['skipped']}; device silences {r['device_silences']}, stale models {r['model_stalls']}")
    # The log holds faults (counted above) and events (a device silence's or a stale model's fade,
    # a watchdog trip: the force faded or zeroed, nothing failed).
    for f in r["faults"][:10]:
        what = "fault" if f.get("fault", True) else "event"
        print(f"  {what} at tick {f['tick']} (t = {f['time']:.3f} s): {f['reason']}")
    if a.realtime:
        if r["realtime"].startswith("refused"):
            print(f"palpate haptic: warning: real-time scheduling {r['realtime']}", file=sys.stderr)
        else:
            print(f"  servo scheduling: {r['realtime']}")
    if r.get("replay_divergence"):
        print(f"palpate haptic: warning: the replay left its recording at tick {r['replay_diverged_at']}: "
              f"{r['replay_divergence']}", file=sys.stderr)
    elif "replay_diverged_at" in r:
        print("  replay: every force as recorded, bit for bit")
    bs = loop.bridge_stats()
    if bs is not None:
        print("  bridge: " + ", ".join(f"{k} {v}" for k, v in bs.items()))
    if a.record:
        try:
            n = loop.save_recording(a.record)
        except OSError as e:
            raise RunFailed(f"palpate haptic: cannot write {a.record}: {e}") from None
        print(f"  recorded {n} ticks: {a.record}")
        if r["recording_dropped_ticks"]:
            print(f"palpate haptic: warning: the recording buffer was full: the last {r['recording_dropped_ticks']} of "
                  f"{n + r['recording_dropped_ticks']} ticks were not recorded (--seconds S sizes it; 144 bytes a tick)",
                  file=sys.stderr)
    if r["interrupted"]:
        return INTERRUPTED
    return FAILED if r["n_faults"] or adapter_failed else 0
