"""A/B interleaved in one process: StreetNeRF training steps (the real path's, warm-started from the masks' reference)
with this code and with the step of before: the sparse-point rays rendering their colour too, Adam's per-tensor loop,
the hash grid's level weights multiplied outside the kernel. Blocks of 20 steps in the order
after, before, before, after; CPU ms a step (time.process_time: run it with OMP_NUM_THREADS=1).
Usage: python benchmarks/validation/streetnerf_step_ab.py ROOT OUT --steps N
(ROOT: a real-path-speed run folder with capture/ and masks-reference/)."""
import argparse
from pathlib import Path

from nerf2gs_bench.real_path_speed import _trainer_config
from nerf2gs_bench.step_ab import interleaved_step_cpu
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.fields import hash_encoding

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("root", type=Path)
ap.add_argument("out", type=Path, help="the run folder to train into")
ap.add_argument("--steps", type=int, default=480, help="steps of the A/B (half each)")
args = ap.parse_args()
block = 20
trainer = Trainer(_trainer_config("streetnerf", args.root / "capture", args.out, None, warm_start=args.root / "masks-reference"))
trainer.setup()
model = trainer.pipeline.model
render = model._render_rays
fused = hash_encoding._fused_available


def use(after: bool) -> None:
    model._render_rays = render if after else (lambda r, idx, *a, colour=True: render(r, idx, *a, colour=True))
    for opt in trainer.optimizers.optimizers.values():
        for group in opt.param_groups:
            group["foreach"] = after
    hash_encoding._fused_available = fused if after else (lambda *a: False)  # training has no other use of it


start = trainer.step
for step in range(start, start + block):  # warm-up
    trainer.train_step(step)
per = interleaved_step_cpu(trainer, use, start + block, args.steps, block)
print(f"steps {start + block}-{start + block + args.steps}: CPU ms a step { {k: round(v, 1) for k, v in per.items()} }, after/before {per['after'] / per['before']:.3f}")
