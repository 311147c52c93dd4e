"""The viewer: :class:`Viewer`, a viser server over a running :class:`palpate.HapticLoop`.

Threads: the servo loop is native (Rust, 1 kHz) and never waits on Python; the viewer's frame
thread reads the loop's snapshots (:meth:`HapticLoop.snapshot`, :meth:`HapticLoop.surface`, both
non-blocking) at ``fps`` and pushes them to the page; viser's callbacks (the page's drags, gizmo
moves, GUI values) only validate a value and store it (a hand target is one atomic store into the
loop, :meth:`HapticLoop.set_hand_target`). A restart (reset, a new material, tool radius or
device) builds the next loop in a helper thread.

The scene is drawn in millimetres (the model's world frame scaled by 1000): viser's camera,
gizmo and point sizes suit an object of tens of units.
"""
from __future__ import annotations

import contextlib
import io
import math
import os
import threading
import time
from collections import deque
from typing import Any, Callable, Deque, Dict, Optional, Tuple

import numpy as np

from .. import _palpate as _p
from ..haptics import DEVICE_KINDS, device_kind
from . import colors
from .fem import FemModel, loop_model
from .guard import STATS, TargetGuard, finite_number, install_message_bounds
from .origin import OriginCheckUnavailable, checking, policy_for

#: Scene units per metre (the scene is in millimetres).
MM = 1000.0
#: Material presets of the GUI: name -> Material factory.
PRESETS: Dict[str, Callable[[], "_p.Material"]] = {}
#: Devices of the GUI.
DEVICES = ("hand", "bridge")
#: Tool radius bounds [m] (the GUI slider's, and what the viewer accepts).
TOOL_RADIUS_RANGE = (0.001, 0.015)
#: Press depth bounds [m] for a drag on the surface.
PRESS_RANGE = (0.0, 0.010)
#: Seconds of history in the live plot.
PLOT_SECONDS = 10.0
#: Force arrow: it starts on the tool sphere and is this long per newton [m/N].
ARROW_M_PER_N = 0.050
#: How far the hand lifts off when a drag ends [m] (beyond the press depth).
LIFT = 0.008


#: Niceness of the viewer's frame thread (Linux: per thread).
FRAME_NICE = 10


def lower_priority(tid: int, nice: int) -> bool:
    """Lowers thread or process ``tid``'s CPU priority to niceness ``nice`` (Linux: a thread id
    works); returns whether it did (False where the OS does not allow it)."""
    try:
        os.setpriority(os.PRIO_PROCESS, tid, max(os.getpriority(os.PRIO_PROCESS, tid), nice))
        return True
    except (AttributeError, OSError):
        return False


def _presets() -> Dict[str, Callable[[], "_p.Material"]]:
    if not PRESETS:
        from .. import haptics

        PRESETS["haptic (30 kPa, damped)"] = haptics.material
        PRESETS["myocardium"] = _p.Material.myocardium
        PRESETS["paper ellipsoids"] = _p.Material.paper_ellipsoids
    return PRESETS


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 and math.isfinite(n) else fallback


