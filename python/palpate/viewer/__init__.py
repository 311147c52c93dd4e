"""``palpate view``: see the haptic loop and touch it in a browser (issue 14).

:class:`Viewer` serves a web page (viser, on 127.0.0.1 unless told otherwise) showing the outer
surface of a hybrid model as the running :class:`palpate.HapticLoop` deforms it, coloured by
displacement (a colour bar in mm), the tool sphere, the force on the hand (an arrow), and a live
plot of the force and the loop's rate. Dragging on the surface, or the gizmo, moves the target of
the loop's simulated hand; a bridge device drives the same view. The viewer reads the loop's
snapshots at its own rate and never waits on the loop, nor the loop on it.

:func:`palpate.viewer.browser.screenshot` renders a frame with the system's headless Chromium.
Who may open the page and its WebSocket (the viewer's own loopback origin, or the viewer's
token): :mod:`palpate.viewer.origin`.
Needs the ``view`` extra (viser, and Playwright for pictures).
"""
from __future__ import annotations

from .app import DEVICES, PRESETS, Viewer
from .guard import TargetGuard, install_message_bounds
from .origin import OriginCheckUnavailable, RequestPolicy

__all__ = ["DEVICES", "OriginCheckUnavailable", "PRESETS", "RequestPolicy", "TargetGuard", "Viewer",
           "install_message_bounds"]
