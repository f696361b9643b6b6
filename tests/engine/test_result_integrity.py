"""Results are only written when valid, user files are never taken over, corrupt inputs are refused:
eval's --max-images 0 keeps a good eval.json, --run-dir refuses a folder of the user's own files,
checkpoints carry a checksum verified on load, config.yml is loaded with aliases bounded and field
types checked, a NaN downscale is one line (each test failed before the fix)."""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

import pytest
import torch

from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.errors import CheckpointError, ConfigError
from nerf2gs_plugin.registry import get_method


def _config(data, out, steps=4, **kw):
    kw.setdefault("steps_per_save", 2)
    kw.setdefault("timestamp", "run")
    return dataclasses.replace(get_method("voxel-grid").config, data=data, output_dir=out, max_num_iterations=steps,
                               steps_per_eval_image=0, progress=False, **kw)


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    trainer = Trainer(_config(tiny_scene, tmp_path_factory.mktemp("runs")))
    trainer.setup()
    return trainer.train()


def _cli(module, argv, monkeypatch, capsys):
    import importlib

    mod = importlib.import_module(f"nerf2gs_plugin.cli.{module}")
    monkeypatch.setattr(sys, "argv", [module, *map(str, argv)])
    try:
        mod.entrypoint()
        code = 0
    except SystemExit as e:
        code = int(e.code or 0)
    return code, capsys.readouterr().err.strip()


# ---------------------------------------------------------------- eval keeps a good result
@pytest.mark.parametrize("n", [0, -3])
def test_eval_max_images_zero_keeps_the_good_eval_json(tiny_run, tmp_path, monkeypatch, capsys, n):
    out = tmp_path / "eval.json"
    out.write_text('{"good": true}')
    code, err = _cli("eval", [tiny_run, "--max-images", n, "--output", out, "--render-dir", tmp_path / "r"], monkeypatch, capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "--max-images" in err, err
    assert out.read_text() == '{"good": true}'


def test_eval_writes_nothing_from_an_empty_result(tiny_run, tmp_path):
    from nerf2gs_plugin.errors import DataError
    from nerf2gs_plugin.eval.evaluate import check_result

    with pytest.raises(DataError, match="no image"):
        check_result({"results": {"eval": {"num_images": 0, "psnr": None, "ssim": None}}})
    with pytest.raises(DataError, match="non-finite"):
        check_result({"results": {"eval": {"num_images": 2, "psnr": float("nan"), "ssim": 0.5}}})


# ---------------------------------------------------------------- run folders
def test_run_dir_with_the_users_files_is_refused_and_kept(tiny_scene, tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "config.yml").write_text("my: own config\n")
    (folder / "train_log.json").write_text('{"mine": 1}')
    trainer = Trainer(_config(tiny_scene, tmp_path, timestamp="{timestamp}", run_dir=folder))
    trainer.setup()
    with pytest.raises(ConfigError, match="not a run folder of ours"):
        trainer.train()
    assert (folder / "config.yml").read_text() == "my: own config\n"
    assert (folder / "train_log.json").read_text() == '{"mine": 1}'


def test_run_dir_empty_or_ours_is_taken(tiny_scene, tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    trainer = Trainer(_config(tiny_scene, tmp_path, steps=2, timestamp="{timestamp}", run_dir=folder))
    trainer.setup()
    run_dir = trainer.train()
    assert (run_dir / ".ns2gs_run").is_file() and list_checkpoints(run_dir)
    ckpt = list_checkpoints(run_dir)[-1]  # ours: resuming into it is allowed
    again = Trainer(_config(tiny_scene, tmp_path, steps=4, timestamp="{timestamp}", run_dir=folder, load_checkpoint=ckpt))
    again.setup()
    assert again.train() == run_dir


# ---------------------------------------------------------------- checkpoint checksum
def test_flipped_checkpoint_fails_its_checksum_and_is_never_last_good(tiny_run, tmp_path, tiny_scene):
    ckpt = list_checkpoints(tiny_run)[-1]
    bad = tmp_path / "checkpoints" / ckpt.name
    bad.parent.mkdir(parents=True)
    data = bytearray(ckpt.read_bytes())
    # a float byte in the middle of the archive: torch.load still reads it, the values change
    data[len(data) // 2] ^= 0x7F
    bad.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="checksum"):
        load_checkpoint(bad)
    trainer = Trainer(_config(tiny_scene, tmp_path / "resumed", steps=8, load_checkpoint=bad))
    with pytest.raises(CheckpointError, match="checksum"):
        trainer.setup()  # refused before training: no divergence that names it the last good one


def test_nan_optimizer_state_is_refused_on_load(tiny_run, tmp_path):
    from nerf2gs_plugin.engine.checkpoints import save_checkpoint

    doc = torch.load(list_checkpoints(tiny_run)[-1], weights_only=True)
    state = doc["optimizers"]
    tensors = [t for t in _walk(state) if t.is_floating_point() and t.numel()]
    assert tensors
    tensors[0].view(-1)[0] = float("nan")
    out = tmp_path / "step-000000001.ckpt"
    save_checkpoint(out, {k: v for k, v in doc.items() if k != "format_version"})
    with pytest.raises(CheckpointError, match="non-finite"):
        load_checkpoint(out)


def _walk(tree):
    if torch.is_tensor(tree):
        yield tree
    elif isinstance(tree, dict):
        for v in tree.values():
            yield from _walk(v)
    elif isinstance(tree, (list, tuple)):
        for v in tree:
            yield from _walk(v)


# ---------------------------------------------------------------- config.yml
def test_yaml_alias_bomb_is_one_line_quickly(tiny_run, tmp_path):
    from nerf2gs_plugin.engine.config import read_config_doc

    lines = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i, (prev, name) in enumerate(zip("abcdefgh", "bcdefghi")):
        lines.append(f"{name}: &{name} [" + ",".join([f"*{prev}"] * 9) + "]")
    bomb = tmp_path / "config.yml"
    bomb.write_text("format_version: 1\nmethod_name: voxel-grid\nconfig:\n  x: 1\n" + "\n".join(lines) + "\n")
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match="alias"):
        read_config_doc(bomb)
    assert time.perf_counter() - t0 < 2.0


def test_config_field_types_are_checked(tiny_run, tmp_path):
    import yaml

    from nerf2gs_plugin.engine.config import load_config

    doc = yaml.safe_load((tiny_run / "config.yml").read_text())
    for field, value, want in (("experiment_name", ["a", "list"], "expected str"), ("load_checkpoint", [1, 2], "expected a path")):
        d = json.loads(json.dumps(doc))
        d["config"][field] = value
        p = tmp_path / f"{field}.yml"
        p.write_text(yaml.safe_dump(d))
        with pytest.raises(ConfigError, match=f"config.{field}: {want}"):
            load_config(p, get_method("voxel-grid").config)


# ---------------------------------------------------------------- flags
def test_nan_downscale_is_one_line(tiny_scene, tmp_path, monkeypatch, capsys):
    code, err = _cli("train", ["voxel-grid", "--data", tiny_scene, "--output-dir", tmp_path, "--max-num-iterations", 2,
                               "--pipeline.datamanager.downscale", "nan"], monkeypatch, capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "--pipeline.datamanager.dataparser.downscale" in err, err
