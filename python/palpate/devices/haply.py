"""Haply Inverse3 through ``HaplyHardwareAPI``. Imported only when used.

Units and axes: ``Inverse3.end_effector_force(force)`` sends a force [N] and returns the
position [m] and velocity in the device's base frame, which is taken as the world frame's axes
(x right, y away from the user, z up, for the device set up facing the user):

    world = p_dev                            force_dev = F

(then :class:`~palpate.devices.bridge.Placement`: its ``offset`` moves the Inverse3's workspace,
which does not start at the origin, over the organ). Orientation: identity (the VerseGrip's is
not read). Buttons: none (0).
"""
from __future__ import annotations

from typing import Sequence, Tuple

import numpy as np

from . import import_vendor
from .bridge import Adapter, Placement


class HaplyAdapter(Adapter):
    name = "haply"

    def __init__(self, placement: Placement = Placement(), port: str = ""):
        self.placement, self.port = placement, port
        self._dev = None
        self._force = [0.0, 0.0, 0.0]

    def open(self) -> None:
        api = import_vendor("haply")
        port = self.port or (api.detect_inverse3s() or [None])[0]
        if port is None:
            raise OSError("palpate device haply: no Inverse3 found")
        self._dev = api.Inverse3(api.SerialStream(port))
        self._dev.device_wakeup_dict()

    def read(self) -> Tuple[np.ndarray, Sequence[float], int]:
        # One exchange: the last force out, the position back.
        position, _velocity = self._dev.end_effector_force(self._force)
        return self.placement.position(np.asarray(position, dtype=np.float64)), (1.0, 0.0, 0.0, 0.0), 0

    def write(self, force: np.ndarray) -> None:
        self._force = [float(v) for v in np.asarray(force, dtype=np.float64)]

    def close(self) -> None:
        if self._dev is not None:
            self._dev.end_effector_force([0.0, 0.0, 0.0])
            self._dev = None
