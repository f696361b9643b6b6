"""Moving objects from motion, no weights: where the image moves otherwise than the static scene would.

A camera moving through a static street sees every static pixel move along its *epipolar line*
(from where the camera's rotation alone puts it, outward as the surface comes closer), and by how far
depends on the surface's distance. Dense optical flow (OpenCV's DIS, after warping the neighbour by
the rigid flow of a prior depth: the first reference's render, so that what is left is small) measures
how the image actually moved. A pixel moves where no static surface explains its flow:

  * it leaves the epipolar line (``perp_px``): a pedestrian crossing, a car turning;
  * it has less parallax than the farthest static surface along its ray (``bound``): an object riding
    ahead at the camera's speed stays put in the image, while the road beneath it flows, and a
    static surface seen by a ray pointing down is never farther than the ground plane along that ray
    (:func:`static_distance`), so a mask-less reference that rendered the object far away (where zero
    parallax puts it) cannot hide it;
  * it has clearly less parallax than the reference depth gives (``ref_rel``): farther than the
    reference says. Not the other way (``ref_close_rel``, off): a short reference's holes and
    smeared depth put static surfaces too far much more often than a mover comes closer;
  * a parked car is where its depth says: its flow is the rigid flow, it stays unmasked.

Each frame is compared with several neighbours before and after it (``neighbours``); a pair counts where
the pixel's static point lands inside the neighbour, in front of it, and a pixel moves when at least ``vote`` of its valid pairs say so, on both sides (what a mover uncovers
was hidden only in the frames before it). A voted pixel stays where the image also differs from
the reference's render (``residual_rel``: the road beside a mover, where DIS spreads the mover's flow,
matches the reference) and, optionally, where the frames just before and after move too
(``carry``). The votes are grown to object outlines: superpixels (SLIC on the image) join where
``grow`` of their pixels move, the regions are closed, their holes filled and small ones dropped
(``masks/from_renders.clean_regions``), then grown / trimmed to the image's edges by grabCut (``outline``).

Memory: one frame's flows at a time, plus the sequence's grey images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Optional, Sequence

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.masks import from_renders as fr
from nerf2gs_plugin.masks.temporal import keep_flow, persistent
from nerf2gs_plugin.utils.parallel import map_ahead

Intrinsics = tuple[float, float, float, float]  # fx, fy, cx, cy (pixel centres at +0.5)


@dataclass
class MotionOptions:
    """``--segmenter auto``'s motion route (see ``masks/motion.py``)."""

    enabled: bool = True
    """Add what moves against the static scene's flow to the transient masks (``--motion.no-enabled``:
    the residual route alone)."""
    sequences_only: bool = True
    """Only for captures processed as a sequence (``process video``, or sequential matching): the
    route compares neighbouring frames; in a photo set they need not be near each other."""
    neighbours: tuple[int, ...] = (-2, -1, 1, 2)
    """Frames compared with each frame (offsets in the sequence, sorted by file name), in steps of
    ``min_baseline``'s stride."""
    min_baseline: float = 0.35
    """The offsets count in strides of the fewest frames whose median camera step reaches this fraction
    of the camera's median height above the road (0: one frame). A video at 15 fps moves a dashcam a
    few tens of centimetres a frame: the road a few metres ahead then flows by a pixel or two, within
    the route's tolerances, and a mover riding ahead is not told from it. Captures whose frames are
    that far apart already (key frames, a long video's frames spread out) keep a stride of one."""
    perp_px: float = 1.5
    """A pixel moves where its flow leaves the epipolar line by more than this many pixels ..."""
    perp_rel: float = 0.05
    """... and this fraction of its flow (pose errors grow with the flow) ..."""
    rel: float = 0.15
    """... or where its parallax falls short of the farthest static surface's (the ground plane's,
    below the horizon) by more than this fraction of it ..."""
    floor_px: float = 2.0
    """... and this many pixels (at the reference's resolution) ..."""
    ref_rel: float = 0.3
    """... or where its parallax falls short of the reference depth's by more than this fraction (inf:
    off; only this side: a short reference's floaters and holes make static pixels read closer than
    it says far more often than a mover does) ..."""
    ref_close_rel: float = math.inf
    """... or where its parallax exceeds the reference depth's by more than this fraction (inf: off) ..."""
    photo_grey: float = 45.0
    """... or where frame ``j`` warped by the rigid flow differs from frame ``i`` by more than this
    (grey levels of images normalised to a spread of 48, 3x3 means; 0: off): a small mover that DIS
    loses in its coarse levels still fails to line up."""
    sweep_grey: float = 6.0
    """... or where a textured pixel matches frame ``j`` nowhere on its epipolar line at a parallax a static
    surface could have (``masks/static_sweep.py``: no optical flow) by this many grey levels (5x5 means, 0: off) ..."""
    sweep_rel: float = 3.0
    """... and this multiple of the frame's median best match ..."""
    sweep_texture: float = 8.0
    """... textured: a 5x5 mean gradient above this (grey levels a pixel) ..."""
    sweep_reach: float = 0.35
    """... the line searched up to this fraction of the image width from where the rotation alone puts the pixel ..."""
    sweep_scale: int = 2
    """... on images shrunk by this factor (a power of two; speed) ..."""
    vote: float = 1.0
    """... in at least this fraction of its valid neighbour pairs on each side (1: all of them; lower
    values let in more of the road a mover uncovers)."""
    loose_vote: float = 1.0
    """Hysteresis: pixels that move in at least this share of their pairs on each side join a moving
    region they touch (connected to a pixel that ``vote`` keeps; 1: off). A mover's flow holds in every
    pair where DIS follows it, its plain parts (a car's windows and roof, a walker's clothes) in
    fewer. Off by default: 0.5 finds more of the movers on KITTI's real frames, and marks more
    static road and facade beside the movers on the synthetic streets (docs/masks-motion.md)."""
    loose_residual_rel: float = 2.0
    """... where those pixels also differ from the reference's render by more than this multiple of the
    frame's median residual (``residual_rel``'s test, stricter: a mover's plain parts differ from the
    static scene behind them, the road and facades beside a mover less)."""
    one_sided_grey: float = 5.0
    """Where only the pairs on one side are valid (what leaves the frame on the other: the road near
    the bottom, the side walls), a pair counts only where frame ``j`` warped by the prior's rigid flow
    also differs from frame ``i`` by more than this (grey levels, 5x5 means; 0: off): DIS spreads a
    mover's flow onto the plain road beside it, which the static warp matches; without the other
    side's vote nothing else removes it."""
    grow: float = 1.0
    """A superpixel joins a moving region where this fraction of its pixels move (1: off; 0.3 and 0.5
    measured no better than closing and hole filling alone on the synthetic street with movers)."""
    superpixel_frac: float = 0.06
    """Superpixel size, as a fraction of the image's shorter side."""
    ground_clamp: bool = True
    """Clamp the reference's depth to the ground plane along downward rays (what finds a mover that
    the reference rendered far away; it needs the plane right)."""
    min_region_frac: float = 0.002
    """Moving regions smaller than this fraction of the image are dropped."""
    residual_rel: float = 1.0
    """A moving pixel must also differ from the reference's render (the residual route's photometric
    residual, 5x5 means) by more than this multiple of the frame's median residual (0: off): the road
    beside a mover, where the flow of the mover spills over, matches the reference; the mover does not."""
    carry: float = 0.0
    """Carried by the observed flow into the frames just before and after, a moving pixel must land on
    moving pixels there in at least this share of them (0: off). Off by default: it dropped flow errors
    on the synthetic streets, but on real frames (walking people, 2 Hz key frames) it dropped more of
    the movers (docs/masks-motion.md)."""
    outline: bool = True
    """Grow / trim the regions to the image's outlines (OpenCV's grabCut, seeded by each region's core as
    the object, the region as probably object, a ring around it as probably not, the rest as not)."""
    outline_ring: float = 0.03
    """The ring's width, as a fraction of the image's shorter side."""
    second_pass_steps: int = 300
    """Second pass (``masks/second_pass.py``): the first reference continued for this many steps with the
    marked pixels excluded from its loss and rendered where they are; a marked pixel stays where that
    render differs from the image more than the first reference's does (0: off)."""
    second_pass_margin: float = 0.2
    """... by more than this, each residual divided by its frame's median."""
    persist: float = 0.1
    """Last (``masks/temporal.py``): the final regions, outlined once more, are dropped where no frame
    just before or after confirms them: carried there by the observed flow, less than this share of a
    region lands within ``persist_ring`` of that frame's regions, in each of them that sees a quarter of
    it, and one of them sees half of it (0: off; the outline again stays with ``outline``). A blip (one
    pair's flow spill, a facade a short reference renders badly) has no counterpart; a mover has."""
    persist_ring: float = 0.035
    """... the ring, as a fraction of the image's shorter side (the flow's error at a mover's edge)."""
    floating: float = 0.4
    """Oncoming traffic (``masks/floating.py``): regions of the reference's surface that float over the road below
    the camera's height, their lowest tenth above this share of the camera's height, join the moving ones (0: off).
    A car driving toward the camera reads to the reference as a static copy nearer the camera whose wheels float
    (a car as fast as the camera: at half the camera's height); nothing else of the route sees it."""
    floating_reach: float = 3.5
    """... where their middle lies within this many metres of the camera's path sideways (the copy sits over the
    road: a lane's width)."""


