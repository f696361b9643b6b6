"""A/B interleaved in one process: Splatfacto + NeRF views training steps (the real path's target) with this code
and with the earlier step (torch SSIM, the depth channel on every view, and, with --before-csrc, the compositing
kernel built from an earlier checkout's rendering/csrc). Blocks of 20 steps in the order after, before, before, after;
CPU ms a step (time.process_time: run it with OMP_NUM_THREADS=1).
Usage: python benchmarks/validation/splatfacto_step_ab.py ROOT OUT --start S --steps N [--before-csrc DIR]
(ROOT: a real-path-speed run folder with capture/ and streetnerf/, the views in its view store)."""
import argparse
from pathlib import Path

from nerf2gs_bench.real_path_speed import _trainer_config
from nerf2gs_bench.step_ab import interleaved_step_cpu
from nerf2gs_plugin.engine.model import Model
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.methods.splatfacto.model import SplatfactoModel
from nerf2gs_plugin.rendering import rasterization
from nerf2gs_plugin.utils import image_metrics
from nerf2gs_plugin.utils.extensions import load_extension

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("root", type=Path)
ap.add_argument("out", type=Path, help="the run folder to train into")
ap.add_argument("--start", type=int, default=0, help="steps trained (with this code) before the A/B")
ap.add_argument("--steps", type=int, default=480, help="steps of the A/B (half each)")
ap.add_argument("--before-csrc", type=Path, default=None, help="an earlier checkout's nerf2gs_plugin/rendering/csrc")
args = ap.parse_args()
block = 20
before_kernel = None
if args.before_csrc:
    d = args.before_csrc
    before_kernel = load_extension("nerf2gs_rasterize_gaussians_before", [d / "rasterize_gaussians.cpp"], sorted(d.glob("*.h")),
                                   rasterization.EXT_CFLAGS)
trainer = Trainer(_trainer_config("splatfacto", args.root / "capture", args.out, None, augment_from=args.root / "streetnerf"))
trainer.setup()
after_kernel, lean, fused = rasterization.load_kernel(), SplatfactoModel.get_train_outputs, image_metrics._fused_applies


def use(after: bool) -> None:
    SplatfactoModel.get_train_outputs = lean if after else Model.get_train_outputs
    image_metrics._fused_applies = fused if after else (lambda *a: False)
    kernel = after_kernel if after or before_kernel is None else before_kernel
    rasterization.load_kernel = lambda: kernel


use(True)
for step in range(args.start):
    trainer.train_step(step)
per = interleaved_step_cpu(trainer, use, args.start, args.steps, block)
print(f"steps {args.start}-{args.start + args.steps}: CPU ms a step { {k: round(v, 1) for k, v in per.items()} }, after/before {per['after'] / per['before']:.3f}, "
      f"{trainer.pipeline.model.num_primitives()} Gaussians")
