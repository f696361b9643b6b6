"""``--augment.composite-loss either``: a composite's pixel is learnt as painted or as photographed, whichever the
render is nearer; pixels where photo and composite agree are unchanged."""

import torch

from nerf2gs_plugin.datamanagers.image_set import ImageSet
from nerf2gs_plugin.methods.splatfacto.shared import image_loss


def test_the_nearer_of_paint_and_photo_is_the_target():
    photo = torch.full((8, 8, 3), 0.2)
    comp = photo.clone()
    comp[2:5, 2:5] = 0.8  # painted over a false alarm: the render learnt the photo there
    pred = photo.clone().requires_grad_(True)
    plain = image_loss({"rgb": pred}, {"image": comp}, ssim_lambda=0.0)["main_loss"]
    either = image_loss({"rgb": pred}, {"image": comp, "photo": photo}, ssim_lambda=0.0)["main_loss"]
    assert float(plain) > 0.05 and float(either) == 0.0
    # where the render is nearer the paint (a mover the other views contradict), the paint is the target
    pred2 = comp.clone()
    pred2[2:5, 2:5] = 0.7
    loss = image_loss({"rgb": pred2}, {"image": comp, "photo": photo}, ssim_lambda=0.2)["main_loss"]
    ref = image_loss({"rgb": pred2}, {"image": comp}, ssim_lambda=0.2)["main_loss"]
    assert torch.allclose(loss, ref)


def test_image_sets_carry_the_photos_to_the_batch():
    from nerf2gs_plugin.cameras import Cameras

    cams = Cameras(torch.eye(4)[:3][None].repeat(2, 1, 1), fx=4.0, fy=4.0, cx=2.0, cy=2.0, width=4, height=4)
    images = [torch.rand(4, 4, 3), torch.rand(4, 4, 3)]
    base = ImageSet.from_images(cams, images)
    comp = base.with_images([im * 0.5 for im in images]).with_photos(base.pixels)
    batch = comp.to("cpu").with_confidence([torch.ones(4, 4, 1)] * 2).image_batch(1)
    assert torch.equal(batch["photo"], images[1]) and torch.allclose(batch["image"], images[1] * 0.5)
    assert "photo" not in base.image_batch(0)


def test_the_photo_wins_unless_the_paint_is_nearer_by_the_margin():
    photo, comp = torch.full((8, 8, 3), 0.2), torch.full((8, 8, 3), 0.8)
    pred = torch.full((8, 8, 3), 0.52)  # 0.32 from the photo, 0.28 from the paint
    to_paint = image_loss({"rgb": pred}, {"image": comp}, ssim_lambda=0.0)["main_loss"]
    to_photo = image_loss({"rgb": pred}, {"image": photo}, ssim_lambda=0.0)["main_loss"]
    no_margin = image_loss({"rgb": pred}, {"image": comp, "photo": photo}, ssim_lambda=0.0)["main_loss"]
    margin = image_loss({"rgb": pred}, {"image": comp, "photo": photo, "photo_margin": 0.05}, ssim_lambda=0.0)["main_loss"]
    assert torch.allclose(no_margin, to_paint) and torch.allclose(margin, to_photo)


def test_sky_stays_the_step_background_whichever_target_is_taken():
    photo, comp = torch.full((4, 4, 3), 0.2), torch.full((4, 4, 3), 0.8)
    pred = photo.clone()  # nearer the photo everywhere
    sky = torch.zeros(4, 4, 1, dtype=torch.bool)
    sky[0] = True
    bg = torch.tensor([0.2, 0.5, 0.9])
    loss = image_loss({"rgb": pred}, {"image": comp, "photo": photo, "sky_mask": sky}, ssim_lambda=0.0, sky_background=bg)
    expected = (pred - torch.where(sky, bg.expand(4, 4, 3), photo)).abs().mean()
    assert torch.allclose(loss["main_loss"], expected) and float(loss["main_loss"]) > 0


def test_a_ray_sampled_target_refuses_either_and_image_targets_take_it(tmp_path):
    import dataclasses

    import pytest

    from nerf2gs_plugin.engine.validate import check_trainer_config
    from nerf2gs_plugin.errors import ConfigError
    from nerf2gs_plugin.registry import get_method

    def cfg(method: str, **aug):
        c = get_method(method).config
        return dataclasses.replace(c, augment_from=tmp_path, augment=dataclasses.replace(c.augment, **aug))

    with pytest.raises(ConfigError, match="--augment.composite-loss"):
        check_trainer_config(cfg("streetnerf", composite_loss="either"))
    check_trainer_config(cfg("streetnerf"))  # paint: rays are fine
    for method in ("splatfacto", "scaffold-gs", "2dgs"):
        check_trainer_config(cfg(method, composite_loss="either"))
    with pytest.raises(ConfigError, match="--augment.composite-loss-margin"):
        check_trainer_config(cfg("splatfacto", composite_loss="either", composite_loss_margin=-0.1))