@dataclass
class MotionFrame:
    """One frame of the sequence: ``image [H, W, 3]`` in [0, 1], ``dist [H, W]`` the static scene's
    distance along each unit ray (inf: sky), camera-to-world ``c2w [3, 4]`` (OpenGL) and intrinsics."""

    image: Tensor
    dist: Tensor
    c2w: Tensor
    intr: Intrinsics
    bound: Optional[Tensor] = None
    """``[H, W]`` the farthest a static surface can be along each ray (the ground plane's distance
    along downward rays, inf elsewhere); None: no bound."""
    residual: Optional[Tensor] = None
    """``[H, W]`` the image's difference from the static reference's render of it; None: not gated."""


def ray_directions(c2w: Tensor, intr: Intrinsics, h: int, w: int) -> Tensor:
    """``[H, W, 3]`` unit world directions through the pixel centres of an OpenGL camera."""
    fx, fy, cx, cy = intr
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64) + 0.5, torch.arange(w, dtype=torch.float64) + 0.5, indexing="ij")
    d = torch.stack([(u - cx) / fx, -(v - cy) / fy, -torch.ones_like(u)], dim=-1)
    return torch.nn.functional.normalize(d @ c2w[:, :3].double().T, dim=-1)


def static_distance(dist: Tensor, c2w: Tensor, intr: Intrinsics, up: Tensor, height: float) -> Tensor:
    """``dist`` clamped to where each downward ray meets the ground plane ``{x . up = height}``:
    nothing static stands beyond the road a ray points down at."""
    h, w = dist.shape
    d = ray_directions(c2w, intr, h, w)
    dn = d @ up.double()
    o = c2w[:, 3].double() @ up.double()
    t = torch.where(dn < -1e-6, (height - o) / dn.clamp(max=-1e-6), torch.full_like(dn, math.inf))
    return torch.minimum(dist.double(), t.clamp(min=0)).to(dist.dtype)


