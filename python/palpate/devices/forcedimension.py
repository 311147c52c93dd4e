"""Force Dimension devices (omega, delta, sigma, lambda) and the Novint Falcon through
``forcedimension-core`` (module ``forcedimension_core``; the vendor's SDK underneath). Imported
only when used.

Units and axes: the SDK reports the end effector in metres in its base frame, x toward the user,
y to the user's right, z up. The world frame is x right, y away from the user, z up:

    world = (y_dev, -x_dev, z_dev)          force_dev = (-F_y, F_x, F_z)

(then :class:`~palpate.devices.bridge.Placement`). Orientation: identity (the 3-DOF devices have
none). Buttons: ``dhd.getButtonMask()``.
"""
from __future__ import annotations

from typing import Sequence, Tuple

import numpy as np

from . import import_vendor
from .bridge import Adapter, Placement

#: Device axes -> world axes (rows: world x, y, z in device coordinates).
AXES = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


class ForceDimensionAdapter(Adapter):
    name = "forcedimension"

    def __init__(self, placement: Placement = Placement()):
        self.placement = placement
        self._dhd = None
        self._pos = [0.0, 0.0, 0.0]

    def open(self) -> None:
        vendor = import_vendor("forcedimension")
        dhd = vendor.dhd
        if dhd.open() == -1:
            raise OSError(f"palpate device forcedimension: no device: {dhd.errorGetLastStr()}")
        self._dhd = dhd

    def read(self) -> Tuple[np.ndarray, Sequence[float], int]:
        if self._dhd.getPosition(out=self._pos) == -1:
            raise OSError(f"palpate device forcedimension: getPosition failed: {self._dhd.errorGetLastStr()}")
        pos = self.placement.position(AXES @ np.asarray(self._pos, dtype=np.float64))
        return pos, (1.0, 0.0, 0.0, 0.0), int(self._dhd.getButtonMask())

    def write(self, force: np.ndarray) -> None:
        f = AXES.T @ np.asarray(force, dtype=np.float64)
        self._dhd.setForce([float(v) for v in f])

    def close(self) -> None:
        if self._dhd is not None:
            self._dhd.setForce([0.0, 0.0, 0.0])
            self._dhd.close()
            self._dhd = None
