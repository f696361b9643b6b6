"""Splatfacto through the real Trainer: a densified checkpoint resumes and reloads for eval."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from splat_tiny_scene import needs_rasterizer, write_dataset

from nerf2gs_plugin.engine.checkpoints import list_checkpoints
from nerf2gs_plugin.runs.load import load_run
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_method
from nerf2gs_plugin.rendering.backend import gsplat_available


pytestmark = needs_rasterizer

def _config(data, out, steps, **model_kw):
    base = splatfacto_method.config
    strategy = dataclasses.replace(base.pipeline.model.strategy, warmup_length=3, refine_every=3, stop_screen_size_at=0)
    model = dataclasses.replace(base.pipeline.model, strategy=strategy, **model_kw)
    return dataclasses.replace(base, data=data, output_dir=out, max_num_iterations=steps, steps_per_save=6,
                               steps_per_eval_image=0, progress=False, keep_all_checkpoints=True, timestamp="run",
                               optimizers=gaussian_optimizers(steps), pipeline=dataclasses.replace(base.pipeline, model=model))


def test_resume_densified_checkpoint_and_eval(tmp_path):
    data = write_dataset(tmp_path / "data")
    trainer = Trainer(_config(data, tmp_path / "out", 8))
    trainer.setup()
    n0 = trainer.pipeline.model.num_primitives()
    run_dir = trainer.train()
    n1 = trainer.pipeline.model.num_primitives()
    assert n1 != n0
    first = list_checkpoints(run_dir)[0]  # step 5, after a refinement
    resumed = Trainer(dataclasses.replace(_config(data, tmp_path / "out", 10), load_checkpoint=first, timestamp="resumed"))
    resumed.setup()
    assert resumed.step == 6 and resumed.pipeline.model.strategy.count is not None
    resumed.train()  # optimizer moments of the densified parameters load and step
    loaded = load_run(run_dir)
    assert loaded.model.num_primitives() == n1
    cam = loaded.pipeline.datamanager.train_images.cameras[0]
    a = loaded.model.render_camera(cam)["rgb"]
    b = trainer.pipeline.model.eval().render_camera(cam)["rgb"]
    # on a GPU the run trained through gsplat and reloads onto the CPU kernel: same image, not same bits
    atol = 1e-6 if a.device == b.device else 1e-4
    assert torch.allclose(a.cpu(), b.cpu(), atol=atol)


def test_a_run_resumed_between_refinements_densifies_as_one_never_stopped(tmp_path):
    """The checkpoint carries the densification statistics: resumed at step 5 (accumulated since the
    refinement at step 3), the refinement at step 6 decides on steps 4-6 as in the run never
    stopped, so both end with the same Gaussians (they used to decide on step 6 alone)."""
    data = write_dataset(tmp_path / "data")
    # on the CPU kernels: gsplat's backward sums with atomics, so on a GPU even two runs never stopped differ
    whole = Trainer(dataclasses.replace(_config(data, tmp_path / "out", 12), device="cpu"))
    whole.setup()
    run_dir = whole.train()
    first = list_checkpoints(run_dir)[0]
    assert "training_state" in torch.load(first, weights_only=True)
    resumed = Trainer(dataclasses.replace(_config(data, tmp_path / "out", 12), load_checkpoint=first, timestamp="resumed",
                                          device="cpu"))
    resumed.setup()
    assert resumed.step == 6 and resumed.pipeline.model.strategy.count is not None
    resumed.train()
    a, b = whole.pipeline.model.gauss, resumed.pipeline.model.gauss
    assert a["means"].shape == b["means"].shape
    for k in a:
        assert torch.allclose(a[k], b[k], atol=1e-5), k


def _train_psnr(trainer: Trainer) -> float:
    images = trainer.pipeline.datamanager.train_images
    model = trainer.pipeline.model.eval()
    with torch.no_grad():
        mse = [float(((model.render_camera(images.cameras[i])["rgb"].cpu() - images.image(i).cpu()) ** 2).mean())
               for i in range(len(images))]
    model.train()
    return -10.0 * float(torch.log10(torch.tensor(sum(mse) / len(mse))))


@pytest.mark.skipif(not gsplat_available(), reason="needs CUDA and gsplat")
def test_trains_on_cuda_through_gsplat(tmp_path):
    """The same Trainer on a GPU: every render goes through gsplat and PSNR rises as on the CPU."""
    data = write_dataset(tmp_path / "data")
    trainer = Trainer(dataclasses.replace(_config(data, tmp_path / "out", 60), device="cuda"))
    trainer.setup()
    p0 = _train_psnr(trainer)
    trainer.train()
    model = trainer.pipeline.model
    assert next(model.parameters()).device.type == "cuda"
    model.get_outputs(trainer.pipeline.datamanager.train_images.cameras[0])  # a training render keeps its meta
    assert model._meta["backend"] == "gsplat"
    assert _train_psnr(trainer) > p0 + 1.0


def test_weight_prune_reads_the_training_views_through_the_trainer(tmp_path):
    """strategy.prune_weight_fraction in a real run: the model renders the data manager's training
    views once after densification and ends with fewer Gaussians than the same run without it."""
    data = write_dataset(tmp_path / "data")
    counts, prunes = {}, {}
    for fraction, margin in ((0.0, 0.0), (0.3, 0.0), (0.3, 60.0)):
        cfg = _config(data, tmp_path / f"out{fraction}-{margin}", 12)
        model = cfg.pipeline.model
        strategy = dataclasses.replace(model.strategy, stop_split_at=9, prune_weight_fraction=fraction, prune_margin_db=margin)
        cfg = dataclasses.replace(cfg, pipeline=dataclasses.replace(cfg.pipeline, model=dataclasses.replace(model, strategy=strategy)))
        torch.manual_seed(0)
        trainer = Trainer(cfg)
        trainer.setup()
        trainer.train()
        counts[fraction, margin] = trainer.pipeline.model.num_primitives()
        prunes[fraction, margin] = trainer.pipeline.model.strategy.weight_prunes
        weights = trainer.pipeline.model.training_blend_weights()
        assert weights is not None and weights.shape == (counts[fraction, margin],)
    assert counts[0.3, 0.0] < 0.9 * counts[0.0, 0.0], counts
    # a margin no prune can keep (the renders' change 60 dB below the model's error): nothing pruned, both measured
    assert counts[0.3, 60.0] == counts[0.0, 0.0], counts
    record = prunes[0.3, 60.0][-1]
    assert record["pruned"] == 0 and 0 < record["error_db"] < record["change_db"] < 100, record
