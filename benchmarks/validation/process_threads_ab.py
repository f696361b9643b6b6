"""A/B interleaved in one process: the real path's ``process video`` stage (frames + SfM) with COLMAP on one thread
(the benches' repeatable setting) vs the product's default (all cores); CPU s (user + sys of this process and its
children: COLMAP runs in a worker process), wall s, registered frames, and each run's trajectory against the first one-thread run (ATE as a
percentage of its length after a Sim(3), mean rotation difference).
Usage: python benchmarks/validation/process_threads_ab.py VIDEO WORK ROUNDS [--fov-deg 81 --camera-height 1.65 --frames 100]"""
import argparse, json, shutil, time
from pathlib import Path

import numpy as np

from nerf2gs_bench.real import process_capture
from nerf2gs_plugin.data.process.sfm import SfmOptions
from nerf2gs_plugin.eval.pose_eval import pose_errors
from nerf2gs_plugin.utils.parallel import cpu_seconds as cpu

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("video", type=Path)
ap.add_argument("work", type=Path, help="scratch folder (its capture folders are made afresh)")
ap.add_argument("rounds", type=int)
ap.add_argument("--frames", type=int, default=100)
ap.add_argument("--fov-deg", type=float, default=81.0, help="KITTI's (nerf2gs_bench/real_captures.py)")
ap.add_argument("--camera-height", type=float, default=1.65)
args = ap.parse_args()


def poses(capture: Path) -> dict[str, np.ndarray]:
    frames = json.loads((capture / "transforms.json").read_text())["frames"]
    return {Path(f["file_path"]).name: np.asarray(f["transform_matrix"], dtype=np.float64)[:3] for f in frames}


variants = {"one thread": 1, "default": SfmOptions().num_threads}
first = None
for rep in range(args.rounds):
    order = list(variants) if rep % 2 == 0 else list(variants)[::-1]
    for name in order:
        out = args.work / f"capture_{name.replace(' ', '_')}_{rep}"
        shutil.rmtree(out, ignore_errors=True)
        w0, c0 = time.perf_counter(), cpu()
        report = process_capture(args.video, out, args.frames, args.fov_deg, args.camera_height, num_threads=variants[name])
        w, c = time.perf_counter() - w0, cpu() - c0
        est = poses(out)
        if first is None:
            first = est
        common = sorted(set(est) & set(first))
        e = pose_errors(np.stack([est[k] for k in common]), np.stack([first[k] for k in common]))
        stages = {k: round(v, 1) for k, v in report.stage_seconds.items()}
        print(f"{name}: CPU {c:.1f} s, wall {w:.1f} s, registered {report.registered}/{report.frames}, vs first one-thread "
              f"run: ATE {e.ate_percent:.3f}% rot {e.rotation_deg_mean:.3f} deg; stages (wall) {stages}; "
              f"load {open('/proc/loadavg').read().split()[0]}", flush=True)
