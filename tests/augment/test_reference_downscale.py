"""A reference trained at another ``downscale`` is accepted and renders at the target's resolution."""

import dataclasses

import pytest

from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.errors import CheckpointError
from nerf2gs_plugin.registry import get_method


def _train(data, out, downscale, steps=2, **kw):
    base = get_method("voxel-grid").config
    dm = base.pipeline.datamanager
    dm = dataclasses.replace(dm, dataparser=dataclasses.replace(dm.dataparser, downscale=downscale))
    pipe = dataclasses.replace(base.pipeline, datamanager=dm)
    cfg = dataclasses.replace(base, data=data, output_dir=out, max_num_iterations=steps, steps_per_eval_image=0, progress=False,
                              timestamp="run", pipeline=pipe, **kw)
    t = Trainer(cfg)
    t.setup()
    return t, t.train()


def test_reference_at_other_downscale(tiny_scene, tmp_path):
    from nerf2gs_plugin.augment.datamanager import AugmentConfig
    from tiny_scene import write_tiny_scene

    _, ref = _train(tiny_scene, tmp_path / "ref", downscale=2.0)
    aug = AugmentConfig(delta_h=1.0, composites=False, min_coverage=0.0, view_downscale=1)  # a 2-step reference sees little
    t, _ = _train(tiny_scene, tmp_path / "tgt", downscale=1.0, augment_from=ref, augment=aug)
    dm = t.pipeline.datamanager
    extra = dm.views.extra
    assert extra is not None
    w = int(dm.train_images.cameras.width[0])
    assert int(extra.cameras.width[0]) == w and extra.image(0).shape[1] == w  # the target's resolution
    other = write_tiny_scene(tmp_path / "other", n_train=6)
    with pytest.raises(CheckpointError, match="different dataset"):  # another dataset is still refused
        _train(other, tmp_path / "t2", downscale=1.0, augment_from=ref, augment=aug)
