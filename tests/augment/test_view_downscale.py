"""--augment.view-downscale: the additional views rendered and trained smaller than the input views; and
--augment.step-factor: the longer run that the smaller views pay for."""

import dataclasses
from dataclasses import asdict

import pytest
import torch

from nerf2gs_plugin.augment.cache import cache_key
from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.errors import ConfigError


class SizeRecorder:
    """A stand-in reference: a grey render at the camera's size, recording each size asked for."""

    def __init__(self):
        self.sizes = []

    def __call__(self, camera):
        h, w = int(camera.height[0]), int(camera.width[0])
        self.sizes.append((h, w))
        return {"rgb": torch.full((h, w, 3), 0.3), "depth": torch.ones(h, w, 1), "accumulation": torch.ones(h, w, 1)}


def _augmented(data, root, cfg, render):
    dm = FullImageDataManagerConfig().setup(data=data, device="cpu")
    AugmentedDataManager(dm, Reference(render, "ref:vd", root), cfg)
    return dm


def test_half_size_views_render_and_cache_under_their_own_keys(tiny_scene, tmp_path):
    cfg = AugmentConfig(delta_h=2.0, min_coverage=0.0, composites=False, view_downscale=1)
    full_r, half_r = SizeRecorder(), SizeRecorder()
    full = _augmented(tiny_scene, tmp_path, cfg, full_r)
    half = _augmented(tiny_scene, tmp_path, dataclasses.replace(cfg, view_downscale=2), half_r)
    h, w = full.train_images.hw(0)
    assert full_r.sizes and set(full_r.sizes) == {(h, w)}
    # every additional view rendered at half the width and height (none of the full-size store reused)
    assert len(half_r.sizes) == len(full_r.sizes) and set(half_r.sizes) == {(round(h / 2), round(w / 2))}
    assert half.extra_images.hw(0) == (round(h / 2), round(w / 2)) and half.train_images.hw(0) == (h, w)
    cams, big = half.extra_images.cameras, full.extra_images.cameras
    assert torch.allclose(cams.fx, big.fx / 2) and torch.allclose(cams.cx, big.cx / 2)
    entries = sorted(p.name for p in (tmp_path / "augment_cache").iterdir() if p.name != "views")
    assert len(entries) == 2  # one entry per size
    assert len(list((tmp_path / "augment_cache" / "views").glob("*.json"))) == 2 * len(full_r.sizes)
    # each size again: nothing rendered, each from its own entry
    again = SizeRecorder()
    _augmented(tiny_scene, tmp_path, dataclasses.replace(cfg, view_downscale=2), again)
    _augmented(tiny_scene, tmp_path, cfg, again)
    assert again.sizes == []


def test_half_size_views_seed_about_as_many_points(tiny_scene, tmp_path):
    counts = {}
    for n in (1, 2):
        dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
        aug = AugmentedDataManager(dm, Reference(SizeRecorder(), "ref:vd", tmp_path),
                                   AugmentConfig(delta_h=2.0, min_coverage=0.0, composites=False, view_downscale=n))
        counts[n] = len(aug.initial_points()[0])
    # the smaller views are lifted more densely: the same surfaces, about the same points
    assert counts[1] > 0 and abs(counts[2] - counts[1]) <= 0.2 * counts[1]


def test_an_image_conditioned_enhancer_gets_its_reference_at_the_view_s_size(tiny_scene, tmp_path):
    seen = []

    class ShapeEnhancer:
        def enhance(self, rgb, reference=None):
            seen.append((tuple(rgb.shape), tuple(reference.shape)))
            return rgb

        def cache_key(self):
            return "shape"

    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    AugmentedDataManager(dm, Reference(SizeRecorder(), "ref:vd", tmp_path),
                         AugmentConfig(delta_h=2.0, min_coverage=0.0, composites=False, view_downscale=2), ShapeEnhancer())
    h, w = dm.train_images.hw(0)
    assert seen and all(r == v == (round(h / 2), round(w / 2), 3) for v, r in seen)