def rigid_flow(c2w_i: Tensor, intr_i: Intrinsics, dist_i: Tensor, c2w_j: Tensor, intr_j: Intrinsics,
               rays: Optional[Tensor] = None) -> tuple[Tensor, Tensor]:
    """The flow ``[H, W, 2]`` (pixels, x then y) that frame ``i``'s static scene (distance ``dist_i``
    along its rays; inf: a direction only) makes into frame ``j``, and where it is defined (in front
    of camera ``j``). ``rays``: frame ``i``'s :func:`ray_directions`, where already at hand."""
    h, w = dist_i.shape
    d = ray_directions(c2w_i, intr_i, h, w) if rays is None else rays
    dist = dist_i.double()
    finite = torch.isfinite(dist)
    p = c2w_i[:, 3].double() + d * torch.where(finite, dist, torch.zeros_like(dist))[..., None]
    rel = torch.where(finite[..., None], p - c2w_j[:, 3].double(), d)  # at infinity only the rotation counts
    cam = rel @ c2w_j[:, :3].double()
    z = -cam[..., 2]
    ok = z > 1e-6
    zs = torch.where(ok, z, torch.ones_like(z))
    fx, fy, cx, cy = intr_j
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64) + 0.5, torch.arange(w, dtype=torch.float64) + 0.5, indexing="ij")
    flow = torch.stack([fx * cam[..., 0] / zs + cx - u, cy - fy * cam[..., 1] / zs - v], dim=-1)
    return flow.float(), ok


def grey(image: Tensor) -> np.ndarray:
    """``[H, W, 3]`` -> uint8 grey, normalised to a fixed mean and spread (exposure changes between
    frames would read as flow)."""
    g = (image.float() @ torch.tensor([0.299, 0.587, 0.114])).numpy()
    g = (g - g.mean()) / max(float(g.std()), 1e-3) * 48.0 + 128.0
    return np.clip(g, 0, 255).astype(np.uint8)


def optical_flow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dense flow ``[H, W, 2]`` from grey ``a`` to ``b`` (DIS, medium preset)."""
    import cv2

    return cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(a, b, None)


def warp(image: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``image`` (of frame ``j``) sampled at ``pixel + flow``: frame ``j`` seen from frame ``i``'s
    pixels; and where the sample falls inside the image."""
    import cv2

    h, w = flow.shape[:2]
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    mx, my = xs + flow[..., 0].astype(np.float32), ys + flow[..., 1].astype(np.float32)
    inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), inside


