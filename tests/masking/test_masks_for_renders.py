"""masks_for_renders (the masks stage after the renders): the bench's view of the first pass, and the
second pass told the render size."""

import json

import torch

import nerf2gs_plugin.masking.auto_masks as am
import nerf2gs_plugin.masking.second_pass as sp
import nerf2gs_plugin.masks.motion as mo
from nerf2gs_plugin.masks.auto import FrameMasks


def test_first_pass_seen_before_the_second_and_render_step_passed(tmp_path, monkeypatch):
    (tmp_path / "transforms.json").write_text(json.dumps({"frames": []}))
    calls = {}

    def first(renders, opts, log):
        return {"train": [FrameMasks(*(torch.zeros(2, 2, dtype=torch.bool),) * 3)]}

    def motion(full, result, opts, log, progress, sequence):
        result["train"][0].transient = torch.ones(2, 2, dtype=torch.bool)
        return True

    def second(view, reference, full, result, steps, margin, log, progress, render_step=1):
        calls["render_step"] = render_step
        result["train"][0].transient = torch.zeros(2, 2, dtype=torch.bool)
        return {"second_pass_seconds": 1.0}

    monkeypatch.setattr(am, "masks_from_renders", first)
    monkeypatch.setattr(am, "at_full_size", lambda renders, result: renders)
    monkeypatch.setattr(mo, "add_motion", motion)
    monkeypatch.setattr(sp, "second_pass", second)
    seen, stats = [], {}
    out = am.masks_for_renders(tmp_path, tmp_path / "ref", None, None, motion=mo.MotionOptions(), stats=stats, render_downscale=2,
                               first_pass=lambda res: seen.append(int(res["train"][0].transient.sum())))
    assert seen == [4] and int(out["train"][0].transient.sum()) == 0
    assert calls["render_step"] == 2 and stats == {"second_pass_seconds": 1.0}
