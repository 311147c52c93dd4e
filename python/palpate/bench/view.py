"""``palpate bench view``: what the viewer costs the haptic loop.

The same loop (device ``hand`` on the same model, material and rate) runs four times for
``seconds`` each, its hand target moved from a Python thread at 20 Hz as a mouse drag does (a
press of :data:`DEPTH` at the probe point sliding back and forth :data:`SLIDE` along the surface,
one cycle every 2 s):

1. ``alone``: no viewer;
2. ``viewer_no_page``: under the viewer, no page connected (the viewer's own cost);
3. ``viewer``: under :class:`palpate.viewer.Viewer` (the loop restarted once the page is open, so
   its whole run has the page open), with the page open in the system's headless Chromium
   (software WebGL on the same CPUs, its processes niced to :data:`BROWSER_NICE`) and the
   target set through the viewer's guard;
4. ``alone_again``: no viewer, to show how much the machine's load drifted meanwhile.

Reported per run: the loop's period percentiles, overruns and achieved rate; for the viewer run,
the frames the viewer pushed per second and the page's animation frames per second
(``requestAnimationFrame`` counted in the page over 3 s).
"""
from __future__ import annotations

import math
import os
import platform
import threading
import time
from datetime import datetime, timezone
from typing import Any, Callable, Dict, Optional

import numpy as np

from .. import _palpate as _p

DEPTH = 0.004
SLIDE = 0.006
DRIVE_HZ = 20.0
#: Niceness the benchmark gives its headless Chromium (software WebGL on the loop's CPUs).
BROWSER_NICE = 10
KEYS = ("ticks", "achieved_hz", "period_us_p50", "period_us_p99", "period_us_max", "compute_us_p99", "overruns",
        "max_force_n", "n_faults")


def drag_path(probe: np.ndarray, inward: np.ndarray, tangent: np.ndarray, radius: float) -> Callable[[float], np.ndarray]:
    """The hand target [m] at time ``t`` [s]: pressed :data:`DEPTH` at the probe, sliding
    ``SLIDE * sin(pi t)`` along ``tangent``."""
    def at(t: float) -> np.ndarray:
        return probe - inward * (radius - DEPTH) + tangent * SLIDE * math.sin(math.pi * t)
    return at


def _drive(set_target: Callable[[np.ndarray], Any], path: Callable[[float], np.ndarray], stop: threading.Event) -> None:
    t0 = time.monotonic()
    while not stop.wait(1.0 / DRIVE_HZ):
        set_target(path(time.monotonic() - t0))


def _pick(r: Dict[str, Any]) -> Dict[str, Any]:
    return {k: r[k] for k in KEYS}


def run_alone(model: "_p.HybridModel", material: "_p.Material", home: np.ndarray, path, seconds: float,
              rate_hz: float, tool_radius: float, realtime: bool = False) -> Dict[str, Any]:
    from ..viewer.fem import loop_model

    loop = _p.HapticLoop(loop_model(model), material, "hand", hand_start=home, rate_hz=rate_hz, tool_radius=tool_radius,
                         realtime=realtime)
    stop = threading.Event()
    th = threading.Thread(target=_drive, args=(loop.set_hand_target, path, stop), daemon=True)
    loop.start()
    th.start()
    try:
        time.sleep(seconds)
    finally:
        stop.set()
        th.join()
        r = loop.stop()
    return _pick(r)


