"""Drive the viewer from a real headless browser: the README screenshot and the browser test.

Uses the system Chromium (Debian's ``chromium``, installed by ``make setup`` where apt exists)
through playwright's driver; nothing is downloaded at run time. WebGL runs on SwiftShader.
"""

from __future__ import annotations

import os
import shutil
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Optional

from nerf2gs_plugin.errors import UserError

BROWSER_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
# software WebGL (no GPU on the test machines); no sandbox so it also runs as root in containers
BROWSER_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox", "--mute-audio"]
_HIDE_NOTIFICATIONS = '[role="alert"] { display: none !important; }'


def find_browser() -> Optional[str]:
    """Path of a Chromium-family browser (``NERF2GS_BROWSER`` overrides), or None."""
    override = os.environ.get("NERF2GS_BROWSER")
    if override:
        return override if Path(override).is_file() else shutil.which(override)
    for name in BROWSER_NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


def browser_unavailable_reason() -> Optional[str]:
    """Why a browser session cannot start here (None when it can)."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright package is not installed (make setup installs it)"
    if find_browser() is None:
        return f"no Chromium browser found ({', '.join(BROWSER_NAMES)}; make setup installs Debian's chromium where apt exists)"
    return None


@contextmanager
def headless_page(url: str, width: int = 1280, height: int = 800, timeout: float = 60.0) -> Iterator[object]:
    """A playwright page showing ``url`` in headless Chromium."""
    reason = browser_unavailable_reason()
    if reason is not None:
        raise UserError(f"cannot open a headless browser: {reason}")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=find_browser(), args=BROWSER_ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.set_default_timeout(timeout * 1000)
            page.goto(url)
            yield page
        finally:
            browser.close()


def grab(page) -> "np.ndarray":
    """The page as an RGB ``uint8`` array."""
    import cv2
    import numpy as np

    png = page.screenshot()
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1].copy()


def wait_until_still(page, timeout: float = 30.0, interval: float = 0.5, tol: float = 0.5) -> "np.ndarray":
    """Screenshots until two in a row agree (viser fades new scene content in over a while,
    much longer on software WebGL); returns the last one."""
    import numpy as np

    deadline = time.monotonic() + timeout
    prev = grab(page)
    while time.monotonic() < deadline:
        time.sleep(interval)
        cur = grab(page)
        if np.abs(cur.astype(np.int16) - prev.astype(np.int16)).mean() < tol:
            return cur
        prev = cur
    return prev


def screenshot_viewer(viewer, path: Path, width: int = 1280, height: int = 800, timeout: float = 120.0, settle: float = 1.5) -> Path:
    """Open the viewer in a headless browser, wait for a full-resolution frame, save a PNG."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with headless_page(viewer.url, width, height, timeout) as page:
        page.add_style_tag(content=_HIDE_NOTIFICATIONS)
        if not viewer.wait_for_frames(1, timeout, full=True):
            raise UserError(f"the viewer rendered no full-resolution frame within {timeout:.0f} s")
        time.sleep(settle)  # let the browser decode and draw the last frame
        wait_until_still(page, timeout=timeout / 2)
        page.screenshot(path=str(path))
    return path
