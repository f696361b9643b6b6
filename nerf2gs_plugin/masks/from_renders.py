"""Sky, ground and transient masks from a reference's renders of an input view (pure tensor code).

Inputs per view (all in the reference's normalised world, one image of ``[H, W]`` pixels):
``directions [H, W, 3]`` unit ray directions, ``origin [3]`` the camera centre, ``depth [H, W]``
distance along the ray, ``acc [H, W]`` accumulation, ``render`` / ``image`` ``[H, W, 3]``; the
ground plane is ``{x : x . up = height}``.

  * sky: what the reference sees nothing at (accumulation below ``acc_max``, or mass only at the
    contraction boundary: a reference trained without sky masks parks some sky there) and that lies above the
    horizon of the ground plane (a downward ray meets the road before it can see the sky; a small
    margin below the horizon is allowed for a street that ends in open ground); optionally box-voted
    and kept only where a region reaches the image's top row (a see-through patch that a short
    reference leaves in a facade is empty too, but enclosed);
  * ground: the rendered surface lies on the plane: its height above the plane (optionally a
    median over a window: floater speckle) is below ``tol`` (a kerb of 15 cm stays ground; below
    the plane counts as on it: a too-long depth), the ray points down, and, where normals are
    given, the normal is within ``max_normal_deg`` of up (too noisy on a short reference's depth);
    optionally a downward ray the reference sees nothing along is ground too (a short reference
    leaves the grey road near the camera see-through; nothing it saw stands there);
  * transient: the photometric residual against the multi-view consistent reference (after a
    per-image affine colour fit, as the reference renders the mean appearance), thresholded at a
    robust level (median + k * 1.4826 MAD over the dataset, RobustNeRF-style trimmed statistics),
    then smoothed as RobustNeRF does (a 3x3 box filter of the outlier indicator, majority vote),
    opened (thin strokes: poles and edges the reference blurs) and cleaned by connected regions:
    small regions are dropped, holes closed. Transient pixels are not ground; sky pixels are not
    transient (the sky is where a mask-less reference is weakest).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor


def horizon_mask(directions: Tensor, up: Tensor, margin_deg: float = 2.0) -> Tensor:
    """Pixels whose ray points above ``-margin_deg`` of elevation: where sky can be seen."""
    return (directions @ up) > -math.sin(math.radians(margin_deg))


def top_connected(mask: Tensor) -> Tensor:
    """The connected regions (8-neighbours) of ``mask`` that touch the image's top row."""
    import cv2

    m = mask.cpu().numpy().astype(np.uint8)
    n, labels = cv2.connectedComponents(m, connectivity=8)
    keep = np.zeros(n, dtype=bool)
    keep[np.unique(labels[0][m[0] > 0])] = True
    keep[0] = False
    return torch.from_numpy(keep[labels]).to(mask.device)


def enclosed_holes(mask: Tensor) -> Tensor:
    """``mask`` with its holes filled: the regions outside it (4-neighbours) that touch neither the left,
    the right nor the bottom row of the image (the top row counts as more of the mask: the sky goes on
    above the frame)."""
    import cv2

    m = mask.cpu().numpy().astype(bool)
    n, labels = cv2.connectedComponents((~m).astype(np.uint8), connectivity=4)
    open_ = np.zeros(n, dtype=bool)
    for border in (labels[:, 0], labels[:, -1], labels[-1, :]):
        open_[np.unique(border)] = True
    hole = ~open_
    hole[0] = False  # label 0: the mask's own pixels
    filled = m | hole[labels]
    return torch.from_numpy(filled).to(mask.device)


def sky_from_render(acc: Tensor, directions: Tensor, up: Tensor, acc_max: float = 0.5, margin_deg: float = 2.0,
                    depth: Optional[Tensor] = None, far: float = float("inf"), vote: int = 0, from_top: bool = False,
                    fill_holes: bool = False) -> Tensor:
    """Low accumulation, or a depth beyond ``far`` (mass pushed to the contraction boundary), above
    the horizon (see the module docstring); then, optionally, RobustNeRF's ``vote`` x ``vote`` box
    vote (speckle out), only the regions that reach the top of the image (``from_top``: what a
    see-through patch inside a facade or a floater hole below the skyline is not) and the holes
    filled (``fill_holes``: clouds a mask-less reference gave density, enclosed by sky)."""
    empty = acc < acc_max
    if depth is not None:
        empty = empty | (depth > far)
    sky = empty & horizon_mask(directions, up, margin_deg)
    if vote > 1:
        sky = box_vote(sky, vote)
    if from_top:
        sky = top_connected(sky)
    return enclosed_holes(sky) if fill_holes else sky


def surface_points(origin: Tensor, directions: Tensor, depth: Tensor) -> Tensor:
    """``[H, W, 3]`` rendered surface points."""
    return origin.reshape(1, 1, 3) + directions * depth[..., None]


