"""Divergence, run-directory clashes, step arithmetic, disk full, signals."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint, save_checkpoint
from nerf2gs_plugin.engine.optimizers import OptimizerConfig
from nerf2gs_plugin.engine.run_dir import unique_run_dir
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.errors import CheckpointError, ConfigError, TrainingDiverged
from nerf2gs_plugin.registry import get_method

BIN = Path(sys.executable).parent


def _config(data, out, steps=12, **kw):
    cfg = get_method("voxel-grid").config
    kw.setdefault("steps_per_save", 5)
    return dataclasses.replace(cfg, data=data, output_dir=out, max_num_iterations=steps, steps_per_eval_image=0,
                               progress=False, timestamp="run", **kw)


def _cli(*args, timeout=180):
    p = subprocess.run([str(BIN / args[0]), *args[1:]], capture_output=True, text=True, timeout=timeout)
    return p.returncode, p.stderr.strip()


def _assert_kept_checkpoints_render_finite(run_dir: Path):
    from nerf2gs_plugin.runs.load import load_run

    for ckpt in list_checkpoints(run_dir):
        run = load_run(ckpt)  # refuses non-finite parameters
        cams = run.pipeline.datamanager.train_images.cameras
        with torch.no_grad():
            assert torch.isfinite(run.pipeline.model.render_camera(cams[0])["rgb"]).all(), ckpt


# ---------------------------------------------------------------- 1. divergence
def test_splatfacto_huge_lr_never_writes_nonfinite_checkpoint(tiny_scene, tmp_path):
    """lr 1e6 on means/scales: exited 0 with 1146 NaN means in its checkpoint."""
    base = get_method("splatfacto").config
    opts = {k: dataclasses.replace(v, lr=1e6) if k in ("means", "scales") else v for k, v in base.optimizers.items()}
    cfg = dataclasses.replace(base, data=tiny_scene, output_dir=tmp_path, max_num_iterations=12, steps_per_save=3,
                              steps_per_eval_image=0, progress=False, timestamp="run", optimizers=opts)
    trainer = Trainer(cfg)
    trainer.setup()
    with pytest.raises(TrainingDiverged, match="training diverged"):
        trainer.train()
    _assert_kept_checkpoints_render_finite(trainer.run_dir)


def test_streetnerf_huge_lr_keeps_a_checkpoint_that_renders_finite(tiny_scene, tmp_path):
    """lr 1e12: its 'last good checkpoint' (saved after the update that produced the NaN) rendered NaN."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "methods" / "streetnerf"))
    from test_streetnerf import small_model_config

    base = get_method("streetnerf").config
    pipe = dataclasses.replace(base.pipeline, model=small_model_config(),
                               datamanager=dataclasses.replace(base.pipeline.datamanager, rays_per_batch=128))
    opts = {k: dataclasses.replace(v, lr=1e12 if k == "fields" else v.lr) for k, v in base.optimizers.items()}
    cfg = dataclasses.replace(base, data=tiny_scene, output_dir=tmp_path, max_num_iterations=8, steps_per_save=1,
                              steps_per_eval_image=0, progress=False, timestamp="run", optimizers=opts, pipeline=pipe)
    trainer = Trainer(cfg)
    trainer.setup()
    with pytest.raises(TrainingDiverged, match="training diverged"):
        trainer.train()
    _assert_kept_checkpoints_render_finite(trainer.run_dir)


def test_nonfinite_checkpoint_is_refused_by_load_export_and_eval(tiny_scene, tmp_path):
    trainer = Trainer(_config(tiny_scene, tmp_path, steps=2))
    trainer.setup()
    run_dir = trainer.train()
    ckpt = list_checkpoints(run_dir)[-1]
    doc = torch.load(ckpt, weights_only=True)
    doc["model"]["grid"][0, 0] = float("nan")
    save_checkpoint(ckpt, {k: v for k, v in doc.items() if k != "format_version"})
    with pytest.raises(CheckpointError, match="non-finite parameters: grid"):
        load_checkpoint(ckpt)
    for tool in ("ns2gs-export", "ns2gs-eval"):
        code, err = _cli(tool, str(run_dir))
        assert code == 2 and err.startswith("error: ") and "non-finite" in err and len(err.splitlines()) == 1, (tool, err)


