"""Moog (FCS) HapticMaster, the paper's device, over TCP through ``haptic-master`` (module
``haptic_master``). Imported only when used.

The HapticMaster is admittance-controlled: the adapter puts it in its force state and renders
the loop's force as a bias force. Units and axes: ``get_position()`` in metres in the device's
base frame, taken as the world frame's axes:

    world = p_dev                            bias force = F

(then :class:`~palpate.devices.bridge.Placement`). Orientation: identity. Buttons: none (0).
"""
from __future__ import annotations

import importlib
from typing import Sequence, Tuple

import numpy as np

from . import import_vendor
from .bridge import Adapter, Placement


class HapticMasterAdapter(Adapter):
    name = "hapticmaster"

    def __init__(self, placement: Placement = Placement(), ip: str = "192.168.0.25", port: int = 7654):
        self.placement, self.ip, self.tcp_port = placement, ip, port
        self._robot = None
        self._bias = None

    def open(self) -> None:
        vendor = import_vendor("hapticmaster")
        HapticMaster = importlib.import_module(vendor.__name__ + ".haptic_master").HapticMaster
        try:
            BiasForce = importlib.import_module(vendor.__name__ + ".effect").BiasForce
        except (ImportError, AttributeError):  # the package's earlier layout
            BiasForce = importlib.import_module(vendor.__name__ + ".bias_force").BiasForce
        self._robot = HapticMaster(self.ip, self.tcp_port)
        self._robot.connect()
        self._bias = BiasForce("palpateBias")
        self._robot.create_bias_force(self._bias)
        self._robot.set_state("force")

    def read(self) -> Tuple[np.ndarray, Sequence[float], int]:
        p = np.asarray(self._robot.get_position(), dtype=np.float64)
        return self.placement.position(p), (1.0, 0.0, 0.0, 0.0), 0

    def write(self, force: np.ndarray) -> None:
        self._bias.force = [float(v) for v in np.asarray(force, dtype=np.float64)]
        self._robot.set_bias_force(self._bias)

    def close(self) -> None:
        if self._robot is not None:
            self.write(np.zeros(3))
            self._robot.disconnect()
            self._robot = None
