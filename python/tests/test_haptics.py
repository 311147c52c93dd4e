"""The haptic loop from Python (issue 13): palpate.HapticLoop, the bridge's reference client, the
vendor adapters and the haptic, soak, bench haptic and device commands.

What a wrong implementation would do:
- a binding that holds the GIL in the loop, or a loop that waits on Python, stalls while Python
  sleeps (``test_loop_runs_while_python_sleeps``);
- a replay through the binding that is not bit-identical, or accepts another model's recording;
- a bridge that accepts malformed packets, or a reference client that encodes the protocol
  wrongly (the Rust bridge refuses it: no accepted packet, no force back);
- a vendor adapter that imports its SDK at import time (``palpate`` then needs every SDK), or
  maps millimetres as metres, or swaps axes (``test_*_adapter_maps_*`` with fake vendor modules);
- commands that crash without a vendor SDK instead of saying what to install;
- an adapter loop that does not zero the device when the loop goes silent, or zeroes it before
  30 ms of silence (``test_run_adapter_*``);
- a binding that holds its lock while the GIL is released (a deadlock with ``snapshot()``);
- a recording cut short without a word (``test_haptic_command_*_recording_*``).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import threading
import time
import types

import numpy as np
import pytest

import palpate
from palpate import _palpate as _p
from palpate import haptics

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def model():
    return palpate.hybrid.build_shape("ellipsoids")


def cycle(model, ticks=1200):
    t, k = haptics.palpation_cycle(model)
    return t, k


def test_replay_through_the_binding_is_bit_identical(model, tmp_path):
    t, k = cycle(model)
    loop = _p.HapticLoop(model, haptics.material(), "scripted", times=t, knots=k, record_ticks=3000,
                         single_rate=True)
    r = loop.run()
    assert r["ticks"] == 2000 and r["n_faults"] == 0
    assert r["max_force_n"] > 0.02, "the palpation touches"
    path = str(tmp_path / "cycle.palprec")
    assert loop.save_recording(path) == 2000
    a = loop.recorded()
    # Live (the servo thread, the wall clock) and offline replays give the same bits.
    live = _p.HapticLoop(model, haptics.material(), "replay", recording=path, record_ticks=3000)
    live.start()
    time.sleep(0.2)
    got = live.surface()                 # a viewer's snapshot while the loop runs
    assert got is not None and got[1].shape == (len(np.asarray(model.outer_points)), 3) and got[0] % 32 == 0
    assert live.wait(60)
    rep = live.stop()
    assert rep["ticks"] == 2000
    # Only a watchdog trip (this shared machine's scheduler stalling the thread 30 ms) may break
    # bit identity live; offline, nothing may. A trip is a counted fault in the single-rate loop
    # and a logged event in the multirate one: no fault but trips.
    assert rep["n_faults"] <= rep["watchdog_trips"]
    b = live.recorded()
    off = _p.HapticLoop(model, haptics.material(), "replay", recording=path, record_ticks=3000)
    off.run()
    c = off.recorded()
    for key in ("force", "tool", "device"):
        assert np.array_equal(a[key], c[key]), key
        if rep["watchdog_trips"] == 0:
            assert np.array_equal(a[key], b[key]), key


def test_a_recording_of_another_model_is_refused(model, tmp_path):
    t, k = cycle(model)
    loop = _p.HapticLoop(model, haptics.material(), "scripted", times=t, knots=k, record_ticks=10, max_ticks=10)
    loop.run()
    path = str(tmp_path / "r.palprec")
    loop.save_recording(path)
    stiff = _p.Material(young=9.0e4, poisson=0.4, density=1000.0, phi=1.0, psi=1.0)
    with pytest.raises(_p.HapticsError, match="another simulation"):
        _p.HapticLoop(model, stiff, "replay", recording=path)
    (tmp_path / "bad.palprec").write_bytes(b"PALPREC\0" + b"\x03\x00\x00\x00" + b"\0" * 40)
    with pytest.raises(_p.HapticsError, match="version 3"):
        _p.HapticLoop(model, haptics.material(), "replay", recording=str(tmp_path / "bad.palprec"))


def test_ticks_past_the_recording_buffer_are_reported(model):
    t, k = cycle(model)
    loop = _p.HapticLoop(model, haptics.material(), "scripted", times=t, knots=k, record_ticks=100, idle=True)
    r = loop.run()
    assert r["ticks"] == 2000
    assert len(loop.recorded()["force"]) == 100
    assert r["recording_dropped_ticks"] == 1900, "the ticks that did not fit are counted"
    # A buffer larger than the script is cut to it (allocated at start: no use for the rest).
    loop = _p.HapticLoop(model, haptics.material(), "scripted", times=t, knots=k, record_ticks=10**9, idle=True)
    assert loop.run()["recording_dropped_ticks"] == 0


def test_bad_parameters_raise_value_errors(model):
    t, k = cycle(model)
    m = haptics.material()
    with pytest.raises(ValueError, match="rate"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, rate_hz=100.0)
    with pytest.raises(ValueError, match="max_force"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, max_force=-1.0)
    with pytest.raises(ValueError, match="increase"):
        _p.HapticLoop(model, m, "scripted", times=t[::-1].copy(), knots=k)
    with pytest.raises(ValueError, match="expected scripted"):
        _p.HapticLoop(model, m, "joystick")
    with pytest.raises(ValueError, match="hand_start"):
        _p.HapticLoop(model, m, "hand")
    for bad in (0, 9):
        with pytest.raises(ValueError, match="threads"):
            _p.HapticLoop(model, m, "scripted", times=t, knots=k, threads=bad)
    # spin: 0 to 1 s (a whole period or more: the servo never sleeps).
    for bad in (-1e-3, 1.5, float("nan")):
        with pytest.raises(ValueError, match="spin"):
            _p.HapticLoop(model, m, "scripted", times=t, knots=k, spin=bad)


def test_multirate_loop_replays_bit_identically_offline_and_from_live(model, tmp_path):
    # The multirate loop (physics_rate): offline, and live on two threads whose interleaving the
    # clock decides; each recording replays bit for bit from its recorded schedule (run()).
    t, k = cycle(model)
    m = haptics.material()
    off = _p.HapticLoop(model, m, "scripted", times=t, knots=k, record_ticks=3000, physics_rate=250.0)
    assert off.physics_rate_hz == 250.0
    r = off.run()
    assert r["ticks"] == 2000 and r["n_faults"] == 0 and r["max_force_n"] > 0.02
    assert r["device_silences"] == 0 and r["model_stalls"] == 0
    single = _p.HapticLoop(model, m, "scripted", times=t, knots=k, record_ticks=3000, single_rate=True)
    single.run()
    f_off, f_single = off.recorded()["force"], single.recorded()["force"]
    rel = np.sqrt(np.mean(np.sum((f_off - f_single) ** 2, axis=1)) / np.mean(np.sum(f_single ** 2, axis=1)))
    assert rel < 0.05, f"multirate at 250 Hz vs single-rate: {rel:.1%} RMS"
    for loop, name in ((off, "offline"), (None, "live")):
        if loop is None:
            loop = _p.HapticLoop(model, m, "scripted", times=t, knots=k, record_ticks=3000, physics_rate=500.0,
                                 rate_hz=1000.0)
            loop.start()
            assert loop.wait(60)
            rep = loop.stop()
            p = rep["physics"]
            assert p["rate_hz"] == 500.0 and p["ticks"] > 0 and p["compute_us_p50"] > 0, p
            assert {"achieved_hz", "lag_us_p99", "lag_us_max", "late", "skipped", "compute_us_p99"} <= set(p)
        path = str(tmp_path / f"{name}.palprec")
        loop.save_recording(path)
        again = _p.HapticLoop(model, m, "replay", recording=path, record_ticks=3000)
        assert again.physics_rate_hz == loop.physics_rate_hz
        again.run()
        a, b = loop.recorded(), again.recorded()
        for key in ("force", "tool", "device"):
            assert np.array_equal(a[key], b[key]), (name, key)
    # Single-rate loops report no physics thread; the default is multirate, its physics at 1 kHz
    # or the servo's rate if lower.
    assert single.physics_rate_hz is None
    assert _p.HapticLoop(model, m, "scripted", times=t, knots=k).physics_rate_hz == 1000.0
    assert _p.HapticLoop(model, m, "scripted", times=t, knots=k, rate_hz=500.0).physics_rate_hz == 500.0
    with pytest.raises(ValueError, match="single_rate"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, physics_rate=500.0, single_rate=True)
    with pytest.raises(ValueError, match="physics rate"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, physics_rate=50.0)
    with pytest.raises(ValueError, match="physics rate"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, rate_hz=1000.0, physics_rate=2000.0)
    with pytest.raises(ValueError, match="silence"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, silence=-1.0)


def test_loop_runs_while_python_sleeps_and_the_hand_follows(model):
    t, k = cycle(model)
    loop = _p.HapticLoop(model, haptics.material(), "hand", hand_start=k[0], idle=True, rate_hz=2000.0)
    loop.start()
    time.sleep(0.3)                    # Python busy elsewhere: the loop must keep ticking
    s1 = loop.snapshot()
    assert s1 is not None and s1["tick"] > 200, s1
    loop.set_hand_target(k[0] + np.array([0.0, 0.0, 0.01]))
    time.sleep(0.5)
    s2 = loop.snapshot()
    assert abs(s2["device"][2] - (k[0][2] + 0.01)) < 1e-3, s2["device"]
    r = loop.stop()
    assert r["ticks"] >= s2["tick"] and r["n_faults"] <= r["watchdog_trips"]
    with pytest.raises(_p.HapticsError):
        loop.start()


def test_snapshot_from_another_thread_while_stop_or_run_releases_the_gil():
    # stop() and run() release the GIL for their wait; if the loop's lock were still held then, a
    # thread calling snapshot() (a viewer, a status line) would take the GIL and wait on the lock,
    # and stop() could never take the GIL back: a deadlock. A deadlocked process cannot be
    # stopped from inside, so the threads run in a child with a time limit.
    code = textwrap.dedent("""
        import sys, threading, time
        sys.setswitchinterval(1e-5)          # hand the GIL over as often as possible
        import palpate
        from palpate import _palpate as _p, haptics
        model = palpate.hybrid.build_shape("ellipsoids")
        t, k = haptics.palpation_cycle(model)
        calls = [0]

        def hammer(loop, done):
            while not done.is_set():
                loop.snapshot(); loop.surface(); loop.finished()
                calls[0] += 1

        def with_hammer(loop, action):
            done = threading.Event()
            th = threading.Thread(target=hammer, args=(loop, done))
            th.start()
            time.sleep(0.005)
            try:
                return action()
            finally:
                done.set()
                th.join()

        for _ in range(20):
            loop = _p.HapticLoop(model, haptics.material(), "hand", hand_start=k[0], idle=True)
            loop.start()
            # The first tick (its snapshot), not a time: on a busy machine the loop's thread may not have run
            # within a few milliseconds of start(), and a stop before it has nothing to report.
            t0 = time.monotonic()
            while loop.snapshot() is None and time.monotonic() - t0 < 10:
                time.sleep(0.001)
            r = with_hammer(loop, loop.stop)
            assert r["ticks"] > 0, r
        for _ in range(5):
            loop = _p.HapticLoop(model, haptics.material(), "scripted", times=t, knots=k, idle=True)
            r = with_hammer(loop, loop.run)
            assert r["ticks"] == 2000, r
        print("OK", calls[0])
    """)
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("deadlock: stop() or run() and snapshot() from another thread never returned")
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("OK"), out.stdout


def test_run_adapter_against_the_loop_and_its_silence_rule(model, monkeypatch):
    # The loop a vendor adapter runs (palpate device NAME), with a fake device, against a running
    # loop on the bridge: its positions reach the loop, the loop's forces reach the device, and
    # once the loop stops (silent), the device's force is zeroed, once, after SILENCE_S (30 ms)
    # without a force packet and not before.
    from palpate.devices import bridge as br

    t, k = cycle(model)
    events = []                                  # ("packet" | "write", time [s], force [N])

    class Fake(br.Adapter):
        name = "fake"

        def __init__(self):
            self.t0, self.closed, self.reads = None, False, set()

        def open(self):
            self.t0 = time.monotonic()

        def read(self):
            # From 2 mm clear to the press's depth over 0.3 s, then held.
            s = min(1.0, (time.monotonic() - self.t0) / 0.3)
            p = k[0] + s * (k[1] - k[0])
            self.reads.add(tuple(p))
            return p, (1.0, 0.0, 0.0, 0.0), 2

        def write(self, force):
            events.append(("write", time.monotonic(), np.array(force, dtype=np.float64)))

        def close(self):
            self.closed = True

    latest = br.BridgeClient.latest

    def logged_latest(self):
        f = latest(self)
        if f is not None:
            events.append(("packet", time.monotonic(), f.force.copy()))
        return f

    monkeypatch.setattr(br.BridgeClient, "latest", logged_latest)
    loop = _p.HapticLoop(model, haptics.material(), "bridge", port=0, record_ticks=60_000)
    host, port = loop.bridge_address.split(":")
    loop.start()
    adapter, stats = Fake(), {}
    th = threading.Thread(target=lambda: stats.update(br.run_adapter(adapter, host, int(port), 1000.0, seconds=1.3)))
    th.start()
    try:
        time.sleep(0.8)
    finally:
        t_stop = time.monotonic()
        loop.stop()
        th.join(60)
    assert not th.is_alive() and adapter.closed
    bs = loop.bridge_stats()
    rec = loop.recorded()
    assert stats["sent"] > 100 and stats["forces"] > 50, stats
    assert bs["accepted"] > 50 and bs["dropped"] == 0, bs
    assert stats["max_force_n"] > 0.01, f"the device felt the tissue: {stats}"
    # The loop's device positions are the adapter's, its forces what the device got, bit for bit.
    assert all(tuple(p) in adapter.reads for p in rec["device"])
    sent = {tuple(f) for f in rec["force"]} | {(0.0, 0.0, 0.0)}   # the loop's last act: zero
    # Each write right after a packet is that packet's force; the others are the silence rule's
    # zeros and, last, run_adapter's own zero on the way out.
    packets, silences, last_packet, prev = [], [], adapter.t0, None
    for e in events[:-1]:
        if e[0] == "packet":
            last_packet = e[1]
        elif prev is not None and prev[0] == "packet":
            assert tuple(e[2]) in sent and np.array_equal(e[2], prev[2])
            packets.append(e)
        else:
            silences.append((e, e[1] - last_packet))
        prev = e
    assert events[-1][0] == "write" and not events[-1][2].any(), "zero force on the way out"
    assert len(packets) == stats["forces"] and len(silences) == stats["silences"], (stats, len(packets), len(silences))
    for (e, gap) in silences:
        assert not e[2].any(), "a silence writes zero force"
        assert gap > br.SILENCE_S, f"zeroed after only {gap * 1e3:.1f} ms of silence"
    after = [gap for (e, gap) in silences if e[1] > t_stop]
    assert len(after) == 1, f"one zeroing once the loop went silent, got {len(after)} (gaps [s] {after[:5]})"
    assert after[0] < br.SILENCE_S + 0.25, f"zeroed {after[0] * 1e3:.0f} ms after the last force"


def test_a_replay_says_where_and_why_it_leaves_a_recording_with_a_watchdog_trip(model, tmp_path):
    # A watchdog trip (the physics stalled on the recording's machine) cannot be replayed: the
    # replay reports the first tick whose force differs and names the recorded trip. The trip is
    # written into a recording as the servo writes one (the tick's stalled byte, its force the
    # fault path's zero, the fault count).
    import struct

    t, k = cycle(model)
    loop = _p.HapticLoop(model, haptics.material(), "scripted", times=t, knots=k, record_ticks=3000, single_rate=True)
    loop.run()
    path = tmp_path / "cycle.palprec"
    loop.save_recording(str(path))
    clean = _p.HapticLoop(model, haptics.material(), "replay", recording=str(path)).run()
    assert clean["replay_diverged_at"] is None and clean["replay_divergence"] is None, clean
    b = bytearray(path.read_bytes())
    (desc_len,) = struct.unpack_from("<I", b, 28)
    faults_at = 32 + desc_len + 9 * 8
    first = faults_at + 16
    forces = np.asarray(loop.recorded()["force"])
    tick = int(np.flatnonzero(np.linalg.norm(forces, axis=1) > 0.02)[0])
    rec = first + 144 * tick
    struct.pack_into("<Q", b, faults_at, 1)
    b[rec + 65] = 1                                  # stalled
    struct.pack_into("<3d", b, rec + 72, 0.0, 0.0, 0.0)
    tripped = tmp_path / "tripped.palprec"
    tripped.write_bytes(bytes(b))
    r = _p.HapticLoop(model, haptics.material(), "replay", recording=str(tripped)).run()
    assert r["replay_diverged_at"] == tick, r
    assert f"watchdog tripped at tick {tick}" in r["replay_divergence"], r["replay_divergence"]
    out = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ellipsoids", "--device", f"replay:{tripped}",
                          "--quiet"], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert f"left its recording at tick {tick}" in out.stderr and "watchdog tripped" in out.stderr, out.stdout + out.stderr


def test_bridge_with_the_reference_client_in_a_second_process(model):
    from palpate.devices.bridge import BridgeClient, encode_state

    t, k = cycle(model)
    loop = _p.HapticLoop(model, haptics.material(), "bridge", port=0, idle=False)
    host, port = loop.bridge_address.split(":")
    loop.start()
    try:
        # The malformed corpus first, from this process: dropped and counted, never moving the tool.
        c = BridgeClient(host, int(port))
        s = c.session
        good = encode_state(s, 5, k[0])
        corpus = [b"", good[:111], good + b"\0", b"\xff" * 4000, b"XXXX" + good[4:],
                  good[:4] + b"\x03\x00" + good[6:], good[:4] + b"\x01\x00" + good[6:],
                  encode_state(s, 1, [np.nan, 0, 0]), encode_state(s, 2, [1e9, 0, 0]),
                  encode_state(s, 3, k[0], orientation=(2.0, 0, 0, 0)), encode_state(s ^ 1, 4, k[0])]
        for b in corpus:
            c.send_raw(b)
        deadline = time.monotonic() + 5
        while loop.bridge_stats()["dropped"] < len(corpus) and time.monotonic() < deadline:
            time.sleep(0.01)
        st = loop.bridge_stats()
        assert st["dropped"] == len(corpus) and st["accepted"] == 0, st
        assert (st["short"], st["long"], st["bad_magic"], st["bad_version"], st["old_version"], st["non_finite"],
                st["out_of_range"], st["no_session"]) == (2, 1, 2, 1, 1, 1, 2, 1), st
        c.close()
        # A second process presses through the probe point and back, receiving forces.
        script = textwrap.dedent(f"""
            import sys, time, numpy as np
            sys.path.insert(0, {os.path.join(ROOT)!r})
            from palpate.devices.bridge import BridgeClient
            a, b = np.array({k[0].tolist()}), np.array({k[1].tolist()})
            c = BridgeClient({host!r}, {int(port)})
            n, fmax, t0 = 0, 0.0, time.monotonic()
            while time.monotonic() - t0 < 2.0:
                s = min(1.0, 2 * (1 - abs((time.monotonic() - t0) - 1.0)))
                c.send(a + s * (b - a))
                f = c.recv(0.002)
                while f is not None:
                    n += 1
                    fmax = max(fmax, float(np.linalg.norm(f.force)))
                    f = c.recv(0.0)
            print("CHILD", n, fmax)
        """)
        out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        _, n, fmax = out.stdout.split()
        st = loop.bridge_stats()
    finally:
        r = loop.stop()
    assert int(n) > 100, out.stdout
    assert float(fmax) > 0.01, f"the child felt the tissue: {out.stdout}"
    # The child's hellos are refused 'busy' until this process's session has been silent for the
    # hand-over time (0.5 s), then it gets the tool.
    assert st["accepted"] > 100 and st["dropped"] - st["busy"] == len(corpus), st
    assert st["sessions"] == 2, st                          # this process's, then the child's
    assert r["n_faults"] <= r["watchdog_trips"]


def test_a_stranger_on_another_port_cannot_take_the_tool(model):
    # The attack, through the Python API: a client holds the tool and presses; another
    # local port sends state packets far ahead in sequence (with no session, a guessed one, and the
    # client's own id as if sniffed) and asks for a session of its own. The tool stays on the
    # client's path, the stranger gets no force packet (one refusal, 'busy'), the log names the
    # holder and the refused hello.
    import socket
    from palpate.devices import bridge as br

    t, k = cycle(model)
    loop = _p.HapticLoop(model, haptics.material(), "bridge", port=0, record_ticks=20_000)
    host, port = loop.bridge_address.split(":")
    loop.start()
    evil = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    evil.connect((host, int(port)))
    evil.settimeout(0.05)
    far = np.array([0.3, 0.3, 0.3])
    try:
        c = br.BridgeClient(host, int(port))
        seen, events = {}, []
        t0 = time.monotonic()
        sent = 0
        while time.monotonic() - t0 < 1.0:
            s = min(1.0, (time.monotonic() - t0) / 0.5)
            c.send(k[0] + s * (k[1] - k[0]))
            if sent < 40:
                evil.send(br.encode_state([0, c.session ^ 0x5A5A, c.session][sent % 3], 1 << 30 + sent % 2, far))
                sent += 1
            if sent == 40:
                evil.send(br.encode_hello(7))
                sent += 1
            c.latest()
            time.sleep(0.002)
        events += haptics.bridge_events(loop.bridge_stats(), seen)
        got = []
        try:
            while True:
                got.append(evil.recv(256))
        except (socket.timeout, BlockingIOError):
            pass
        holder = f"{c.sock.getsockname()[0]}:{c.sock.getsockname()[1]}"
        c.close()
    finally:
        evil.close()
        loop.stop()
    st = loop.bridge_stats()
    rec = loop.recorded()
    assert st["sessions"] == 1 and st["holder"] == holder, st
    assert st["no_session"] == 27 and st["wrong_peer"] == 13 and st["busy"] == 1, st
    dev = np.asarray(rec["device"])
    assert len(dev) > 100 and np.all(np.linalg.norm(dev - far, axis=1) > 0.2), "a stranger's packet moved the device"
    assert len(got) == 1 and br.decode_handshake(got[0]) == (br.KIND_REFUSED, 0, 7, 1), got
    assert any(f"{holder} holds the tool" in e for e in events), events
    assert any("hellos refused" in e for e in events) and any("no open session" in e for e in events), events


def test_a_keyed_bridge_and_the_non_loopback_rule(model, tmp_path):
    from palpate.devices import bridge as br

    key_file = tmp_path / "bridge.key"
    key_file.write_text("0f" * 32 + "\n")
    key = br.load_key(str(key_file))
    assert key == b"0f" * 32
    with pytest.raises(_p.ParameterError, match="shared key"):
        _p.HapticLoop(model, haptics.material(), "bridge", port=0, host="0.0.0.0")
    with pytest.raises(_p.ParameterError, match="at least 16 bytes"):
        _p.HapticLoop(model, haptics.material(), "bridge", port=0, bridge_key=b"short")
    (tmp_path / "short.key").write_text("abc\n")
    with pytest.raises(_p.HapticsError, match="at least 16"):
        br.load_key(str(tmp_path / "short.key"))
    loop = _p.HapticLoop(model, haptics.material(), "bridge", port=0, bridge_key=key)
    host, port = loop.bridge_address.split(":")
    loop.start()
    try:
        for wrong in (None, b"another key of enough bytes"):
            with pytest.raises(br.BridgeRefused, match="shared key"):
                br.BridgeClient(host, int(port), key=wrong, timeout=2.0)
        c = br.BridgeClient(host, int(port), key=key)
        t, k = cycle(model)
        forces = 0
        t0 = time.monotonic()
        while time.monotonic() - t0 < 0.5:
            c.send(k[0])
            forces += c.latest() is not None
            time.sleep(0.002)
        c.close()
    finally:
        loop.stop()
    st = loop.bridge_stats()
    assert st["accepted"] > 50 and forces > 20 and st["bad_tag"] >= 2 and st["sessions"] == 1, (st, forces)


def test_cli_haptic_bridge_beyond_loopback_needs_a_key(tmp_path):
    out = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ventricle", "--device", "bridge:0", "--host", "0.0.0.0",
                          "--seconds", "0.2"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 2 and "--key-file" in out.stderr, out.stderr
    (tmp_path / "bridge.key").write_text("ab" * 16)
    out = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ventricle", "--device", "bridge:0", "--host", "0.0.0.0",
                          "--key-file", str(tmp_path / "bridge.key"), "--seconds", "0.3", "--quiet"],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0 and "not encrypted" in out.stderr, out.stdout + out.stderr
    out = subprocess.run([sys.executable, "-m", "palpate", "device", "touch", "--key-file", str(tmp_path / "none.key")],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 2 and "cannot read the bridge key" in out.stderr, out.stderr


# A stand-in for pyOpenHaptics that a child process can import (a stylus at the device's origin,
# served by a 1 kHz thread, as the OpenHaptics scheduler would).
FAKE_TOUCH = {
    "__init__.py": "",
    "hd.py": textwrap.dedent("""\
        def get_transform():
            return [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
        def get_buttons():
            return 0
        def set_force(f):
            pass
        """),
    "hd_callback.py": "def hd_callback(f):\n    return f\n",
    "hd_device.py": textwrap.dedent("""\
        import threading, time
        class HapticDevice:
            def __init__(self, device_name, callback):
                self._stop = threading.Event()
                callback()
                def serve():
                    while not self._stop.is_set():
                        callback()
                        time.sleep(0.001)
                self._thread = threading.Thread(target=serve, daemon=True)
                self._thread.start()
            def close(self):
                self._stop.set()
                self._thread.join(1.0)
        """),
}


def test_haptic_with_a_vendor_device_starts_its_adapter_beside_the_loop(tmp_path):
    # `palpate haptic MODEL --device geomagic`: one command for the common case. The loop binds a
    # free loopback port with a fresh key and starts `palpate device geomagic` on it; the adapter's
    # states reach the loop signed (none refused), the child is stopped with the loop, and the
    # key's file is gone afterwards. Without the vendor's package: exit 3 and what to install,
    # before any loop starts.
    import glob
    import tempfile

    fake = tmp_path / "vendor" / "pyOpenHaptics"
    fake.mkdir(parents=True)
    for name, text in FAKE_TOUCH.items():
        (fake / name).write_text(text)
    keys_before = set(glob.glob(os.path.join(tempfile.gettempdir(), "palpate-bridge-*")))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "vendor")] + [p for p in [os.environ.get("PYTHONPATH")] if p])}
    out = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ellipsoids", "--device", "geomagic", "--seconds", "3",
                          "--quiet"], capture_output=True, text=True, timeout=300, cwd=ROOT, env=env)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "starting palpate device geomagic on port" in out.stdout, out.stdout
    bridge = next(line for line in out.stdout.splitlines() if line.strip().startswith("bridge:"))
    stats = dict(item.strip().rsplit(" ", 1) for item in bridge.split(":", 1)[1].split(","))
    assert int(stats["accepted"]) > 500 and int(stats["bad_tag"]) == 0 and int(stats["sessions"]) == 1, bridge
    assert set(glob.glob(os.path.join(tempfile.gettempdir(), "palpate-bridge-*"))) == keys_before
    missing = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ellipsoids", "--device", "haply", "--seconds", "1"],
                             capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert missing.returncode == 3 and "pip install" in missing.stderr and "starting" not in missing.stdout, \
        missing.stdout + missing.stderr


def test_haptic_stops_when_the_vendor_adapter_dies_mid_session(tmp_path):
    # The device's driver crashes one second in (the adapter process exits with an error): the
    # loop stops with it at once, says so, prints its summary and fails the run (exit 3) rather
    # than rendering to a device that is gone for the rest of --seconds.
    fake = tmp_path / "vendor" / "pyOpenHaptics"
    fake.mkdir(parents=True)
    crashing = dict(FAKE_TOUCH)
    crashing["hd_device.py"] = textwrap.dedent("""\
        import os, threading, time
        class HapticDevice:
            def __init__(self, device_name, callback):
                callback()
                def serve():
                    t0 = time.monotonic()
                    while time.monotonic() - t0 < 1.0:
                        callback()
                        time.sleep(0.001)
                    os._exit(5)              # the driver dies with the process
                threading.Thread(target=serve, daemon=True).start()
            def close(self):
                pass
        """)
    for name, text in crashing.items():
        (fake / name).write_text(text)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "vendor")] + [p for p in [os.environ.get("PYTHONPATH")] if p])}
    t0 = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ellipsoids", "--device", "touch", "--seconds", "30",
                          "--quiet"], capture_output=True, text=True, timeout=300, cwd=ROOT, env=env)
    wall = time.monotonic() - t0
    assert out.returncode == 3, out.stdout + out.stderr
    assert "palpate device geomagic stopped (exit code 5)" in out.stderr and "the loop stopped with it" in out.stderr, out.stderr
    assert " ticks in " in out.stdout, out.stdout                 # the summary still comes
    assert wall < 25, f"the loop ran on for {wall:.1f} s after the adapter died"


# ------------------------------------------------------------------------------- vendor adapters

VENDOR_MODULES = ("pyOpenHaptics", "forcedimension_core", "HaplyHardwareAPI", "haptic_master")


def test_adapters_are_import_free_when_unused():
    code = ("import sys, palpate, palpate.devices, palpate.devices.bridge, palpate.devices.geomagic_touch, "
            "palpate.devices.touch, "
            "palpate.devices.forcedimension, palpate.devices.haply, palpate.devices.hapticmaster, palpate.cli; "
            f"print([m for m in {VENDOR_MODULES!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60,
                         env={**os.environ, "PYTHONPATH": ROOT})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("name,package", [("geomagic", "pyopenhaptics"), ("touch", "pyopenhaptics"), ("forcedimension", "forcedimension-core"),
                                          ("haply", "HaplyHardwareAPI"), ("hapticmaster", "haptic-master")])
def test_device_command_without_the_vendor_says_what_to_install(name, package, monkeypatch, capsys):
    from palpate.cli import main

    for m in VENDOR_MODULES:
        monkeypatch.setitem(sys.modules, m, None)   # importing it raises ImportError
    assert main(["device", name, "--seconds", "0.01"]) == 3     # a missing optional package: the run cannot be done
    err = capsys.readouterr().err
    assert package in err and "pip install" in err, err


def _fake_touch(monkeypatch, transform, buttons=1):
    applied = []
    pkg = types.ModuleType("pyOpenHaptics")
    hd = types.ModuleType("pyOpenHaptics.hd")
    hd.get_transform = lambda: transform
    hd.get_buttons = lambda: buttons
    hd.set_force = lambda f: applied.append(list(f))
    cb = types.ModuleType("pyOpenHaptics.hd_callback")
    cb.hd_callback = lambda f: f
    dev = types.ModuleType("pyOpenHaptics.hd_device")

    class HapticDevice:
        def __init__(self, device_name, callback):
            self.callback = callback
            callback()                               # the scheduler's first call

        def close(self):
            pass

    dev.HapticDevice = HapticDevice
    pkg.hd = hd
    for name, m in (("pyOpenHaptics", pkg), ("pyOpenHaptics.hd", hd), ("pyOpenHaptics.hd_callback", cb),
                    ("pyOpenHaptics.hd_device", dev)):
        monkeypatch.setitem(sys.modules, name, m)
    return applied


def test_touch_adapter_maps_millimetres_and_axes(monkeypatch):
    from palpate.devices.bridge import Placement
    from palpate.devices.geomagic_touch import TouchAdapter

    # Stylus at (10, 20, 30) mm in the device frame (x right, y up, z toward the user), a
    # rotation of 90 degrees about the device's y (up) axis; OpenHaptics' column-major transform.
    r = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    t = np.eye(4)
    t[:3, :3] = r.T
    t[3, :3] = [10.0, 20.0, 30.0]
    applied = _fake_touch(monkeypatch, t.tolist())
    a = TouchAdapter(Placement(2.0, (0.1, 0.0, 0.0)))
    a.open()
    p, q, b = a.read()
    # world = 1e-3 (x, -z, y), then 2 * world + (0.1, 0, 0)
    np.testing.assert_allclose(p, [0.1 + 0.020, -0.060, 0.040])
    # about the world's z (up) axis, 90 degrees the other way round (the y -> z, z -> -y change)
    np.testing.assert_allclose(np.abs(q), [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)], atol=1e-12)
    assert b == 1
    a.write(np.array([1.0, 2.0, 3.0]))               # world force
    a._device.callback()
    np.testing.assert_allclose(applied[-1], [1.0, 3.0, -2.0])   # device (F_x, F_z, -F_y)
    a.close()


def test_forcedimension_adapter_maps_axes(monkeypatch):
    from palpate.devices.forcedimension import ForceDimensionAdapter

    forces = []
    dhd = types.SimpleNamespace(open=lambda: 0, close=lambda: 0, errorGetLastStr=lambda: "",
                                getButtonMask=lambda: 3, setForce=lambda f: forces.append(list(f)))

    def get_position(out):
        out[:] = [0.01, 0.02, 0.03]                  # x toward the user, y right, z up [m]
        return 0

    dhd.getPosition = get_position
    monkeypatch.setitem(sys.modules, "forcedimension_core", types.SimpleNamespace(dhd=dhd, __name__="forcedimension_core"))
    a = ForceDimensionAdapter()
    a.open()
    p, q, b = a.read()
    np.testing.assert_allclose(p, [0.02, -0.01, 0.03])  # world (y, -x, z)
    assert b == 3 and tuple(q) == (1.0, 0.0, 0.0, 0.0)
    a.write(np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(forces[-1], [-2.0, 1.0, 3.0])  # device (-F_y, F_x, F_z)
    a.close()
    assert forces[-1] == [0.0, 0.0, 0.0]


def test_haply_adapter_passes_metres_through_the_placement(monkeypatch):
    from palpate.devices.bridge import Placement
    from palpate.devices.haply import HaplyAdapter

    sent = []

    class Inverse3:
        def __init__(self, stream):
            pass

        def device_wakeup_dict(self):
            return {"device_id": 1}

        def end_effector_force(self, f):
            sent.append(list(f))
            return [0.05, -0.15, 0.2], [0.0, 0.0, 0.0]

    api = types.SimpleNamespace(detect_inverse3s=lambda: ["/dev/ttyACM0"], SerialStream=lambda p: p, Inverse3=Inverse3)
    monkeypatch.setitem(sys.modules, "HaplyHardwareAPI", api)
    a = HaplyAdapter(Placement(1.0, (0.0, 0.15, -0.2)))
    a.open()
    a.write(np.array([0.5, 0.0, -0.5]))
    p, _, _ = a.read()
    np.testing.assert_allclose(p, [0.05, 0.0, 0.0])
    assert sent[-1] == [0.5, 0.0, -0.5]


def test_hapticmaster_adapter_renders_a_bias_force(monkeypatch):
    from palpate.devices.hapticmaster import HapticMasterAdapter

    log = []

    class Robot:
        def __init__(self, ip, port):
            log.append(("init", ip, port))

        def connect(self):
            log.append("connect")

        def create_bias_force(self, f):
            log.append("bias")

        def set_state(self, s):
            log.append(("state", s))

        def get_position(self):
            return [0.1, 0.2, 0.3]

        def set_bias_force(self, f):
            log.append(("force", list(f.force)))

        def disconnect(self):
            log.append("disconnect")

    class BiasForce:
        def __init__(self, name):
            self.force = [0.0, 0.0, 0.0]

    pkg = types.ModuleType("haptic_master")
    hm = types.ModuleType("haptic_master.haptic_master")
    hm.HapticMaster = Robot
    eff = types.ModuleType("haptic_master.effect")
    eff.BiasForce = BiasForce
    for n, m in (("haptic_master", pkg), ("haptic_master.haptic_master", hm), ("haptic_master.effect", eff)):
        monkeypatch.setitem(sys.modules, n, m)
    a = HapticMasterAdapter(ip="10.0.0.2", port=7654)
    a.open()
    np.testing.assert_allclose(a.read()[0], [0.1, 0.2, 0.3])
    a.write(np.array([0.0, 0.0, 2.0]))
    a.close()
    assert ("state", "force") in log and ("force", [0.0, 0.0, 2.0]) in log and log[-1] == "disconnect"
    assert ("init", "10.0.0.2", 7654) in log


# ----------------------------------------------------------------------------------------- CLI

def test_haptic_command_scripted_record_and_replay(tmp_path, capsys):
    from palpate.cli import main

    script = tmp_path / "press.toml"
    script.write_text('[probe]\nvertex = "probe"\n[[segment]]\nkind = "press"\ndepth = 0.003\nduration = 0.3\n'
                      '[[segment]]\nkind = "release"\nduration = 0.2\n')
    rec = tmp_path / "press.palprec"
    # Exit code 3 only for a fault (on this shared machine, a watchdog trip), which is printed.
    # The single-rate loop (--single-rate; the default is the multirate loop, below).
    assert main(["haptic", "ellipsoids", "--device", f"scripted:{script}", "--record", str(rec), "--quiet",
                 "--single-rate"]) in (0, 3)
    out = capsys.readouterr().out
    assert "500 ticks" in out and "recorded 500 ticks" in out and "multirate" not in out, out
    assert main(["haptic", "ellipsoids", "--device", f"replay:{rec}"]) in (0, 3)
    out = capsys.readouterr().out
    assert "500 ticks" in out and "Hz" in out and "overruns" in out
    # The replay on two threads (the particle passes split; bitwise the same ticks, which the
    # haptics crate's tests check).
    assert main(["haptic", "ellipsoids", "--device", f"replay:{rec}", "--threads", "2", "--quiet"]) in (0, 3)
    assert "500 ticks" in capsys.readouterr().out
    assert main(["haptic", "ellipsoids", "--device", f"replay:{rec}", "--threads", "0"]) == 2     # usage
    assert "--threads must be 1 to 8" in capsys.readouterr().err
    # --busy-wait: the servo spins instead of sleeping; the same ticks. Not with --realtime.
    assert main(["haptic", "ellipsoids", "--device", f"replay:{rec}", "--busy-wait", "--quiet"]) in (0, 3)
    assert "500 ticks" in capsys.readouterr().out
    assert main(["haptic", "ellipsoids", "--device", f"replay:{rec}", "--busy-wait", "--realtime"]) == 2     # usage
    assert "--busy-wait and --realtime" in capsys.readouterr().err
    # --sleep: the servo sleeps through each wait (the busy wait is the default); the same ticks.
    assert main(["haptic", "ellipsoids", "--device", f"replay:{rec}", "--sleep", "--quiet"]) in (0, 3)
    assert "500 ticks" in capsys.readouterr().out
    assert main(["haptic", "ellipsoids", "--device", "joystick"]) == 2     # usage
    assert "unknown device" in capsys.readouterr().err
    # The multirate loop: recorded live, replayed offline from its schedule.
    mrec = tmp_path / "multirate.palprec"
    assert main(["haptic", "ellipsoids", "--device", f"scripted:{script}", "--physics-rate", "500", "--record",
                 str(mrec), "--quiet"]) in (0, 3)
    out = capsys.readouterr().out
    assert "physics 500 Hz (multirate)" in out and "physics:" in out and "recorded 500 ticks" in out, out
    assert main(["haptic", "ellipsoids", "--device", f"replay:{mrec}"]) == 0
    assert "replayed 500 servo ticks offline" in capsys.readouterr().out
    assert main(["haptic", "ellipsoids", "--device", f"scripted:{script}", "--physics-rate", "2000"]) == 2   # usage
    assert "--physics-rate must be within" in capsys.readouterr().err
    assert main(["haptic", "ellipsoids", "--device", f"scripted:{script}", "--quiet"]) in (0, 3)
    assert "physics 1000 Hz (multirate)" in capsys.readouterr().out, "the multirate loop by default"
    assert main(["haptic", "ellipsoids", "--device", "hand", "--rate", "500", "--seconds", "0.1", "--quiet"]) in (0, 3)
    assert "physics 500 Hz (multirate)" in capsys.readouterr().out, "no faster than the servo by default"


def test_haptic_command_warns_of_a_recording_cut_short(tmp_path, capsys, monkeypatch):
    from palpate.cli import haptic as cli_haptic
    from palpate.cli import main

    script = tmp_path / "press.toml"
    script.write_text('[probe]\nvertex = "probe"\n[[segment]]\nkind = "press"\ndepth = 0.003\nduration = 0.3\n'
                      '[[segment]]\nkind = "release"\nduration = 0.2\n')
    rec = tmp_path / "press.palprec"
    # The default buffer (no --seconds) made smaller than the 500-tick script.
    monkeypatch.setattr(cli_haptic, "DEFAULT_RECORD_TICKS", 200)
    assert main(["haptic", "ellipsoids", "--device", f"scripted:{script}", "--record", str(rec), "--quiet"]) in (0, 3)
    cap = capsys.readouterr()
    assert "recorded 200 ticks" in cap.out, cap.out
    warning = [line for line in cap.err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "the last 300 of 500 ticks were not recorded" in warning[0], cap.err


def test_haptic_command_seconds_records_every_tick(tmp_path, capsys):
    from palpate.cli import haptic as cli_haptic
    from palpate.cli import main

    # --seconds: the loop stops itself after S seconds of ticks, all in the buffer (stopped at
    # the next status line instead, it ran on past a buffer of S seconds and lost the rest).
    rec = tmp_path / "hand.palprec"
    assert main(["haptic", "ellipsoids", "--device", "hand", "--seconds", "0.3", "--record", str(rec), "--quiet"]) in (0, 3)
    cap = capsys.readouterr()
    assert "300 ticks" in cap.out and "recorded 300 ticks" in cap.out, cap.out
    assert "warning" not in cap.err, cap.err
    # Without --seconds: a bridge or a hand (no end) gets the default; a replay, at any rate, up
    # to 4 kHz for S seconds (the loop cuts the buffer to the recording).
    args = lambda **kw: types.SimpleNamespace(**{"record": "f", "seconds": None, "device": "hand", "rate": 1000.0, **kw})  # noqa: E731
    assert cli_haptic.record_ticks(args()) == cli_haptic.DEFAULT_RECORD_TICKS == 300_000
    assert cli_haptic.record_ticks(args(seconds=2.0, rate=2000.0)) == 4001
    assert cli_haptic.record_ticks(args(seconds=2.0, device="replay:x")) == 8001
    assert cli_haptic.record_ticks(args(record=None)) == 0


def test_soak_and_bench_haptic_commands(capsys):
    from palpate.cli import main

    assert main(["soak", "ellipsoids", "--minutes", "0.02", "--json"]) in (0, 3)
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["ticks"] == 1200 and r["n_faults"] <= r["watchdog_trips"] and "energy_into_user_j" in r and r["max_force_n"] >= 0
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.5", "--rate", "2000", "--json"]) in (0, 3)
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    for key in haptics.BENCH_KEYS:
        assert key in r, key
    assert r["ticks"] == 1000 and r["rate_hz"] == 2000.0
    assert r["idle"]["ticks"] == 1000
    # The multirate loop by default: the physics thread's figures, the force's largest steps.
    assert r["physics"]["rate_hz"] == 1000.0 and r["physics"]["ticks"] > 0, r["physics"]
    assert 0 <= r["max_force_step_contact_n"] <= r["max_force_step_n"]
    assert r["realtime"] == "off" and r["idle"]["realtime"] == "off"
    # Overruns split into the physics' own (CPU time past the period) and the machine's.
    for x in (r, r["idle"]):
        assert x["overruns_own"] + x["overruns_machine"] == x["overruns"] and x["overruns_own"] >= 0
        assert 0 <= x["cpu_us_p99"] <= x["compute_us_p99"] * 1.0001 + 1.0
    assert r["steal_s"] is None or r["steal_s"] >= 0
    # --realtime: SCHED_FIFO where privileged, else refused with the reason (crates/palpate-haptics/
    # tests/realtime.rs checks that a grant is real).
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.2", "--json", "--realtime"]) in (0, 3)
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["realtime"] == "SCHED_FIFO priority 80" or r["realtime"].startswith("refused: SCHED_FIFO"), r["realtime"]
    # --threads 2: the particle passes on two threads (the servo's and a helper); same physics.
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.3", "--json", "--no-idle", "--threads", "2"]) in (0, 3)
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["threads"] == 2 and r["ticks"] == 300 and r["n_faults"] <= r["watchdog_trips"] and "idle" not in r
    # --busy-wait: both runs' servo spins through its periods (same tick counts); not with --realtime.
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.3", "--json", "--busy-wait"]) in (0, 3)
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["busy_wait"] is True and r["ticks"] == 300 and r["idle"]["ticks"] == 300
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.2", "--busy-wait", "--realtime"]) == 2
    assert "--busy-wait and --realtime" in capsys.readouterr().err
    # The single-rate loop's default is the busy wait (without --realtime); the multirate loop's
    # servo sleeps (the physics thread needs the core); --sleep sleeps through each wait.
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.2", "--json", "--no-idle", "--single-rate"]) in (0, 3)
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["busy_wait"] is True
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.2", "--json", "--no-idle"]) in (0, 3)
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["busy_wait"] is False
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.2", "--json", "--no-idle", "--sleep"]) in (0, 3)
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["busy_wait"] is False and r["ticks"] == 200
    assert main(["bench", "haptic", "ellipsoids", "--busy-wait", "--sleep"]) == 2     # one or the other
    assert "not allowed with argument" in capsys.readouterr().err
    assert main(["bench", "haptic", "ellipsoids", "--seconds", "0.2", "--json", "--no-idle", "--single-rate"]) in (0, 3)
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["physics"] is None
    assert main(["bench", "haptic", "ellipsoids", "--single-rate", "--physics-rate", "500"]) == 2


def test_full_fem_body_hand_worst_stays_finite():
    """A hand's worst on a full-FEM body (issue 14) through the loop: a push aimed 25 mm into the
    tissue (a 5 N-scale push held by the coupling, the servo's limit at 5 N) and a 0.5 m/s slide
    over 50 mm and back: every force finite, no fault, the body touched. A wrong contact (no
    stability cap on the penalty, a reaction of the wrong sign) blows up or faults here."""
    from palpate.viewer.fem import load_fem_model

    _, m = load_fem_model("ellipsoid_192")
    free = np.flatnonzero(m.outer_free)
    pts = m.outer_points
    v = free[np.argmax(pts[free, 0] + 10 * (pts[free, 2] > 0.005))]
    p = pts[v]
    n = np.array([p[0], p[1], 0.0]) / np.hypot(p[0], p[1])
    r = 0.005
    c = lambda d, s: p + n * (r - d) + np.array([0.0, 0.0, s])      # noqa: E731
    times = [0.0, 0.6, 0.9, 1.0, 1.1, 1.3]
    knots = [c(-0.003, 0), c(-0.003, 0), c(0.025, 0), c(0.025, 0.05), c(0.025, 0), c(-0.003, 0)]
    loop = palpate.HapticLoop(m.body, m.material, "scripted", times=times, knots=knots, max_force=5.0,
                              record_ticks=2000)
    r = loop.run()
    assert r["n_faults"] == 0 and r["ticks"] > 1200, r
    rec = loop.recorded()
    assert np.isfinite(rec["force"]).all() and np.isfinite(rec["tool"]).all()
    assert r["max_force_n"] > 0.3 and r["max_force_n"] <= 5.0 + 1e-9, r
    with pytest.raises(palpate.ParameterTypeError, match="HybridModel or a Body"):
        palpate.HapticLoop(m.body.mesh, m.material, "hand", hand_start=p)


def test_unit_mistakes_warn_or_are_refused(model):
    """Issue 37: a hand target in mm (the same point 1000x farther), E in kPa or a tool radius in
    mm warn with ``UnitWarning`` (the target once a loop), and ``strict_units=True`` refuses
    them; plausible values say nothing."""
    import warnings

    p = np.asarray(model.outer_points).max(axis=0) + 0.01
    mat = haptics.material()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loop = palpate.HapticLoop(model, mat, "hand", hand_start=p, max_ticks=5)
        loop.set_hand_target(p - 0.005)
    with pytest.warns(palpate.UnitWarning, match="set_hand_target.*m from the organ"):
        loop.set_hand_target(p * 1e3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loop.set_hand_target(p * 1e3)                  # once a loop
    with pytest.warns(palpate.UnitWarning, match="hand_start.*m from the organ"):
        palpate.HapticLoop(model, mat, "hand", hand_start=p * 1e3, max_ticks=5)
    with pytest.warns(palpate.UnitWarning, match="typed in kPa"):
        palpate.HapticLoop(model, palpate.Material(young=30.0, poisson=0.4), "hand", hand_start=p, max_ticks=5)
    with pytest.raises(palpate.ParameterError, match=r"tool radius 5 m.*\(strict_units\)"):
        palpate.HapticLoop(model, mat, "hand", hand_start=p, tool_radius=5.0, strict_units=True)
    strict = palpate.HapticLoop(model, mat, "hand", hand_start=p, max_ticks=5, strict_units=True)
    with pytest.raises(palpate.ParameterError, match="m from the organ"):
        strict.set_hand_target(p * 1e3)


def test_contact_stiffness_is_per_unit_area(model):
    """The tool meets a full-FEM body's surface and a hybrid model's skin with a penalty per unit
    area (``tool_area_stiffness`` [N/m^3]); the per-point ``tool_stiffness`` [N/m] of before is
    refused, not silently reinterpreted."""
    from palpate.viewer.fem import load_fem_model

    _, m = load_fem_model("ellipsoid_192")
    p = m.outer_points[np.flatnonzero(m.outer_free)[0]]
    for k in (1e5, 1e9):
        loop = palpate.HapticLoop(m.body, m.material, "hand", hand_start=p + 0.02, tool_area_stiffness=k, max_ticks=10)
        assert loop.run()["ticks"] == 10
    with pytest.raises(TypeError, match="tool_stiffness"):
        palpate.HapticLoop(m.body, m.material, "hand", hand_start=p, tool_stiffness=60.0)
    with pytest.raises(palpate.ParameterError, match="tool_area_stiffness"):
        palpate.HapticLoop(m.body, m.material, "hand", hand_start=p, tool_area_stiffness=-1.0)
    hybrid = palpate.HapticLoop(model, haptics.material(), "hand", hand_start=p + 0.02, tool_area_stiffness=1e7, max_ticks=10)
    assert hybrid.run()["ticks"] == 10
    # A body's tick is not split over threads (the hybrid model's particle passes are).
    with pytest.raises(palpate.ParameterError, match="threads = 2: for a hybrid model only"):
        palpate.HapticLoop(m.body, m.material, "hand", hand_start=p, threads=2)
    # Nor has it a core under a shell for the tool's wall.
    with pytest.raises(palpate.ParameterError, match="core_contact_stiffness: for a hybrid model only"):
        palpate.HapticLoop(m.body, m.material, "hand", hand_start=p, core_contact_stiffness=2000.0)


def test_core_contact_stiffness_reaches_the_hybrid_loop(model):
    """``core_contact_stiffness`` [N/m] sets the hybrid loop's wall against the core's surface:
    it is part of the simulation's identity (a recording made with another wall is refused on
    replay), and a nonsense value is refused by name."""
    p = np.asarray(model.outer_points)[0] + 0.02
    a = palpate.HapticLoop(model, haptics.material(), "hand", hand_start=p, max_ticks=1)
    b = palpate.HapticLoop(model, haptics.material(), "hand", hand_start=p, max_ticks=1, core_contact_stiffness=500.0)
    c = palpate.HapticLoop(model, haptics.material(), "hand", hand_start=p, max_ticks=1, core_contact_stiffness=2000.0)
    assert a.identity != b.identity and a.identity == c.identity
    with pytest.raises(palpate.ParameterError, match="core_contact_stiffness"):
        palpate.HapticLoop(model, haptics.material(), "hand", hand_start=p, core_contact_stiffness=-1.0)


def test_limits_beyond_the_device_rating_are_refused_unless_asked(model):
    # The hostile run of issue 35: a 50 N limit with a Touch, a 100 s watchdog, both accepted.
    t, k = cycle(model)
    m = haptics.material()
    with pytest.raises(_p.ParameterError, match="rated 3.3 N"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, kind="geomagic", max_force=50.0)
    with pytest.raises(_p.ParameterError, match="rated 1020 N/m"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, kind="geomagic", coupling_stiffness=5000.0)
    # `touch`, the Geomagic Touch's former name, is the same make.
    with pytest.raises(_p.ParameterError, match="rated 3.3 N"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, kind="touch", max_force=50.0)
    with pytest.raises(_p.ParameterError, match="stall_timeout"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, stall_timeout=100.0)
    with pytest.raises(_p.ParameterError, match="silence"):
        _p.HapticLoop(model, m, "scripted", times=t, knots=k, silence=0.5)
    # The class's own rating: a HapticMaster may push 50 N.
    _p.HapticLoop(model, m, "scripted", times=t, knots=k, kind="hapticmaster", max_force=50.0)
    with pytest.warns(UserWarning, match="unsafe limits: max_force = 50 N"):
        loop = _p.HapticLoop(model, m, "scripted", times=t, knots=k, kind="touch", max_force=50.0,
                             unsafe_limits=True, max_ticks=5)
    assert "rated 3.3 N" in loop.run()["unsafe_limits"]
    assert _p.HapticLoop(model, m, "scripted", times=t, knots=k, max_ticks=5).run()["unsafe_limits"] is None


def test_cli_refuses_a_force_limit_beyond_the_device(tmp_path):
    r = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ellipsoids", "--device", "hand", "--kind", "touch", "--max-force", "50",
                        "--seconds", "0.05"], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert r.returncode != 0 and "rated 3.3 N" in r.stderr and "--unsafe-limits" in r.stderr, r.stderr
    r = subprocess.run([sys.executable, "-m", "palpate", "haptic", "ellipsoids", "--device", "hand", "--kind", "touch", "--max-force", "50",
                        "--unsafe-limits", "--seconds", "0.05"], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert r.returncode == 0 and "unsafe limits" in r.stderr, r.stderr


def test_ctrl_c_on_the_haptic_command_prints_its_summary_and_writes_the_recording(tmp_path):
    # A session is often ended with Ctrl-C: the loop stops as at --seconds, the summary is printed
    # and --record written, and the exit code says it was interrupted (130).
    import signal

    rec = tmp_path / "hand.palprec"
    # The child gets SIGINT's default disposition (a runner in the background ignores SIGINT and
    # its children inherit that: Python then installs no Ctrl-C handler; see test_cli).
    p = subprocess.Popen([sys.executable, "-m", "palpate", "haptic", "ellipsoids", "--device", "hand", "--seconds", "60",
                          "--record", str(rec), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert p.stdout.readline().startswith("palpate haptic:")   # the loop is built and starting
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 130, (p.returncode, out, err)
    assert "interrupted" in err and "Traceback" not in err, err
    assert "ticks in" in out and "recorded" in out, out
    assert rec.stat().st_size > 0


def test_devices_command_lists_every_device_and_how_to_run_it(capsys, monkeypatch):
    # Issue 37: devices you can find. The built-in ones need nothing; each vendor adapter names its
    # package (looked up, never imported), whether it is installed, and its two commands.
    import importlib.util

    from palpate.cli import main
    from palpate.devices import VENDORS

    assert main(["devices", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    names = [r["name"] for r in rows]
    assert names[:4] == ["hand", "scripted", "replay", "bridge"] and set(names[4:]) == set(VENDORS)
    for r in rows[4:]:
        module, package, extra, _ = VENDORS[r["name"]]
        assert r["kind"] == "vendor" and package in r["needs"] and f"the {extra} extra" in r["needs"]
        assert f"palpate device {r['name']}" in r["command"] and "--device bridge:" in r["command"]
        assert r["installed"] == (importlib.util.find_spec(module) is not None)
    # A package that Python can find is reported installed, without being imported.
    found = types.SimpleNamespace(name="pyOpenHaptics")
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda m, *a: found if m == "pyOpenHaptics" else real(m, *a))
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "geomagic (vendor): 3D Systems / Geomagic Touch (OpenHaptics; formerly `touch`)  [package installed]" in out
    assert "pyOpenHaptics" not in sys.modules or sys.modules["pyOpenHaptics"] is None