def test_save_refuses_nonfinite_parameters(tiny_scene, tmp_path):
    trainer = Trainer(_config(tiny_scene, tmp_path, steps=20))
    trainer.setup()
    trainer._write_run_files()
    first = trainer.save_checkpoint(4)
    with torch.no_grad():
        trainer.pipeline.model.grid.view(-1)[:7] = float("inf")
    with pytest.raises(TrainingDiverged, match=r"non-finite values in model.grid \(7\).*last good checkpoint.*step-000000004"):
        trainer.save_checkpoint(9)
    assert list_checkpoints(trainer.run_dir) == [first]


# ---------------------------------------------------------------- 2. run directories
def test_two_concurrent_trainings_with_one_timestamp(tiny_scene, tmp_path):
    """Both reported success; one's keep-latest cleanup deleted the other's final checkpoint."""
    args = [str(BIN / "ns2gs-train"), "voxel-grid", "--data", str(tiny_scene), "--output-dir", str(tmp_path),
            "--timestamp", "same", "--max-num-iterations", "40", "--steps-per-save", "5", "--progress", "False"]
    procs = [subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    codes = sorted(c for c, _ in results)
    assert codes == [0, 2], results
    err = [e for c, e in results if c == 2][0].strip()
    assert err.startswith("error: ") and "run directory" in err and "Traceback" not in err
    run_dir = tmp_path / Path(tiny_scene).name / "voxel-grid" / "same"
    assert [p.name for p in list_checkpoints(run_dir)] == ["step-000000039.ckpt"]


def test_default_timestamp_clash_gets_a_new_directory(tmp_path):
    a = unique_run_dir(tmp_path / "stamp")
    b = unique_run_dir(tmp_path / "stamp")
    assert a != b and a.is_dir() and b.is_dir() and b.name == "stamp-1"


# ---------------------------------------------------------------- 4. step arithmetic
@pytest.mark.parametrize("kw, flag", [
    ({"max_num_iterations": 0}, "--max-num-iterations"),
    ({"max_num_iterations": -5}, "--max-num-iterations"),
    ({"steps_per_save": 0}, "--steps-per-save"),
    ({"steps_per_eval_image": -1}, "--steps-per-eval-image"),
])
def test_bad_step_numbers_are_one_line_errors(tiny_scene, tmp_path, kw, flag):
    cfg = _config(tiny_scene, tmp_path)
    with pytest.raises(ConfigError, match=f"^{flag}: "):
        Trainer(dataclasses.replace(cfg, **kw))


def test_cli_steps_per_save_zero_is_one_line(tiny_scene, tmp_path):
    code, err = _cli("ns2gs-train", "voxel-grid", "--data", str(tiny_scene), "--output-dir", str(tmp_path), "--steps-per-save", "0")
    assert code == 2 and err == "error: --steps-per-save: must be a positive number of steps, got 0"


def test_resume_past_max_iterations_and_on_other_dataset(tiny_scene, tmp_path):
    from tiny_scene import write_tiny_scene

    trainer = Trainer(_config(tiny_scene, tmp_path / "a", steps=10))
    trainer.setup()
    ckpt = list_checkpoints(trainer.train())[-1]
    past = Trainer(_config(tiny_scene, tmp_path / "b", steps=3, load_checkpoint=ckpt))
    with pytest.raises(ConfigError, match="--max-num-iterations: is 3 but the checkpoint .* step 9"):
        past.setup()
    other = write_tiny_scene(tmp_path / "other", n_train=6)
    elsewhere = Trainer(_config(other, tmp_path / "c", steps=20, load_checkpoint=ckpt))
    with pytest.raises(CheckpointError, match="trained on another dataset"):
        elsewhere.setup()


# ---------------------------------------------------------------- 6. smaller ones
def test_disk_full_is_one_line_and_keeps_previous_checkpoint(tiny_scene, tmp_path, monkeypatch):
    trainer = Trainer(_config(tiny_scene, tmp_path, steps=12))
    trainer.setup()
    real = trainer._write_checkpoint
    calls = []

    def full(path, step, dm):
        calls.append(step)
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, step, dm)

    monkeypatch.setattr(trainer, "_write_checkpoint", full)
    with pytest.raises(CheckpointError, match="No space left on device.*previous checkpoint kept: .*step-000000004"):
        trainer.train()
    assert [p.name for p in list_checkpoints(trainer.run_dir)] == ["step-000000004.ckpt"]