def run_with_viewer(model: "_p.HybridModel", name: str, path, seconds: float, rate_hz: float, tool_radius: float,
                    fps: float, on_status: Optional[Callable[[str], None]] = None,
                    nice_browser: bool = True, realtime: bool = False) -> Dict[str, Any]:
    from playwright.sync_api import sync_playwright

    from ..viewer import Viewer
    from ..viewer.browser import hide_toasts, launch, lower_browser_priority, wait_for_scene

    v = Viewer(model, name, port=0, rate_hz=rate_hz, tool_radius=tool_radius, fps=fps, realtime=realtime)
    try:
        with sync_playwright() as pw:
            browser, page = launch(pw)
            try:
                niced = lower_browser_priority(BROWSER_NICE) if nice_browser else 0
                page.goto(v.url, wait_until="load", timeout=60_000)
                hide_toasts(page)
                wait_for_scene(page, settle_s=5.0)
                if on_status:
                    on_status("page open; restarting the loop under it")
                v.reset()                                    # the measured loop: its whole run with the page open
                f0, t0 = v.status()["frames"], time.monotonic()
                stop = threading.Event()
                th = threading.Thread(target=_drive, args=(v.set_target, path, stop), daemon=True)
                th.start()
                try:
                    time.sleep(max(0.0, seconds - 3.5))
                    raf = page.evaluate("""() => new Promise(done => { let n = 0; const t0 = performance.now();
                        const f = () => { n++; if (performance.now() - t0 < 3000) requestAnimationFrame(f);
                        else done(n / ((performance.now() - t0) / 1000)); }; requestAnimationFrame(f); })""")
                finally:
                    stop.set()
                    th.join()
                pushed = (v.status()["frames"] - f0) / (time.monotonic() - t0)
                status = v.status()
            finally:
                browser.close()
    finally:
        with v.lock:
            loop, v.loop = v.loop, None
        r = loop.stop() if loop is not None else None
        v.close()
    if r is None:
        raise _p.HapticsError("the viewer's loop did not run")
    out = _pick(r)
    out["viewer_frames_per_s"] = pushed
    out["page_animation_frames_per_s"] = float(raf)
    out["viewer_frame_ms_max"] = status["frame_ms_max"]
    out["targets"] = status["inputs"]
    out["browser_processes_niced"] = niced
    return out


def run_viewer_no_page(model: "_p.HybridModel", name: str, path, seconds: float, rate_hz: float,
                       tool_radius: float, fps: float, realtime: bool = False) -> Dict[str, Any]:
    """The loop under the viewer with no page connected: the viewer's own cost (its frame thread
    still reads the snapshots and builds every frame)."""
    from ..viewer import Viewer

    v = Viewer(model, name, port=0, rate_hz=rate_hz, tool_radius=tool_radius, fps=fps, realtime=realtime)
    stop = threading.Event()
    th = threading.Thread(target=_drive, args=(v.set_target, path, stop), daemon=True)
    th.start()
    try:
        time.sleep(seconds)
        pushed = v.status()["fps"]
    finally:
        stop.set()
        th.join()
        r = v.close()
    if r is None:
        raise _p.HapticsError("the viewer's loop did not run")
    out = _pick(r)
    out["viewer_frames_per_s"] = pushed
    return out


def bench(model: "_p.HybridModel", name: str, seconds: float = 20.0, rate_hz: float = 1000.0, fps: float = 30.0,
          tool_radius: float = 0.005, on_status: Optional[Callable[[str], None]] = None,
          realtime: bool = False) -> Dict[str, Any]:
    """The four runs (see the module); a dict with ``alone``, ``viewer_no_page``, ``viewer``,
    ``alone_again`` and the machine (CPU count, processor, load averages before and after, date);
    ``realtime``: every run's servo under ``SCHED_FIFO`` (:class:`palpate.HapticLoop`)."""
    from .. import haptics
    from .hybrid import probe

    _, point, inward, tangent = probe(model)
    home = point - inward * (tool_radius + 0.010)
    path = drag_path(point, inward, tangent, tool_radius)
    mat = haptics.material()
    say = on_status or (lambda s: None)
    res: Dict[str, Any] = {"model": name, "seconds": seconds, "rate_hz": rate_hz, "fps": fps,
                           "load_avg_before": list(os.getloadavg()), "realtime": realtime}
    say("alone")
    res["alone"] = run_alone(model, mat, home, path, seconds, rate_hz, tool_radius, realtime)
    say("under the viewer, no page open")
    res["viewer_no_page"] = run_viewer_no_page(model, name, path, seconds, rate_hz, tool_radius, fps, realtime)
    say("with the viewer and the page open")
    res["viewer"] = run_with_viewer(model, name, path, seconds, rate_hz, tool_radius, fps, say, realtime=realtime)
    say("alone again")
    res["alone_again"] = run_alone(model, mat, home, path, seconds, rate_hz, tool_radius, realtime)
    res["load_avg_after"] = list(os.getloadavg())
    res["cpu_count"] = os.cpu_count()
    res["machine"] = platform.processor() or platform.machine()
    res["date"] = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return res
