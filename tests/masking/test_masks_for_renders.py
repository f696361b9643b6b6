"""masks_for_renders (the masks stage after the renders): the bench's view of the first pass, the
second pass told the render size, and the neighbours' check after it."""

import json
from pathlib import Path

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

    def motion(full, result, opts, log, progress, sequence, kept=None):
        result["train"][0].transient = torch.ones(2, 2, dtype=torch.bool)
        kept.update(flows="kept")
        return True

    def second(view, reference, full, result, steps, margin, log, progress, render_step=1, keep=False):
        calls["render_step"] = render_step
        result["train"][0].transient = torch.zeros(2, 2, dtype=torch.bool)
        return {"second_pass_seconds": 1.0}

    def settle(full, result, kept, opts, log, progress):
        calls["settled"] = (kept["flows"], int(result["train"][0].transient.sum()))
    monkeypatch.setattr(am, "masks_from_renders", first)
    monkeypatch.setattr(am, "at_full_size", lambda renders, result: renders)
    monkeypatch.setattr(mo, "add_motion", motion)
    monkeypatch.setattr(sp, "second_pass", second)
    monkeypatch.setattr(mo, "settle_transients", settle)
    seen, stats = [], {}
    out = am.masks_for_renders(tmp_path, tmp_path / "ref", None, None, motion=mo.MotionOptions(), stats=stats, render_downscale=2,
                               first_pass=lambda res: seen.append(int(res["train"][0].transient.sum())))
    assert seen == [4] and int(out["train"][0].transient.sum()) == 0
    assert calls["render_step"] == 2 and stats == {"second_pass_seconds": 1.0}
    assert calls["settled"] == ("kept", 0)  # the route's flows, on the second pass's masks


def test_auto_masks_runs_the_second_pass_end_to_end_on_half_size_renders(tmp_path, monkeypatch):
    """auto_masks on the tiny scene with a 5-step reference, renders at every 2nd pixel and the real second
    pass (3 steps); only the flow is stood in for: it marks each car and a patch of ground. The second
    pass may only drop first-pass pixels, the masks keep the images' size, the stats carry its cost and
    nothing is left beside the reference."""
    import shutil

    from masks.test_masks import _tiny
    from nerf2gs_plugin.data.images import load_mask
    from nerf2gs_plugin.masking.mask_reference import ensure_reference
    from nerf2gs_plugin.masks.auto import AutoOptions
    from nerf2gs_plugin.masks.maskless import SECOND_PASS_DIRNAME, maskless_view

    data = _tiny(tmp_path, "scene")
    cars = {p.stem: load_mask(p) for p in sorted((data / "masks" / "transient").glob("train_*.png"))}
    shutil.rmtree(data / "masks")
    ref = ensure_reference(data, tmp_path / "refs" / "ref", steps=5, progress=False, log=lambda s: None)
    first: list[torch.Tensor] = []

    def flow_stand_in(full, result, opts, log, progress, sequence, kept=None):
        kept.update(order=sorted((v["name"], "train", i) for i, v in enumerate(full.views["train"])), flows=[{}] * len(full.views["train"]))
        for view, m in zip(full.views["train"], result["train"]):
            assert tuple(m.transient.shape) == tuple(view["image"].shape[:2])  # the flow sees full-size frames
            m.transient = cars[Path(view["name"]).stem].clone() if Path(view["name"]).stem in cars else torch.zeros_like(m.transient)
            m.transient[18:22, 20:30] = True
            first.append(m.transient.clone())
        return True

    monkeypatch.setattr(mo, "add_motion", flow_stand_in)
    stats: dict = {}
    out = am.auto_masks(maskless_view(data), ref, ["train"], AutoOptions(), log=lambda s: None, progress=False,
                        motion=mo.MotionOptions(second_pass_steps=3), render_downscale=2, stats=stats)
    assert len(out["train"]) == len(first) == 8 and sum(int(m.sum()) for m in first) > 8 * 40  # the cars are in
    for m, before in zip(out["train"], first):
        assert m.transient.shape == (24, 32) and not bool((m.transient & ~before).any())
    assert stats["second_pass_seconds"] >= stats["second_pass_train_seconds"] > 0 and stats["render_cpu_seconds"] > 0
    assert [p.name for p in ref.parent.iterdir()] == ["ref"] and not (data / SECOND_PASS_DIRNAME).exists()
