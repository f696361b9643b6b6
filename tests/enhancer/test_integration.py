"""The enhancer inside the augmentation (enhanced bird's-eye views, cache keyed by model content)
and the trainer's reference-render pairs from a real (tiny, partially trained) run."""

import dataclasses

import pytest
import torch

from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.enhancer.train import EnhancerTrainConfig, reference_pairs, train_enhancer


class GreyRenderer:
    def __init__(self):
        self.calls = 0

    def __call__(self, camera):
        self.calls += 1
        h, w = int(camera.height[0]), int(camera.width[0])
        return {"rgb": torch.full((h, w, 3), 0.3)}


def _augment(dm, render, key, root, cfg):
    """The AugmentedDataManager over ``dm`` (the enhancer built as the engine builds it); its views."""
    from nerf2gs_plugin.augment.reference import build_enhancer

    return AugmentedDataManager(dm, Reference(render, key, root), cfg, build_enhancer(cfg.enhancer)).views


def _dm(data):
    return FullImageDataManagerConfig().setup(data=data, device="cpu")


def test_enhanced_views_are_cached_per_model_content(tiny_scene, tmp_path):
    import onnx
    from onnx import helper

    # an ONNX model written by hand: y = 1 - x (so the enhanced views are visibly different)
    node = helper.make_node("Sub", ["one", "image"], ["out"])
    graph = helper.make_graph([node], "invert", [helper.make_tensor_value_info("image", onnx.TensorProto.FLOAT, ["b", 3, "h", "w"])],
                              [helper.make_tensor_value_info("out", onnx.TensorProto.FLOAT, ["b", 3, "h", "w"])],
                              [helper.make_tensor("one", onnx.TensorProto.FLOAT, [], [1.0])])
    # IR 9 (what torch's exporter writes at opset 17): older onnxruntime builds refuse newer IR versions
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=9)
    path = tmp_path / "invert.onnx"
    onnx.save(model, str(path))
    cfg = AugmentConfig(composites=False, delta_h=3.0, enhancer=f"onnx:{path}")
    r1 = GreyRenderer()
    views = _augment(_dm(tiny_scene), r1, "ref:x", tmp_path, cfg)
    assert r1.calls > 0 and len(views.extra) == len(views.extra_raw)
    for j in range(len(views.extra)):
        assert (views.extra.image(j) - (1 - views.extra_raw[j])).abs().max() < 1.5 / 255
    r2 = GreyRenderer()
    assert _augment(_dm(tiny_scene), r2, "ref:x", tmp_path, cfg).reused and r2.calls == 0
    # same path, new content: the cache key changes and the views are enhanced again, from the
    # reference's renders kept in the per-view store (the reference is not asked again)
    model.graph.initializer[0].float_data[:] = [0.5]
    onnx.save(model, str(path))
    r3 = GreyRenderer()
    again = _augment(_dm(tiny_scene), r3, "ref:x", tmp_path, cfg)
    assert r3.calls == 0 and not again.reused and again.cache_dir != views.cache_dir
    for j in range(len(again.extra)):
        assert (again.extra.image(j) - (0.5 - again.extra_raw[j]).clamp(0, 1)).abs().max() < 1.5 / 255


def test_reference_pairs_from_a_partially_trained_run(tiny_scene, tmp_path):
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path, max_num_iterations=5,
                              steps_per_eval_image=0, progress=False, timestamp="ref")
    t = Trainer(cfg)
    t.setup()
    run = t.train()
    pairs = reference_pairs([run], tiny_scene, max_renders=3, gen=torch.Generator().manual_seed(0), progress=False)
    assert len(pairs) == 3 and {q.kind for q in pairs} == {"pose"}
    for q in pairs:
        assert q.render.shape == q.target.shape == (3, 24, 32) and q.mask.shape == (1, 24, 32)
        assert (q.render - q.target).abs().mean() > 0.01  # an early reference is visibly off: a real degraded input
        assert (q.mask == 0).any() == (q.index % 2 == 0)  # transient pixels (even images in the tiny scene) leave the loss
    report = train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=tmp_path / "e.onnx", reference=(run,), steps=4, batch_size=4,
                                                crop=16, max_renders=4, progress=False, eval_splits=("street",), holdout_every=2,
                                                checkpoints=2))
    assert report.config["reference"] == [str(run)] and len(report.losses) >= 2
    # pose and perturbed-pose pairs of the 4 rendered non-held-out images; the identity (step 0) and 2 checkpoints scored
    assert report.pairs == {"pose": 4, "perturbed": 4}, report.pairs
    assert [v["step"] for v in report.validation] == [0, 2, 4] and report.selected_step in (0, 2, 4)
    # ns2gs-enhance eval --reference: the run's renders of held-out cameras, before/after enhancement
    from nerf2gs_plugin.cli.enhance import evaluate_enhancer

    res = evaluate_enhancer(f"onnx:{tmp_path / 'e.onnx'}", tiny_scene, run, ("street", "bev_1"))
    assert set(res["splits"]) == {"street", "bev_1"}
    for r in res["splits"].values():
        assert r["images"] == 2 and 0 < r["psnr_before"] < 60 and 0 < r["psnr_after"] < 60
    # before = the reference's own renders, after = the same renders through the exported enhancer,
    # both against the ground truth: recomputed here with numpy
    import numpy as np

    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.enhancer import make_enhancer

    enh = make_enhancer(f"onnx:{tmp_path / 'e.onnx'}")
    loaded = load_run(run, data=tiny_scene)
    dm = loaded.pipeline.datamanager
    centres = dm.train_images.cameras.camera_to_worlds[:, :3, 3]
    mse_psnr = lambda a, b: float(10 * np.log10(1 / np.mean((a.double().numpy() - b.double().numpy()) ** 2)))  # noqa: E731
    changed = False
    for split, r in res["splits"].items():
        _, imgs = dm.eval_split(split)
        before, after = [], []
        with torch.no_grad():
            for i in range(len(imgs)):
                gt = imgs.image(i).cpu()
                render = loaded.model.render_camera(imgs.cameras[i])["rgb"].detach().cpu()
                k = int(torch.cdist(imgs.cameras.camera_to_worlds[i : i + 1, :3, 3], centres).argmin())
                out = enh.enhance(render, reference=dm.train_images.image(k).cpu())
                changed |= bool((out - render).abs().max() > 1e-3)
                before.append(mse_psnr(render.clamp(0, 1), gt))
                after.append(mse_psnr(out.clamp(0, 1), gt))
        assert r["psnr_before"] == pytest.approx(np.mean(before), abs=0.02), split
        assert r["psnr_after"] == pytest.approx(np.mean(after), abs=0.02), split
    # the report compares two different images unless the identity was selected
    assert changed == (report.selected_step != 0)
    if changed:
        assert any(abs(r["psnr_after"] - r["psnr_before"]) > 1e-4 for r in res["splits"].values())
