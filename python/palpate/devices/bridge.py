"""The reference bridge client (pure Python) and the adapter loop.

:class:`BridgeClient` speaks the bridge protocol, version 2 (``crates/palpate-haptics/PROTOCOL.md``):
it opens a session with a *hello* (the loop answers *welcome* with a random session id, or
*refused* with the reason), then sends *state* packets (position [m], orientation quaternion
(w, x, y, z), buttons; 112 bytes) naming that session, and receives the session's *force* packets
(force [N] on the hand, the loop's sequence number, the acknowledged state sequence number, a
"zeroed" flag; 88 bytes). With a shared key (``key=``, at least 16 bytes; required by a loop bound
beyond 127.0.0.1) every packet ends in an HMAC-SHA256 tag of its other bytes. :func:`run_adapter`
runs a device adapter against it: read the device, send its state, apply the newest force, and
zero the device's force if the loop goes silent for 30 ms (the protocol's rule for clients).
"""
from __future__ import annotations

import hashlib
import hmac
import math
import secrets
import socket
import struct
import time
from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple

import numpy as np

from .._palpate import HapticsError

MAGIC = 0x4850_4C50
VERSION = 2
KIND_STATE, KIND_FORCE, KIND_HELLO, KIND_WELCOME, KIND_REFUSED = 1, 2, 3, 4, 5
TAG_BYTES = 32
MIN_KEY_BYTES = 16
STATE = struct.Struct("<IHHQII3d4d32s")   # 112 bytes: header, seq, buttons, position, orientation, tag
FORCE = struct.Struct("<IHHQII3dII32s")   # 88 bytes: header, seq, ack, force, flags, reserved, tag
HANDSHAKE = struct.Struct("<IHHQQII32s")  # 64 bytes: header, nonce, reason, reserved, tag
FLAG_ZEROED = 1
#: Why a loop refuses a hello (the refused packet's reason code).
REFUSALS = {1: "another client holds the tool (the loop hands it over once that client has been silent "
               "for the hand-over time, 0.5 s)",
            2: "the loop requires a shared key and this client's does not match (--key-file)"}
#: A client zeroes its device's force when no force packet came for this long [s].
SILENCE_S = 0.030

assert STATE.size == 112 and FORCE.size == 88 and HANDSHAKE.size == 64


class BridgeRefused(HapticsError):
    """The loop refused the session (another client holds the tool, or the key does not match),
    or never answered."""


def load_key(path: str) -> bytes:
    """The shared key in file ``path``: its bytes, trailing whitespace removed (at least 16 bytes;
    ``python -c "import secrets; print(secrets.token_hex(32))" > bridge.key`` makes one)."""
    try:
        with open(path, "rb") as f:
            key = f.read().rstrip()
    except OSError as e:
        raise HapticsError(f"cannot read the bridge key {path}: {e.strerror or e}") from None
    if len(key) < MIN_KEY_BYTES:
        raise HapticsError(f"the bridge key {path} has {len(key)} bytes: at least {MIN_KEY_BYTES} are needed")
    return key


def _seal(body: bytes, key: Optional[bytes]) -> bytes:
    return body + (hmac.new(key, body, hashlib.sha256).digest() if key else bytes(TAG_BYTES))


def _verifies(b: bytes, key: Optional[bytes]) -> bool:
    return key is None or hmac.compare_digest(hmac.new(key, b[:-TAG_BYTES], hashlib.sha256).digest(), b[-TAG_BYTES:])


def encode_state(session: int, seq: int, position: Sequence[float], orientation: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
                 buttons: int = 0, key: Optional[bytes] = None) -> bytes:
    """A state packet of ``session``: ``position`` (3,) [m], ``orientation`` (w, x, y, z), ``buttons``
    bit mask, signed with ``key`` if given."""
    p = [float(v) for v in position]
    q = [float(v) for v in orientation]
    body = STATE.pack(MAGIC, VERSION, KIND_STATE, session & 0xFFFF_FFFF_FFFF_FFFF, seq & 0xFFFF_FFFF,
                      int(buttons) & 0xFFFF_FFFF, *p, *q, bytes(TAG_BYTES))[:-TAG_BYTES]
    return _seal(body, key)


