"""The space the capture moved through, kept free of primitives.

Why: whoever carried the camera (a car, a person) stood on its path, so nothing the scene holds lies
within about a metre of it; yet a splatting model puts semi-transparent primitives there when the
training views' far backgrounds need them (on castle-P30 a dozen such Gaussians blacked out a held-out
photo: ``benchmarks/results/near_camera_floaters.md``). Every view later rendered from the road stands on
that path, so these are the floaters users see first.

The path is the training cameras' centres joined in capture order; a join longer than
``max_join`` times the typical spacing of the cameras (the median distance to the nearest other
camera) is left out, so an unordered photo set is not joined across the scene it surrounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor


@dataclass
class CapturePath:
    segments: Tensor
    """``[S, 2, 3]`` world: start and end of each piece of the path (a lone camera: start == end)."""

    def distance(self, points: Tensor, chunk: int = 16384) -> Tensor:
        """``[N]``: each point's distance to the nearest piece of the path (chunked over the points,
        memory ``chunk x S``)."""
        a = self.segments[:, 0].to(points)
        ab = self.segments[:, 1].to(points) - a  # [S, 3]
        len2 = (ab * ab).sum(-1).clamp_min(1e-20)
        out = torch.empty(points.shape[0], dtype=points.dtype, device=points.device)
        for s in range(0, points.shape[0], chunk):
            ap = points[s: s + chunk, None, :] - a[None]  # [n, S, 3]
            t = ((ap * ab[None]).sum(-1) / len2[None]).clamp(0.0, 1.0)
            out[s: s + chunk] = (ap - t[..., None] * ab[None]).norm(dim=-1).amin(-1)
        return out

    def near(self, points: Tensor, radius: float) -> Tensor:
        """``[N]`` bool: points within ``radius`` (world units) of the path."""
        if radius <= 0 or points.shape[0] == 0 or self.segments.shape[0] == 0:
            return torch.zeros(points.shape[0], dtype=torch.bool, device=points.device)
        return self.distance(points) < radius


def capture_path(centres: Tensor, max_join: float = 3.0) -> CapturePath:
    """The path through camera ``centres [C, 3]`` (capture order): consecutive cameras joined where
    they are at most ``max_join`` x the median nearest-camera spacing apart, and every camera a
    point of the path."""
    c = centres.detach().float().reshape(-1, 3)
    points = torch.stack([c, c], dim=1)  # [C, 2, 3]
    if c.shape[0] < 2:
        return CapturePath(points)
    d = torch.cdist(c, c)
    d.fill_diagonal_(float("inf"))
    spacing = float(d.amin(1).median())
    gaps = (c[1:] - c[:-1]).norm(dim=-1)
    joined = gaps <= max_join * spacing
    segs = torch.stack([c[:-1][joined], c[1:][joined]], dim=1)
    return CapturePath(torch.cat([segs, points]))
