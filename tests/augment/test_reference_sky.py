"""``--augment.reference-sky``: the reference's sky at the input views joins their sky masks (cached)."""

import dataclasses
from dataclasses import asdict

import torch

from nerf2gs_plugin.augment.cache import cache_key
from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.methods.splatfacto.shared import image_loss


class LeftSkyRenderer:
    """A stand-in reference: the left half of every view is empty (accumulation 0), the rest a surface."""

    def __init__(self):
        self.calls = 0

    def __call__(self, camera):
        self.calls += 1
        h, w = int(camera.height[0]), int(camera.width[0])
        acc = torch.ones(h, w, 1)
        acc[:, : w // 2] = 0.0
        return {"rgb": torch.full((h, w, 3), 0.3), "accumulation": acc, "depth": torch.ones(h, w, 1)}


CFG = AugmentConfig(delta_h=2.0, min_coverage=0.0, reference_sky=True)


def _augmented(data, root, cfg=CFG, render=None):
    dm = FullImageDataManagerConfig().setup(data=data, device="cpu")
    return AugmentedDataManager(dm, Reference(render or LeftSkyRenderer(), "ref:leftsky", root), cfg), dm


def test_the_reference_sky_joins_the_input_views_sky_masks(tiny_scene, tmp_path):
    plain, _ = _augmented(tiny_scene, tmp_path / "p", dataclasses.replace(CFG, reference_sky=False))
    adm, _ = _augmented(tiny_scene, tmp_path / "s")
    before, after = plain.train_images, adm.train_images
    assert torch.equal(before.pixels, after.pixels)  # only the masks change
    added = 0
    for i in range(len(after)):
        old = before.mask("sky", i)[..., 0] if "sky" in before.masks else torch.zeros(*after.hw(i), dtype=torch.bool)
        new = after.mask("sky", i)[..., 0]
        assert bool((new | old).eq(new).all())  # the masks' own sky stays
        extra = new & ~old
        w = new.shape[1]
        assert not bool(extra[:, w // 2 + w // 8:].any())  # nothing where the reference has a surface
        added += int(extra.sum())
        # the model's sky alpha loss sees the joined mask
        batch = after.image_batch(i)
        assert torch.equal(batch["sky_mask"][..., 0], new)
    assert added > 0


def test_the_sky_alpha_loss_reaches_the_new_pixels(tiny_scene, tmp_path):
    adm, _ = _augmented(tiny_scene, tmp_path)
    batch = adm.train_images.image_batch(0)
    h, w = adm.train_images.hw(0)
    acc = torch.zeros(h, w, 1)
    acc[:, : w // 2] = 1.0  # the target fills the reference's sky
    out = {"rgb": batch["image"].clone(), "accumulation": acc}
    assert float(image_loss(out, batch, 0.2, sky_alpha_weight=0.05)["sky_alpha_loss"]) > 0


def test_the_masks_are_cached_and_leave_the_render_cache_key_alone(tiny_scene, tmp_path):
    render = LeftSkyRenderer()
    adm, _ = _augmented(tiny_scene, tmp_path, render=render)
    again = LeftSkyRenderer()
    adm2, _ = _augmented(tiny_scene, tmp_path, render=again)
    assert again.calls == 0  # the additional views and the sky masks both from the cache
    assert torch.equal(adm.train_images.masks["sky"], adm2.train_images.masks["sky"])
    cams = adm.train_images.cameras
    assert cache_key("r", "d", asdict(CFG), None, cams, "none") == cache_key("r", "d", asdict(dataclasses.replace(CFG, reference_sky=False)), None, cams, "none")
