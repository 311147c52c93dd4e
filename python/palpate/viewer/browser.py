"""A headless browser for the viewer: the system's Chromium (Debian's ``chromium`` package)
driven by Playwright, never Playwright's own browser download. :func:`find_chromium` says where
it is or why there is none; :func:`screenshot` renders one frame of a running viewer into a PNG.
"""
from __future__ import annotations

import os
import shutil
import time
from typing import Any, Optional, Tuple

from .._extras import install_hint

#: Chromium flags for a headless run on a machine without a GPU or a display (WebGL falls back to
#: SwiftShader) and without network: no sandbox (root in a container), no background traffic.
CHROMIUM_ARGS = ("--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage")
#: Where a Chromium is looked for when ``$PALPATE_CHROMIUM`` is not set.
CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> Tuple[Optional[str], str]:
    """``(path, "")`` of a Chromium executable (``$PALPATE_CHROMIUM``, else the first of
    :data:`CANDIDATES` on ``PATH``), or ``(None, why)``."""
    env = os.environ.get("PALPATE_CHROMIUM")
    if env:
        if os.path.isfile(env) and os.access(env, os.X_OK):
            return env, ""
        return None, f"PALPATE_CHROMIUM={env} is not an executable file"
    for name in CANDIDATES:
        p = shutil.which(name)
        if p:
            return p, ""
    return None, ("no Chromium on PATH (Debian: apt-get install -y chromium; or set PALPATE_CHROMIUM); "
                  "Playwright's own browser download is not used")


def have_playwright() -> Tuple[bool, str]:
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError as e:
        return False, f"the Python package playwright is not installed ({e}; {install_hint('view')})"
    return True, ""


def launch(pw: Any, width: int = 1000, height: int = 650) -> Tuple[Any, Any]:
    """``(browser, page)``: the system Chromium, headless, through a Playwright instance ``pw``.
    Raises ``RuntimeError`` when there is no Chromium."""
    exe, why = find_chromium()
    if exe is None:
        raise RuntimeError(why)
    browser = pw.chromium.launch(executable_path=exe, headless=True, args=list(CHROMIUM_ARGS))
    page = browser.new_page(viewport={"width": width, "height": height})
    return browser, page


def lower_browser_priority(nice: int = 10) -> int:
    """Lowers the CPU priority of this process's Chromium descendants (Linux ``/proc``) to
    niceness ``nice``, so that a browser rendering in software on the same CPUs yields to the
    haptic loop; returns how many processes it lowered (0 where it cannot)."""
    from .app import lower_priority

    try:
        children: dict = {}
        for d in os.listdir("/proc"):
            if not d.isdigit():
                continue
            try:
                with open(f"/proc/{d}/stat") as f:
                    stat = f.read()
            except OSError:
                continue
            comm = stat[stat.index("(") + 1:stat.rindex(")")]
            ppid = int(stat[stat.rindex(")") + 2:].split()[1])
            children.setdefault(ppid, []).append((int(d), comm))
    except (OSError, ValueError):
        return 0
    n, todo = 0, [os.getpid()]
    while todo:
        for pid, comm in children.get(todo.pop(), []):
            todo.append(pid)
            if "chrom" in comm.lower() and lower_priority(pid, nice):
                n += 1
    return n


def hide_toasts(page: Any) -> None:
    """Hides viser's notifications (the "software WebGL rendering" toast) for a clean picture."""
    page.add_style_tag(content=".mantine-Notifications-root { display: none !important; }")


def wait_for_scene(page: Any, timeout_s: float = 30.0, settle_s: float = 3.0) -> None:
    """Waits for the viewer's canvas, then ``settle_s`` [s] for the scene to arrive and draw."""
    page.wait_for_selector("canvas", timeout=timeout_s * 1e3)
    time.sleep(settle_s)


def screenshot(url: str, out: str, width: int = 1000, height: int = 650, settle_s: float = 6.0,
               max_colors: Optional[int] = 256) -> int:
    """Opens ``url`` (a running viewer) in headless Chromium, waits ``settle_s`` [s] and writes
    one frame to ``out`` (PNG; ``max_colors``: quantised to that many colours to keep it small);
    returns the file's size [bytes]. Raises ``RuntimeError`` without a browser or Playwright."""
    ok, why = have_playwright()
    if not ok:
        raise RuntimeError(why)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser, page = launch(pw, width, height)
        try:
            page.goto(url, wait_until="load", timeout=60_000)
            hide_toasts(page)
            wait_for_scene(page, settle_s=settle_s)
            png = page.screenshot(type="png")
        finally:
            browser.close()
    if max_colors:
        import io

        from PIL import Image

        im = Image.open(io.BytesIO(png)).convert("RGB").quantize(colors=max_colors, method=Image.Quantize.MEDIANCUT)
        buf = io.BytesIO()
        im.save(buf, format="PNG", optimize=True)
        png = buf.getvalue()
    with open(out, "wb") as f:
        f.write(png)
    return len(png)
