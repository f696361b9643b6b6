"""The mask maths spread over the cores (``utils/parallel.map_ahead``: one frame per forked worker) give
the masks of one frame after another: the residual route, the motion route (with and without the
temporal carry), the outlines again and the neighbours' check, on the textured sequence with movers."""

from __future__ import annotations

import dataclasses

import pytest
import torch

import nerf2gs_plugin.utils.parallel as parallel
from nerf2gs_plugin.masks.auto import AutoOptions, Renders, masks_from_renders
from nerf2gs_plugin.masks.motion import MotionOptions, add_motion, motion_masks, ray_directions, settle_transients


def _renders() -> Renders:
    from masks.test_motion import _sequence

    frames, truth = _sequence(6)
    views = []
    for k, (f, t) in enumerate(zip(frames, truth)):
        h, w = f.dist.shape
        dirs = ray_directions(f.c2w, f.intr, h, w).float()
        views.append({"image": f.image, "rgb": t["static"], "depth": f.dist, "acc": torch.ones(h, w), "dirs": dirs,
                      "origin": f.c2w[:, 3].clone(), "c2w": f.c2w, "intr": torch.tensor(f.intr), "name": f"frame_{k:02d}.png"})
    # the ground plane well below the cameras: the route's bound stays out of the way
    return Renders({"train": views}, torch.tensor([0.0, 1.0, 0.0]), -50.0, 1.0, 0.0, box_extent=100.0)


def _all_masks(monkeypatch, workers: int, opts: MotionOptions) -> list[torch.Tensor]:
    monkeypatch.setattr(parallel, "view_workers", lambda requested=None: workers)
    r = _renders()
    result = masks_from_renders(r, AutoOptions(), log=lambda s: None)
    kept: dict = {}
    assert add_motion(r, result, opts, log=lambda s: None, progress=False, kept=kept)
    out = [m.transient.clone() for m in result["train"]] + [torch.stack([m.sky, m.ground]) for m in result["train"]]
    settle_transients(r, result, kept, opts, log=lambda s: None, progress=False)
    return out + [m.transient for m in result["train"]]


@pytest.mark.parametrize("carry", [0.0, 0.5])
def test_the_mask_maths_over_two_workers_equal_one_frame_after_another(monkeypatch, carry):
    opts = dataclasses.replace(MotionOptions(), carry=carry)
    serial, spread = _all_masks(monkeypatch, 1, opts), _all_masks(monkeypatch, 2, opts)
    assert len(serial) == len(spread) == 18
    assert all(torch.equal(a, b) for a, b in zip(serial, spread))
    moving = serial[:6]
    assert sum(int(m.sum()) for m in moving) > 6 * 300  # the movers are found: the comparison is not of empty masks


def test_motion_masks_flows_and_progress_over_workers():
    from masks.test_motion import _sequence

    frames, _ = _sequence(5)
    runs = []
    for workers in (1, 2):
        flows: list = []
        ticks: list = []
        masks = motion_masks(frames, MotionOptions(), lambda: ticks.append(1), flows_out=flows, workers=workers)
        runs.append((masks, flows, len(ticks)))
    (m1, f1, t1), (m2, f2, t2) = runs
    assert t1 == t2 == 5 and [sorted(f) for f in f2] == [[1], [0, 2], [1, 3], [2, 4], [3]]
    assert all(torch.equal(a, b) for a, b in zip(m1, m2))
    assert all(torch.equal(a[j], b[j]) for a, b in zip(f1, f2) for j in a)
