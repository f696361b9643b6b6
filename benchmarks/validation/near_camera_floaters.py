"""Floaters in front of a held-out camera: how much of one view's error they make, and which
training views hold them.

Why: on castle-P30 the augmented Splatfacto of ``ns2gs-bench real-photos`` scored one held-out photo
at ~9 dB (nearly black) while the others were fine; this measures, for that view, the Gaussians
whose centre lies within a distance in front of its camera: the view's PSNR with them muted (opacity
to zero), and their blending weight summed over the real training views and over the bird's-eye
views the augmentation rendered (``--augment.delta-h``, ``--augment.theta-pitch``, ``--augment.every-n``
as given), so a floater copied from the reference's views from above tells itself apart.

Usage: python benchmarks/validation/near_camera_floaters.py OUT_STEM RUN SPLIT VIEW DELTA_H THETA_PITCH EVERY_N
Produced benchmarks/results/near_camera_floaters.{json,md} with the augmented castle-P30 run of the
real-photos bench (test 1 3 30 2); near_camera_floaters_castle_val.{json,md}
with plain Splatfacto on castle-P30's validation photos (augment_appearance.md; the view 3 of its "test" split,
photo 0028; the last three arguments only place the views from above it reports weights in).
The calls: benchmarks/plans/near_camera_floaters.yaml.
"""
import argparse
import json
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.augment.geometry import ViewGeometry  # noqa: E402
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_plugin.methods.capture_path import capture_path  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_plugin.utils.image_metrics import psnr_from_mse  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
for name, kind in (("out_stem", Path), ("run", Path), ("split", str), ("view", int), ("delta_h", float), ("theta_pitch", float),
                   ("every_n", int)):
    ap.add_argument(name, type=kind)
args = ap.parse_args()
out, run_dir, split, view = args.out_stem, args.run, args.split, args.view
delta_h, pitch, every_n = args.delta_h, args.theta_pitch, args.every_n
run = load_run(run_dir)
dm, model = run.pipeline.datamanager, run.model
g = model.gauss
cam, image = next((c, b["image"]) for k, (c, b) in enumerate(dm.eval_images(split)) if k == view)


def view_psnr() -> float:
    with torch.no_grad():
        rgb = model.render_camera(cam)["rgb"]
    return float(psnr_from_mse(((rgb - image.to(rgb)) ** 2).mean()))


with torch.no_grad():
    c2w = cam.camera_to_worlds.reshape(-1, 3, 4)[0]
    rel = (g["means"] - c2w[:, 3]) @ c2w[:, :3]  # camera frame (OpenGL: -z ahead)
    ahead = -rel[:, 2]
    reach = torch.exp(g["scales"]).amax(-1)
train = dm.all_train_cameras
metre = dm.train_data.metres_to_world(1.0)
bev = ViewGeometry(delta_h, pitch, every_n, "absolute").cameras(train, dm.train_data)
w_real, w_bev = model.blend_weights(train), model.blend_weights(bev)
to_path = capture_path(train.camera_to_worlds[:, :3, 3]).distance(g["means"].detach()) / metre  # what the path clearance measures
rows = []
for dist in (0.02, 0.05, 0.1, 0.2):
    near = (ahead > 0) & (ahead < dist) & (rel[:, :2].norm(dim=-1) < ahead * 1.5 + 3 * reach)
    saved = g["opacities"].data.clone()
    g["opacities"].data[near] = -30.0
    muted = view_psnr()
    g["opacities"].data.copy_(saved)
    rows.append({"within_world": dist, "within_m": dist / metre, "gaussians": int(near.sum()), "psnr_muted": muted,
                 "weight_real": [round(float(v), 1) for v in w_real[near]], "weight_bev": [round(float(v), 1) for v in w_bev[near]],
                 "to_path_m": [round(float(v), 2) for v in to_path[near]]})
centres = train.camera_to_worlds[:, :3, 3]
doc = {"machine": machine_line(), "run": str(run_dir), "split": split, "view": view, "psnr": view_psnr(),
       "camera_to_nearest_training_camera_m": float(torch.cdist(c2w[None, :, 3], centres).min()) / metre,
       "median_weight_real": float(w_real.median()), "median_weight_bev": float(w_bev.median()), "rows": rows}
atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
md = [f"# Floaters in front of held-out view {view} ({split}) of `{run_dir}`", "", f"Machine: {doc['machine']}. Produced by "
      "`benchmarks/validation/near_camera_floaters.py`.", "",
      f"The view scores {doc['psnr']:.2f} dB; its camera stands {doc['camera_to_nearest_training_camera_m']:.1f} m from the nearest "
      "training camera.", "", "| Gaussians within (world / m) ahead | count | view PSNR with them muted | their weight in the real views | in the views from above | metres from the capture path |",
      "|---|---|---|---|---|---|"]
md += [f"| {r['within_world']} / {r['within_m']:.2f} | {r['gaussians']} | {r['psnr_muted']:.2f} | {min(r['weight_real'], default=0):.0f}-"
       f"{max(r['weight_real'], default=0):.0f} | {min(r['weight_bev'], default=0):.0f}-{max(r['weight_bev'], default=0):.0f} | "
       f"{min(r['to_path_m'], default=0):.1f}-{max(r['to_path_m'], default=0):.1f} |" for r in rows]
atomic_write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
print("\n".join(md))
