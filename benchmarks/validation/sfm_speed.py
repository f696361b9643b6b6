"""Issue 18's speed target: SfM of ~120 photos at ~1200x900 within 10 minutes on 2 cores. No public
~120-photo street set is reachable from this machine, so the photos are the forward pass of the synthetic street's drive
(its first 120 of 240 training frames, 0.5 m apart over 60 m: a dashcam's frames; the street's two
passes look in opposite directions and share no view) rendered at 1200x900 (one sample per pixel),
a folder of PNGs in capture order, through ``ns2gs-data process images`` with the defaults (matching
chosen automatically, every core) and the camera's FOV and height. Reports each stage's time (wall,
as ``process`` stores them), the registered fraction, and the poses against the true cameras (ATE
after a Sim(3), % of the trajectory; the camera-height scale's error).

Usage: python benchmarks/validation/sfm_speed.py WORK OUT_STEM
(WORK keeps the rendered street between runs; the capture is processed again every time.)
Produced benchmarks/results/sfm_speed_120.{json,md}.
"""
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from nerf2gs_plugin.data.process.pipeline import TIMES_FILE
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street
from nerf2gs_plugin.eval import bench_real as br
from nerf2gs_plugin.eval.machine import machine_line
from nerf2gs_plugin.eval.pose_eval import capture_report
from nerf2gs_plugin.utils.io import atomic_write_text

work, out = Path(sys.argv[1]), Path(sys.argv[2])
N, W, H, FOV, CAM_H = 120, 1200, 900, 80.0, 3.0
street, photos, data = work / "street", work / "photos", work / "data"
if not (street / "transforms.json").is_file():
    generate_street(SynthStreetConfig(out=street, seed=11, width=W, height=H, num_train=2 * N, spp=1, num_street=1, num_bev=1,
                                      num_val_street=0, num_val_bev=0, fov_deg=FOV, cam_height=CAM_H, drive_half_len=30.0,
                                      progress=False, overwrite=True))
meta = json.loads((street / "transforms.json").read_text())
train = [f for f in meta["frames"] if Path(f["file_path"]).name.startswith("train_")][:N]  # the forward pass
photos.mkdir(parents=True, exist_ok=True)
for f in train:
    link = photos / Path(f["file_path"]).name
    if not link.exists():
        link.symlink_to((street / f["file_path"]).resolve())
shutil.rmtree(data, ignore_errors=True)
load0 = os.getloadavg()[0]
t0 = time.perf_counter()
cmd = f"{sys.executable} -m nerf2gs_plugin.cli.data process images {photos} --out {data} --fov-deg {FOV:g} --camera-height {CAM_H:g} --no-progress"
rc = os.system(cmd)
wall = time.perf_counter() - t0
load1 = os.getloadavg()[0]
if rc != 0:
    raise SystemExit(f"process failed (exit {rc}): {cmd}")
est_meta = json.loads((data / "transforms.json").read_text())
stages = json.loads((data / "colmap" / TIMES_FILE).read_text())
est = br.read_frames(data)["train"]
true = {Path(f.image).name: f for f in br.read_frames(street)["train"]}
rep = capture_report(br.c2w_array(est), br.c2w_array([true[Path(f.image).name] for f in est]), float(est_meta["metres_per_unit"]), np.asarray(est_meta.get("up", [0, 0, 1])),
                     np.asarray(meta.get("up", [0, 0, 1])), len(est), N)
sfm = sum(stages.get(k, 0.0) for k in ("features", "matching", "mapping"))
doc = {"photos": N, "size": [W, H], "command": cmd.replace(sys.executable, "python"), "wall_seconds": wall, "stage_seconds": stages,
       "sfm_seconds": sfm, "matching": est_meta.get("process", {}).get("matching"), "load_start_end": [load0, load1],
       "capture": rep, "machine": machine_line(), "target_seconds": 600}
atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
md = [f"# SfM of {N} photos at {W}x{H} (`ns2gs-data process images`)", "", f"Machine: {machine_line()}; load average "
      f"{load0:.1f} at the start, {load1:.1f} at the end (other jobs ran beside it).", "",
      f"Photos: the forward pass of the synthetic street's drive (seed 11; {N} frames 0.5 m apart over 60 m), rendered at "
      f"{W}x{H} with one sample per pixel, PNG, in capture order: a stand-in for a ~120-photo capture (no public street set "
      "of that size is reachable from this machine). Produced by `benchmarks/validation/sfm_speed.py`.", "",
      "| stage | seconds |", "|---|---|"]
md += [f"| {k} | {v:.1f} |" for k, v in stages.items()]
md += [f"| SfM (features + matching + mapping) | {sfm:.1f} |", f"| `process` wall clock | {wall:.1f} |", "",
       f"Target: SfM within 600 s. Registered {rep['registered_fraction'] * N:.0f}/{N}; ATE {rep['ate_percent']:.2f}% of the "
       f"trajectory, scale error {rep['scale_error_percent']:+.2f}% (camera height {CAM_H:g} m), up {rep['up_error_deg']:.2f} deg, "
       f"rotation {rep['rotation_error_deg']:.2f} deg."]
atomic_write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
print("\n".join(md))
