"""The built-in enhancer: training lowers the loss, the exported ONNX improves held-out PSNR;
CLI front ends; the bench's train-once helper."""

import json
import sys

import pytest
import torch

from nerf2gs_plugin.enhancer import make_enhancer
from nerf2gs_plugin.enhancer.degrade import KINDS, degrade
from nerf2gs_plugin.enhancer.train import EnhancerTrainConfig, heldout_psnr, load_split_images, report_path, train_enhancer
from nerf2gs_plugin.errors import ConfigError


def test_degradations_change_images_and_are_seeded():
    img = torch.rand(2, 3, 24, 32)
    for kind in KINDS:
        out = degrade(img, torch.Generator().manual_seed(1), (kind,))
        assert out.shape == img.shape and (out - img).abs().mean() > 1e-3, kind
        assert torch.equal(out, degrade(img, torch.Generator().manual_seed(1), (kind,)))
    clean = torch.rand(32, 3, 16, 16)
    mix = degrade(clean, torch.Generator().manual_seed(2), KINDS)
    assert ((mix - clean).abs().flatten(1).amax(1) > 1e-3).all()  # every sample is degraded somehow
    with pytest.raises(ValueError, match="unknown"):
        degrade(img, torch.Generator(), ("jpeg",))


def test_train_lowers_loss_and_improves_heldout_psnr(tiny_scene, tmp_path):
    out = tmp_path / "enh" / "enhancer.onnx"
    cfg = EnhancerTrainConfig(data=tiny_scene, out=out, steps=150, batch_size=8, crop=24, lr=3e-3, degradations=("noise",), progress=False)
    report = train_enhancer(cfg)
    assert out.is_file() and report_path(out).is_file()
    saved = json.loads(report_path(out).read_text())
    assert saved["steps"] == 150 and saved["heldout"]["splits"] == ["street", "bev_1"]
    first, last = sum(report.losses[:5]) / 5, sum(report.losses[-5:]) / 5
    assert last < 0.85 * first, (first, last)
    # checkpoint selection on the held-out training image (every 8th): the identity (step 0) is a
    # candidate, and the exported state is the best-scoring one
    scores = {v["step"]: v["score"] for v in report.validation}
    assert report.validation[0]["step"] == 0 and len(scores) == 11 and report.selected_step == max(scores, key=scores.get)
    assert scores[report.selected_step] > scores[0] + 1.0  # denoising a held-out image beats leaving it noisy
    # held-out eval-split images, never seen in training, degraded the same way (fixed seed):
    h = report.heldout
    assert h["images"] == 4 and h["psnr_enhanced"] > h["psnr_degraded"] + 1.0, h
    # the same file through the public spec, independently of the trainer's own measurement
    enh = make_enhancer(f"builtin:{out}")
    imgs, _ = load_split_images(tiny_scene, "bev_1")
    again = heldout_psnr(enh.enhance, imgs, ("noise",), 1.0, seed=123)
    assert again["psnr_enhanced"] > again["psnr_degraded"] + 1.0, again


def test_conditioned_model_exports_two_inputs(tiny_scene, tmp_path):
    out = tmp_path / "cond.onnx"
    train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=out, steps=3, batch_size=2, crop=16, condition="view", progress=False,
                                       eval_splits=("street",)))
    enh = make_enhancer(f"onnx:{out}")
    assert enh.runtime.reference_name == "reference" and enh.runtime.multiple == 4
    img = torch.rand(22, 30, 3)  # not a multiple of 4: padded and cropped back
    assert enh.enhance(img, reference=torch.rand(24, 32, 3)).shape == img.shape


def test_bad_training_config(tiny_scene, tmp_path):
    with pytest.raises(ConfigError, match="degradations"):
        train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=tmp_path / "x.onnx", steps=2, degradations=("jpeg",), progress=False))


