"""The bench's enhancer is trained on the bench's own StreetNeRF run (its real renders)."""

from pathlib import Path

from nerf2gs_bench import cli as bench_cli


def test_bench_enhancer_trains_on_the_bench_reference(tiny_scene, tmp_path, monkeypatch):
    import nerf2gs_bench.enhancer as enh
    import nerf2gs_bench.runs as runs

    calls = {}

    def fake_train_or_reuse(spec, data, runs_root, dataset, *a, **k):
        calls["spec"] = spec
        return Path(runs_root) / "street" / "streetnerf" / "abc", "abc"

    def fake_ensure(data, runs_root, scale, reference=None, init=None):
        calls["reference"], calls["init"] = reference, init
        return Path(runs_root) / "enhancer.onnx"

    monkeypatch.setattr(runs, "train_or_reuse", fake_train_or_reuse)
    monkeypatch.setattr(enh, "ensure_bench_enhancer", fake_ensure)
    spec = bench_cli.bench_enhancer(tiny_scene, tmp_path, "quick")
    assert spec == f"onnx:{tmp_path / 'enhancer.onnx'}"
    assert calls["spec"].method == "streetnerf" and calls["spec"].label == "StreetNeRF"
    assert calls["reference"] == tmp_path / "street" / "streetnerf" / "abc" and calls["init"] is None
    # --enhancer-prior: the prior as it is (copied under the runs, keyed by its content; nothing trained) ...
    prior = tmp_path / "made" / "prior.onnx"
    prior.parent.mkdir()
    prior.write_bytes(b"onnx bytes")
    prior.with_suffix(".pt").write_bytes(b"weights")
    calls.clear()
    spec = bench_cli.bench_enhancer(tiny_scene, tmp_path / "runs", "quick", prior=prior)
    copy = Path(spec.split(":", 1)[1])
    assert copy.parent.parent == tmp_path / "runs" / "enhancer" and copy.read_bytes() == b"onnx bytes" and not calls
    # ... or fine-tuned from its weights (--enhancer-fine-tune)
    bench_cli.bench_enhancer(tiny_scene, tmp_path / "runs", "quick", prior=prior, fine_tune=True)
    assert calls["init"] == copy.with_suffix(".pt") and calls["init"].read_bytes() == b"weights"
    import pytest

    from nerf2gs_plugin.errors import ConfigError

    with pytest.raises(ConfigError, match="absent.onnx does not exist"):
        bench_cli.bench_enhancer(tiny_scene, tmp_path / "runs", "quick", prior=tmp_path / "absent.onnx")
    # the same run the paper table's plan trains (same label, method and overrides)
    from nerf2gs_bench.paper import paper_table_plan

    assert paper_table_plan("quick", ("splatfacto",))[0] == calls["spec"]
