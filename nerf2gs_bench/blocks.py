"""``ns2gs-bench blocks``: a partitioned-and-merged run against one whole-scene run, on two small
synthetic streets (the layout of the partition/merge test, and a second street: another seed,
camera height, field of view and traffic). Per street: ``partition --blocks 2x1 --overlap 0.2``,
Splatfacto for ``steps`` on each block and on the whole street, ``merge``, and both evaluated on
the whole street's eval views. Writes ``blocks.json`` / ``blocks.md`` (with the machine)."""

from __future__ import annotations

import dataclasses
import shutil
import time
from pathlib import Path
from typing import Any

from nerf2gs_bench.runner import fmt, write_bench_files

BASE = dict(width=64, height=40, num_train=16, num_street=4, num_bev=4, num_val_street=0, num_val_bev=0, num_cars=2,
            spp=1, num_points=600, progress=False)
SCENES = {
    "seed 0": {"seed": 0},
    "seed 7 (2 m camera, 70 deg, 4 cars)": {"seed": 7, "cam_height": 2.0, "fov_deg": 70.0, "num_cars": 4},
}
SPLITS = ("street", "bev_1", "bev_2")


def _train(data: Path, root: Path, name: str, steps: int) -> Path:
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("splatfacto").with_steps(steps), data=data, output_dir=root, timestamp=name,
                              progress=False, steps_per_eval_image=0, device="cpu")
    trainer = Trainer(cfg)
    trainer.setup()
    return trainer.train()


def _scene(name: str, overrides: dict, root: Path, steps: int) -> list[dict[str, Any]]:
    from nerf2gs_plugin.blocks.merge import MergeConfig, merge
    from nerf2gs_plugin.blocks.partition import PartitionConfig, partition
    from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.eval.evaluate import evaluate_run

    shutil.rmtree(root, ignore_errors=True)
    street = root / "street"
    generate_street(SynthStreetConfig(out=street, **{**BASE, **overrides}))
    doc = partition(PartitionConfig(data=street, out=root / "parts", blocks="2x1", overlap=0.2))
    runs = root / "runs"
    t0 = time.perf_counter()
    whole = _train(street, runs, "whole", steps)
    t_whole = time.perf_counter() - t0
    t0 = time.perf_counter()
    blocks = [_train(root / "parts" / b["folder"], runs, b["name"], steps) for b in doc["blocks"]]
    merged = merge(MergeConfig(runs=blocks, out=runs / "merged"))
    t_blocks = time.perf_counter() - t0
    rows = []
    for label, run_dir, seconds in (("whole scene", whole, t_whole), ("2 blocks merged", merged, t_blocks)):
        res = evaluate_run(load_run(run_dir), list(SPLITS), fps_repeats=1)
        rows.append({"scene": name, "run": label, "steps": steps, "wall_seconds": seconds, "primitives": res["size"]["primitives"],
                     **{s: res["results"][s]["psnr"] for s in SPLITS},
                     "block_train_images": [b["train_images"] for b in doc["blocks"]] if label != "whole scene" else None})
    return rows


def run(out: Path, runs_root: Path, steps: int = 200) -> dict[str, Any]:
    rows = []
    for i, (name, overrides) in enumerate(SCENES.items()):
        rows += _scene(name, overrides, Path(runs_root) / "blocks" / f"scene_{i}", steps)
    gaps = {r["scene"]: {s: w[s] - r[s] for s in SPLITS} for w, r in zip(rows[::2], rows[1::2])}
    lines = ["| scene | run | PSNR street | bev_1 | bev_2 | primitives | wall s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['run']} | {fmt(r['street'])} | {fmt(r['bev_1'])} | {fmt(r['bev_2'])} | "
                     f"{r['primitives']:,} | {fmt(r['wall_seconds'], 0)} |")
    lines += ["", "Whole scene minus merged (dB; positive = the merged run is worse):", ""]
    lines += [f"- {scene}: " + ", ".join(f"{s} {g:+.2f}" for s, g in gap.items()) for scene, gap in gaps.items()]
    body = (f"Splatfacto, {steps} steps per run; each street 16 training views at 64x40, partitioned 2x1 with 20% overlap; "
            "eval views of the whole street.\n\n" + "\n".join(lines))
    payload = {"rows": rows, "gaps": gaps, "steps": steps}
    write_bench_files(out, "blocks", "City blocks: 2 blocks merged vs one whole-scene run", payload, body)
    return payload
