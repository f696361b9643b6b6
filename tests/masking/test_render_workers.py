"""The masks' renders side by side in forked workers (torch at two threads) equal those rendered one
after another (one thread), every other pixel with the full-size frames beside them."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import torch

from nerf2gs_plugin.masking.auto_masks import render_views
from nerf2gs_plugin.masking.mask_reference import ensure_reference
from nerf2gs_plugin.masks.maskless import maskless_view


def test_masks_renders_in_workers_equal_one_by_one(tmp_path):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tiny_scene import write_tiny_scene

    data = write_tiny_scene(tmp_path / "scene")
    shutil.rmtree(data / "masks")
    ref = ensure_reference(data, tmp_path / "ref", 1, progress=False, log=lambda s: None)
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        one = render_views(maskless_view(data), ref, ["train"], log=lambda s: None, progress=False, render_downscale=2)
        torch.set_num_threads(2)  # two views at once
        two = render_views(maskless_view(data), ref, ["train"], log=lambda s: None, progress=False, render_downscale=2)
    finally:
        torch.set_num_threads(before)
    assert len(one.views["train"]) == len(two.views["train"]) > 2
    for a, b in zip(one.views["train"], two.views["train"]):
        assert a["name"] == b["name"] and set(a) == set(b) and "full_image" in a
        for k in ("rgb", "depth", "acc", "dirs", "full_image", "intr", "full_intr"):
            torch.testing.assert_close(a[k], b[k], rtol=1e-4, atol=1e-4)
    assert two.cpu_seconds > 0
