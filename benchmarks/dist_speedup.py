"""Data-parallel speedup of Splatfacto on this machine: steps per second of one process against two
gloo ranks at the same global batch (2 images per step, the same draws: see tests/engine/test_distributed.py).

    python benchmarks/dist_speedup.py --data data/street --work /tmp/dist_speedup --steps 100 \
        --out benchmarks/results/dist_speedup

Configurations, each a fresh ``ns2gs-train splatfacto`` (default config, no densification in the
first 300 steps), run one after another:

* 1 process, 1 thread, ``--machine.batches-per-rank 2``;
* 1 process, 2 threads, ``--machine.batches-per-rank 2``;
* 2 ranks of 1 thread each, ``--machine.num-devices 2``.

Steps per second = steps / the run's ``train_seconds`` (the training steps only, rank 0's clock:
it waits for the other rank in every all-reduce). The load average before and after each run is
recorded: on a shared machine the figures move with it. ``max_param_diff``: the largest difference
of any final parameter from the first configuration's (0: the same model to the bit).
Results: ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

CONFIGS = [
    ("1 process, 1 thread, 2 batches per step", 1, ["--machine.batches-per-rank", "2"]),
    ("1 process, 2 threads, 2 batches per step", 2, ["--machine.batches-per-rank", "2"]),
    ("2 ranks (gloo), 1 thread each", 1, ["--machine.num-devices", "2"]),
]


def run(data: Path, work: Path, label: str, threads: int, flags: list[str], steps: int, index: int) -> dict:
    import torch

    stamp = f"c{index}"
    env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
    cmd = [str(Path(sys.executable).parent / "ns2gs-train"), "splatfacto", "--data", str(data), "--output-dir", str(work),
           "--max-num-iterations", str(steps), "--steps-per-save", str(steps), "--steps-per-eval-image", "0",
           "--progress", "False", "--timestamp", stamp, *flags]
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    ckpt = sorted((work / data.name / "splatfacto" / stamp / "checkpoints").glob("step-*.ckpt"))[-1]
    saved = torch.load(ckpt, weights_only=True)
    train_s = float(saved["train_seconds"])
    return {"model": saved["model"], "config": label, "threads_per_process": threads, "flags": " ".join(flags), "steps": steps,
            "train_seconds": round(train_s, 2), "steps_per_second": round(steps / train_s, 3), "wall_seconds": round(wall, 1),
            "load_before": round(load_before, 2), "load_after": round(os.getloadavg()[0], 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    import torch

    rows = [run(a.data.absolute(), a.work, label, threads, flags, a.steps, i) for i, (label, threads, flags) in enumerate(CONFIGS)]
    base, first = rows[0]["steps_per_second"], rows[0]["model"]
    for r in rows:
        r["speedup_vs_1_thread"] = round(r["steps_per_second"] / base, 2)
    for r in rows:  # after the loop: the first row's model is compared with itself too
        model = r.pop("model")
        r["max_param_diff"] = max(float((model[k].float() - first[k].float()).abs().max()) if model[k].shape == first[k].shape
                                  else float("inf") for k in first)
    doc = {"bench": "dist_speedup", "data": a.data.name, "machine": {"cpu": platform.processor() or platform.machine(),
           "cores": os.cpu_count(), "torch": torch.__version__}, "rows": rows}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".json").write_text(json.dumps(doc, indent=1) + "\n")
    lines = [f"# Data-parallel speedup (Splatfacto, {a.data.name}, {a.steps} steps, global batch 2 images)", "",
             f"{os.cpu_count()} cores, torch {torch.__version__}; `python benchmarks/dist_speedup.py` (shared machine: see the load).", "",
             "| configuration | steps/s | speedup | train s | load before / after | max param diff |", "|---|---|---|---|---|---|"]
    lines += [f"| {r['config']} | {r['steps_per_second']:.2f} | {r['speedup_vs_1_thread']:.2f}x | {r['train_seconds']:.1f} | "
              f"{r['load_before']:.1f} / {r['load_after']:.1f} | {r['max_param_diff']:.2g} |" for r in rows]
    a.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