def epipolar_line(fi: "MotionFrame", fj: "MotionFrame", rays: Optional[Tensor] = None) -> tuple[Tensor, Tensor, Tensor]:
    """Where frame ``i``'s pixels can land in frame ``j`` if static: on the epipolar line from
    ``p_inf`` (the pixel's flow at infinity: the rotation alone) along the unit direction ``u``
    (``[H, W, 2]`` each, as flows from the pixel) in which parallax grows as the surface comes closer;
    and where that direction is defined (not at the epipole)."""
    h, w = fi.dist.shape
    p_inf, _ = rigid_flow(fi.c2w, fi.intr, torch.full((h, w), math.inf), fj.c2w, fj.intr, rays)
    far = 100.0 * max(float((fi.c2w[:, 3] - fj.c2w[:, 3]).norm()), 1e-9)  # in front of both cameras
    p_far, ok = rigid_flow(fi.c2w, fi.intr, torch.full((h, w), far), fj.c2w, fj.intr, rays)
    d = (p_far - p_inf).double()
    n = d.norm(dim=-1, keepdim=True)
    return p_inf, (d / n.clamp(min=1e-12)).float(), ok & (n[..., 0] > 1e-6)


def along(flow: Tensor, p_inf: Tensor, u: Tensor) -> Tensor:
    """``flow``'s parallax: its position along the epipolar line, pixels from ``p_inf``."""
    return ((flow - p_inf) * u).sum(-1)


