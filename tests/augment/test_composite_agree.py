"""--augment.composite-agree-tol: a masked pixel whose photo already looks like the reference's render keeps
the photo (the mask took static street there); where they differ (a mover) the render is pasted."""

from dataclasses import asdict

import pytest
import torch

from nerf2gs_plugin.augment.cache import cache_key
from nerf2gs_plugin.augment.datamanager import AugmentConfig, composite, composite_share
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.errors import ConfigError


def _scene():
    real = torch.full((20, 40, 3), 0.5)
    render = real.clone()
    render[:, 20:] = 0.1  # the right half: a mover the reference does not render
    real[:, :20] += 0.02 * torch.rand(20, 20, 3)  # the left half: static, a little noise
    return real, render, torch.ones(20, 40, 1, dtype=torch.bool)


def test_off_pastes_the_whole_mask():
    real, render, mask = _scene()
    assert torch.equal(composite(real, render, mask), render)


def test_agreeing_pixels_keep_the_photo_and_the_mover_is_pasted():
    real, render, mask = _scene()
    share = composite_share(real, render, mask, agree_tol=0.05)
    assert share[:, :17].max() == 0 and share[:, 23:].min() == 1  # away from the seam, where the 5 px box sees one side
    out = composite(real, render, mask, agree_tol=0.05)
    assert torch.equal(out[:, :17], real[:, :17]) and torch.equal(out[:, 23:], render[:, 23:])
    unmasked = composite_share(real, render, torch.zeros_like(mask), agree_tol=0.05)
    assert unmasked.max() == 0  # never outside the mask


def test_the_tolerance_keys_the_cache_only_when_on(tiny_scene):
    cams = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu").train_images.cameras
    plain = asdict(AugmentConfig())
    before = {k: v for k, v in plain.items() if k != "composite_agree_tol"}
    assert cache_key("r", "d", plain, cams, cams, "none") == cache_key("r", "d", before, cams, cams, "none")
    assert cache_key("r", "d", {**plain, "composite_agree_tol": 0.05}, cams, cams, "none") != cache_key("r", "d", plain, cams, cams, "none")


def test_a_negative_tolerance_is_refused():
    import dataclasses

    from nerf2gs_plugin.engine.validate import check_trainer_config
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("splatfacto").config, augment=AugmentConfig(composite_agree_tol=-0.1))
    with pytest.raises(ConfigError, match="--augment.composite-agree-tol"):
        check_trainer_config(cfg)
