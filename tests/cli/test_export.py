"""ns2gs-export: a trained Splatfacto run -> standard 3DGS PLY that reads back to the model's Gaussians."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "methods" / "splatfacto"))
from splat_tiny_scene import needs_rasterizer, write_dataset  # noqa: E402

from nerf2gs_plugin.cli.export import ExportArgs, export  # noqa: E402
from nerf2gs_plugin.engine.reference import load_run  # noqa: E402
from nerf2gs_plugin.engine.trainer import Trainer  # noqa: E402
from nerf2gs_plugin.methods.gaussian_utils import read_gaussian_ply  # noqa: E402
from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_method  # noqa: E402


pytestmark = needs_rasterizer


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("export")
    data = write_dataset(root / "data")
    base = splatfacto_method.config
    strategy = dataclasses.replace(base.pipeline.model.strategy, warmup_length=5, refine_every=5, stop_screen_size_at=0)
    model = dataclasses.replace(base.pipeline.model, strategy=strategy)
    cfg = dataclasses.replace(base, data=data, output_dir=root / "out", max_num_iterations=12, steps_per_save=100,
                              steps_per_eval_image=0, progress=False, optimizers=gaussian_optimizers(12),
                              pipeline=dataclasses.replace(base.pipeline, model=model))
    trainer = Trainer(cfg)
    trainer.setup()
    return trainer.train()


def test_export_ply_round_trip(run_dir, tmp_path):
    out = export(ExportArgs(run=run_dir, output=tmp_path / "s.ply", background=False))
    back = read_gaussian_ply(out)
    model = load_run(run_dir).model
    ref = model.export_gaussians()
    assert back["means"].shape[0] == model.num_primitives()
    for key, value in ref.items():
        assert torch.allclose(back[key], value.float().cpu(), atol=1e-6), key
    assert back["features_rest"].shape[1] == 15  # SH degree 3


def test_export_default_path_and_bad_run(run_dir, tmp_path):
    out = export(ExportArgs(run=run_dir))
    assert out == run_dir / "export" / "splat.ply" and out.is_file()
    proc = subprocess.run([sys.executable, "-m", "nerf2gs_plugin.cli.export", str(tmp_path / "nope")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stderr.startswith("error:")