def pair_moving(fi: "MotionFrame", fj: "MotionFrame", grey_i: np.ndarray, grey_j: np.ndarray, opts: "MotionOptions",
                rays: Optional[Tensor] = None) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Frame ``j`` warped onto frame ``i`` by the rigid flow of ``i``'s prior depth: what is static
    lines up roughly, so DIS measures the rest of the observed flow where it is reliable (small
    flows). The observed flow is then judged against what any static surface could do, not against
    the prior depth alone (a short reference's depth has floaters and holes):

      * off the epipolar line by more than ``perp_px`` (and ``perp_rel`` of the flow): no depth explains it;
      * less parallax than the farthest static surface along the ray (``bound``: the ground plane
        below the horizon; infinity above it) by more than ``rel`` of that parallax and
        ``floor_px``: it recedes with the camera (a car ahead at the drive's speed);
      * less parallax than the prior depth's by more than ``ref_rel`` of it and ``floor_px``: farther
        than the reference says (one-sided and loose: the reference is the least reliable part);
      * the neighbour warped by the observed flow differs by ``photo_grey`` grey levels: a small
        mover DIS lost still fails to line up.

    Returns (moving, valid, the observed flow, the static mismatch: ``|i - j warped by the prior|``,
    5x5 means, grey levels)."""
    import cv2

    rays = ray_directions(fi.c2w, fi.intr, *fi.dist.shape) if rays is None else rays  # one set for the four flows below
    rig, ok = rigid_flow(fi.c2w, fi.intr, fi.dist, fj.c2w, fj.intr, rays)
    wj, inside = warp(grey_j, rig.numpy())
    wj = np.where(inside, wj, grey_i)  # outside frame j: nothing to compare, no flow to invent there
    resid = torch.from_numpy(optical_flow(grey_i, wj))
    obs = rig + resid  # the residual is measured on i's grid: the composition is rig + resid where rig is smooth
    p_inf, u, line_ok = epipolar_line(fi, fj, rays)
    off = obs - p_inf
    perp = (off[..., 0] * u[..., 1] - off[..., 1] * u[..., 0]).abs()
    moving = line_ok & (perp > torch.clamp(opts.perp_rel * off.norm(dim=-1), min=opts.perp_px))
    s_obs = along(obs, p_inf, u)
    if fi.bound is not None:
        rb, ok_b = rigid_flow(fi.c2w, fi.intr, fi.bound, fj.c2w, fj.intr, rays)
        s_b = torch.where(ok_b, along(rb, p_inf, u), torch.zeros_like(s_obs))
    else:
        s_b = torch.zeros_like(s_obs)
    lowest = s_b - torch.clamp(opts.rel * s_b, min=opts.floor_px)
    moving |= line_ok & (s_obs < lowest)
    if opts.sweep_grey > 0:
        from nerf2gs_plugin.masks.static_sweep import unexplained

        explained = [wj] + ([warp(grey_j, rb.numpy())[0]] if fi.bound is not None else [])
        moving |= line_ok & unexplained(grey_i, grey_j, p_inf, u, lowest, explained, opts.sweep_grey, opts.sweep_rel,
                                        opts.sweep_texture, opts.sweep_reach, opts.sweep_scale)
    if math.isfinite(opts.ref_rel):
        s_r = along(rig, p_inf, u)
        moving |= line_ok & ok & (s_r - s_obs > torch.clamp(opts.ref_rel * s_r.abs(), min=opts.floor_px))
    if math.isfinite(opts.ref_close_rel):
        s_r = along(rig, p_inf, u)
        moving |= line_ok & ok & (s_obs - s_r > torch.clamp(opts.ref_close_rel * s_r.abs(), min=opts.floor_px))
    if opts.photo_grey > 0:
        wo, _ = warp(grey_j, obs.numpy())  # not by the prior's flow: where the reference's depth is off, that misaligns static texture
        diff = np.abs(cv2.blur(grey_i.astype(np.float32), (3, 3)) - cv2.blur(wo.astype(np.float32), (3, 3)))
        moving |= torch.from_numpy(diff > opts.photo_grey)
    static = np.abs(cv2.blur(grey_i.astype(np.float32), (5, 5)) - cv2.blur(wj.astype(np.float32), (5, 5)))
    return moving, ok & torch.from_numpy(inside), obs, torch.from_numpy(static)


def frame_votes(frames: Sequence[MotionFrame], i: int, opts: MotionOptions, greys: Optional[Sequence[np.ndarray]] = None) -> tuple[Tensor, dict[int, Tensor]]:
    """``[H, W]``: the share of frame ``i``'s valid neighbour pairs in which a pixel moves, the
    smaller of the shares before and after it (where both have a valid pair): what a mover hid in
    the frames before (the road it uncovers) is seen moving only on one side, the mover on both.
    Where only one side has a valid pair, its pairs count only where the static warp fails too
    (``one_sided_grey``).
    0 where no pair is valid, and where the static scene is at infinity (sky: no parallax to test).
    Also the observed flows into the nearest neighbours before and after (by index)."""
    greys = greys if greys is not None else [grey(f.image) for f in frames]
    f = frames[i]
    rays = ray_directions(f.c2w, f.intr, *f.dist.shape)  # shared by the frame's pairs
    nearest = min(abs(o) for o in opts.neighbours)
    shares, flows = [], {}
    for side in (-1, 1):
        votes = torch.zeros(f.dist.shape)
        confirmed = torch.zeros(f.dist.shape)
        valid_n = torch.zeros(f.dist.shape)
        for off in opts.neighbours:
            j = i + off
            if off * side <= 0 or j < 0 or j >= len(frames):
                continue
            moving, valid, obs, static = pair_moving(f, frames[j], greys[i], greys[j], opts, rays)
            votes += (moving & valid).float()
            confirmed += (moving & valid & ((static > opts.one_sided_grey) | (opts.one_sided_grey <= 0))).float()
            valid_n += valid.float()
            if abs(off) == nearest:
                flows[j] = obs
        shares.append((votes / valid_n.clamp(min=1), valid_n > 0, confirmed / valid_n.clamp(min=1)))
    (back, has_b, back_c), (fwd, has_f, fwd_c) = shares
    share = torch.where(has_b & has_f, torch.minimum(back, fwd), torch.where(has_b, back_c, fwd_c))
    return torch.where(torch.isfinite(f.dist), share, torch.zeros_like(share)), flows


def moving_fraction(frames: Sequence[MotionFrame], i: int, opts: MotionOptions, greys: Optional[Sequence[np.ndarray]] = None) -> Tensor:
    """:func:`frame_votes`' share alone."""
    return frame_votes(frames, i, opts, greys)[0]


def residual_gate(frame: MotionFrame, rel: float) -> Tensor:
    """Where the frame differs from the static reference's render by more than ``rel`` times its
    median difference over the pixels with a static surface (5x5 means; all True without a residual)."""
    if frame.residual is None or rel <= 0:
        return torch.ones(frame.dist.shape, dtype=torch.bool)
    import cv2

    r = cv2.blur(frame.residual.float().numpy(), (5, 5))
    scene = torch.isfinite(frame.dist).numpy()
    med = float(np.median(r[scene])) if scene.any() else float(np.median(r))
    return torch.from_numpy(r > rel * max(med, 1e-6))


def touching(seeds: Tensor, loose: Tensor) -> Tensor:
    """``seeds`` with the 8-connected regions of ``loose | seeds`` that hold a seed pixel."""
    import cv2

    n, labels = cv2.connectedComponents((loose | seeds).numpy().astype(np.uint8), connectivity=8)
    keep = np.bincount(labels[seeds.numpy()], minlength=n) > 0
    keep[0] = False
    return seeds | torch.from_numpy(keep[labels])


def carried_share(seeds: Tensor, flows: dict[int, Tensor], others: dict[int, Tensor]) -> Tensor:
    """``[H, W]``: the share of the frames in ``flows`` (index -> observed flow ``[H, W, 2]`` into it)
    where a pixel, carried by the flow, lands on (or one pixel beside) a seed of that frame
    (``others``); 1 where it lands in none of them (nothing to check against)."""
    import cv2

    h, w = seeds.shape
    hit, n = torch.zeros(h, w), torch.zeros(h, w)
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    for j, flow in flows.items():
        near = torch.from_numpy(cv2.dilate(others[j].numpy().astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
        x, y = (xs + flow[..., 0]).round().long(), (ys + flow[..., 1]).round().long()
        inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        hit += (near[y.clamp(0, h - 1), x.clamp(0, w - 1)] & inside).float()
        n += inside.float()
    return torch.where(n > 0, hit / n.clamp(min=1), torch.ones(h, w))


def outline(mask: Tensor, image: Tensor, ring_frac: float) -> Tensor:
    """``mask``'s regions grown or trimmed to the image's outlines by grabCut: the regions eroded by 2
    pixels are the object, the rest of them probably the object, a ring ``ring_frac`` of the shorter
    side wide around them probably not, everything else not."""
    import cv2

    m = mask.numpy().astype(np.uint8)
    if not m.any():
        return mask
    h, w = m.shape
    r = max(3, int(round(ring_frac * min(h, w))))
    g = np.full((h, w), cv2.GC_BGD, np.uint8)
    g[cv2.dilate(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))) > 0] = cv2.GC_PR_BGD
    if not (g == cv2.GC_BGD).any():
        return mask  # the regions and their rings cover the frame: no background to learn from
    g[m > 0] = cv2.GC_PR_FGD
    g[cv2.erode(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))) > 0] = cv2.GC_FGD
    bgr = np.ascontiguousarray((image.clamp(0, 1).numpy()[..., ::-1] * 255).astype(np.uint8))
    # grabCut's k-means starts its colour models from OpenCV's global (per-thread) random stream: reseed it so
    # a frame's outline does not depend on the calls before it (0 is the state a fresh process starts in)
    cv2.setRNGSeed(0)
    cv2.grabCut(bgr, g, None, np.zeros((1, 65)), np.zeros((1, 65)), 3, cv2.GC_INIT_WITH_MASK)
    return torch.from_numpy((g == cv2.GC_FGD) | (g == cv2.GC_PR_FGD))