def encode_hello(nonce: int, key: Optional[bytes] = None) -> bytes:
    """A hello asking for a session; ``nonce`` comes back in the answer."""
    return _seal(HANDSHAKE.pack(MAGIC, VERSION, KIND_HELLO, 0, nonce, 0, 0, bytes(TAG_BYTES))[:-TAG_BYTES], key)


@dataclass
class ForcePacket:
    session: int
    seq: int
    ack: int
    force: np.ndarray
    zeroed: bool


def decode_force(b: bytes, key: Optional[bytes] = None) -> Optional[ForcePacket]:
    """A force packet, or None if ``b`` is not a valid one (size, header, tag with ``key``, finite
    values)."""
    if len(b) != FORCE.size:
        return None
    magic, version, kind, session, seq, ack, fx, fy, fz, flags, _, _ = FORCE.unpack(b)
    if magic != MAGIC or version != VERSION or kind != KIND_FORCE or not _verifies(b, key):
        return None
    if not all(map(math.isfinite, (fx, fy, fz))):
        return None
    return ForcePacket(session, seq, ack, np.array([fx, fy, fz]), bool(flags & FLAG_ZEROED))


def decode_handshake(b: bytes, key: Optional[bytes] = None) -> Optional[Tuple[int, int, int, int]]:
    """``(kind, session, nonce, reason)`` of a welcome or refused packet, or None (a refusal is
    never signed: it is advice, and opens nothing)."""
    if len(b) != HANDSHAKE.size:
        return None
    magic, version, kind, session, nonce, reason, _, _ = HANDSHAKE.unpack(b)
    if magic != MAGIC or version != VERSION or kind not in (KIND_WELCOME, KIND_REFUSED):
        return None
    if kind == KIND_WELCOME and not _verifies(b, key):
        return None
    return kind, session, nonce, reason


class BridgeClient:
    """A client of the haptic loop's bridge at ``host:port`` (UDP, from an ephemeral port). The
    constructor opens the session (waiting up to ``timeout`` [s] while the loop is busy with
    another client or not yet listening); ``key`` (bytes, see :func:`load_key`) signs every packet.
    Raises :class:`BridgeRefused` with the loop's reason."""

    def __init__(self, host: str = "127.0.0.1", port: int = 5005, key: Optional[bytes] = None, timeout: float = 5.0):
        if key is not None and len(key) < MIN_KEY_BYTES:
            raise HapticsError(f"a bridge key needs at least {MIN_KEY_BYTES} bytes, got {len(key)}")
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect((host, int(port)))
        self.address = f"{host}:{int(port)}"
        self.key = key
        self.session = 0
        self.seq = 0
        try:
            self.open_session(timeout)
        except BaseException:
            self.sock.close()
            raise

    def open_session(self, timeout: float = 5.0) -> int:
        """A hello every 20 ms until the loop welcomes it (returns the session id) or ``timeout``
        passes; a wrong key ends it at once. The state sequence starts again from 1."""
        nonce = secrets.randbits(64) or 1
        deadline = time.monotonic() + timeout
        refused = None
        while time.monotonic() < deadline:
            try:
                self.sock.send(encode_hello(nonce, self.key))
            except ConnectionRefusedError:
                pass                                      # not listening yet: ask again
            wait_until = min(deadline, time.monotonic() + 0.02)
            while (left := wait_until - time.monotonic()) > 0:
                self.sock.settimeout(left)
                try:
                    b = self.sock.recv(256)
                except (socket.timeout, BlockingIOError, ConnectionRefusedError):
                    break
                h = decode_handshake(b, self.key)
                if h is None or h[2] != nonce:
                    continue
                kind, session, _, reason = h
                if kind == KIND_WELCOME:
                    self.session, self.seq = session, 0
                    return session
                refused = REFUSALS.get(reason, f"reason {reason}")
                if reason == 2:
                    raise BridgeRefused(f"the loop at {self.address} refused the session: {refused}")
        if refused:
            raise BridgeRefused(f"the loop at {self.address} refused the session: {refused}")
        raise BridgeRefused(f"no answer from the loop at {self.address} within {timeout:g} s: is `palpate haptic "
                            f"MODEL --device bridge:PORT` running there, and does it speak protocol version {VERSION}?")

    def send(self, position: Sequence[float], orientation: Sequence[float] = (1.0, 0.0, 0.0, 0.0), buttons: int = 0) -> int:
        """Sends the next state; returns its sequence number."""
        self.seq = (self.seq + 1) & 0xFFFF_FFFF
        self.sock.send(encode_state(self.session, self.seq, position, orientation, buttons, self.key))
        return self.seq

    def send_raw(self, b: bytes) -> None:
        self.sock.send(b)

    def recv(self, timeout: float = 0.0) -> Optional[ForcePacket]:
        """The next valid force packet of this session within ``timeout`` [s] (0: only if one is
        waiting), else None."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            self.sock.settimeout(max(left, 0.0) if timeout > 0 else 0.0)
            try:
                b = self.sock.recv(FORCE.size + 1)
            except (BlockingIOError, socket.timeout):
                return None
            except ConnectionRefusedError:
                # The loop is not (yet) listening: nothing to receive.
                return None
            f = decode_force(b, self.key)
            if f is not None and f.session == self.session:
                return f

    def latest(self) -> Optional[ForcePacket]:
        """The newest force packet waiting (draining the others), or None."""
        last = None
        while (f := self.recv(0.0)) is not None:
            last = f
        return last

    def close(self) -> None:
        self.sock.close()


class Adapter:
    """A device as :func:`run_adapter` drives it: ``open()``, ``read() -> (position (3,) [m],
    orientation (w, x, y, z), buttons)`` in the world frame, ``write(force (3,) [N])`` in the world
    frame, ``close()``. Subclasses map their device's units and axes."""

    name = "device"

    def open(self) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def read(self) -> Tuple[np.ndarray, Sequence[float], int]:  # pragma: no cover - interface
        raise NotImplementedError

    def write(self, force: np.ndarray) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def close(self) -> None:
        pass


