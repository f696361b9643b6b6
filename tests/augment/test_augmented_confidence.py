"""The confidence's data path: rendered and cached with the views, handed out with every batch."""

import dataclasses
from dataclasses import asdict

import pytest
import torch

from nerf2gs_plugin.augment.cache import cache_key, confidence_path, read_manifest
from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.datamanagers.image_set import ImageSet
from nerf2gs_plugin.datamanagers.rays import RayDataManagerConfig
from nerf2gs_plugin.errors import ConfigError


class FlatRenderer:
    """A stand-in reference: grey, every pixel 1 unit deep (z), counting its calls."""

    def __init__(self, depth=True):
        self.calls, self.depth = 0, depth

    def __call__(self, camera):
        self.calls += 1
        h, w = int(camera.height[0]), int(camera.width[0])
        out = {"rgb": torch.full((h, w, 3), 0.3), "accumulation": torch.ones(h, w, 1)}
        if self.depth:
            out["depth"] = torch.ones(h, w, 1)
        return out


CFG = AugmentConfig(delta_h=2.0, min_coverage=0.0, confidence="visibility")


def _augmented(data, root, cfg=CFG, render=None, **kw):
    dm = FullImageDataManagerConfig().setup(data=data, device="cpu")
    return AugmentedDataManager(dm, Reference(render or FlatRenderer(), "ref:flat", root), cfg, **kw)


def test_confidence_is_cached_beside_the_renders_and_batched(tiny_scene, tmp_path):
    render = FlatRenderer()
    adm = _augmented(tiny_scene, tmp_path, render=render)
    n = len(adm.train_images)
    assert render.calls == n + len(adm.extra_images)  # every input view rendered once (its depth), then the extra views
    manifest = read_manifest(adm.views.cache_dir)
    assert manifest.composited_images and all(confidence_path(manifest.composite_png(i)).is_file() for i in manifest.composited_images)
    assert all(confidence_path(manifest.extra_png(j)).is_file() for j in range(manifest.num_extra))
    comp, extra = adm.train_images, adm.extra_images
    assert comp.confidence is not None and extra.confidence is not None
    assert bool(((comp.confidence >= 0) & (comp.confidence <= 1)).all()) and bool(((extra.confidence >= 0) & (extra.confidence <= 1)).all())
    for i in range(n):  # real pixels weigh 1: only the painted (dilated transient) pixels may weigh less
        m = comp.mask("transient", i).float().permute(2, 0, 1)[None]
        grown = torch.nn.functional.max_pool2d(m, 2 * CFG.dilate_px + 1, 1, CFG.dilate_px)[0, 0].bool()
        conf = comp.image_batch(i)["confidence"][..., 0]
        assert torch.equal(conf[~grown], torch.ones_like(conf[~grown]))
    batch = extra.image_batch(0)
    assert batch["confidence"].shape == (*batch["image"].shape[:2], 1)
    # reused from the cache: nothing rendered, the same maps
    again = FlatRenderer()
    adm2 = _augmented(tiny_scene, tmp_path, render=again)
    assert again.calls == 0 and adm2.views.reused
    assert torch.equal(adm2.extra_images.confidence, extra.confidence) and torch.equal(adm2.train_images.confidence, comp.confidence)


def test_without_confidence_nothing_changes(tiny_scene, tmp_path):
    render = FlatRenderer()
    adm = _augmented(tiny_scene, tmp_path, dataclasses.replace(CFG, confidence="none"), render)
    n_comp = len(adm.manifest.composited_images)
    assert render.calls == n_comp + len(adm.extra_images)  # only the composited views and the extra views
    assert adm.train_images.confidence is None and adm.extra_images.confidence is None
    assert "confidence" not in adm.extra_images.image_batch(0)
    assert not list(adm.views.cache_dir.rglob("*_conf.npy"))
    # the cache key of a run without confidence is the key it had before the option existed
    cams = adm.train_images.cameras
    legacy = {k: v for k, v in asdict(AugmentConfig()).items() if not k.startswith("confidence")}
    assert cache_key("r", "d", asdict(AugmentConfig()), None, cams, "none") == cache_key("r", "d", legacy, None, cams, "none")
    assert cache_key("r", "d", asdict(CFG), None, cams, "none") != cache_key("r", "d", asdict(AugmentConfig()), None, cams, "none")


