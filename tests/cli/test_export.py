"""ns2gs-export: a trained Splatfacto run -> standard 3DGS PLY that reads back to the model's Gaussians."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "methods" / "splatfacto"))
from splat_tiny_scene import needs_rasterizer, write_dataset  # noqa: E402

from nerf2gs_plugin.cli.export import ExportArgs, export  # noqa: E402
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_plugin.engine.trainer import Trainer  # noqa: E402
from nerf2gs_plugin.methods.gaussian_utils import read_gaussian_ply
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


def _parse_ply(path: Path) -> np.ndarray:
    """A minimal binary little-endian PLY reader of float properties (independent of the package)."""
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    names = [line.split()[-1] for line in raw[:end].decode().splitlines() if line.startswith("property float ")]
    return np.frombuffer(raw[end:], dtype=[(n, "<f4") for n in names])


def test_export_ply_holds_the_checkpoint_parameters_in_3dgs_layout(run_dir, tmp_path):
    """Expected values from the checkpoint's raw parameters and the 3DGS file layout (log scales,
    logit opacity, unit wxyz quaternions, SH rest channel-major), not from the exporter's own code."""
    out = export(ExportArgs(run=run_dir, output=tmp_path / "s.ply", background=False))  # the model's own Gaussians only
    ply = _parse_ply(out)
    ckpt = sorted((run_dir / "checkpoints").glob("*.ckpt"))[-1]
    state = {k.split("gauss.", 1)[1]: v.numpy() for k, v in torch.load(ckpt, map_location="cpu", weights_only=False)["model"].items()
             if "gauss." in k}
    n = state["means"].shape[0]
    assert len(ply) == n > 0
    np.testing.assert_allclose(np.stack([ply["x"], ply["y"], ply["z"]], 1), state["means"], atol=1e-6)
    np.testing.assert_allclose(np.stack([ply[f"scale_{i}"] for i in range(3)], 1), state["scales"], atol=1e-6)
    np.testing.assert_allclose(ply["opacity"], state["opacities"].reshape(n), atol=1e-6)
    q = state["quats"] / np.linalg.norm(state["quats"], axis=1, keepdims=True)
    np.testing.assert_allclose(np.stack([ply[f"rot_{i}"] for i in range(4)], 1), q, atol=1e-6)
    np.testing.assert_allclose(np.stack([ply[f"f_dc_{i}"] for i in range(3)], 1), state["features_dc"].reshape(n, 3), atol=1e-6)
    rest = state["features_rest"]  # [N, 15, 3]: f_rest_{c * 15 + k} = rest[:, k, c]
    for c in range(3):
        for k in (0, 7, 14):
            np.testing.assert_allclose(ply[f"f_rest_{c * 15 + k}"], rest[:, k, c], atol=1e-6)
    assert not any(name.startswith("f_rest_45") for name in ply.dtype.names)


def test_export_default_path_and_bad_run(run_dir, tmp_path):
    out = export(ExportArgs(run=run_dir))
    assert out == run_dir / "export" / "splat.ply" and out.is_file()
    proc = subprocess.run([sys.executable, "-m", "nerf2gs_plugin.cli.export", str(tmp_path / "nope")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stderr.startswith("error:")