def superpixels(image: Tensor, size_px: int) -> np.ndarray:
    """``[H, W]`` int labels of SLIC superpixels (OpenCV's ximgproc, SLICO) of about ``size_px``."""
    import cv2

    rgb = (image.clamp(0, 1).numpy() * 255).astype(np.uint8)
    lab = cv2.cvtColor(rgb, cv2.COLOR_RGB2LAB)
    slic = cv2.ximgproc.createSuperpixelSLIC(lab, algorithm=cv2.ximgproc.SLICO, region_size=max(4, size_px))
    slic.iterate(10)
    return slic.getLabels()


def grow_regions(seeds: Tensor, image: Tensor, opts: MotionOptions) -> Tensor:
    """Seeds -> object outlines: superpixels holding ``grow`` of seed pixels, closed, holes filled,
    small regions dropped."""
    h, w = seeds.shape
    m = seeds
    if opts.grow < 1.0:
        labels = superpixels(image, int(round(opts.superpixel_frac * min(h, w))))
        n = int(labels.max()) + 1
        share = np.bincount(labels.ravel(), weights=seeds.numpy().ravel().astype(np.float64), minlength=n) / np.maximum(
            np.bincount(labels.ravel(), minlength=n), 1)
        m = torch.from_numpy(share[labels] >= opts.grow)
    return fr.clean_regions(m, max(4, int(opts.min_region_frac * h * w)), close_px=max(1, round(0.01 * min(h, w))))


def _outlined(m: Tensor, image: Tensor, opts: MotionOptions) -> Tensor:
    """Regions outlined by :func:`outline`, then cleaned as :func:`grow_regions` cleans them."""
    h, w = m.shape
    return fr.clean_regions(outline(m, image, opts.outline_ring), max(4, int(opts.min_region_frac * h * w)),
                            close_px=max(1, round(0.01 * min(h, w))))


def _regions(m: Tensor, image: Tensor, opts: MotionOptions) -> Tensor:
    """A frame's moving pixels -> its regions: grown (:func:`grow_regions`), then outlined (:func:`outline`)."""
    m = grow_regions(m, image, opts)
    return _outlined(m, image, opts) if opts.outline else m


