"""What the viewer accepts from the page, and how much of it.

viser 1.1.1 accepts websocket messages of up to 50 MiB from a page (it raises websockets' limit
for its own screenshots) and as many as a page sends. The viewer's page sends only small messages
(camera moves, drags, GUI values: well under a kilobyte each), so :func:`install_message_bounds`
bounds each connection to :data:`MAX_MESSAGE_BYTES` a message (websockets closes a connection that
sends more, code 1009) and to :data:`MESSAGE_RATE` messages a second with bursts of
:data:`MESSAGE_BURST` (messages past that are dropped before viser decodes them, and a connection
that goes on flooding, :data:`FLOOD_DROPS` drops, is closed). viser has no public hook for this:
the bounds wrap its per-connection receive loop (``viser.infra._infra._message_consumer``), checked
to exist with the signature of the pinned version; where it does not, the viewer says so and runs
with the callback bounds only.

The callback bounds (:class:`TargetGuard`) apply whatever the transport: a target for the hand
must be three finite numbers, is clamped to a box around the model, and at most
:data:`TARGET_RATE` targets a second are taken (the browser sends about 20 a second while
dragging); the rest are counted and ignored.
"""
from __future__ import annotations

import inspect
import math
import threading
import time
from typing import Any, Callable, Dict, Optional, Sequence

import numpy as np

#: Largest websocket message a page may send [bytes].
MAX_MESSAGE_BYTES = 64 * 1024
#: Messages a second a page may send, sustained, and in a burst.
MESSAGE_RATE = 200.0
MESSAGE_BURST = 400
#: Dropped messages after which a connection is closed (a page that keeps flooding).
FLOOD_DROPS = 2000
#: Hand targets a second the viewer takes from the page.
TARGET_RATE = 100.0


class TokenBucket:
    """``rate`` tokens a second up to ``burst``; :meth:`take` spends one if there is one. Thread-safe."""

    def __init__(self, rate: float, burst: float, clock: Callable[[], float] = time.monotonic):
        self.rate, self.burst, self.clock = float(rate), float(burst), clock
        self.tokens = float(burst)
        self.t = clock()
        self.lock = threading.Lock()

    def take(self) -> bool:
        with self.lock:
            now = self.clock()
            self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
            self.t = now
            if self.tokens >= 1.0:
                self.tokens -= 1.0
                return True
            return False


class TargetGuard:
    """Checks a hand target from the page: three finite numbers [m], clamped to the box
    ``[lo, hi]`` (3,) [m], at most ``rate`` a second. :meth:`check` returns the point to use or
    None; ``accepted``, ``clamped``, ``non_finite`` and ``rate_limited`` count what happened."""

    def __init__(self, lo: Sequence[float], hi: Sequence[float], rate: float = TARGET_RATE,
                 clock: Callable[[], float] = time.monotonic):
        self.lo = np.asarray(lo, dtype=np.float64).reshape(3)
        self.hi = np.asarray(hi, dtype=np.float64).reshape(3)
        self.bucket = TokenBucket(rate, max(1.0, rate / 10.0), clock)
        self.accepted = self.clamped = self.non_finite = self.rate_limited = 0

    @classmethod
    def around(cls, points: np.ndarray, margin: float, **kw: Any) -> "TargetGuard":
        """A guard whose box is the bounding box of ``points`` (n, 3) [m] grown by ``margin`` [m]."""
        p = np.asarray(points, dtype=np.float64)
        return cls(p.min(axis=0) - margin, p.max(axis=0) + margin, **kw)

    def check(self, p: Any) -> Optional[np.ndarray]:
        try:
            v = np.asarray(p, dtype=np.float64)
        except (TypeError, ValueError):
            self.non_finite += 1
            return None
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            self.non_finite += 1
            return None
        if not self.bucket.take():
            self.rate_limited += 1
            return None
        c = np.clip(v, self.lo, self.hi)
        if not np.array_equal(c, v):
            self.clamped += 1
        self.accepted += 1
        return c

    def counts(self) -> Dict[str, int]:
        return {"accepted": self.accepted, "clamped": self.clamped, "non_finite": self.non_finite,
                "rate_limited": self.rate_limited}


def finite_number(x: Any, lo: float, hi: float, default: float) -> float:
    """A GUI number from the page: ``x`` clamped to ``[lo, hi]``, ``default`` if not a finite number."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return default
    if not math.isfinite(v):
        return default
    return min(hi, max(lo, v))


class MessageStats:
    """Counts of the transport bounds, over all connections (read by the viewer's status)."""

    def __init__(self) -> None:
        self.dropped = 0
        self.closed_flooding = 0
        self.lock = threading.Lock()

    def as_dict(self) -> Dict[str, int]:
        with self.lock:
            return {"dropped": self.dropped, "closed_flooding": self.closed_flooding}


#: The one set of counts (the bounds are process-wide: viser's receive loop is a module function).
STATS = MessageStats()
_installed: Optional[str] = None


def install_message_bounds(max_bytes: int = MAX_MESSAGE_BYTES, rate: float = MESSAGE_RATE,
                           burst: int = MESSAGE_BURST, flood_drops: int = FLOOD_DROPS) -> Optional[str]:
    """Bounds what every viser connection of this process accepts (see the module). Returns None
    when installed (or already), else why not (the viewer prints it as a warning)."""
    global _installed
    if _installed is not None:
        return None
    try:
        from viser.infra import _infra
    except ImportError as e:  # pragma: no cover - viser is there when the viewer runs
        return f"viser's transport is not importable ({e})"
    orig = getattr(_infra, "_message_consumer", None)
    if orig is None or not inspect.iscoroutinefunction(orig) or \
            list(inspect.signature(orig).parameters) != ["websocket", "handle_message", "message_class"]:
        return "this viser version's receive loop is not the one the bounds wrap (viser 1.1.1): messages are unbounded"

    async def bounded(websocket, handle_message, message_class):
        proto = getattr(websocket, "protocol", None)
        if proto is not None and hasattr(proto, "max_message_size"):
            proto.max_message_size = max_bytes      # websockets >= 13: read at each frame
        bucket = TokenBucket(rate, burst)
        drops = 0

        # The receive loop, as viser's, with the rate check before the decode.
        while True:
            raw = await websocket.recv()
            if not isinstance(raw, bytes):
                continue
            if not bucket.take():
                drops += 1
                with STATS.lock:
                    STATS.dropped += 1
                if drops >= flood_drops:
                    with STATS.lock:
                        STATS.closed_flooding += 1
                    await websocket.close(1008, "too many messages")
                    return
                continue
            handle_message(message_class.deserialize(raw))

    _infra._message_consumer = bounded
    _installed = "viser.infra._infra._message_consumer"
    return None