def test_the_input_views_size_keeps_the_entries_written_before_the_option(tiny_scene):
    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    cams = dm.train_images.cameras
    plain = asdict(AugmentConfig(view_downscale=1))
    before = {k: v for k, v in plain.items() if k != "view_downscale"}
    assert cache_key("r", "d", plain, cams, cams, "none") == cache_key("r", "d", before, cams, cams, "none")
    assert cache_key("r", "d", {**plain, "view_downscale": 2}, cams, cams, "none") != cache_key("r", "d", plain, cams, cams, "none")


def test_a_target_trains_on_views_of_another_size(tiny_scene, tmp_path):
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    def train(method, out, steps, **kw):
        cfg = dataclasses.replace(get_method(method).config, data=tiny_scene, output_dir=out, max_num_iterations=steps,
                                  steps_per_eval_image=0, progress=False, timestamp="run", seed=3, **kw)
        t = Trainer(cfg)
        t.setup()
        return t, t.train()

    _, ref = train("voxel-grid", tmp_path / "ref", 20)
    trainer, run_dir = train("splatfacto", tmp_path / "tgt", 12, augment_from=ref,
                             augment=AugmentConfig(delta_h=2.0, min_coverage=0.0, view_downscale=2, confidence="footprint",
                                                   real_only_from=1.0, step_factor=1.5))
    # 12 x 1.5 steps, the schedule with them; the saved config is the run as trained (a reload does not scale again)
    assert trainer.step + 1 == trainer.config.max_num_iterations == 18
    assert trainer.config.optimizers["means"].max_steps == 18
    from nerf2gs_plugin.runs.load import load_run

    saved = load_run(run_dir).config
    assert saved.max_num_iterations == 18 and saved.augment.step_factor == 1.0
    dm = trainer.pipeline.datamanager
    assert dm.extra_images.hw(0) != dm.train_images.hw(0)
    # both sizes are drawn (extra views are about half the samples) and the model stayed finite
    drawn = [dm.next_train(s)[1]["image_idx"] for s in range(12)]
    n = len(dm.train_images)
    assert any(int(i) >= n for i in drawn) and any(int(i) < n for i in drawn)
    assert all(bool(torch.isfinite(p).all()) for p in trainer.pipeline.model.parameters())


@pytest.mark.parametrize("bad", [0, -1])
def test_a_bad_view_downscale_is_refused(bad):
    from nerf2gs_plugin.engine.validate import check_trainer_config
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("splatfacto").config, augment=AugmentConfig(view_downscale=bad))
    with pytest.raises(ConfigError, match="--augment.view-downscale"):
        check_trainer_config(cfg)


def test_the_birds_eye_render_path_keeps_the_captures_size(tiny_scene):
    from types import SimpleNamespace

    from nerf2gs_plugin.render.scene import trained_birds_eye

    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    td, cams = dm.train_data, dm.train_images.cameras
    config = SimpleNamespace(augment_from=tiny_scene / "no-such-run", augment=AugmentConfig(view_downscale=2))
    path, _ = trained_birds_eye(config, None, cams, td.up, 1.0 / td.metres_per_unit)
    assert path is not None and torch.equal(path.width, cams.width) and torch.equal(path.height, cams.height)


def test_the_step_factor_lengthens_only_an_augmented_run():
    from nerf2gs_plugin.engine.trainer import augmented_length
    from nerf2gs_plugin.registry import get_method

    base = get_method("splatfacto").config
    assert AugmentConfig().step_factor == 1.4 and AugmentConfig().view_downscale == 2  # the measured defaults
    assert augmented_length(base) is base  # no --augment-from: the method's own length
    from pathlib import Path

    cfg = dataclasses.replace(base, augment_from=Path("ref"), max_num_iterations=3000)
    longer = augmented_length(cfg)
    assert longer.max_num_iterations == 4200 and longer.augment.step_factor == 1.0
    assert longer.pipeline.model.strategy.refine_every > 0  # rescaled with the run, not removed
    same = augmented_length(dataclasses.replace(cfg, augment=AugmentConfig(step_factor=1.0)))
    assert same.max_num_iterations == 3000


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_a_bad_step_factor_is_refused(bad):
    from nerf2gs_plugin.engine.validate import check_trainer_config
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("splatfacto").config, augment=AugmentConfig(step_factor=bad))
    with pytest.raises(ConfigError, match="--augment.step-factor"):
        check_trainer_config(cfg)
