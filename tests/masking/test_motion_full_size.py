"""``--render-downscale 2`` with the motion route: the reference renders every other pixel, the route
measures flow on the full-size frames with that depth upsampled (``auto_masks.at_full_size``)."""

from __future__ import annotations

import torch

from masks.test_motion import INTR, H, W, _pooled, _sequence
from nerf2gs_plugin.masking.auto_masks import at_full_size, upsample
from nerf2gs_plugin.masks.auto import FrameMasks, Renders
from nerf2gs_plugin.masks.motion import MotionOptions, add_motion, motion_masks

D = 2


def _half_renders(frames) -> Renders:
    """What ``render_views(render_downscale=2)`` keeps of each frame: the reference's depth and the
    image at every other pixel (a perfect static reference: the frames' own static depth), the
    full-size image and camera beside them."""
    rows, cols = torch.arange(H // D) * D + D // 2, torch.arange(W // D) * D + D // 2
    fx, fy, cx, cy = INTR
    shift = D // 2 + 0.5 - D / 2
    views = [{"image": f.image[rows][:, cols], "rgb": f.image[rows][:, cols], "depth": f.dist[rows][:, cols], "c2w": f.c2w,
              "intr": torch.tensor([fx / D, fy / D, (cx - shift) / D, (cy - shift) / D]), "name": f"frame_{k:03d}.png",
              "full_image": f.image, "full_intr": torch.tensor(INTR), "step": D} for k, f in enumerate(frames)]
    return Renders({"train": views}, torch.tensor([0.0, 1.0, 0.0]), -100.0, 1.0, 0.0)


def _empty(n: int) -> dict:
    z = torch.zeros(H // D, W // D, dtype=torch.bool)
    return {"train": [FrameMasks(z.clone(), z.clone(), z.clone()) for _ in range(n)]}


def test_half_size_depth_with_full_size_frames_finds_the_rider():
    """The block riding with the camera is found as from full-size renders; on half-size frames the
    same route finds nothing of it (its flow and the road's shrink below what the route resolves)."""
    frames, truth = _sequence()
    renders = _half_renders(frames)
    small = _empty(len(frames))
    add_motion(renders, small, MotionOptions(), log=lambda s: None, progress=False)
    assert _pooled([upsample(m.transient, D, (H, W)) for m in small["train"]], truth, "rider") < 0.2
    result = _empty(len(frames))
    add_motion(at_full_size(renders, result), result, MotionOptions(), log=lambda s: None, progress=False)
    moving = [m.transient for m in result["train"]]
    assert all(tuple(m.shape) == (H, W) for m in moving)  # the residual route's masks upsampled to match
    reference = motion_masks(frames, MotionOptions())  # full-size depth
    assert _pooled(moving, truth, "rider") > 0.8 * _pooled(reference, truth, "rider") > 0.5
    assert _pooled(moving, truth, "parked") < 0.1


def test_upsample_takes_each_block_from_its_sample_or_interpolates_between_samples():
    x = torch.arange(12.0).reshape(3, 4)
    near = upsample(x, 2, (6, 8))
    assert torch.equal(near[::2, ::2], x) and torch.equal(near[1::2, 1::2], x)  # the sample sits at (2k+1, 2j+1)
    smooth = upsample(x, 2, (6, 8), smooth=True)
    assert torch.equal(smooth[1::2, 1::2], x)  # exact at the samples
    assert smooth[2, 3] == (x[0, 1] + x[1, 1]) / 2 and smooth[0, 0] == x[0, 0]  # halfway between rows; clamped at the border
    assert upsample(torch.ones(2, 2, 3), 2, (5, 5)).shape == (5, 5, 3)  # odd sizes: the last block repeats