class Viewer:
    """A web viewer of the haptic loop on ``model`` (a :class:`palpate.HybridModel`, or a
    full-FEM :class:`palpate.viewer.fem.FemModel`: a tet mesh or a scene's body), served by viser
    on ``host``:``port`` (``port=0``: a free one; :attr:`url`).

    ``device`` ``"hand"``: a simulated hand the page moves (drag on the surface, or the gizmo);
    ``"bridge"``: a real device through the UDP bridge on ``bridge_host``:``bridge_port``
    (:attr:`bridge_address`; ``bridge_key``, bytes, signs its packets and is required for a
    ``bridge_host`` beyond loopback: ``crates/palpate-haptics/PROTOCOL.md``). ``preset`` is a key of :data:`PRESETS`, ``tool_radius`` [m],
    ``press_depth`` [m] how deep a drag on the surface presses, ``fps`` the viewer's update rate
    [Hz] (the loop's is ``rate_hz``); ``show_core``, ``show_particles``: draw the core's tets and
    the active particles from the start (the GUI's "Show" boxes); ``realtime``: the servo under
    ``SCHED_FIFO`` (:class:`palpate.HapticLoop`), so that the browser and the viewer's own threads
    cannot preempt a tick; ``physics_rate`` [Hz] and ``single_rate``: the loop's physics thread
    (:class:`palpate.HapticLoop`; default: multirate, the physics at 1 kHz); ``unsafe_limits``: a
    ``max_force`` above the device class's rating allowed (:class:`palpate.HapticLoop`); ``kind``: the
    device's make (:data:`palpate.haptics.DEVICE_KINDS`; default: the loop's for the device), which
    sets the coupling's and the safety's defaults and limits. A full-FEM model draws its boundary faces as the surface and its tets
    as the "core"; a scene's material is the first preset ("scene: ..."). Raises
    :class:`palpate.ParameterError` for a bad value.

    Who may open the page and its WebSocket (:mod:`palpate.viewer.origin`): pages of the viewer's
    own loopback origin, and anything with the viewer's ``token`` (``None``: a random one,
    :attr:`token`) in its URL (``?token=``) or the cookie a page loaded with it gets;
    ``require_token`` (always so when ``host`` is not loopback): nothing without the token, and
    :attr:`url` carries it (as it does for a token given here). Raises
    :class:`palpate.viewer.origin.OriginCheckUnavailable` (a ``RuntimeError``) rather than serve
    unchecked when the installed viser cannot be hooked.
    :meth:`close` stops the loop and the server."""

    def __init__(self, model: "_p.HybridModel | FemModel", name: str = "model", *, host: str = "127.0.0.1", port: int = 8080,
                 device: str = "hand", bridge_host: str = "127.0.0.1", bridge_port: int = 0,
                 preset: Optional[str] = None, tool_radius: float = 0.005, press_depth: float = 0.003,
                 rate_hz: float = 1000.0, fps: float = 30.0, max_force: Optional[float] = None,
                 show_core: bool = False, show_particles: bool = False, realtime: bool = False,
                 physics_rate: Optional[float] = None, single_rate: bool = False, unsafe_limits: bool = False,
                 token: Optional[str] = None, require_token: bool = False, bridge_key: Optional[bytes] = None,
                 kind: Optional[str] = None):
        self.fem = isinstance(model, FemModel)
        # The bridge's shared key (PROTOCOL.md; required beyond loopback): kept out of the
        # settings, which the page shows.
        self._bridge_key = bridge_key
        presets = dict(_presets())
        if self.fem and model.material is not None:
            m = model.material
            # The scene's own material first (the default), beside the viewer's presets.
            presets = {f"scene: {m.young / 1e3:g} kPa, nu {m.poisson:g}": (lambda: m), **presets}
        self.presets = presets
        preset = preset if preset is not None else next(iter(presets))
        if preset not in presets:
            raise _p.ParameterError(f"preset {preset!r}: expected one of {', '.join(presets)}")
        if device not in DEVICES:
            raise _p.ParameterError(f"device {device!r}: expected one of {', '.join(DEVICES)}")
        kind = None if kind is None else device_kind(kind)
        if kind is not None and kind not in DEVICE_KINDS:
            raise _p.ParameterError(f"kind {kind!r}: expected one of {', '.join(DEVICE_KINDS)}")
        lo, hi = TOOL_RADIUS_RANGE
        if not (math.isfinite(tool_radius) and lo <= tool_radius <= hi):
            raise _p.ParameterError(f"tool_radius = {tool_radius} m: expected {lo} to {hi} m")
        if not (math.isfinite(press_depth) and PRESS_RANGE[0] <= press_depth <= PRESS_RANGE[1]):
            raise _p.ParameterError(f"press_depth = {press_depth} m: expected {PRESS_RANGE[0]} to {PRESS_RANGE[1]} m")
        if not (math.isfinite(fps) and 1.0 <= fps <= 120.0):
            raise _p.ParameterError(f"fps = {fps}: expected 1 to 120")
        try:
            self.policy = policy_for(host, token, require_token)
        except ValueError as e:
            raise _p.ParameterError(f"token: {e}") from None
        import viser  # noqa: F401 - fail early with ImportError when the extra is missing

        from ..probe import probe_point, vertex_normals

        self.model, self.name = model, name
        self.rest = np.asarray(model.outer_points, dtype=np.float64)
        self.tris = np.asarray(model.outer_triangles, dtype=np.int64)
        # Drawn front faces only (double-sided drawing cost the software renderer 4x): the
        # triangles turned outward if the surface's signed volume says they face in.
        a, b, c = (self.rest[self.tris[:, k]] for k in range(3))
        if float(np.einsum("ij,ij->i", a - a.mean(axis=0), np.cross(b - a, c - a)).sum()) < 0:
            self.tris = self.tris[:, ::-1].copy()
        self.normals = vertex_normals(self.rest, self.tris)
        used = np.unique(self.tris)
        self.center = 0.5 * (self.rest[used].min(axis=0) + self.rest[used].max(axis=0))
        self.size = float(np.linalg.norm(np.ptp(self.rest[used], axis=0)))
        v = probe_point(self.rest, self.tris)
        if self.fem and not model.outer_free[v] and model.outer_free.any():
            # A held node does not move: the free boundary node nearest the probe instead.
            free = np.flatnonzero(model.outer_free)
            v = int(free[np.argmin(np.linalg.norm(self.rest[free] - self.rest[v], axis=1))])
        self.probe = self.rest[v].copy()
        self.probe_normal = _unit(self.normals[v], _unit(self.rest[v] - self.center, np.array([1.0, 0.0, 0.0])))
        self.guard = TargetGuard.around(self.rest[used], margin=max(0.02, 0.25 * self.size))
        self.settings: Dict[str, Any] = {"device": device, "preset": preset, "tool_radius": float(tool_radius),
                                         "press_depth": float(press_depth), "bridge_host": bridge_host,
                                         "bridge_port": int(bridge_port), "rate_hz": float(rate_hz),
                                         "max_force": max_force, "realtime": bool(realtime),
                                         "physics_rate": None if physics_rate is None else float(physics_rate),
                                         "single_rate": bool(single_rate), "unsafe_limits": bool(unsafe_limits),
                                         "kind": kind}
        self.fps = float(fps)
        self._show_initial = (bool(show_core), bool(show_particles))
        self.paused = False
        self.lock = threading.RLock()
        self.loop: Optional[_p.HapticLoop] = None
        self.loop_error: Optional[str] = None
        self.target = self.home()
        self.history: Deque[Tuple[float, float, float]] = deque(maxlen=int(PLOT_SECONDS * fps) + 1)
        self.stats: Dict[str, Any] = {"frames": 0, "surface_updates": 0, "fps": 0.0, "max_force_n": 0.0,
                                      "force_n": 0.0, "max_surface_mm": 0.0, "surface_mm": 0.0, "drags": 0,
                                      "gizmo_moves": 0, "restarts": 0, "loop_ticks": 0, "loop_overruns": 0, "physics_hz": None, "active_particles": None,
                                      "frame_ms_max": 0.0}
        self._last_surface_tick = -1
        self._physics: Deque[Tuple[float, int]] = deque(maxlen=max(2, int(0.5 * fps)))
        self._sent = self.rest.copy()
        self._bands: Dict[int, Any] = {}
        self._scale_mm = max(1.0, round(0.05 * self.size * MM))  # colour scale [mm]
        self._stop = threading.Event()
        self._restarting = threading.Lock()

        self.bounds_warning = install_message_bounds()
        import viser as _viser

        # viser prints a banner and "Server stopped" to stdout whatever `verbose` says: kept off
        # stdout, which carries the command's own lines (and its --json).
        with contextlib.redirect_stdout(io.StringIO()), checking(self.policy):
            self.server = _viser.ViserServer(host=host, port=port, label=f"palpate view: {name}", verbose=False)
        if not self.policy.installed:
            with contextlib.redirect_stdout(io.StringIO()):
                self.server.stop()
            raise OriginCheckUnavailable("cannot check who opens the viewer: this viser (%s) did not start its "
                                         "server through the hook written for viser 1.1.1; not serving"
                                         % getattr(_viser, "__version__", "?"))
        self.host = host
        self.port = self.server.get_port()
        self._build_scene()
        self._build_gui()
        self._restart()
        self._thread = threading.Thread(target=self._frames, name="palpate-view-frames", daemon=True)
        self._thread.start()

    # -- public -----------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """The page's address; with ``?token=`` when the token is required or was given."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.policy.show_token else "")

    @property
    def token(self) -> str:
        """The viewer's token: ``?token=`` with it admits a page or a WebSocket from anywhere."""
        return self.policy.token

    @property
    def bridge_address(self) -> Optional[str]:
        loop = self.loop
        return loop.bridge_address if loop is not None else None

    def home(self) -> np.ndarray:
        """Where the hand waits [m]: clear of the probe point by the tool radius and 10 mm."""
        return self.probe + self.probe_normal * (self.settings["tool_radius"] + 0.010)

    def press_target(self, depth: float) -> np.ndarray:
        """The hand target [m] that presses the probe point ``depth`` [m] deep along its normal."""
        return self.probe + self.probe_normal * (self.settings["tool_radius"] - depth)

    def set_target(self, p: Any, move_gizmo: bool = True) -> bool:
        """Moves the hand's target to ``p`` (3,) [m] after the guard's checks (finite, clamped to
        the box around the model, rate-limited); returns whether it was taken (never for a bridge
        device, which the page cannot move)."""
        if self.settings["device"] != "hand":
            return False
        c = self.guard.check(p)
        if c is None:
            return False
        with self.lock:
            self.target = c
            loop = self.loop
            if loop is not None and self.settings["device"] == "hand":
                loop.set_hand_target(c)
        if move_gizmo:
            self.gizmo.position = tuple(c * MM)
        return True

    def status(self) -> Dict[str, Any]:
        """The viewer's counters: frames pushed, their rate, force [N] and surface displacement
        [mm] now and at most since the start, drags, the guard's and the transport's counts."""
        with self.lock:
            s = dict(self.stats)
        s["inputs"] = self.guard.counts()
        s["messages"] = STATS.as_dict()
        s["requests"] = self.policy.counts()
        s["paused"] = self.paused
        s["device"] = self.settings["device"]
        s["loop_error"] = self.loop_error
        return s

    def wait_ready(self, timeout: float = 30.0) -> bool:
        """Waits until the loop runs and a surface has been pushed; returns whether it did."""
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            if self.stats["surface_updates"] > 0 and self.loop is not None:
                return True
            if self.loop_error is not None:
                return False
            time.sleep(0.05)
        return False

    def reset(self) -> None:
        """A new loop with the current settings: the tissue at rest, the hand at home."""
        self._restart()

    def close(self) -> Optional[Dict[str, Any]]:
        """Stops the frame thread, the loop (returns its report) and the server."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        with self.lock:
            loop, self.loop = self.loop, None
        report = loop.stop() if loop is not None else None
        with contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()
        return report

    # -- the loop -------------------------------------------------------------------------------
    def _make_loop(self) -> "_p.HapticLoop":
        s = self.settings
        mat = self.presets[s["preset"]]()
        common: Dict[str, Any] = dict(rate_hz=s["rate_hz"], tool_radius=s["tool_radius"], realtime=s["realtime"],
                                      physics_rate=s["physics_rate"], single_rate=s["single_rate"],
                                      unsafe_limits=s["unsafe_limits"])
        if s["max_force"] is not None:
            common["max_force"] = s["max_force"]
        if s["kind"] is not None:
            common["kind"] = s["kind"]
        if s["device"] == "bridge":
            return _p.HapticLoop(loop_model(self.model), mat, "bridge", port=s["bridge_port"], host=s["bridge_host"],
                                 bridge_key=self._bridge_key, **common)
        return _p.HapticLoop(loop_model(self.model), mat, "hand", hand_start=self.home(), **common)

    def _restart(self, wait: bool = True) -> None:
        """Stops the running loop and starts one with the current settings (``wait``: here, else
        in a helper thread so that a GUI callback returns at once)."""
        def work() -> None:
            if not self._restarting.acquire(blocking=False):
                return
            try:
                with self.lock:
                    old, self.loop = self.loop, None
                if old is not None:
                    old.stop()
                self._show_note("building the simulation...")
                while True:
                    wanted = dict(self.settings)
                    try:
                        loop = self._make_loop()
                        loop.start()
                    except (_p.PalpateError, ValueError, OSError) as e:
                        self.loop_error = f"{type(e).__name__}: {e}"
                        self._show_note(f"**could not start the loop**: {self.loop_error}")
                        return
                    if self._stop.is_set():          # closed meanwhile
                        loop.stop()
                        return
                    if self.settings == wanted:
                        break
                    loop.stop()                      # a setting changed while it was built: again
                with self.lock:
                    self.loop, self.loop_error = loop, None
                    self.target = self.home()
                    self.history.clear()
                    self.stats["restarts"] += 1
                    self._last_surface_tick = -1
                self.gizmo.position = tuple(self.target * MM)
                self.tool.radius = self.settings["tool_radius"] * MM
                addr = loop.bridge_address
                self._show_note(f"bridge listening on `{addr}` (UDP)" if addr else "")
            finally:
                self._restarting.release()

        if wait:
            work()
        else:
            threading.Thread(target=work, name="palpate-view-restart", daemon=True).start()

    # -- scene and GUI --------------------------------------------------------------------------
    def _build_scene(self) -> None:
        sc = self.server.scene
        sc.set_up_direction("+z")
        ic = self.server.initial_camera
        side = _unit(np.array([self.probe_normal[0], self.probe_normal[1], 0.0]), np.array([1.0, 0.0, 0.0]))
        tangent = np.cross([0.0, 0.0, 1.0], side)
        eye = self.center + self.size * (0.62 * side + 0.22 * tangent + 0.18 * np.array([0.0, 0.0, 1.0]))
        # Shifted right by a tenth of the model's size, so that the model sits left of the GUI panel.
        right = _unit(np.cross(self.center - eye, [0.0, 0.0, 1.0]), tangent)
        shift = 0.10 * self.size * right
        ic.look_at = tuple((self.center + shift) * MM)
        ic.position = tuple((eye + shift) * MM)
        ic.near = 1.0
        ic.far = 50.0 * self.size * MM
        self.surface = sc.add_mesh_simple("/organ/surface", (self.rest * MM).astype(np.float32),
                                          self.tris.astype(np.uint32), color=colors.BANDS[0], cast_shadow=False,
                                          receive_shadow=False)
        self.surface.on_drag(self._on_drag)
        self.tool = sc.add_icosphere("/tool", radius=self.settings["tool_radius"] * MM, color=(235, 235, 235),
                                     opacity=0.85, position=tuple(self.home() * MM), cast_shadow=False)
        self.arrow = sc.add_arrows("/force", np.zeros((1, 2, 3), dtype=np.float32), (230, 60, 40),
                                   shaft_radius=0.5, head_radius=1.4, head_length=3.0, visible=False)
        self.gizmo = sc.add_transform_controls("/hand", scale=max(10.0, 0.15 * self.size * MM), disable_rotations=True,
                                               position=tuple(self.home() * MM))
        self.gizmo.on_update(self._on_gizmo)
        # The core's tets as their edges, and the active particles: live from the loop's interior
        # snapshot (HapticLoop.interior: the core's nodes, then the active particles), drawn only
        # when shown.
        core_p = np.asarray(self.model.core_points, dtype=np.float64)
        self.n_core = len(core_p)
        tets = np.asarray(self.model.core_tets, dtype=np.int64)
        pairs = np.concatenate([tets[:, [a, b]] for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
        self.core_edges = np.unique(np.sort(pairs, axis=1), axis=0)
        self.core = sc.add_line_segments("/organ/core", (core_p[self.core_edges] * MM).astype(np.float32),
                                         (240, 140, 60), thickness=2.0, thickness_units="screen", visible=False)
        self.active: Optional[Any] = None
        self._last_interior_tick = -1

    def _build_gui(self) -> None:
        gui = self.server.gui
        kind = (f"full FEM, {len(self.model.core_tets):,} tets; the tool meets the boundary nodes" if self.fem
                else "hybrid")
        gui.add_markdown(f"**{self.name}** ({kind}): {len(self.rest):,} surface vertices. Drag on the surface to press "
                         "with the tool (the press depth below), or move the gizmo: both set the target of the "
                         "simulated hand, which the 1 kHz loop follows.")
        self.note = gui.add_markdown("")
        import viser.uplot as up

        t = np.zeros(2)
        self.plot = gui.add_uplot(
            (t, t.copy(), t.copy()),
            (up.Series(label="wall time [s]"),
             up.Series(label="force [N]", stroke="#e63c28", width=2, scale="N"),
             up.Series(label="haptic rate [Hz]", stroke="#3c78e6", width=1, scale="Hz")),
            scales={"x": up.Scale(time=False), "N": up.Scale(auto=True), "Hz": up.Scale(auto=True)},
            axes=(up.Axis(), up.Axis(scale="N", label="force [N]"), up.Axis(scale="Hz", side=1, label="rate [Hz]")),
            title="force and haptic rate", aspect=1.4)
        self.g_status = gui.add_markdown("")
        with gui.add_folder("Displacement [mm]"):
            self.g_bar = gui.add_image(colors.bar_image(), format="png")
            self.g_bar_text = gui.add_markdown(colors.bar_labels(self._scale_mm))
            self.g_scale = gui.add_slider("colour scale [mm]", 0.5, 20.0, 0.5, float(self._scale_mm))
            self.g_scale.on_update(lambda _: self._set_scale())
        with gui.add_folder("Touch"):
            self.g_depth = gui.add_slider("press depth [mm]", 0.0, PRESS_RANGE[1] * MM, 0.5,
                                          self.settings["press_depth"] * MM)
            self.g_depth.on_update(lambda _: self._set_depth())
            self.g_pause = gui.add_checkbox("pause", False, hint="freeze the view; the page's input is ignored")
            self.g_pause.on_update(lambda _: self._set_pause())
            self.g_reset = gui.add_button("reset", hint="a new loop: the tissue at rest, the hand at home")
            self.g_reset.on_click(lambda _: self._restart(wait=False))
        with gui.add_folder("Tool and device"):
            self.g_preset = gui.add_dropdown("material", tuple(self.presets), initial_value=self.settings["preset"])
            self.g_preset.on_update(lambda _: self._set("preset", self.g_preset.value))
            self.g_radius = gui.add_slider("tool radius [mm]", TOOL_RADIUS_RANGE[0] * MM, TOOL_RADIUS_RANGE[1] * MM,
                                           0.5, self.settings["tool_radius"] * MM)
            self.g_radius.on_update(lambda _: self._set("tool_radius", finite_number(
                self.g_radius.value, TOOL_RADIUS_RANGE[0] * MM, TOOL_RADIUS_RANGE[1] * MM, 5.0) / MM))
            self.g_device = gui.add_dropdown("device", DEVICES, initial_value=self.settings["device"])
            self.g_device.on_update(lambda _: self._set("device", self.g_device.value))
        with gui.add_folder("Show", expand_by_default=any(self._show_initial)):
            self.g_core = gui.add_checkbox("tets" if self.fem else "core tets", self._show_initial[0],
                                           hint="the FEM core's tet edges, as simulated")
            self.g_core.on_update(lambda _: self._show_interior())
            # A full-FEM body has no particles: the box stays off and hidden.
            self.g_active = gui.add_checkbox("active particles", self._show_initial[1] and not self.fem,
                                             hint="the shell particles simulated now", visible=not self.fem)
            self.g_active.on_update(lambda _: self._show_interior())
            self.core.visible = bool(self.g_core.value)
            self.surface.opacity = self._opacity()
            self.g_gizmo = gui.add_checkbox("tool gizmo", True)
            self.g_gizmo.on_update(lambda _: setattr(self.gizmo, "visible", bool(self.g_gizmo.value)))

    def _show_note(self, text: str) -> None:
        try:
            self.note.content = text
        except AttributeError:      # before the GUI exists
            pass

    def _set(self, key: str, value: Any) -> None:
        if key == "preset" and value not in self.presets:
            return
        if key == "device" and value not in DEVICES:
            return
        if self.settings.get(key) == value:
            return
        self.settings[key] = value
        self._restart(wait=False)

    def _opacity(self) -> Optional[float]:
        """The surface's opacity: see-through while the interior is shown."""
        return 0.45 if (self.g_core.value or self.g_active.value) else None

    def _show_interior(self) -> None:
        self.core.visible = bool(self.g_core.value)
        self.surface.opacity = self._opacity()
        for h in self._bands.values():
            h.opacity = self._opacity()
        if not self.g_active.value:
            self.stats["active_particles"] = None
            if self.active is not None:
                self.active.remove()
                self.active = None
        self._last_interior_tick = -1

    def _push_interior(self, loop: "_p.HapticLoop") -> None:
        """The core's edges and the active particles from the loop's interior snapshot."""
        got = loop.interior()
        if got is None or got[0] == self._last_interior_tick:
            return
        self._last_interior_tick = got[0]
        pts = np.asarray(got[1], dtype=np.float64)
        if len(pts) < self.n_core or not np.all(np.isfinite(pts)):
            return
        if self.g_core.value:
            self.core.points = (pts[self.core_edges] * MM).astype(np.float32)
        if self.g_active.value:
            act = pts[self.n_core:]
            with self.lock:
                self.stats["active_particles"] = len(act)
            if len(act) == 0:
                if self.active is not None:
                    self.active.remove()
                    self.active = None
                return
            self.active = self.server.scene.add_point_cloud(
                "/organ/active", (act * MM).astype(np.float32), (120, 220, 255), point_size=0.8,
                point_shape="circle", precision="float32")

    def _set_depth(self) -> None:
        self.settings["press_depth"] = finite_number(self.g_depth.value, 0.0, PRESS_RANGE[1] * MM, 3.0) / MM

    def _set_pause(self) -> None:
        self.paused = bool(self.g_pause.value)

    def _set_scale(self) -> None:
        self._scale_mm = finite_number(self.g_scale.value, 0.5, 20.0, 4.0)
        self.g_bar_text.content = colors.bar_labels(self._scale_mm)
        self._last_surface_tick = -1      # recolour now

    # -- input from the page ----------------------------------------------------------------------
    async def _on_drag(self, ev: Any) -> None:
        """A drag on the surface: the tool centre goes to the pointer's point on the drag plane
        (camera-facing, through the grabbed surface point), pushed away from the camera by the
        press depth less the tool radius; at the end the hand lifts off towards the camera."""
        if self.paused or self.settings["device"] != "hand":
            return
        try:
            hit = np.asarray(ev.start_position, dtype=np.float64) / MM
            cam = np.asarray(ev.client.camera.position, dtype=np.float64) / MM
            p = np.asarray(ev.end_position, dtype=np.float64) / MM
        except (TypeError, ValueError, AttributeError):
            self.guard.non_finite += 1
            return
        if not (np.all(np.isfinite(hit)) and np.all(np.isfinite(cam))):
            self.guard.non_finite += 1
            return
        toward = _unit(cam - hit, self.probe_normal)
        r, d = self.settings["tool_radius"], self.settings["press_depth"]
        if ev.phase == "end":
            target = p + toward * (r + LIFT)
        else:
            target = p + toward * (r - d)
        if self.set_target(target) and ev.phase == "start":
            with self.lock:
                self.stats["drags"] += 1

    async def _on_gizmo(self, ev: Any) -> None:
        if self.paused or self.settings["device"] != "hand":
            return
        try:
            p = np.asarray(ev.target.position, dtype=np.float64) / MM
        except (TypeError, ValueError, AttributeError):
            self.guard.non_finite += 1
            return
        if self.set_target(p, move_gizmo=False):
            with self.lock:
                self.stats["gizmo_moves"] += 1

    # -- the frame thread -------------------------------------------------------------------------
    def _frames(self) -> None:
        # Below the servo thread (same process, nice 0) where the OS allows: a frame waits, a tick
        # does not.
        lower_priority(threading.get_native_id(), FRAME_NICE)
        period = 1.0 / self.fps
        window: Deque[float] = deque(maxlen=int(self.fps) + 1)
        next_status = 0.0
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                pushed = self._frame()
            except Exception as e:  # noqa: BLE001 - the page must not lose its viewer to one bad frame
                self._show_note(f"frame error: {type(e).__name__}: {e}")
                pushed = False
            now = time.monotonic()
            if pushed:
                window.append(now)
                with self.lock:
                    self.stats["frames"] += 1
                    self.stats["frame_ms_max"] = max(self.stats["frame_ms_max"], 1e3 * (now - t0))
                    if len(window) >= 2 and window[-1] > window[0]:
                        self.stats["fps"] = (len(window) - 1) / (window[-1] - window[0])
            if now >= next_status:
                next_status = now + 0.5
                self._status_text()
            self._stop.wait(max(0.0, period - (time.monotonic() - t0)))

    def _frame(self) -> bool:
        with self.lock:
            loop = self.loop
        if loop is None or self.paused:
            return False
        snap = loop.snapshot()
        if snap is None:
            return False
        got = loop.surface()
        tool = np.asarray(snap["tool"], dtype=np.float64)
        force = np.asarray(snap["force"], dtype=np.float64)
        fmag = float(np.linalg.norm(force))
        rate = 1e6 / snap["period_us"] if snap["period_us"] > 0 else 0.0
        with self.lock:
            self.history.append((time.monotonic(), fmag, rate))
            self.stats["force_n"] = fmag
            self.stats["max_force_n"] = max(self.stats["max_force_n"], fmag)
            self.stats["loop_ticks"] = int(snap["tick"])
            self.stats["loop_overruns"] = int(snap["overruns"])
            if not self.settings["single_rate"]:
                # The physics thread's rate over the last half second of frames.
                self._physics.append((time.monotonic(), int(snap["physics_ticks"])))
                (t0, n0), (t1, n1) = self._physics[0], self._physics[-1]
                if t1 > t0:
                    self.stats["physics_hz"] = (n1 - n0) / (t1 - t0)
        with self.server.atomic():
            if got is not None and got[0] != self._last_surface_tick:
                self._push_surface(np.asarray(got[1], dtype=np.float64))
                self._last_surface_tick = got[0]
            if self.g_core.value or self.g_active.value:
                self._push_interior(loop)
            if np.all(np.isfinite(tool)):
                self.tool.position = tuple(tool * MM)
                if fmag > 1e-4:
                    u = force / fmag
                    base = tool + u * self.settings["tool_radius"]
                    tip = base + u * min(fmag * ARROW_M_PER_N, 0.5 * self.size)
                    self.arrow.points = (np.stack([base, tip])[None] * MM).astype(np.float32)
                    self.arrow.visible = True
                else:
                    self.arrow.visible = False
            h = np.asarray(self.history, dtype=np.float64)
            if len(h) >= 2:
                self.plot.data = (h[:, 0] - h[-1, 0], h[:, 1], h[:, 2])
        return True

    def _push_surface(self, surf: np.ndarray) -> None:
        disp = np.linalg.norm(surf - self.rest, axis=1)
        if not np.all(np.isfinite(disp)):
            return
        dmax = float(disp.max()) if len(disp) else 0.0
        with self.lock:
            self.stats["surface_mm"] = dmax * MM
            self.stats["max_surface_mm"] = max(self.stats["max_surface_mm"], dmax * MM)
            self.stats["surface_updates"] += 1
        if float(np.abs(surf - self._sent).max()) > 1e-7:
            self.surface.vertices = (surf * MM).astype(np.float32)
            self._sent = surf
        # Colour bands: the triangles above the first band edge, one small mesh per band, laid a
        # hair outward over the surface (viser's simple meshes have one colour each).
        tri_mm = disp[self.tris].mean(axis=1) * MM
        band = colors.band_of(tri_mm, self._scale_mm)
        lift = (self.normals * 0.05 / MM)
        for k in range(1, len(colors.BANDS)):
            faces = self.tris[band == k]
            name = f"/organ/band{k}"
            if len(faces) == 0:
                h = self._bands.pop(k, None)
                if h is not None:
                    h.remove()
                continue
            used, inv = np.unique(faces, return_inverse=True)
            verts = ((surf[used] + lift[used]) * MM).astype(np.float32)
            self._bands[k] = self.server.scene.add_mesh_simple(
                name, verts, inv.reshape(-1, 3).astype(np.uint32), color=colors.BANDS[k],
                opacity=self._opacity(), cast_shadow=False, receive_shadow=False)

    def _status_text(self) -> None:
        s = self.status()
        lines = [f"force **{s['force_n']:.3f} N** (max {s['max_force_n']:.3f}) | surface {s['surface_mm']:.2f} mm "
                 f"(max {s['max_surface_mm']:.2f})",
                 f"viewer {s['fps']:.1f} frames/s | loop tick {s['loop_ticks']:,}, overruns {s['loop_overruns']}"
                 + (f" | physics {s['physics_hz']:.0f} Hz" if s.get("physics_hz") is not None else "")]
        if self.paused:
            lines.append("**paused**")
        try:
            self.g_status.content = "  \n".join(lines)
        except AttributeError:
            pass
