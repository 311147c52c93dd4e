"""The reference bridge client (pure Python) and the adapter loop.

:class:`BridgeClient` encodes and decodes the bridge protocol, version 1
(``crates/palpate-haptics/PROTOCOL.md``): it sends *state* packets (position [m], orientation
quaternion (w, x, y, z), buttons; 80 bytes) to the haptic loop and receives *force* packets
(force [N] on the hand, the loop's sequence number, the acknowledged state sequence number, a
"zeroed" flag; 48 bytes). :func:`run_adapter` runs a device adapter against it: read the device,
send its state, apply the newest force, and zero the device's force if the loop goes silent for
30 ms (the protocol's rule for clients).
"""
from __future__ import annotations

import math
import socket
import struct
import time
from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple

import numpy as np

MAGIC = 0x4850_4C50
VERSION = 1
KIND_STATE, KIND_FORCE = 1, 2
STATE = struct.Struct("<IHHII3d4dII")     # 80 bytes
FORCE = struct.Struct("<IHHII3dII")       # 48 bytes
FLAG_ZEROED = 1
#: A client zeroes its device's force when no force packet came for this long [s].
SILENCE_S = 0.030

assert STATE.size == 80 and FORCE.size == 48


def encode_state(seq: int, position: Sequence[float], orientation: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
                 buttons: int = 0) -> bytes:
    """A state packet: ``position`` (3,) [m], ``orientation`` (w, x, y, z), ``buttons`` bit mask."""
    p = [float(v) for v in position]
    q = [float(v) for v in orientation]
    return STATE.pack(MAGIC, VERSION, KIND_STATE, seq & 0xFFFF_FFFF, 0, *p, *q, int(buttons) & 0xFFFF_FFFF, 0)


@dataclass
class ForcePacket:
    seq: int
    ack: int
    force: np.ndarray
    zeroed: bool


def decode_force(b: bytes) -> Optional[ForcePacket]:
    """A force packet, or None if ``b`` is not a valid one (size, header, finite values)."""
    if len(b) != FORCE.size:
        return None
    magic, version, kind, seq, ack, fx, fy, fz, flags, _ = FORCE.unpack(b)
    if magic != MAGIC or version != VERSION or kind != KIND_FORCE or not all(map(math.isfinite, (fx, fy, fz))):
        return None
    return ForcePacket(seq, ack, np.array([fx, fy, fz]), bool(flags & FLAG_ZEROED))


class BridgeClient:
    """A client of the haptic loop's bridge at ``host:port`` (UDP, from an ephemeral port)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 5005):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect((host, int(port)))
        self.seq = 0

    def send(self, position: Sequence[float], orientation: Sequence[float] = (1.0, 0.0, 0.0, 0.0), buttons: int = 0) -> int:
        """Sends the next state; returns its sequence number."""
        self.seq = (self.seq + 1) & 0xFFFF_FFFF
        self.sock.send(encode_state(self.seq, position, orientation, buttons))
        return self.seq

    def send_raw(self, b: bytes) -> None:
        self.sock.send(b)

    def recv(self, timeout: float = 0.0) -> Optional[ForcePacket]:
        """The next valid force packet within ``timeout`` [s] (0: only if one is waiting), else None."""
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
            f = decode_force(b)
            if f is not None:
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
                seconds: Optional[float] = None, on_status: Optional[Callable[[str], None]] = None) -> dict:
    """Runs ``adapter`` against the loop's bridge until ``seconds`` pass (None: Ctrl-C). Returns
    ``sent``, ``forces``, ``silences`` (times the device's force was zeroed because the loop went
    silent for :data:`SILENCE_S`), ``max_force_n``."""
    client = BridgeClient(host, port)
    adapter.open()
    period = 1.0 / rate_hz
    stats = {"sent": 0, "forces": 0, "silences": 0, "max_force_n": 0.0}
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