def test_huge_learning_rate_is_one_line(tiny_scene, tmp_path):
    cfg = _config(tiny_scene, tmp_path)
    cfg = dataclasses.replace(cfg, optimizers={"grid": OptimizerConfig(lr=1e38)})
    with pytest.raises(ConfigError, match=r"^--optimizers.grid.lr: learning rate must be in"):
        Trainer(cfg)


def test_negative_augment_delta_h_is_rejected(tiny_scene, tmp_path):
    cfg = _config(tiny_scene, tmp_path)
    with pytest.raises(ConfigError, match="^--augment.delta-h: must be >= 0"):
        Trainer(dataclasses.replace(cfg, augment=dataclasses.replace(cfg.augment, delta_h=-3.0)))


def test_view_family_share_out_of_range_is_rejected(tiny_scene, tmp_path):
    from nerf2gs_plugin.augment.config import LaneShiftConfig

    cfg = _config(tiny_scene, tmp_path)
    aug = dataclasses.replace(cfg.augment, views=("birds-eye", "lane-shift"), lane_shift=LaneShiftConfig(share=1.5))
    with pytest.raises(ConfigError, match=r"^--augment.lane-shift.share: must be in \[0, 1\)"):
        Trainer(dataclasses.replace(cfg, augment=aug))


def test_train_log_is_written_with_every_checkpoint(tiny_scene, tmp_path, monkeypatch):
    trainer = Trainer(_config(tiny_scene, tmp_path, steps=30, steps_per_save=10))
    trainer.setup()
    orig = trainer.train_step

    def crash(step):
        if step == 15:
            raise KeyboardInterrupt
        return orig(step)

    monkeypatch.setattr(trainer, "train_step", crash)
    with pytest.raises(KeyboardInterrupt):
        trainer.train()
    log = json.loads((trainer.run_dir / "train_log.json").read_text())
    assert [r["step"] for r in log["history"]] == list(range(10))


def test_sigterm_saves_like_sigint(tiny_scene, tmp_path):
    args = [str(BIN / "ns2gs-train"), "voxel-grid", "--data", str(tiny_scene), "--output-dir", str(tmp_path),
            "--timestamp", "t", "--max-num-iterations", "100000", "--steps-per-save", "100000", "--progress", "False"]
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    run_dir = tmp_path / Path(tiny_scene).name / "voxel-grid" / "t"
    deadline = time.time() + 120
    while not (run_dir / "config.yml").is_file() and time.time() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)
    p.send_signal(signal.SIGTERM)
    code = p.wait(timeout=60)
    err = p.stderr.read()
    assert code != 0 and "interrupted: checkpoint saved" in err, err
    ckpts = list_checkpoints(run_dir)
    assert len(ckpts) == 1 and load_checkpoint(ckpts[0])["step"] > 0


def test_os_errors_in_any_front_end_are_one_line(capsys):
    """A full disk while writing config.yml/eval.json/a PLY was a traceback."""
    from nerf2gs_plugin.cli.common import run_cli

    def main():
        raise OSError(errno.ENOSPC, "No space left on device", "/out/eval.json")

    with pytest.raises(SystemExit) as e:
        run_cli(main)
    err = capsys.readouterr().err  # the disk too: its mount point and what is left on it
    assert e.value.code == 2 and err.startswith("error: /out/eval.json: No space left on device (") and err.count("\n") == 1
