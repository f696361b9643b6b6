"""The motion route's second pass (pure tensor code): the first pass's transient masks checked against a
second reference that was trained with them excluded from its loss.

The first reference is trained without masks, so it partly learns the movers (a car riding ahead at the
camera's speed as something far away): the residual against it is low on them. The second reference
(the first one continued a few hundred steps with the first pass's masks excluded from its loss) has no
reason to keep them: on a mover its residual grows, while on the static pixels that the first pass
marked (flow spilt onto the road beside a mover, facades a short reference renders badly) both
references render the same surface about as well. A first-pass pixel stays where the second residual
exceeds the first by ``margin`` (both divided by their frame's median residual); the regions are then
cleaned and grown to the image's outlines as the first pass's are. A mover that the first reference did
not learn at all is as far from both renders: the difference can drop it.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.masks import from_renders as fr

SAMPLE_EVERY = 4
"""Besides the first pass's regions the second reference renders every 4th pixel per side: the frame's
median residual and the colour fit are taken there."""
SUPPORT_PX = 3
"""The regions are rendered this many pixels wider: the 5x5 mean residual at their edges."""


def _disc(r: int) -> np.ndarray:
    import cv2

    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def render_pixels(first: Tensor, step: int = 1) -> tuple[Tensor, Tensor]:
    """``(pixels the second reference renders, the sample grid among them)`` for a frame whose first-pass
    mask is ``first`` (bool ``[H, W]``): the regions (every ``step``-th pixel per side of them, as the first
    reference rendered the frame: the residual is a 5x5 mean over what was rendered) and the sample grid."""
    import cv2

    h, w = first.shape
    grid = torch.zeros(h, w, dtype=torch.bool)
    grid[SAMPLE_EVERY // 2::SAMPLE_EVERY, SAMPLE_EVERY // 2::SAMPLE_EVERY] = True
    near = torch.from_numpy(cv2.dilate(first.numpy().astype(np.uint8), _disc(SUPPORT_PX)) > 0)
    if step > 1:
        lattice = torch.zeros(h, w, dtype=torch.bool)
        lattice[::step, ::step] = True
        near = near & lattice
    return near | grid, grid


def relative_residual(image: Tensor, render: Tensor, rendered: Tensor, fit_on: Tensor, sample: Tensor) -> Tensor:
    """``[H, W]``: the residual of ``image`` against ``render`` after the colour fit (fitted on the
    ``fit_on`` pixels), 5x5 means over the ``rendered`` pixels, divided by its median over ``sample``."""
    import cv2

    fitted = fr.fit_colour(render, image, keep=fit_on)
    weight = rendered.numpy().astype(np.float32)
    res = (fr.residual_map(image, fitted).numpy() * weight).astype(np.float32)
    mean = cv2.blur(res, (5, 5)) / np.maximum(cv2.blur(weight, (5, 5)), 1e-6)
    med = float(np.median(mean[sample.numpy()])) if bool(sample.any()) else float(np.median(mean))
    return torch.from_numpy(mean / max(med, 1e-6))


def second_pass_mask(first: Tensor, image: Tensor, render1: Tensor, render2: Tensor, rendered: Tensor, sample: Tensor,
                     sky: Tensor, margin: float = 0.2, min_region_frac: float = 0.002, outline_ring: float = 0.03) -> Tensor:
    """The first pass's mask ``first`` kept where ``image``'s residual against the second reference's
    render (``render2``, valid on ``rendered``) exceeds that against the first's (``render1``) by more
    than ``margin``, each divided by the frame's median residual over ``sample`` (outside ``first`` and
    the sky); cleaned and grown to the image's outlines (:func:`~nerf2gs_plugin.masks.motion.outline`)."""
    from nerf2gs_plugin.masks.motion import outline

    if not bool(first.any()):
        return first
    static = rendered & ~first
    sample = sample & ~first & ~sky
    r1 = relative_residual(image, render1, rendered, static, sample)
    r2 = relative_residual(image, render2, rendered, static, sample)
    keep = first & ~sky & (r2 - r1 > margin)
    h, w = first.shape
    area, close = max(4, int(min_region_frac * h * w)), max(1, round(0.01 * min(h, w)))
    m = fr.clean_regions(fr.opening(keep, 1), area, close_px=close)
    return fr.clean_regions(outline(m, image, outline_ring), area, close_px=close)