def normals_from_points(points: Tensor) -> Tensor:
    """``[H, W, 3]`` unit normals from finite differences of the surface points (central inside,
    one-sided at the border); the sign is meaningless, compare ``|n . up|``."""
    p = points.permute(2, 0, 1)[None]
    pad = F.pad(p, (1, 1, 1, 1), mode="replicate")
    du = (pad[..., 1:-1, 2:] - pad[..., 1:-1, :-2])[0].permute(1, 2, 0)
    dv = (pad[..., 2:, 1:-1] - pad[..., :-2, 1:-1])[0].permute(1, 2, 0)
    return F.normalize(torch.linalg.cross(du, dv, dim=-1), dim=-1, eps=1e-12)


def median_filter(x: Tensor, size: int) -> Tensor:
    """``size`` x ``size`` median of an ``[H, W]`` map (replicated border); ``size`` < 2: unchanged."""
    if size < 2:
        return x
    size += 1 - size % 2
    p = F.pad(x[None, None], (size // 2,) * 4, mode="replicate")
    return F.unfold(p, size)[0].median(0).values.reshape(x.shape)


def box_count(mask: Tensor, size: int) -> Tensor:
    """``[H, W]`` number of true pixels in each ``size`` x ``size`` window (replicated border, odd
    ``size``), exact in integers through a summed-area table."""
    p = F.pad(mask.float()[None, None], (size // 2,) * 4, mode="replicate")[0, 0].to(torch.int32)
    s = F.pad(p.cumsum(0).cumsum(1), (1, 0, 1, 0))
    h, w = mask.shape
    return s[size:size + h, size:size + w] - s[:h, size:size + w] - s[size:size + h, :w] + s[:h, :w]


def median_compare(x: Tensor, threshold: float, size: int, below: bool = True) -> Tensor:
    """``median_filter(x, size) < threshold`` (``below``) or ``>= threshold``, exactly, without sorting
    a window: with an odd count n per window, the median is on a side of the threshold iff at least
    (n + 1) / 2 values are. A window holding a NaN has a NaN median: False either way."""
    side = (x < threshold) if below else (x >= threshold)
    if size < 2:
        return side
    size += 1 - size % 2
    held = box_count(side, size) >= (size * size + 1) // 2
    nan = torch.isnan(x)
    return held & (box_count(nan, size) == 0) if bool(nan.any()) else held


def ground_from_render(origin: Tensor, directions: Tensor, depth: Tensor, acc: Tensor, up: Tensor, height: float, tol: float,
                       acc_min: float = 0.5, normals: Optional[Tensor] = None, max_normal_deg: float = 30.0,
                       smooth_px: int = 0, empty_is_ground: bool = False) -> Tensor:
    """Rendered surface within ``tol`` of the plane (heights in world units), seen by a downward
    ray with a solid render (see the module docstring). ``smooth_px``: the heights (and the
    accumulation) are ``smooth_px``-wide medians first, so a floater's speckle in front of the road
    or a see-through hole in a facade does not flip a pixel. ``empty_is_ground``: a downward ray
    whose (median) accumulation is below ``acc_min`` counts as ground as well."""
    h = surface_points(origin, directions, depth) @ up - height
    # the medians are only compared with a threshold: counted per window, as exact as the sort and
    # two orders of magnitude faster at the default window (29 px at 360 rows)
    solid = median_compare(acc, acc_min, smooth_px, below=False)
    # one-sided: nothing is below the road, a surface rendered below the plane is a depth error on the road
    g = median_compare(h, tol, smooth_px) & solid
    if empty_is_ground:
        g |= ~solid
    g &= (directions @ up) < 0
    if normals is not None:
        g &= (normals @ up).abs() > math.cos(math.radians(max_normal_deg))
    return g


def fit_colour(render: Tensor, image: Tensor, keep: Optional[Tensor] = None, iters: int = 3, trim: float = 0.7,
               ridge: float = 1e-2) -> Tensor:
    """``render`` mapped by the affine colour transform (3x4) that best takes it to ``image``,
    refitted on the ``trim`` fraction of best-fitting pixels (outliers such as cars excluded).
    Ridge-regularised towards the identity: a view of few colours cannot tilt the map elsewhere."""
    x = torch.cat([render.reshape(-1, 3), torch.ones(render.shape[0] * render.shape[1], 1)], dim=1).double()
    y = image.reshape(-1, 3).double()
    base = keep.reshape(-1) if keep is not None else torch.ones(len(x), dtype=torch.bool)
    if int(base.sum()) < 16:
        return render
    eye = torch.cat([torch.eye(3), torch.zeros(1, 3)]).double()  # [4, 3]: the identity map
    sel, A = base, eye
    for _ in range(iters):
        xs, ys = x[sel], y[sel]
        lam = ridge * len(xs)
        A = torch.linalg.solve(xs.T @ xs + lam * torch.eye(4, dtype=x.dtype), xs.T @ ys + lam * eye)
        r = (x @ A - y).abs().sum(-1)
        lim = torch.quantile(r[base][torch.randperm(int(base.sum()), generator=torch.Generator().manual_seed(0))[:200000]], trim)
        sel = base & (r <= lim)
        if int(sel.sum()) < 16:
            break
    return (x @ A).float().reshape(render.shape).clamp(0, 1)


def residual_map(image: Tensor, render: Tensor, blur: int = 1) -> Tensor:
    """``[H, W]`` mean absolute colour difference after a ``blur`` x ``blur`` box blur of both
    images (1: none; the box vote already drops one-pixel edge misregistrations)."""
    def smooth(x: Tensor) -> Tensor:
        if blur <= 1:
            return x
        return F.avg_pool2d(F.pad(x.permute(2, 0, 1)[None], (blur // 2,) * 4, mode="replicate"), blur, 1)[0].permute(1, 2, 0)

    return (smooth(image) - smooth(render)).abs().mean(-1)


def robust_threshold(residuals: Tensor, k: float = 4.0, floor: float = 0.04, sample: int = 1_000_000) -> float:
    """median + ``k`` * 1.4826 * MAD of the residuals (all views pooled), at least ``floor``."""
    r = residuals.reshape(-1)
    if len(r) > sample:
        r = r[torch.randperm(len(r), generator=torch.Generator().manual_seed(0))[:sample]]
    med = r.median()
    mad = (r - med).abs().median()
    return max(float(med + k * 1.4826 * mad), floor)


def box_vote(mask: Tensor, size: int = 3, frac: float = 0.5) -> Tensor:
    """RobustNeRF's smoothing: a pixel is an outlier when more than ``frac`` of its ``size`` x
    ``size`` neighbourhood is."""
    m = mask.float()[None, None]
    return F.avg_pool2d(F.pad(m, (size // 2,) * 4, mode="replicate"), size, 1)[0, 0] > frac


def clean_regions(mask: Tensor, min_area: int, close_px: int = 2) -> Tensor:
    """Morphological closing by ``close_px``, then connected regions smaller than ``min_area``
    pixels dropped, then holes inside regions filled (a car's windows are part of the car)."""
    import cv2

    m = mask.cpu().numpy().astype(np.uint8)
    if close_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_px + 1, 2 * close_px + 1))
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, k)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    keep = np.zeros(n, dtype=bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= min_area
    m = keep[labels].astype(np.uint8)
    inv = 1 - m  # holes: background components that do not touch the border
    n2, lab2, _, _ = cv2.connectedComponentsWithStats(inv, connectivity=4)
    border = np.unique(np.concatenate([lab2[0], lab2[-1], lab2[:, 0], lab2[:, -1]]))
    hole = np.ones(n2, dtype=bool)
    hole[border] = False
    hole[0] = False if 0 in border else hole[0]
    m = np.where(inv.astype(bool) & hole[lab2], 1, m)
    return torch.from_numpy(m.astype(bool)).to(mask.device)


def opening(mask: Tensor, px: int) -> Tensor:
    """Morphological opening by a disc of radius ``px``: strokes thinner than the disc go (a pole or an
    edge the reference blurs), blobs stay."""
    if px < 1:
        return mask
    import cv2

    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * px + 1, 2 * px + 1))
    return torch.from_numpy(cv2.morphologyEx(mask.cpu().numpy().astype(np.uint8), cv2.MORPH_OPEN, k).astype(bool)).to(mask.device)


def transient_from_residual(residual: Tensor, threshold: float, min_area: int, vote: int = 3, close_px: int = 2,
                            low: Optional[float] = None, open_px: int = 0) -> Tensor:
    """Residual above ``threshold`` -> RobustNeRF box vote -> opening by ``open_px`` -> connected
    regions (see above). With ``low`` (hysteresis): regions of the box-voted ``residual > low`` that
    hold a box-voted ``residual > threshold`` pixel, so a car's weaker parts join its strong core."""
    strong = opening(box_vote(residual > threshold, vote), open_px)
    if low is not None and low < threshold:
        import cv2

        weak = box_vote(residual > low, vote).cpu().numpy().astype(np.uint8)
        n, labels = cv2.connectedComponents(weak, connectivity=8)
        hit = np.zeros(n, dtype=bool)
        hit[np.unique(labels[strong.cpu().numpy() & (labels > 0)])] = True
        hit[0] = False
        strong = torch.from_numpy(hit[labels]).to(residual.device) | strong
    return clean_regions(strong, min_area, close_px)
