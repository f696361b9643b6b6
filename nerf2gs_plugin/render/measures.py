"""What can be measured from above without ground truth there (real captures have none).

* Holes: the share of pixels whose accumulation is below 0.5 (the render sees through the model:
  background colour, black or sky where the road should be), over all frames of a path.
* Near-camera floaters: the share of pixels that are covered (accumulation >= 0.5) and whose depth
  is closer to the camera than ``max(FLOATER_MIN_M, FLOATER_HEIGHT_FRACTION x h)``, where ``h`` is the
  camera's height above the capture's own cameras (along the ground's up, to the capture camera
  nearest it on the ground plane). From 10 m above a drive nothing real is within 2.5 m of the
  camera: what renders there is a floater, a blob the model left in free space. Depth is the
  method's rendered depth (z along the view axis for splatting, expected ray distance for NeRFs).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras

HOLE_ACCUMULATION = 0.5
FLOATER_HEIGHT_FRACTION = 0.25
FLOATER_MIN_M = 1.0


def hole_mask(accumulation: Tensor) -> Tensor:
    """``[H, W]`` pixels with accumulation below :data:`HOLE_ACCUMULATION`."""
    return accumulation.reshape(accumulation.shape[0], accumulation.shape[1], -1)[..., 0] < HOLE_ACCUMULATION


def floater_mask(depth: Tensor, accumulation: Tensor, near: float) -> Tensor:
    """``[H, W]`` covered pixels whose depth is in ``(0, near)`` (world units)."""
    d = depth.reshape(depth.shape[0], depth.shape[1], -1)[..., 0]
    return ~hole_mask(accumulation) & (d > 0) & (d < near)


def height_above_capture(cameras: Cameras, capture: Cameras, up: Tensor) -> Tensor:
    """``[N]`` each camera's height (world units, >= 0) above the capture camera nearest it on the ground plane."""
    up = up.to(cameras.centers)
    c, t = cameras.centers, capture.centers.to(cameras.centers)
    flat_c = c - (c @ up)[:, None] * up
    flat_t = t - (t @ up)[:, None] * up
    nearest = torch.cdist(flat_c, flat_t).argmin(dim=1)
    return ((c - t[nearest]) @ up).clamp_min(0.0)


def floater_distance(height: float, units_per_metre: float) -> float:
    """The near distance (world units) of a camera ``height`` world units above the capture."""
    return max(FLOATER_MIN_M * units_per_metre, FLOATER_HEIGHT_FRACTION * height)


@dataclass
class PathMeasures:
    """Running counts over the frames of a path."""

    pixels: int = 0
    holes: int = 0
    floaters: int = 0
    frames: int = 0
    per_frame_holes: list = field(default_factory=list)

    def add(self, outputs: dict, near: float) -> None:
        acc = outputs["accumulation"].detach().cpu()
        holes = int(hole_mask(acc).sum())
        n = acc.shape[0] * acc.shape[1]
        self.pixels += n
        self.holes += holes
        self.frames += 1
        self.per_frame_holes.append(holes / n)
        if "depth" in outputs:
            self.floaters += int(floater_mask(outputs["depth"].detach().cpu(), acc, near).sum())

    def result(self) -> dict:
        """``bev_hole_fraction`` and ``floater_fraction`` (shares of all pixels of the path), ``frames``."""
        p = max(self.pixels, 1)
        return {"bev_hole_fraction": self.holes / p, "floater_fraction": self.floaters / p, "frames": self.frames,
                "worst_frame_hole_fraction": max(self.per_frame_holes, default=0.0)}


def measure_path(model, cameras: Cameras, capture: Cameras, up: Tensor, units_per_metre: float, progress=None) -> dict:
    """Render every camera of a path and measure holes and near-camera floaters (see the module doc)."""
    from nerf2gs_plugin.render.frames import render_outputs

    heights = height_above_capture(cameras, capture, up)
    m = PathMeasures()
    for i, out in enumerate(render_outputs(model, cameras)):
        m.add(out, floater_distance(float(heights[i]), units_per_metre))
        if progress is not None:
            progress()
    return m.result()
