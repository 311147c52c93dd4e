"""3D Systems (Geomagic) Touch through ``pyopenhaptics`` (module ``pyOpenHaptics``; the vendor's
OpenHaptics SDK underneath). Imported only when used.

Units and axes: OpenHaptics reports the stylus transform (4 x 4, column-major as OpenGL's: the
translation in row 3) in millimetres, in the device frame x to the user's right, y up, z toward
the user. The world frame is x right, y away from the user, z up, in metres:

    world = 1e-3 * (x_dev, -z_dev, y_dev)          force_dev = (F_x, F_z, -F_y)

(then :class:`~palpate.devices.bridge.Placement`). The orientation is mapped by the same axis
change (``R_world = A R_dev A^T``). Buttons: OpenHaptics' bit mask as is. The OpenHaptics
scheduler calls the adapter's callback at its own 1 kHz: the callback copies the state out and
applies the newest force; the bridge loop never runs inside it.
"""
from __future__ import annotations

import threading
from typing import Sequence, Tuple

import numpy as np

from . import import_vendor
from .bridge import Adapter, Placement

#: Device axes -> world axes (rows: world x, y, z in device coordinates).
AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
MM = 1e-3


def quaternion(r: np.ndarray) -> Tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a rotation matrix (3, 3)."""
    w = np.sqrt(max(0.0, 1.0 + np.trace(r))) / 2.0
    if w > 1e-6:
        return (w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w))
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = np.sqrt(max(0.0, 1.0 + r[i, i] - r[j, j] - r[k, k])) * 2.0
    q = [0.0, 0.0, 0.0, 0.0]
    q[0] = (r[k, j] - r[j, k]) / s
    q[1 + i] = s / 4
    q[1 + j] = (r[j, i] + r[i, j]) / s
    q[1 + k] = (r[k, i] + r[i, k]) / s
    return tuple(q)  # type: ignore[return-value]


class TouchAdapter(Adapter):
    name = "geomagic"

    def __init__(self, placement: Placement = Placement(), device_name: str = "Default Device"):
        self.placement, self.device_name = placement, device_name
        self._lock = threading.Lock()
        self._state = (np.zeros(3), (1.0, 0.0, 0.0, 0.0), 0)
        self._force = np.zeros(3)
        self._device = None

    def _callback(self) -> None:
        t = np.asarray(self._hd.get_transform(), dtype=np.float64).reshape(4, 4)
        p_dev = t[3, :3]
        r_dev = t[:3, :3].T              # column-major: the rotation's columns are t's rows
        pos = self.placement.position(MM * (AXES @ p_dev))
        q = quaternion(AXES @ r_dev @ AXES.T)
        buttons = int(self._hd.get_buttons())
        with self._lock:
            self._state = (pos, q, buttons)
            f = self._force
        self._hd.set_force([float(v) for v in AXES.T @ f])

    def open(self) -> None:
        vendor = import_vendor("geomagic")
        import importlib

        self._hd = importlib.import_module(vendor.__name__ + ".hd")
        hd_callback = importlib.import_module(vendor.__name__ + ".hd_callback").hd_callback
        HapticDevice = importlib.import_module(vendor.__name__ + ".hd_device").HapticDevice
        self._device = HapticDevice(device_name=self.device_name, callback=hd_callback(self._callback))

    def read(self) -> Tuple[np.ndarray, Sequence[float], int]:
        with self._lock:
            return self._state

    def write(self, force: np.ndarray) -> None:
        with self._lock:
            self._force = np.asarray(force, dtype=np.float64).reshape(3).copy()

    def close(self) -> None:
        if self._device is not None:
            self._device.close()
            self._device = None
