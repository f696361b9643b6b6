"""Oncoming traffic from the mask-less reference's geometry (pure tensor code): what floats below the camera.

A car driving toward the camera along the drive (speed ``v_o``; the camera's ``v_c``) gives every frame the same
picture as a static copy of it scaled by ``s = v_c / (v_c + v_o)`` about the camera: nearer, smaller, fixed in the
world, its wheels ``1 - s`` of the camera's height above the road. The mask-less reference learns that copy (it
agrees with every frame) and the car's flow is the copy's rigid flow, so neither the residual route nor the motion
route sees it. What gives it away is that it floats: nothing static hangs below the camera's height, over the road
near the camera's path, with the road visible farther away right under it.

A region here is a depth-continuous patch of the reference's surface between ``LOW`` and ``HIGH`` of the camera's
height above the ground plane, holding a bottom edge under which, within ``BELOW`` of the image height, the road lies
``JUMP`` times farther away. It is kept where its lowest tenth clears ``clear`` of the camera height (a static
object's underside rarely does: a car's, a railing's) and its middle lies within ``reach`` metres of the camera's path
sideways (the scaled copy sits over the road, ``s`` of the real car's offset).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

LOW, HIGH = 0.15, 0.95
"""The band of heights (shares of the camera's height above the plane) a region's pixels lie in."""
ROAD = 0.06
"""A pixel within this share of the camera height of the plane is road."""
JUMP = 1.3
"""The road under a bottom edge lies at least this many times farther along its ray than the edge."""
BELOW = 0.03
"""How far under a bottom edge the road is looked for, as a share of the image height."""
CONTINUOUS = 0.15
"""Neighbouring pixels of a region differ by less than this in log distance."""
MIN_AREA = 0.0013
"""Regions smaller than this share of the image are dropped."""


def floating_objects(dist: Tensor, rays: Tensor, origin: Tensor, up: Tensor, height: float, metres: float,
                     clear: float, reach: float, sky: Tensor | None = None) -> Tensor:
    """Bool ``[H, W]``: the regions of a frame's reference surface that float (module docstring). ``dist [H, W]``:
    distance along the unit ``rays [H, W, 3]`` from ``origin [3]`` (inf: none); the ground plane ``{x . up =
    height}``; ``metres``: world units per metre; ``clear``: the share of the camera height a region's lowest tenth
    must clear; ``reach``: metres sideways from the camera's path; ``sky``: pixels left out."""
    import cv2

    hh, ww = dist.shape
    d = dist.double().numpy()
    finite = np.isfinite(d)
    up64, o = up.double(), origin.double()
    cam_h = float(o @ up64) - height
    if cam_h <= 1e-9:
        return torch.zeros(hh, ww, dtype=torch.bool)
    r = rays.double().numpy()
    rel = r * np.where(finite, d, 0.0)[..., None]
    h = np.where(finite, (rel @ up64.numpy() + cam_h) / cam_h, np.nan)
    keep_out = ~finite if sky is None else (~finite | sky.numpy())
    band = (h > LOW) & (h < HIGH) & ~keep_out
    road = (np.abs(h) < ROAD) & ~keep_out
    seeds = np.zeros_like(band)
    for g in range(1, max(1, round(BELOW * hh)) + 1):
        under_road = np.zeros_like(band)
        under_road[:-g] = road[g:] & (d[g:] > JUMP * d[:-g])
        seeds |= band & under_road
    if not seeds.any():
        return torch.zeros(hh, ww, dtype=torch.bool)
    ld = np.log(np.where(finite, np.maximum(d, 1e-12), 1.0))
    dy, dx = np.abs(np.diff(ld, axis=0)), np.abs(np.diff(ld, axis=1))
    step = np.zeros_like(ld)  # the largest log-distance step to a 4-neighbour
    step[:-1] = np.maximum(step[:-1], dy)
    step[1:] = np.maximum(step[1:], dy)
    step[:, :-1] = np.maximum(step[:, :-1], dx)
    step[:, 1:] = np.maximum(step[:, 1:], dx)
    patch = (band & (step < CONTINUOUS)) | seeds
    n, labels = cv2.connectedComponents(patch.astype(np.uint8), connectivity=4)
    ids = np.unique(labels[seeds])
    ids = ids[ids > 0]
    if ids.size == 0:
        return torch.zeros(hh, ww, dtype=torch.bool)
    sideways = (rel @ _right(up64, r, finite).numpy()) / max(metres, 1e-12)
    out = np.zeros((hh, ww), dtype=bool)
    min_area = max(4, int(MIN_AREA * hh * ww))
    for i in ids:
        m = labels == i
        if m.sum() < min_area:
            continue
        if np.quantile(h[m], 0.1) > clear and abs(float(np.median(sideways[m]))) < reach:
            out |= m
    return torch.from_numpy(out)


def _right(up: Tensor, rays: np.ndarray, finite: np.ndarray) -> Tensor:
    """The unit horizontal direction across the camera's view: its central ray's heading turned about ``up``."""
    h, w = finite.shape
    ahead = torch.from_numpy(rays[h // 2, w // 2]).double()
    level = ahead - (ahead @ up) * up
    return torch.nn.functional.normalize(torch.linalg.cross(level, up), dim=0)