def test_cli_train_apply_eval(tiny_scene, tmp_path, monkeypatch, capsys):
    from nerf2gs_plugin.cli import enhance as cli
    from nerf2gs_plugin.data.images import load_image

    model = tmp_path / "m.onnx"
    monkeypatch.setattr(sys, "argv", ["ns2gs-enhance", "train", "--data", str(tiny_scene), "--out", str(model), "--steps", "4",
                                      "--batch-size", "2", "--crop", "16", "--no-progress"])
    cli.entrypoint()
    assert model.is_file() and "enhancer saved" in capsys.readouterr().out
    src = tiny_scene / "images" / "bev_1_000.png"
    monkeypatch.setattr(sys, "argv", ["ns2gs-enhance", "apply", "--model", str(model), "--input", str(src), "--output", str(tmp_path / "o")])
    cli.entrypoint()
    assert load_image(tmp_path / "o" / src.name).shape == load_image(src).shape
    monkeypatch.setattr(sys, "argv", ["ns2gs-enhance", "apply", "--model", f"builtin:{model}", "--input", str(src), "--output",
                                      str(tmp_path / "tiled.png"), "--tile-size", "16"])
    cli.entrypoint()
    assert (load_image(tmp_path / "tiled.png") - load_image(tmp_path / "o" / src.name)).abs().max() < 3 / 255
    monkeypatch.setattr(sys, "argv", ["ns2gs-enhance", "eval", "--model", str(model), "--data", str(tiny_scene), "--out", str(tmp_path / "e.json")])
    cli.entrypoint()
    res = json.loads((tmp_path / "e.json").read_text())
    assert set(res["splits"]) == {"street", "bev_1"} and res["splits"]["street"]["images"] == 2
    monkeypatch.setattr(sys, "argv", ["ns2gs-enhance", "apply", "--model", str(tmp_path / "absent.onnx"), "--input", str(src), "--output", str(tmp_path)])
    with pytest.raises(SystemExit) as e:
        cli.entrypoint()
    assert e.value.code == 2 and "absent.onnx" in capsys.readouterr().err


def test_bench_enhancer_trains_once(tiny_scene, tmp_path, monkeypatch):
    from nerf2gs_bench import enhancer as bench

    monkeypatch.setitem(bench.SCALES, "quick", {"steps": 3, "batch_size": 2, "crop": 16})
    calls = []
    real = bench.train_enhancer
    monkeypatch.setattr(bench, "train_enhancer", lambda cfg: calls.append(cfg) or real(cfg))
    p1 = bench.ensure_bench_enhancer(tiny_scene, tmp_path, "quick")
    p2 = bench.ensure_bench_enhancer(tiny_scene, tmp_path, "quick")
    assert p1 == p2 and p1.is_file() and p1.suffix == ".onnx" and len(calls) == 1
    with pytest.raises(ConfigError, match="scale"):
        bench.ensure_bench_enhancer(tiny_scene, tmp_path, "huge")


def test_report_summary_names_what_each_number_is_measured_on():
    from nerf2gs_plugin.enhancer.train import TrainReport

    report = TrainReport("m.onnx", 40, 3.0, losses=[0.2, 0.1], threads=2, selected_step=20,
                         validation=[{"step": 0, "psnr": 25.0, "lpips": None}, {"step": 20, "psnr": 25.4, "lpips": 0.1},
                                     {"step": 40, "psnr": 25.2, "lpips": 0.12}],
                         heldout={"psnr_degraded": 20.0, "psnr_enhanced": 22.0, "images": 4, "splits": ["bev_1"]})
    lines = report.summary_lines()
    assert "loss 0.2000 -> 0.1000" in lines[0]
    assert "identity PSNR 25.00 dB; exported step 20: PSNR 25.40 dB, LPIPS 0.1000" in lines[1]
    assert "synthetic degradations" in lines[2] and "20.00 -> 22.00" in lines[2]
    assert len(TrainReport("m.onnx", 0, 0.0).summary_lines()) == 1
