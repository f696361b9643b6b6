"""The enhancer prior: generated streets -> references -> (render, truth) pairs -> a prior that
``train --init`` fine-tunes; evaluation streets are refused; the pairs pair a render with its truth."""

import json

import pytest
import torch

from nerf2gs_plugin.enhancer.pretrain import EnhancerPretrainConfig, RESERVED_SEEDS, pretrain_enhancer, street_settings
from nerf2gs_plugin.enhancer.train import EnhancerTrainConfig, fit_network, load_prior, report_path, save_prior, train_enhancer
from nerf2gs_plugin.enhancer.unet import ResidualUNet
from nerf2gs_plugin.errors import ConfigError, DataError

TINY = dict(width=64, height=40, num_bev=3, reference_steps=30, steps=12, crop=32, batch_size=2, checkpoints=2, progress=False)


def test_street_settings_vary_by_seed_and_refuse_evaluation_streets():
    a, b = street_settings(101, 200, 112, 24), street_settings(102, 200, 112, 24)
    assert a == street_settings(101, 200, 112, 24) and a != b
    assert {k: a[k] for k in ("width", "height", "num_bev")} == {"width": 200, "height": 112, "num_bev": 24}
    for s in RESERVED_SEEDS:
        with pytest.raises(ConfigError, match="reserved"):
            street_settings(s, 200, 112, 24)


@pytest.fixture(scope="module")
def prior(tmp_path_factory):
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("prior")
    cfg = EnhancerPretrainConfig(out=root / "prior.onnx", work=root / "streets", seeds=(101, 102), **TINY)
    return cfg, pretrain_enhancer(cfg)


def test_pretrain_writes_prior_report_and_reuses_streets(prior, monkeypatch):
    from nerf2gs_plugin.enhancer import pretrain

    cfg, report = prior
    assert cfg.out.is_file() and cfg.out.with_suffix(".pt").is_file() and report_path(cfg.out).is_file()
    saved = json.loads(report_path(cfg.out).read_text())
    # every eval camera of each street is a pair (street 8 + bev_1 3 + bev_2 3 + val_street 6 + val_bev 8 views)
    assert [s["pairs"] for s in saved["streets"]] == [28, 28] and [s["held_out"] for s in saved["streets"]] == [False, True]
    assert saved["validation"][0]["step"] == 0 and saved["selected_step"] in {v["step"] for v in saved["validation"]}
    net = ResidualUNet(cfg.net_width)
    assert load_prior(net, cfg.out.with_suffix(".pt"))["seeds"] == [101, 102]
    # a second pre-training reuses the streets, references and rendered pairs: nothing is generated, trained or rendered
    for name in ("generate_street",):
        monkeypatch.setattr("nerf2gs_plugin.data.synthetic_street." + name, lambda *a, **k: pytest.fail("regenerated"))
    monkeypatch.setattr(pretrain, "street_pairs", lambda *a, **k: pytest.fail("rendered again"))
    monkeypatch.setattr("nerf2gs_plugin.engine.trainer.Trainer.train", lambda self: pytest.fail("retrained"))
    again = pretrain_enhancer(cfg.__class__(**{**cfg.__dict__, "out": cfg.out.with_name("again.onnx")}))
    assert [s["pairs"] for s in again.streets] == [28, 28]


def test_street_pairs_are_the_reference_render_and_the_truth(prior):
    from nerf2gs_plugin.enhancer.pretrain import street_pairs
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.utils.image_metrics import psnr

    cfg, _ = prior
    data, run = cfg.work / "street-101", cfg.work / "street-101-streetnerf"
    pairs = street_pairs(data, run, 0, progress=False)
    loaded = load_run(run, data=data)
    _, bev = loaded.pipeline.datamanager.eval_split("bev_1")
    q = next(p for p in pairs if p.kind == "bev_1")
    assert torch.equal(q.target, bev.image(0).permute(2, 0, 1).float().cpu())
    with torch.no_grad():
        render = loaded.model.render_camera(bev.cameras[0])["rgb"].permute(2, 0, 1).cpu()
    assert torch.allclose(q.render, render, atol=1e-5)
    assert 5.0 < float(psnr(q.render, q.target)) < 60.0  # a render of the truth's view, not the truth itself


def test_train_init_fine_tunes_the_prior_and_checks_it(prior, tiny_scene, tmp_path):
    cfg, _ = prior
    weights = cfg.out.with_suffix(".pt")
    out = tmp_path / "ft.onnx"
    report = train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=out, steps=2, batch_size=2, crop=16, progress=False,
                                                eval_splits=("street",), init=weights))
    # step 0 is the prior, not the identity: its held-out score differs from an untrained network's
    ident = train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=tmp_path / "id.onnx", steps=2, batch_size=2, crop=16,
                                               progress=False, eval_splits=("street",)))
    assert report.validation[0]["psnr"] != pytest.approx(ident.validation[0]["psnr"], abs=1e-6)
    assert "prior PSNR" in report.summary_lines()[1]
    with pytest.raises(ConfigError, match="width"):
        train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=tmp_path / "w.onnx", steps=2, width=8, progress=False, init=weights))
    with pytest.raises(DataError, match="does not exist"):
        load_prior(ResidualUNet(16), tmp_path / "absent.pt")
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(DataError, match="bad.pt.*not an enhancer prior|not an enhancer prior"):
        load_prior(ResidualUNet(16), bad)


def test_fit_network_learns_a_correction_and_keeps_the_best_state(tmp_path):
    """A constant colour shift is learnt; the selected state is the best-scoring one, and save/load round-trips it."""
    from nerf2gs_plugin.enhancer.train import _Validator

    gen = torch.Generator().manual_seed(0)
    truth = torch.rand(4, 3, 16, 16, generator=gen)
    shifted = (truth * 0.7 + 0.1).clamp(0, 1)
    validate = _Validator([(shifted[3], truth[3], torch.ones(1, 16, 16), None)], None)
    net = ResidualUNet(8)
    batch = lambda: (shifted[:3], truth[:3], torch.ones(3, 1, 16, 16), None)  # noqa: E731
    losses, history, best = fit_network(net, batch, validate, None, 200, 3e-3, 4, False, "fit")
    assert losses[-1] < 0.5 * losses[0] and history[0]["step"] == 0
    assert best == max(history, key=lambda v: v["score"])["step"] and best > 0
    assert validate(net)["psnr"] == pytest.approx(history[[v["step"] for v in history].index(best)]["psnr"], abs=1e-4)
    save_prior(net, tmp_path / "p.pt", {"seeds": [1]})
    other = ResidualUNet(8)
    load_prior(other, tmp_path / "p.pt")
    x = torch.rand(1, 3, 16, 16)
    assert torch.equal(net(x), other(x))
