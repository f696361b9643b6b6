"""The bench's enhancer is trained on the bench's own StreetNeRF run (its real renders)."""

from pathlib import Path

from nerf2gs_plugin.cli import bench as bench_cli


def test_bench_enhancer_trains_on_the_bench_reference(tiny_scene, tmp_path, monkeypatch):
    import nerf2gs_plugin.enhance.bench as enh
    import nerf2gs_plugin.eval.bench_runs as runs

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
    bench_cli.bench_enhancer(tiny_scene, tmp_path, "quick", prior=tmp_path / "prior.pt")  # --enhancer-prior reaches the trainer
    assert calls["init"] == tmp_path / "prior.pt"
    # the same run the paper table's plan trains (same label, method and overrides)
    from nerf2gs_plugin.eval.bench_paper import paper_table_plan

    assert paper_table_plan("quick", ("splatfacto",))[0] == calls["spec"]
