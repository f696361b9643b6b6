"""``--augment.appearance``: the reference colours its renders for the target with the mean or the
nearest photo's transform; a reference without an appearance model renders as it always does."""

import dataclasses

import pytest
import torch

from nerf2gs_plugin.augment.reference import load_reference
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.registry import get_method


def _train(method, data, out, steps=2):
    cfg = dataclasses.replace(get_method(method).with_steps(steps), data=data, output_dir=out, steps_per_eval_image=0, progress=False,
                              timestamp="run")
    t = Trainer(cfg)
    t.setup()
    return t, t.train()


@pytest.mark.parametrize("appearance", ["mean", "nearest"])
def test_streetnerf_reference_renders_with_the_chosen_appearance(tiny_scene, tmp_path, appearance):
    tgt, _ = _train("voxel-grid", tiny_scene, tmp_path / "tgt", steps=1)
    _, ref_dir = _train("streetnerf", tiny_scene, tmp_path / "ref")
    ref = load_reference(ref_dir, tgt.pipeline.datamanager, "cpu", appearance)
    model = ref.render.func.__self__
    n = model.num_train_images
    with torch.no_grad():  # distinct transforms, so the modes differ
        model.appearance.transforms.copy_(torch.stack([torch.eye(3, 4) * (0.6 + 0.8 * k / n) for k in range(n)]))
    cam = tgt.pipeline.datamanager.train_data.cameras[1:2]
    ours = ref.render(cam)["rgb"]
    torch.testing.assert_close(ours, model.render_camera(cam, appearance=appearance)["rgb"], atol=0, rtol=0)
    other = "mean" if appearance == "nearest" else "nearest"
    assert not torch.allclose(ours, model.render_camera(cam, appearance=other)["rgb"], atol=1e-3)


def test_a_reference_without_appearance_ignores_the_option(tiny_scene, tmp_path):
    tgt, _ = _train("voxel-grid", tiny_scene, tmp_path / "tgt", steps=1)
    _, ref_dir = _train("voxel-grid", tiny_scene, tmp_path / "ref")
    ref = load_reference(ref_dir, tgt.pipeline.datamanager, "cpu", "nearest")
    cam = tgt.pipeline.datamanager.train_data.cameras[0:1]
    torch.testing.assert_close(ref.render(cam)["rgb"], ref.render.__self__.render_camera(cam)["rgb"])


def test_a_reference_rendering_with_fewer_samples_keys_its_views_apart(tiny_scene, tmp_path):
    """The view store keys a reference's renders by its checkpoint and, when renders sample otherwise
    than training (render_nerf_samples), by that too: renders made either way are never mixed up."""
    tgt, _ = _train("voxel-grid", tiny_scene, tmp_path / "tgt", steps=1)
    _, ref_dir = _train("streetnerf", tiny_scene, tmp_path / "ref")
    every = load_reference(ref_dir, tgt.pipeline.datamanager, "cpu")
    yml = ref_dir / "config.yml"
    text = yml.read_text()
    assert text.count("render_nerf_samples: null") == 1
    yml.write_text(text.replace("render_nerf_samples: null", "render_nerf_samples: 16"))
    fewer = load_reference(ref_dir, tgt.pipeline.datamanager, "cpu")
    assert fewer.key == every.key + ":fine16" and ":" in every.key