class Placement:
    """``world = scale * mapped + offset`` for positions; forces are not scaled."""

    def __init__(self, scale: float = 1.0, offset: Sequence[float] = (0.0, 0.0, 0.0)):
        if not (scale > 0 and math.isfinite(scale)):
            raise ValueError(f"scale = {scale} must be positive and finite")
        self.scale = float(scale)
        self.offset = np.asarray(offset, dtype=np.float64).reshape(3)

    def position(self, mapped: np.ndarray) -> np.ndarray:
        return self.scale * np.asarray(mapped, dtype=np.float64) + self.offset


def run_adapter(adapter: Adapter, host: str = "127.0.0.1", port: int = 5005, rate_hz: float = 1000.0,
                seconds: Optional[float] = None, on_status: Optional[Callable[[str], None]] = None,
                key: Optional[bytes] = None) -> dict:
    """Runs ``adapter`` against the loop's bridge until ``seconds`` pass (None: Ctrl-C), in a
    session opened with ``key`` if given. Returns ``sent``, ``forces``, ``silences`` (times the
    device's force was zeroed because the loop went silent for :data:`SILENCE_S`),
    ``max_force_n``, ``session``."""
    # The device first: a missing vendor package or an unplugged device is said at once, before
    # the session waits for a loop (up to its timeout).
    adapter.open()
    try:
        client = BridgeClient(host, port, key=key)
    except BaseException:
        adapter.close()
        raise
    period = 1.0 / rate_hz
    stats = {"sent": 0, "forces": 0, "silences": 0, "max_force_n": 0.0, "session": client.session}
    last_force_t = time.monotonic()
    silent = False
    t0 = next_t = time.monotonic()
    try:
        while seconds is None or time.monotonic() - t0 < seconds:
            p, q, b = adapter.read()
            client.send(p, q, b)
            stats["sent"] += 1
            f = client.latest()
            now = time.monotonic()
            if f is not None:
                adapter.write(f.force)
                stats["forces"] += 1
                stats["max_force_n"] = max(stats["max_force_n"], float(np.linalg.norm(f.force)))
                last_force_t, silent = now, False
            elif not silent and now - last_force_t > SILENCE_S:
                adapter.write(np.zeros(3))
                stats["silences"] += 1
                silent = True
            if on_status is not None and stats["sent"] % max(1, int(rate_hz)) == 0:
                on_status(f"sent {stats['sent']}, forces {stats['forces']}, max force {stats['max_force_n']:.3f} N")
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.monotonic()
    finally:
        try:
            adapter.write(np.zeros(3))
        finally:
            adapter.close()
            client.close()
    return stats
