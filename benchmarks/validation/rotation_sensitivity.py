"""How much a rotation error of the eval cameras alone costs a run: its eval views rendered with every
camera turned by a random ANGLE (one draw per camera, seed 0), PSNR against the true images.

Why: the real-capture bench's estimated path trails its ground-truth path by 2-3 dB with a 1.4 deg
mean rotation error after the Sim(3) alignment; this says how much of that the pose error explains.
Usage: python benchmarks/validation/rotation_sensitivity.py RUN DATA OUT_STEM [ANGLES...]
Produced benchmarks/results/real_rotation_check.{json,md} with RUN the bench's ground-truth
StreetNeRF (benchmarks/runs/gt/streetnerf/<key>), DATA benchmarks/runs/real/gt, angles 0 0.7 1.4.
"""
import argparse
import json
import warnings
from pathlib import Path

import numpy as np
import torch

torch.set_num_threads(1)
from nerf2gs_plugin.data import parse_dataset  # noqa: E402
from nerf2gs_plugin.data.images import load_image  # noqa: E402
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_bench.perturb import random_rotation  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("run", type=Path)
ap.add_argument("data", type=Path)
ap.add_argument("out_stem", type=Path)
ap.add_argument("angles", type=float, nargs="*", default=[0.0, 0.7, 1.4], help="degrees")
args = ap.parse_args()
run_dir, data, out, angles = args.run, args.data, args.out_stem, args.angles
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    model = load_run(run_dir, device="cpu").model
rng = np.random.default_rng(0)
psnr: dict = {}
for split in ("street", "bev_1"):
    d = parse_dataset(data, split)
    for deg in angles:
        ps = []
        for i in range(len(d)):
            cam = d.cameras[i:i + 1]
            if deg:
                c2w = cam.camera_to_worlds.clone()
                c2w[0, :3, :3] = torch.from_numpy(random_rotation(np.radians(deg), rng)).float() @ c2w[0, :3, :3]
                cam.camera_to_worlds = c2w
            with torch.no_grad():
                rgb = model.render_camera(cam)["rgb"]
            ps.append(float(-10 * torch.log10(((rgb - load_image(d.image_filenames[i])[..., :3]) ** 2).mean())))
        psnr.setdefault(split, {})[str(deg)] = float(np.mean(ps))
doc = {"run": str(run_dir), "data": str(data), "angles_deg": angles, "psnr": psnr, "machine": machine_line()}
atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
md = ["# Rotation error of the eval cameras alone (ground-truth StreetNeRF of `ns2gs-bench real`)", "",
      f"Run `{run_dir}`; every eval camera turned by a random angle (seed 0). Produced by "
      "`benchmarks/validation/rotation_sensitivity.py`.", "",
      "| split | " + " | ".join(f"{a:g} deg" for a in angles) + " |", "|---|" + "---|" * len(angles)]
md += [f"| {s} | " + " | ".join(f"{psnr[s][str(a)]:.2f}" for a in angles) + " |" for s in psnr]
atomic_write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
print("\n".join(md))