def test_unseen_weighs_the_extra_views_as_visibility_turned_around_and_keeps_composites_whole(tiny_scene, tmp_path):
    vis = _augmented(tiny_scene, tmp_path / "v")
    for seen_weight in (0.0, 0.3):
        cfg = dataclasses.replace(CFG, confidence="unseen", confidence_seen_weight=seen_weight)
        un = _augmented(tiny_scene, tmp_path / f"u{seen_weight}", cfg)
        # the flat reference's accumulation is 1, so visibility is the seen fraction itself
        expect = 1.0 - (1.0 - seen_weight) * vis.extra_images.confidence
        assert torch.allclose(un.extra_images.confidence, expect, atol=2e-3)  # maps are stored in float16
        assert torch.equal(un.train_images.confidence, torch.ones_like(un.train_images.confidence))
    assert float(vis.extra_images.confidence.max()) > float(vis.extra_images.confidence.min())  # not a constant map


def test_footprint_weighs_the_extra_views_keeps_composites_whole_and_refuses_a_ratio_of_one(tiny_scene, tmp_path):
    cfg = dataclasses.replace(CFG, confidence="footprint")
    fp = _augmented(tiny_scene, tmp_path / "f", cfg)
    conf = fp.extra_images.confidence
    assert bool(((conf >= 0) & (conf <= 1)).all()) and float(conf.max()) > float(conf.min())
    assert torch.equal(fp.train_images.confidence, torch.ones_like(fp.train_images.confidence))
    with pytest.raises(ConfigError, match="confidence-footprint-ratio"):
        _augmented(tiny_scene, tmp_path / "g", dataclasses.replace(cfg, confidence_footprint_ratio=1.0))
    # the ratio keys only footprint's entries: the other confidences keep their cached renders
    cams = fp.train_images.cameras
    other = dataclasses.replace(CFG, confidence="unseen")
    assert cache_key("r", "d", asdict(other), None, cams, "none") == cache_key(
        "r", "d", asdict(dataclasses.replace(other, confidence_footprint_ratio=3.0)), None, cams, "none")
    assert cache_key("r", "d", asdict(cfg), None, cams, "none") != cache_key(
        "r", "d", asdict(dataclasses.replace(cfg, confidence_footprint_ratio=3.0)), None, cams, "none")


def test_a_reference_without_depth_is_refused(tiny_scene, tmp_path):
    with pytest.raises(ConfigError, match="renders depth"):
        _augmented(tiny_scene, tmp_path, render=FlatRenderer(depth=False))


def test_rays_weigh_their_pixel_confidence(tiny_scene):
    dm = RayDataManagerConfig(rays_per_batch=256).setup(data=tiny_scene, device="cpu")
    imgs = dm.train_images
    extra = ImageSet(imgs.cameras, imgs.pixels, imgs.offsets, names=list(imgs.names)).with_confidence(
        [torch.full((*imgs.hw(i), 1), 0.25) for i in range(len(imgs))])
    dm.set_extra_images(extra, 0.5)
    _, batch = dm.next_train(0)
    extra_rays = batch["image_idx"] >= len(imgs)
    assert bool(extra_rays.any()) and bool((~extra_rays).any())
    assert torch.allclose(batch["weight"][extra_rays], torch.full_like(batch["weight"][extra_rays], 0.25))
    assert torch.equal(batch["weight"][~extra_rays], torch.ones_like(batch["weight"][~extra_rays]))


def test_a_target_trains_with_confidence_from_a_trained_reference(tiny_scene, tmp_path):
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    def train(method, out, steps, **kw):
        cfg = dataclasses.replace(get_method(method).config, data=tiny_scene, output_dir=out, max_num_iterations=steps,
                                  steps_per_eval_image=0, progress=False, timestamp="run", **kw)
        t = Trainer(cfg)
        t.setup()
        return t, t.train()

    _, ref = train("voxel-grid", tmp_path / "ref", 30)
    trainer, _ = train("splatfacto", tmp_path / "tgt", 10, augment_from=ref,
                       augment=AugmentConfig(delta_h=2.0, min_coverage=0.0, confidence="visibility"))
    dm = trainer.pipeline.datamanager
    assert dm.extra_images is not None and dm.extra_images.confidence is not None
    conf = dm.extra_images.confidence
    # a reference trained 30 steps knows some pixels and not others: the maps are not constant
    assert float(conf.max()) > float(conf.min())
    assert len(list((ref / "augment_cache").rglob("*_conf.npy"))) == len(dm.extra_images) + len(dm.views.manifest.composited_images)


def test_the_preview_shows_the_confidence(tiny_scene, tmp_path):
    import cv2

    from nerf2gs_plugin.augment.preview import preview_augmented

    with_conf = preview_augmented(_augmented(tiny_scene, tmp_path / "a"), tmp_path / "with.png", 2)
    without = preview_augmented(_augmented(tiny_scene, tmp_path / "b", dataclasses.replace(CFG, confidence="none")), tmp_path / "without.png", 2)
    w1, w0 = cv2.imread(str(with_conf)).shape[1], cv2.imread(str(without)).shape[1]
    assert w1 > w0 * 1.15  # one more column: the bird's-eye view's confidence
