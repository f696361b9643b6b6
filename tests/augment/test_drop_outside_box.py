"""``--augment.drop-outside-box``: the additional views' pixels that show sky or lie outside the scene box weigh 0."""

import dataclasses
from dataclasses import asdict

import pytest
import torch

from nerf2gs_plugin.augment.cache import cache_key
from nerf2gs_plugin.augment.confidence import inside_box_weight
from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.errors import ConfigError

FAR = 1e3
"""Scene units: a surface far outside any box (the far background a NeRF contracts)."""


class SplitRenderer:
    """A stand-in reference: the top half of every view is a near surface, the bottom half far away, and
    the left quarter is sky (accumulation 0)."""

    def __init__(self, depth=True):
        self.depth = depth

    def __call__(self, camera):
        h, w = int(camera.height[0]), int(camera.width[0])
        acc = torch.ones(h, w, 1)
        acc[:, : w // 4] = 0.0
        out = {"rgb": torch.full((h, w, 3), 0.3), "accumulation": acc}
        if self.depth:
            depth = torch.full((h, w, 1), 1e-3)
            depth[h // 2:] = FAR
            out["depth"] = depth
        return out


CFG = AugmentConfig(delta_h=2.0, min_coverage=0.0, drop_outside_box=True)


def _augmented(data, root, cfg=CFG, render=None):
    dm = FullImageDataManagerConfig().setup(data=data, device="cpu")
    return AugmentedDataManager(dm, Reference(render or SplitRenderer(), "ref:split", root), cfg)


def test_far_and_sky_pixels_of_the_views_from_above_weigh_nothing(tiny_scene, tmp_path):
    adm = _augmented(tiny_scene, tmp_path)
    extra = adm.extra_images
    assert extra is not None and len(extra) > 0 and extra.confidence is not None
    for j in range(len(extra)):
        conf = extra.image_batch(j)["confidence"][..., 0]
        h, w = conf.shape
        expected = torch.ones(h, w)
        expected[h // 2:] = 0.0  # far away: outside the box
        expected[:, : w // 4] = 0.0  # sky
        assert torch.equal(conf, expected)
    # the input views (composites) keep every pixel: no map at all
    assert adm.train_images.confidence is None


def test_without_it_every_pixel_counts_and_old_cache_entries_stay_valid(tiny_scene, tmp_path):
    adm = _augmented(tiny_scene, tmp_path, dataclasses.replace(CFG, drop_outside_box=False))
    assert adm.extra_images.confidence is None and "confidence" not in adm.extra_images.image_batch(0)
    cams = adm.train_images.cameras
    legacy = {k: v for k, v in asdict(AugmentConfig()).items() if k != "drop_outside_box"}
    assert cache_key("r", "d", asdict(AugmentConfig()), None, cams, "none") == cache_key("r", "d", legacy, None, cams, "none")
    assert cache_key("r", "d", asdict(CFG), None, cams, "none") != cache_key("r", "d", asdict(AugmentConfig()), None, cams, "none")


def test_it_multiplies_the_visibility_confidence(tiny_scene, tmp_path):
    both = _augmented(tiny_scene, tmp_path / "b", dataclasses.replace(CFG, confidence="visibility"))
    vis = _augmented(tiny_scene, tmp_path / "v", dataclasses.replace(CFG, confidence="visibility", drop_outside_box=False))
    drop = _augmented(tiny_scene, tmp_path / "d")
    assert torch.allclose(both.extra_images.confidence, vis.extra_images.confidence * drop.extra_images.confidence)


def test_a_reference_without_depth_is_refused(tiny_scene, tmp_path):
    with pytest.raises(ConfigError, match="drop-outside-box"):
        _augmented(tiny_scene, tmp_path, render=SplitRenderer(depth=False))


def test_inside_box_weight_lifts_along_the_ray():
    """A camera at the origin looking down -z: a pixel's point is inside the box up to the box's face."""
    c2w = torch.eye(4)[:3][None]
    cam = Cameras(camera_to_worlds=c2w, fx=torch.tensor([[2.0]]), fy=torch.tensor([[2.0]]), cx=torch.tensor([[1.0]]),
                  cy=torch.tensor([[1.0]]), width=torch.tensor([[2]]), height=torch.tensor([[2]]))
    box = torch.tensor([[-5.0, -5.0, -5.0], [5.0, 5.0, 5.0]])
    for along in ("z", "ray"):
        assert torch.equal(inside_box_weight(torch.full((2, 2, 1), 4.0), None, cam, along, box), torch.ones(2, 2, 1))
        assert torch.equal(inside_box_weight(torch.full((2, 2, 1), 6.0), None, cam, along, box), torch.zeros(2, 2, 1))
    acc = torch.tensor([[0.4, 0.6], [1.0, 0.0]])[..., None]
    assert inside_box_weight(torch.ones(2, 2, 1), acc, cam, "z", None)[..., 0].tolist() == [[0.0, 1.0], [1.0, 0.0]]
