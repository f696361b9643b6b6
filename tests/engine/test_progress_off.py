"""``--progress False`` (or no terminal): plain progress lines, never silence; the in-training eval
is named for what it is (one view), in the line and in train_log.json."""

from __future__ import annotations

import dataclasses
import io
import json
import sys
from pathlib import Path

from rich.console import Console

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "methods" / "splatfacto"))
from splat_tiny_scene import needs_rasterizer, write_dataset  # noqa: E402

from nerf2gs_plugin.engine.trainer import Trainer  # noqa: E402
from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_method  # noqa: E402
from nerf2gs_plugin.progress import make_progress  # noqa: E402


def test_not_live_gives_plain_lines_every_interval_even_on_a_terminal():
    buf = io.StringIO()
    clock = iter(float(t) for t in range(0, 1000, 4))  # 4 s per call
    console = Console(file=buf, force_terminal=True, width=200)
    with make_progress(console=console, live=False, get_time=lambda: next(clock)) as p:
        task = p.add_task("train x", total=10, stats="loss 0.1")
        for _ in range(10):
            p.advance(task)
    lines = buf.getvalue().splitlines()
    assert len(lines) >= 3 and all(l.startswith("train x: ") for l in lines)
    assert "ETA" in lines[0] and "it/s" in lines[0] and "loss 0.1" in lines[0]


@needs_rasterizer
def test_trainer_progress_false_prints_lines_and_names_the_one_view_eval(tmp_path, capsys):
    data = write_dataset(tmp_path / "data")
    base = splatfacto_method.config
    cfg = dataclasses.replace(base, data=data, output_dir=tmp_path / "out", max_num_iterations=4, steps_per_save=100,
                              steps_per_eval_image=2, progress=False, optimizers=gaussian_optimizers(4))
    trainer = Trainer(cfg)
    trainer.setup()
    run = trainer.train()
    err = capsys.readouterr().err
    line = [l for l in err.splitlines() if l.startswith("train splatfacto: 4/4")][-1]
    assert "it/s" in line and "loss" in line and "eval psnr (1 view)" in line
    records = json.loads((run / "train_log.json").read_text())["history"]
    assert any("eval_psnr_1view" in r for r in records) and not any("eval_psnr" in r for r in records)
