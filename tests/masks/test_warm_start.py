"""StreetNeRF warm-started from the masks' first reference (``--warm-start``): taken when the
reference is the same model on the same frames, refused with the difference named otherwise."""

from __future__ import annotations

import dataclasses
import json
import shutil

import pytest
import torch

from nerf2gs_plugin.data.synthetic_street import generate_street
from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.engine.warm_start import config_difference
from nerf2gs_plugin.errors import CheckpointError, ConfigError
from nerf2gs_plugin.masking.mask_reference import ensure_reference
from nerf2gs_plugin.registry import get_method
from street_fixtures import small_config

REF_STEPS = 6


@pytest.fixture(scope="module")
def street_and_reference(small_street, tmp_path_factory):
    data = tmp_path_factory.mktemp("warm") / "street"
    shutil.copytree(small_street, data, ignore=shutil.ignore_patterns(".ns2gs_cache", ".ns2gs_maskless"))
    ref = ensure_reference(data, data.parent / "reference", steps=REF_STEPS, progress=False, log=lambda s: None)
    return data, ref


def _streetnerf(data, run_dir, steps=REF_STEPS + 4, **kw):
    cfg = get_method("streetnerf").with_steps(steps)
    return dataclasses.replace(cfg, data=data, run_dir=run_dir, steps_per_eval_image=0, progress=False, **kw)


def test_warm_start_continues_the_reference(street_and_reference, tmp_path):
    data, ref = street_and_reference
    trainer = Trainer(_streetnerf(data, tmp_path / "sn", warm_start=ref))
    trainer.setup()
    ckpt = load_checkpoint(list_checkpoints(ref)[-1])
    assert trainer.step == int(ckpt["step"]) + 1 == REF_STEPS
    state = trainer.pipeline.model.state_dict()
    assert all(torch.equal(state[k].cpu(), v.cpu()) for k, v in ckpt["model"].items())
    run = trainer.train()
    assert int(load_checkpoint(list_checkpoints(run)[-1])["step"]) == REF_STEPS + 3
    assert json.loads((run / "warm_start.json").read_text())["step"] == REF_STEPS - 1
    # the reference's own loss weights differ (its loose appearance regularisation): that is allowed
    from nerf2gs_plugin.engine.config import read_config_doc

    ref_weight = read_config_doc(ref / "config.yml")["config"]["pipeline"]["model"]["appearance_reg_weight"]
    assert ref_weight != trainer.config.pipeline.model.appearance_reg_weight


def test_warm_start_refused_on_other_frames(street_and_reference, tmp_path):
    data, ref = street_and_reference
    other = tmp_path / "other"
    generate_street(small_config(other, seed=5))
    with pytest.raises(CheckpointError, match="warm-start refused: it was trained on other images"):
        Trainer(_streetnerf(other, tmp_path / "sn", warm_start=ref)).setup()


def test_warm_start_refused_on_another_downscale_model_or_length(street_and_reference, tmp_path):
    data, ref = street_and_reference
    cfg = _streetnerf(data, tmp_path / "a", warm_start=ref)
    dm = dataclasses.replace(cfg.pipeline.datamanager, dataparser=dataclasses.replace(cfg.pipeline.datamanager.dataparser, downscale=2.0))
    with pytest.raises(CheckpointError, match="another size"):
        Trainer(dataclasses.replace(cfg, pipeline=dataclasses.replace(cfg.pipeline, datamanager=dm))).setup()
    model = dataclasses.replace(cfg.pipeline.model, num_levels=8)
    with pytest.raises(CheckpointError, match=r"pipeline\.model\.num_levels"):
        Trainer(dataclasses.replace(cfg, run_dir=tmp_path / "b", pipeline=dataclasses.replace(cfg.pipeline, model=model))).setup()
    with pytest.raises(CheckpointError, match="nothing left to train"):
        Trainer(_streetnerf(data, tmp_path / "c", steps=REF_STEPS, warm_start=ref)).setup()
    with pytest.raises(CheckpointError, match="is a 'streetnerf' run"):
        cfg2 = get_method("splatfacto").with_steps(20)
        Trainer(dataclasses.replace(cfg2, data=data, run_dir=tmp_path / "d", progress=False, warm_start=ref)).setup()


def test_warm_start_and_resume_exclude_each_other(street_and_reference, tmp_path):
    data, ref = street_and_reference
    with pytest.raises(ConfigError, match="pass one of them"):
        Trainer(_streetnerf(data, tmp_path / "sn", warm_start=ref, load_checkpoint=ref))


def test_config_difference_ignores_loss_weights_and_render_settings():
    a = {"num_levels": 12, "sky_weight": 0.1, "eval_chunk": 4096, "proposal": {"levels": [5, 5]}}
    assert config_difference(a, {**a, "sky_weight": 0.0, "eval_chunk": 512}) is None
    assert config_difference(a, {**a, "proposal": {"levels": (5, 5)}}) is None
    assert "proposal.levels" in config_difference(a, {**a, "proposal": {"levels": [5, 6]}})
    assert "num_levels" in config_difference(a, {k: v for k, v in a.items() if k != "num_levels"})
    # a run saved before the render-time sample count existed continues under today's config
    assert config_difference(a, {**a, "render_nerf_samples": None}) is None
