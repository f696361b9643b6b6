"""Textured pixels that no static depth explains: a sweep along the epipolar line, no optical flow.

A static pixel of frame ``i`` shows up in frame ``j`` somewhere on its epipolar line, at a parallax set
by its distance, never short of where the ground plane's bound puts it (the farthest a static surface
can be along a ray pointing down). The neighbour is sampled along that line at every feasible parallax
(in steps of a full-size pixel, on images shrunk by ``scale``) and the best 5x5 mean grey difference kept: a textured
pixel whose best match is still poor moves in the pair. DIS is not asked, so its spread across motion
boundaries adds nothing; a plain pixel matches somewhere on the line and is left to the flow tests
(a walker's textured clothes and edges are what this finds; plain car bodies and asphalt it cannot tell).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from torch import Tensor


def textured(grey: np.ndarray, level: float) -> np.ndarray:
    """Pixels whose 5x5 mean gradient (Sobel, in grey levels a pixel) exceeds ``level``."""
    import cv2

    g = grey.astype(np.float32)
    mag = np.sqrt(cv2.Sobel(g, cv2.CV_32F, 1, 0) ** 2 + cv2.Sobel(g, cv2.CV_32F, 0, 1) ** 2) / 8.0
    return cv2.blur(mag, (5, 5)) > level


def _shrunk(grey: np.ndarray, scale: int) -> np.ndarray:
    """``grey`` halved per power of two in ``scale``, Gaussian before decimating (a fine texture aliases less)."""
    import cv2

    for _ in range(max(int(scale).bit_length() - 1, 0)):
        grey = cv2.pyrDown(grey)
    return grey


def _window_cost(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The best 5x5 mean grey difference of ``a`` and ``b`` among the windows within a pixel of each: a window astride
    a depth edge (a pole, a parked car's outline) matches at no single parallax, one beside it on the pixel's own side does."""
    import cv2

    return cv2.erode(cv2.blur(np.abs(a - b.astype(np.float32)), (5, 5)), np.ones((3, 3), np.uint8))


def unexplained(grey_i: np.ndarray, grey_j: np.ndarray, p_inf: Tensor, u: Tensor, lowest: Tensor, warped: Sequence[np.ndarray],
                grey_min: float, median_rel: float, texture: float, reach: float, scale: int) -> Tensor:
    """Bool ``[H, W]``: textured pixels of frame ``i`` that frame ``j`` matches nowhere on the epipolar line at a
    feasible parallax. ``p_inf``, ``u``: the line (``motion.epipolar_line``, pixels of frame ``i``'s grid);
    ``lowest`` ``[H, W]``: the least feasible parallax (pixels); ``warped``: frame ``j`` already warped onto frame
    ``i`` by static hypotheses that vary across a patch (the prior depth's rigid flow, the ground plane's), which
    explain a pixel too: near the camera a slanted surface (the road, a facade seen askew) changes its shape between
    frames, and no shift of a patch matches it; a poor match: the best 5x5 mean difference
    above ``grey_min`` and ``median_rel`` times the frame's median best; ``reach``: the line is searched up to
    this fraction of the image width; ``scale``: on images shrunk by this factor (a power of two; speed)."""
    import cv2

    h, w = grey_i.shape
    gi, gj = _shrunk(grey_i, scale), _shrunk(grey_j, scale)
    hs, ws = gi.shape
    sx, sy = ws / w, hs / h

    def small(t: Tensor) -> np.ndarray:
        return cv2.resize(np.ascontiguousarray(t.float().numpy()), (ws, hs), interpolation=cv2.INTER_NEAREST)

    ux, uy, low = small(u[..., 0]), small(u[..., 1]), small(lowest) * sx
    xs, ys = np.meshgrid(np.arange(ws, dtype=np.float32), np.arange(hs, dtype=np.float32))
    bx, by = xs + small(p_inf[..., 0]) * sx, ys + small(p_inf[..., 1]) * sy
    a = gi.astype(np.float32)
    best = np.full((hs, ws), np.inf, np.float32)
    step = 1.0 / scale  # half a pixel on half-size images: a textured patch off by half a pixel matches poorly
    for s in np.arange(np.floor(max(float(np.nanmin(low)), -8.0)), reach * ws + 1, step, dtype=np.float32):
        mx, my = bx + s * ux, by + s * uy
        inside = cv2.blur(((mx >= 0) & (mx <= ws - 1) & (my >= 0) & (my <= hs - 1)).astype(np.float32), (5, 5)) > 0.999
        best = np.where(inside & (s >= low), np.minimum(best, _window_cost(a, cv2.remap(gj, mx, my, cv2.INTER_LINEAR))), best)
    for wj in warped:
        best = np.minimum(best, _window_cost(a, _shrunk(wj, scale)))
    seen = np.isfinite(best)
    if not seen.any():
        return torch.zeros(h, w, dtype=torch.bool)
    poor = seen & (best > max(grey_min, median_rel * float(np.median(best[seen])))) & textured(gi, texture)
    return torch.from_numpy(cv2.resize(poor.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0)