def motion_masks(frames: Sequence[MotionFrame], opts: MotionOptions, progress: Optional[Callable[[], None]] = None,
                 flows_out: Optional[list] = None, workers: Optional[int] = None) -> list[Tensor]:
    """Bool ``[H, W]`` moving-object masks of a sequence (frames in capture order): per frame the
    pixels that move in ``vote`` of the pairs (:func:`frame_votes`) and differ from the reference
    (:func:`residual_gate`), kept where the frames just before and after move there too
    (:func:`carried_share`), grown to regions (:func:`grow_regions`) and outlines (:func:`outline`).
    The frames are spread over the cores (``utils/parallel.map_ahead``, ``workers``; each frame's mask
    depends on the sequence alone, so the masks are those of one frame after another). One frame
    ahead is kept in memory (its seeds and flows), not the sequence; ``flows_out`` receives each
    frame's observed flows into the frames just before and after (``masks/temporal.keep_flow``)."""
    greys = [grey(f.image) for f in frames]
    seeds: dict[int, Tensor] = {}
    flows: dict[int, dict[int, Tensor]] = {}
    out = []

    def frame(i: int) -> tuple[Tensor, Optional[dict[int, Tensor]], dict[int, Tensor], Optional[Tensor]]:
        """``(seeds, the observed flows or None, the flows kept, the final mask or None)``: without
        ``carry`` a frame is finished here, else it waits for its neighbours' seeds."""
        frac, fl = frame_votes(frames, i, opts, greys)
        s = fr.opening(frac >= opts.vote, 1) if opts.vote > 0 else frac > 0
        s = s & residual_gate(frames[i], opts.residual_rel)
        if opts.loose_vote < opts.vote:
            s = touching(s, (frac >= opts.loose_vote) & residual_gate(frames[i], opts.loose_residual_rel))
        kept = {j: keep_flow(f) for j, f in fl.items()} if flows_out is not None else {}
        if opts.carry > 0:
            return s, fl, kept, None
        return s, None, kept, _regions(s, frames[i].image, opts)

    def finish(i: int) -> None:
        m = seeds[i] & (carried_share(seeds[i], flows[i], {j: seeds[j] for j in flows[i]}) >= opts.carry)
        out.append(_regions(m, frames[i].image, opts))
        for k in [k for k in seeds if k < i]:
            seeds.pop(k), flows.pop(k, None)
        if progress is not None:
            progress()

    for i, (s, fl, kept, done) in enumerate(map_ahead(frame, range(len(frames)), workers)):
        if flows_out is not None:
            flows_out.append(kept)
        if done is not None:
            out.append(done)
            if progress is not None:
                progress()
            continue
        seeds[i], flows[i] = s, fl  # type: ignore[assignment]
        if i >= 1:
            finish(i - 1)
    if frames and opts.carry > 0:
        finish(len(frames) - 1)
    return out


def frames_from_renders(views: Sequence[dict], sky: Sequence[Tensor], up: Tensor, height: float, clamp: bool = True,
                        workers: Optional[int] = None) -> list[MotionFrame]:
    """The reference's renders (``render_views``: image, rgb, depth, c2w, intr) as a motion sequence:
    the rendered depth, the sky at infinity, clamped to the ground plane; the residual of the
    image against the render, after the residual route's colour fit (frames spread over the cores)."""
    def static(k: int) -> tuple[Tensor, Optional[Tensor], Optional[Tensor]]:
        v, s = views[k], sky[k]
        dist = torch.where(s, torch.full_like(v["depth"], math.inf), v["depth"].float())
        bound = static_distance(torch.full_like(dist, math.inf), v["c2w"], _intr(v), up, height) if clamp else None
        dist = torch.minimum(dist, bound) if bound is not None else dist
        residual = fr.residual_map(v["image"], fr.fit_colour(v["rgb"], v["image"])) if "rgb" in v else None
        return dist, bound, residual

    return [MotionFrame(v["image"], dist, v["c2w"], _intr(v), bound, residual)
            for v, (dist, bound, residual) in zip(views, map_ahead(static, range(len(views)), workers))]


def _intr(view: dict) -> Intrinsics:
    return tuple(float(x) for x in view["intr"])  # type: ignore[return-value]


