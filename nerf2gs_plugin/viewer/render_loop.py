"""One background render thread per browser client; the latest camera request wins.

Camera updates only bump a version number: the thread reads the client's camera when it is free
to render, so a burst of updates during a slow frame collapses into one new frame. While the
camera moves, frames use :class:`AdaptiveResolution`'s moving scale; once it has rested for
``rest_delay`` seconds the thread refines up to full resolution.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.viewer.camera import viser_to_cameras
from nerf2gs_plugin.viewer.resolution import AdaptiveResolution

FrameFn = Callable[[Cameras], np.ndarray]  # one camera -> uint8 [H, W, 3]


@dataclass
class FrameInfo:
    """What the last frame was: for the FPS readout and the tests."""

    width: int
    height: int
    seconds: float
    moving: bool
    scale: float


class ClientRenderer:
    """Renders what one client's camera sees, in its own daemon thread."""

    def __init__(self, client: Any, render_frame: FrameFn, resolution: AdaptiveResolution, rest_delay: float = 0.25,
                 jpeg_quality: int = 85, on_frame: Optional[Callable[["ClientRenderer", FrameInfo], None]] = None,
                 threaded: bool = True) -> None:
        self.client = client
        self.render_frame = render_frame
        self.resolution = resolution
        self.rest_delay = rest_delay
        self.jpeg_quality = jpeg_quality
        self.on_frame = on_frame
        self.frames = 0
        self.last: Optional[FrameInfo] = None
        self.last_image: Optional[np.ndarray] = None
        self.fps = 0.0
        self._cond = threading.Condition()
        self._version = 0
        self._done_version = 0
        self._last_move = time.monotonic()
        self._full_done = True
        self._last_scale: Optional[float] = None
        self._stopped = False
        self._error_reported = False
        self._thread: Optional[threading.Thread] = None
        if threaded:
            self._thread = threading.Thread(target=self._loop, daemon=True, name=f"viewer-render-{getattr(client, 'client_id', '?')}")
            self._thread.start()

    # ------------------------------------------------------------------ requests
    def camera_moved(self) -> None:
        """The client's camera changed: render soon at interactive resolution."""
        with self._cond:
            self._version += 1
            self._last_move = time.monotonic()
            self._full_done = False
            self._cond.notify_all()

    def refresh(self) -> None:
        """Same camera, new content (render mode, model update): re-render at full quality."""
        with self._cond:
            self._version += 1
            self._last_move = time.monotonic() - self.rest_delay
            self._full_done = False
            self._last_scale = None
            self._cond.notify_all()

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        if self._thread is not None and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)

    def pump(self) -> bool:
        """Without a thread (live training view): render one due frame now, if any."""
        job = self._next_job(block=False)
        if job is None:
            return False
        self._render_job(*job)
        return True

    # ------------------------------------------------------------------ thread
    def _next_job(self, block: bool = True) -> Optional[tuple[int, bool]]:
        """Block until there is something to render: ``(version, moving)``; None once stopped
        (or, with ``block=False``, when nothing is due now)."""
        with self._cond:
            while not self._stopped:
                now = time.monotonic()
                resting_for = now - self._last_move
                if self._version != self._done_version:
                    self._done_version = self._version
                    return self._version, resting_for < self.rest_delay
                if not self._full_done:
                    if resting_for >= self.rest_delay:
                        return self._version, False
                    if not block:
                        return None
                    self._cond.wait(self.rest_delay - resting_for)
                    continue
                if not block:
                    return None
                self._cond.wait()
            return None

    def _loop(self) -> None:
        while True:
            job = self._next_job()
            if job is None:
                return
            self._render_job(*job)

    def _render_job(self, version: int, moving: bool) -> None:
        try:
            self._render_once(version, moving)
        except Exception as e:  # a failing frame must not kill the viewer; report once
            if not self._error_reported:
                self._error_reported = True
                print(f"viewer: render failed ({type(e).__name__}: {e})", file=sys.stderr)
            with self._cond:
                self._full_done = True

    def _render_once(self, version: int, moving: bool) -> None:
        cam = self.client.camera
        wxyz, position, fov = np.array(cam.wxyz), np.array(cam.position), float(cam.fov)
        full_w, full_h = self.resolution.full_size(cam.image_width, cam.image_height)
        if moving:
            scale = self.resolution.moving_scale(full_w, full_h)
        else:
            scale = self.resolution.resting_scale(full_w, full_h, self._last_scale)
        w, h = self.resolution.frame_size(full_w, full_h, scale)
        camera = viser_to_cameras(wxyz, position, fov, w / h, h)
        t0 = time.perf_counter()
        image = self.render_frame(camera)
        if self._stopped:
            return
        self.client.scene.set_background_image(image, format="jpeg", jpeg_quality=self.jpeg_quality)
        seconds = time.perf_counter() - t0
        self.resolution.record(image.shape[1], image.shape[0], seconds)
        info = FrameInfo(image.shape[1], image.shape[0], seconds, moving, scale)
        with self._cond:
            self._last_scale = scale
            self.frames += 1
            self.last = info
            self.last_image = image
            self.fps = 1.0 / max(seconds, 1e-6)
            if not moving and scale >= 1.0 and self._version == version:
                self._full_done = True
        if self.on_frame is not None:
            self.on_frame(self, info)
