"""The motion route's second pass (``masks/second_pass.py``, ``masking/second_pass.py``): on the textured
sequence of ``test_motion.py`` the first pass's mask holds the block riding with the camera, the flow
spilt onto the background around it and a patch of background that the references render badly."""

from __future__ import annotations

import json

import cv2
import numpy as np
import torch

from masks.test_motion import _iou, _sequence
from nerf2gs_plugin.masks.maskless import SECOND_PASS_DIRNAME, maskless_view
from nerf2gs_plugin.masks.second_pass import render_pixels, second_pass_mask


def _first_pass(truth: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """The rider grown by 6 px (DIS's spill) and a patch of static background: ``(mask, the patch)``."""
    rider = truth["rider"].numpy().astype(np.uint8)
    spill = cv2.dilate(rider, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (13, 13))) > 0
    patch = torch.zeros_like(truth["rider"])
    patch[50:80, 100:140] = True
    return torch.from_numpy(spill) | patch, patch


def _renders(image: torch.Tensor, truth: dict, patch: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The first reference (trained without masks: it learnt the rider halfway, as something far away)
    and the second (the rider excluded: the static scene); both render the patch as badly, the rest with
    the same small noise."""
    g = torch.Generator().manual_seed(0)
    static = truth["static"] + 0.01 * torch.randn(truth["static"].shape, generator=g)
    static[patch] += 0.3 * torch.rand(int(patch.sum()), 3, generator=g)
    first = static.clone()
    first[truth["rider"]] = 0.5 * (image + static)[truth["rider"]]
    return first.clamp(0, 1), static.clamp(0, 1)


def _frame():
    """A frame of the sequence with its truth, first pass, badly rendered patch and both references' renders."""
    frames, truths = _sequence()
    image, truth = frames[2].image, truths[2]
    first, patch = _first_pass(truth)
    return (image, truth, first, patch, *_renders(image, truth, patch))


def test_the_second_pass_keeps_the_rider_and_drops_the_spill_and_what_both_references_render_badly():
    image, truth, first, patch, render1, render2 = _frame()
    pixels, sample = render_pixels(first)
    assert bool((first <= pixels).all()) and 0.05 < float(sample.float().mean()) < 0.07  # every 4th pixel per side
    sky = torch.zeros_like(first)
    out = second_pass_mask(first, image, render1, render2 * pixels[..., None], pixels, sample, sky)
    rider = truth["rider"]
    assert _iou(out, rider) > 0.8 > _iou(first, rider) + 0.3, (_iou(out, rider), _iou(first, rider))
    assert float((out & patch).float().sum()) == 0.0
    # what tells the rider from the patch is the first reference having learnt it: a rider it missed as
    # well (a render as far from it as the second's) goes too, and so does everything with a higher margin
    missed = second_pass_mask(first, image, render2, render2 * pixels[..., None], pixels, sample, sky)
    assert _iou(missed, rider) < 0.1
    assert _iou(second_pass_mask(first, image, render1, render2 * pixels[..., None], pixels, sample, sky, margin=1e6), rider) == 0.0
    assert not bool(second_pass_mask(first, image, render1, render2, pixels, sample, first).any())  # sky is never transient


def test_rendering_every_second_pixel_of_the_regions_keeps_the_rider():
    image, truth, first, patch, render1, render2 = _frame()
    full, sample = render_pixels(first)
    half, sample2 = render_pixels(first, 2)
    assert torch.equal(sample, sample2) and bool((half <= full).all())
    assert 0.2 < float(half[first].float().mean()) < 0.3  # a quarter of the regions' pixels
    out = second_pass_mask(first, image, render1, render2 * half[..., None], half, sample, torch.zeros_like(first))
    assert _iou(out, truth["rider"]) > 0.8 and float((out & patch).float().sum()) == 0.0


def test_the_masked_view_holds_the_first_pass_grown_and_stays_out_of_the_maskless_view(tmp_path):
    data = tmp_path / "data"
    (data / "images").mkdir(parents=True)
    (data / "images" / "a.png").write_bytes(b"x")
    (data / "transforms.json").write_text(json.dumps({"frames": [{"file_path": "images/a.png", "transient_mask_path": "masks/transient/a.png"}]}))
    view = maskless_view(data)
    from nerf2gs_plugin.masking.second_pass import TRAIN_GROW, masked_view

    m = torch.zeros(100, 200, dtype=torch.bool)
    m[40:60, 90:110] = True
    out = masked_view(view, {"a": m})
    assert out == data / SECOND_PASS_DIRNAME and (out / "images" / "a.png").read_bytes() == b"x"
    assert "mask_path" not in (out / "transforms.json").read_text()  # only the masks written here count
    from nerf2gs_plugin.data.images import load_mask

    grown = load_mask(out / "masks" / "transient" / "a.png")
    r = round(TRAIN_GROW * 100)
    assert bool(grown[40 - r, 100]) and not bool(grown[40 - r - 1, 100]) and bool(grown[m].all())
    assert not (maskless_view(data) / SECOND_PASS_DIRNAME).exists()


def _tiny_first_pass(tmp_path):
    """The tiny scene without masks, a 5-step first reference, its renders and first-pass masks with one transient
    block per frame: (data, reference, mask-less view, full-size renders, masks)."""
    import shutil

    from masks.test_masks import _tiny
    from nerf2gs_plugin.masking.auto_masks import at_full_size, render_views
    from nerf2gs_plugin.masking.mask_reference import ensure_reference
    from nerf2gs_plugin.masks.auto import AutoOptions, masks_from_renders

    data = _tiny(tmp_path, "scene")
    shutil.rmtree(data / "masks")
    ref = ensure_reference(data, tmp_path / "refs" / "ref", steps=5, progress=False, log=lambda s: None)
    view = maskless_view(data)
    renders = render_views(view, ref, ["train"], log=lambda s: None, progress=False)
    result = masks_from_renders(renders, AutoOptions(), log=lambda s: None)
    for m in result["train"]:
        m.transient = torch.zeros_like(m.transient)
        m.transient[4:12, 4:14] = True
    return data, ref, view, at_full_size(renders, result), result


def test_the_second_pass_continues_the_first_reference_on_the_masked_view(tmp_path):
    """The training and rendering half on the tiny scene: a 5-step first reference continued 3 steps
    with a transient mask excluded (the warm start must accept the reference's own config), rendered
    where the mask is; the temporary run and dataset view are removed, the masks keep their size."""
    from nerf2gs_plugin.masking.second_pass import second_pass

    data, ref, view, full, result = _tiny_first_pass(tmp_path)
    logs: list[str] = []
    took = second_pass(view, ref, full, result, 3, 0.2, log=logs.append, progress=False)
    assert any("continued for 3 steps" in line for line in logs) and took["second_pass_train_seconds"] > 0
    assert took["second_pass_cpu_seconds"] > 0 and took["second_pass_seconds"] >= took["second_pass_train_seconds"]
    assert [p.name for p in ref.parent.iterdir()] == ["ref"] and (ref / "config.yml").is_file()  # nothing left beside it
    assert not (data / SECOND_PASS_DIRNAME).exists() and "second_pass_run" not in took
    assert all(tuple(m.transient.shape) == tuple(v["image"].shape[:2]) for m, v in zip(result["train"], full.views["train"]))


def test_the_kept_second_pass_is_where_streetnerf_goes_on(tmp_path):
    """``keep``: the continued run stays beside the first reference, and StreetNeRF on the capture takes it as its
    warm start at the step after the second pass's (the second pass's steps are not trained again)."""
    import dataclasses

    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.masking.second_pass import kept_run_dir, second_pass
    from nerf2gs_plugin.registry import get_method

    data, ref, view, full, result = _tiny_first_pass(tmp_path)
    took = second_pass(view, ref, full, result, 3, 0.2, log=lambda s: None, progress=False, keep=True)
    kept = kept_run_dir(ref)
    assert took["second_pass_run"] == str(kept) and kept == tmp_path / "refs" / "ref-second-pass"
    assert kept_run_dir(ref / "checkpoints" / "step-000000004.ckpt") == kept
    assert sorted(p.name for p in ref.parent.iterdir()) == ["ref", "ref-second-pass"] and not (data / SECOND_PASS_DIRNAME).exists()
    from nerf2gs_plugin.runs.load import load_run

    run = load_run(kept, device="cpu")  # its config names the mask-less view and its own folder, both there
    assert run.config.data == view and run.config.run_dir == kept and run.model.num_primitives() > 0
    cfg = dataclasses.replace(get_method("streetnerf").with_steps(12), data=data, run_dir=tmp_path / "sn", warm_start=kept,
                              progress=False)
    trainer = Trainer(cfg)
    trainer.setup()
    assert trainer.step == 8  # 5 steps of the first reference, 3 of the second pass
