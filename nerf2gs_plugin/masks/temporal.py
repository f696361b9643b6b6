"""The motion route's last step (pure tensor code): the final moving-object masks of a sequence checked
against their neighbours in time.

A region that no neighbour confirms is a blip: the spill of one pair's flow, a facade that one frame's
reference renders badly. Carried by the observed flow into the frame just before and the frame just
after, a mover's region lands on (or near) that frame's region of the same mover; a blip lands on
nothing. A region is dropped where some neighbour sees at least half of it and in none that sees a
quarter of it (:data:`CONFIRM_SEEN`) ``persist`` of what it sees lands within ``persist_ring`` of that
neighbour's regions; a region that no neighbour sees half of (it leaves the frame, the sequence's ends)
stays. (``masks/motion.settle_transients`` first grows / trims each frame's regions to the image's
outlines once more, then calls :func:`persistent`.)

The flows are kept at every 2nd pixel per side (:func:`keep_flow`): the test tolerates a ring of several
pixels anyway, and a sequence's flows at full size would hold hundreds of MB.
"""

from __future__ import annotations

from typing import Callable, Optional, Sequence

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.utils.parallel import map_ahead

CONFIRM_SEEN = 0.25
"""A neighbour that sees this share of a region may confirm it (a mover leaving the frame: the frame after
sees only part of it), though only those that see half of it can drop it."""
FLOW_STEP = 2
"""The kept flows' pixel step per side."""


def keep_flow(flow: Tensor) -> Tensor:
    """``flow [H, W, 2]`` (pixels) at every :data:`FLOW_STEP`-th pixel per side, half precision."""
    return flow[::FLOW_STEP, ::FLOW_STEP].to(torch.float16).clone()


def carried(mask: Tensor, flow: Tensor, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``(where the frame's pixels land on mask, where they land inside it)``: bool ``[H, W]`` each, the
    frame's pixels carried by ``flow`` (kept by :func:`keep_flow`, into the frame of ``mask``)."""
    import cv2

    h, w = shape
    f = cv2.resize(flow.float().numpy(), (w, h), interpolation=cv2.INTER_LINEAR)
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    mx, my = xs + f[..., 0], ys + f[..., 1]
    inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    on = cv2.remap(mask.numpy().astype(np.float32), mx, my, cv2.INTER_LINEAR, borderValue=0) > 0.5
    return on & inside, inside


def confirmed_regions(mask: Tensor, neighbours: Sequence[tuple[Tensor, Tensor]], persist: float, ring_px: int) -> Tensor:
    """``mask``'s regions that some neighbour confirms: ``neighbours`` are ``(its mask, the observed flow
    into it)``; a neighbour that sees :data:`CONFIRM_SEEN` of a region confirms it where ``persist`` of
    what it sees lands within ``ring_px`` of the neighbour's mask. Regions no neighbour sees half of stay."""
    import cv2

    m = mask.numpy().astype(np.uint8)
    n, labels = cv2.connectedComponents(m, connectivity=8)
    if n <= 1 or not neighbours:
        return mask
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * ring_px + 1, 2 * ring_px + 1))
    seen = np.zeros((len(neighbours), n))
    hit = np.zeros((len(neighbours), n))
    area = np.bincount(labels.ravel(), minlength=n)
    for k, (other, flow) in enumerate(neighbours):
        near = torch.from_numpy(cv2.dilate(other.numpy().astype(np.uint8), disc) > 0)
        on, inside = carried(near, flow, m.shape)
        seen[k] = np.bincount(labels[inside], minlength=n)
        hit[k] = np.bincount(labels[on], minlength=n)
    sees = seen >= 0.5 * area
    ok = ((seen >= CONFIRM_SEEN * area) & (hit >= persist * np.maximum(seen, 1))).any(0) | ~sees.any(0)
    ok[0] = False
    return torch.from_numpy(ok[labels])


def persistent(masks: Sequence[Tensor], flows: Sequence[dict[int, Tensor]], persist: float, ring_frac: float,
               progress: Optional[Callable[[], None]] = None, workers: Optional[int] = None) -> list[Tensor]:
    """A sequence's masks (frames in capture order; ``flows[i]``: index ``j`` -> the observed flow from
    frame ``i`` into ``j``, kept by :func:`keep_flow`) without the regions that no neighbour in
    ``flows[i]`` confirms (:func:`confirmed_regions`, its ring ``ring_frac`` of the shorter side); the
    frames spread over the cores (``utils/parallel.map_ahead``, ``workers``)."""
    def check(i: int) -> Tensor:
        m = masks[i]
        ring = max(1, int(round(ring_frac * min(m.shape))))
        near = [(masks[j], f) for j, f in flows[i].items() if 0 <= j < len(masks) and tuple(masks[j].shape) == tuple(m.shape)]
        return confirmed_regions(m, near, persist, ring) if bool(m.any()) else m

    kept = []
    for m in map_ahead(check, range(len(masks)), workers):
        kept.append(m)
        if progress is not None:
            progress()
    return kept
