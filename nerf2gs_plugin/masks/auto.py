"""``--segmenter auto``: masks derived from the capture itself through a first reference (no weights).

The reference (``nerf2gs_plugin.masking.mask_reference``: a short StreetNeRF trained without masks)
renders every frame (``nerf2gs_plugin.masking.auto_masks``); this module turns those renders (rgb /
depth / accumulation and the photometric residual, :class:`Renders`) into masks with the pure
functions of ``from_renders.py``. The ground plane is ``data/ground.py``'s RANSAC fit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.masks import from_renders as fr
from nerf2gs_plugin.utils.parallel import map_ahead


@dataclass
class AutoOptions:
    """Thresholds of ``--segmenter auto`` (metres where said; see ``from_renders.py``)."""

    sky_acc: float = 0.5
    """Sky: accumulation of the reference below this."""
    sky_far: float = 20.0
    """Sky also where the rendered depth is beyond this many scene-box half-sizes (what the reference
    pushed toward the contraction boundary)."""
    sky_vote: int = 3
    """Sky: RobustNeRF's box vote over this many pixels square (0: none)."""
    sky_from_top: bool = True
    """Sky: only regions that reach the image's top row (a see-through patch in a facade does not)."""
    sky_fill_holes: bool = False
    """Sky: fill the mask's holes (regions touching neither the left, right nor bottom row: clouds the
    mask-less reference gave density). Off by default: it helped one validation street and hurt the
    other (benchmarks/results/auto_masks_seed{7,3}_video4.md)."""
    horizon_margin_deg: float = 2.0
    """Sky may reach this far below the ground plane's horizon."""
    ground_tol_m: float = 0.5
    """Ground: rendered surface within this many metres of the plane (above the depth noise of a
    short reference at road distances; a kerb stays ground, a car is removed as transient)."""
    ground_smooth: float = 0.08
    """Ground: the heights are medians over a window this fraction of the image's shorter side wide
    (0: per pixel)."""
    ground_empty: bool = True
    """Ground also where a downward ray meets nothing in the reference (accumulation below 0.5 after
    the median): a short reference leaves the textureless road near the camera see-through. On three
    synthetic streets it raised ground IoU and recall without lowering precision
    (benchmarks/results/auto_masks_seed*.md)."""
    ground_normals: bool = False
    """Also require the rendered normal (from depth differences) within 30 deg of up."""
    transient_k: float = 3.0
    """Transient: residual above median + k * 1.4826 * MAD (all training views pooled)."""
    transient_k_low: float = 0.0
    """Hysteresis: regions above median + k_low * 1.4826 * MAD joined to the strong ones (0 or >= k:
    off). Off by default: with a 1000-step reference it cost 0.04 transient IoU and 0.04 ground IoU
    on both synthetic streets (false regions eat sky and ground)."""
    transient_floor: float = 0.04
    """... and above this absolute mean colour difference."""
    min_region_frac: float = 0.005
    """Transient regions smaller than this fraction of the image are dropped."""
    transient_open: float = 0.018
    """Transient: opening by a disc this fraction of the image's shorter side across (thin strokes the
    reference blurs, poles and edges, go; cars stay)."""


@dataclass
class FrameMasks:
    sky: Tensor
    ground: Tensor
    transient: Tensor


@dataclass
class Renders:
    """The reference's renders of every frame (reference resolution), keyed by split, plus the plane."""

    views: dict[str, list[dict[str, Tensor]]]
    up: Tensor
    height: float
    metres_to_world: float
    seconds: float
    box_extent: float = float("inf")  # half the scene box's largest side (world units)
    cpu_seconds: float = 0.0  # of the renders (this process, every thread, and its render workers)


def masks_from_renders(r: Renders, opts: AutoOptions, log: Callable[[str], None] = print,
                       workers: Optional[int] = None) -> dict[str, list[FrameMasks]]:
    """Sky / ground / transient per frame (reference resolution), keyed by split, in parser order; the
    frames spread over the cores (``utils/parallel.map_ahead``, ``workers``)."""
    up, tol = r.up, r.metres_to_world * opts.ground_tol_m
    frames = [(s, i) for s, rs in r.views.items() for i in range(len(rs))]

    def sky_and_residual(si: tuple[str, int]) -> tuple[Tensor, Tensor]:
        v = r.views[si[0]][si[1]]
        sky = fr.sky_from_render(v["acc"], v["dirs"], up, opts.sky_acc, opts.horizon_margin_deg,
                                 depth=v["depth"], far=opts.sky_far * r.box_extent,
                                 vote=opts.sky_vote, from_top=opts.sky_from_top, fill_holes=opts.sky_fill_holes)
        fitted = fr.fit_colour(v["rgb"], v["image"])
        return sky, fr.residual_map(v["image"], fitted)

    sky_res = dict(zip(frames, map_ahead(sky_and_residual, frames, workers)))
    base = "train" if "train" in r.views else next(iter(r.views))
    pool = torch.cat([sky_res[base, i][1][~sky_res[base, i][0]] for i in range(len(r.views[base]))])
    thr = fr.robust_threshold(pool, opts.transient_k, opts.transient_floor)
    low = fr.robust_threshold(pool, opts.transient_k_low, opts.transient_floor / 2) if 0 < opts.transient_k_low < opts.transient_k else None
    log(f"masks: ground plane at height {r.height:.4f} (world units), tolerance {tol:.4f}; transient residual threshold {thr:.3f}" + (f" (regions grown to {low:.3f})" if low else ""))

    def frame_masks(si: tuple[str, int]) -> FrameMasks:
        v = r.views[si[0]][si[1]]
        sky, res = sky_res[si]
        h, w = v["acc"].shape
        trans = fr.transient_from_residual(res, thr, max(4, int(opts.min_region_frac * h * w)), low=low,
                                           open_px=int(round(opts.transient_open * min(h, w))))
        normals = fr.normals_from_points(fr.surface_points(v["origin"], v["dirs"], v["depth"])) if opts.ground_normals else None
        ground = fr.ground_from_render(v["origin"], v["dirs"], v["depth"], v["acc"], up, r.height, tol, normals=normals,
                                       smooth_px=int(round(opts.ground_smooth * min(h, w))), empty_is_ground=opts.ground_empty)
        trans = trans & ~sky  # the sky is where the reference is weakest: a high residual there is no car
        return FrameMasks(sky, ground & ~trans & ~sky, trans)

    result: dict[str, list[FrameMasks]] = {s: [] for s in r.views}
    for (s, _), m in zip(frames, map_ahead(frame_masks, frames, workers)):
        result[s].append(m)
    return result