def neighbour_stride(frames: Sequence[MotionFrame], up: Tensor, height: float, opts: MotionOptions) -> int:
    """How many frames one step of ``opts.neighbours`` is (``min_baseline``): at most what leaves every
    offset inside half the sequence; 1 on a sequence too short or standing still."""
    if opts.min_baseline <= 0 or len(frames) < 2:
        return 1
    reach = max((abs(o) for o in opts.neighbours), default=1)
    c = torch.stack([f.c2w[:, 3].double() for f in frames])
    step = float((c[1:] - c[:-1]).norm(dim=-1).median())
    above = float((c @ up.double() - height).abs().median())
    if step <= 1e-9 or above <= 1e-9:
        return 1
    return max(1, min(math.ceil(opts.min_baseline * above / step - 1e-9), (len(frames) - 1) // (2 * reach)))


def is_sequence(meta: dict) -> bool:
    """Whether a capture's ``transforms.json`` (``meta``) says it was processed as a sequence: from a
    video, or matched sequentially (its frames in capture order)."""
    process = meta.get("process") or {}
    return process.get("source") == "video" or process.get("matching") == "sequential"


def add_motion(renders, result: dict, opts: MotionOptions, log: Callable[[str], None] = print, progress: bool = True,
               sequence: bool = True, kept: Optional[dict] = None) -> bool:
    """Add the moving objects to ``result``'s transient masks (``masks_from_renders``' masks, in
    place): every split's frames in one sequence sorted by file name (a video's order); ``sequence``:
    whether the capture is one (:func:`is_sequence`; see ``sequences_only``). The ground
    and sky masks stay as the residual route made them: with a short reference's depth the motion
    route also marks static road (docs/masks-motion.md), and the ground mask should not pay for it.
    ``kept`` receives what :func:`settle_transients` needs (the frames' order and observed flows).
    Returns whether the route ran."""
    from nerf2gs_plugin.progress import make_progress

    if not opts.enabled:
        return False
    if opts.sequences_only and not sequence:
        log("masks: motion route skipped: the capture was not processed as a sequence (a video or sequential matching)")
        return False
    order = sorted(((v["name"], s, i) for s, vs in renders.views.items() for i, v in enumerate(vs)))
    frames = frames_from_renders([renders.views[s][i] for _, s, i in order], [result[s][i].sky for _, s, i in order],
                                 renders.up, renders.height, opts.ground_clamp)
    stride = neighbour_stride(frames, renders.up, renders.height, opts)
    if stride > 1:
        opts = replace(opts, neighbours=tuple(o * stride for o in opts.neighbours))
        log(f"masks: motion compares frames {stride} apart (the camera's median step is short against its height)")
    with make_progress(progress) as prog:
        task = prog.add_task("masks: motion", total=len(frames), stats="")
        flows: Optional[list] = [] if kept is not None else None
        moving = motion_masks(frames, opts, lambda: prog.advance(task), flows)
    if kept is not None:
        kept.update(order=order, flows=flows)
    if opts.floating > 0:
        floats = list(map_ahead(lambda k: _floating(frames[k], result[order[k][1]][order[k][2]].sky, renders, opts), range(len(frames))))
        log(f"masks: floating over the road (oncoming traffic): {100 * sum(float(f.float().mean()) for f in floats) / max(len(floats), 1):.2f}% of the pixels")
        moving = [m | f for m, f in zip(moving, floats)]
    share = 0.0
    for (_, s, i), m in zip(order, moving):
        result[s][i].transient = result[s][i].transient | m
        share += float(m.float().mean()) / max(len(order), 1)
    log(f"masks: motion marked {100 * share:.2f}% of the pixels as moving")
    return True


def _floating(frame: MotionFrame, sky: Tensor, renders, opts: MotionOptions) -> Tensor:
    from nerf2gs_plugin.masks.floating import floating_objects

    rays = ray_directions(frame.c2w, frame.intr, *frame.dist.shape)
    return floating_objects(frame.dist, rays, frame.c2w[:, 3], renders.up, renders.height, renders.metres_to_world,
                            opts.floating, opts.floating_reach, sky)


def settle_transients(renders, result: dict, kept: dict, opts: MotionOptions, log: Callable[[str], None] = print,
                      progress: bool = True) -> None:
    """The motion route's last step on ``result``'s final transient masks (in place; ``kept``: from
    :func:`add_motion`): each frame's regions outlined once more (``outline``), then those that no frame
    just before or after confirms dropped (``persist``, ``masks/temporal.py``)."""
    from nerf2gs_plugin.progress import make_progress
    order = kept["order"]
    masks = [result[s][i].transient for _, s, i in order]
    if opts.outline:
        def again(k: int) -> Tensor:
            (_, s, i), m = order[k], masks[k]
            return _outlined(m, renders.views[s][i]["image"], opts) if bool(m.any()) else m

        masks = list(map_ahead(again, range(len(masks))))  # one frame per core
    if opts.persist > 0:
        before = sum(int(m.sum()) for m in masks)
        with make_progress(progress) as prog:
            task = prog.add_task("masks: motion, neighbours agree", total=len(masks), stats="")
            masks = persistent(masks, kept["flows"], opts.persist, opts.persist_ring, lambda: prog.advance(task))
        after = sum(int(m.sum()) for m in masks)
        log(f"masks: regions no neighbouring frame confirms dropped: {100 * (before - after) / max(before, 1):.1f}% of the moving pixels")
    for m, (_, s, i) in zip(masks, order):
        result[s][i].transient = m
