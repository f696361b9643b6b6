"""``--segmenter auto`` checked on a second synthetic street, the way ``ns2gs-bench real`` checks it
on the first: the street's 30-frame forward drive as a video, poses and masks thrown away,
``process video`` with the street's FOV and camera height, a 1000-step mask-less reference (every
eighth frame held out: no eval splits here), masks from its renders (default ``AutoOptions``), IoU
pooled over the training frames against the street's exact masks (resampled onto the GT pixel grid
as the bench does).

Usage: python benchmarks/validation/auto_masks_scene.py SEED FOV_DEG CAM_HEIGHT CARS WORK OUT_STEM [VIDEO_SCALE]
(WORK keeps the street, the capture, the reference and the renders (renders.pt) between runs; the
renders are reused, the plane and the masks are derived again). VIDEO_SCALE (default 1): the video is
the street rendered at that multiple of its 200x112, processed at that size, and the reference and
masks are made from the capture's ``images_<VIDEO_SCALE>`` (``bench_real.training_view``), as
``ns2gs-bench real --video-scale`` does; the masks are scored against the 200x112 street's either way.
Produced benchmarks/results/auto_masks_seed7.{json,md} with 7 70 2 10, auto_masks_seed3 with 3 75 2.5 8
and auto_masks_seed0 (the bench's street, through this script) with 0 80 3 6; the ``*_video4`` ones with
VIDEO_SCALE 4.
"""
import argparse
import json
import time
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.masking.auto_masks import ground_plane, render_views  # noqa: E402
from nerf2gs_plugin.masking.mask_reference import ensure_reference  # noqa: E402
from nerf2gs_plugin.data import parse_dataset  # noqa: E402
from nerf2gs_plugin.data.images import load_mask  # noqa: E402
from nerf2gs_plugin.masks.auto import AutoOptions, masks_from_renders  # noqa: E402
from nerf2gs_plugin.masks.maskless import maskless_view  # noqa: E402
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street  # noqa: E402
from nerf2gs_bench import real as br  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_plugin.masks.evaluate import resample_mask  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("seed", type=int)
ap.add_argument("fov_deg", type=float)
ap.add_argument("cam_height", type=float)
ap.add_argument("cars", type=int)
ap.add_argument("work", type=Path)
ap.add_argument("out_stem", type=Path)
ap.add_argument("video_scale", type=int, nargs="?", default=1)
args = ap.parse_args()
seed, fov, cam_h, cars, work, out, scale = args.seed, args.fov_deg, args.cam_height, args.cars, args.work, args.out_stem, args.video_scale
work.mkdir(parents=True, exist_ok=True)
t0 = time.time()


def make_street(path: Path, k: int) -> dict:
    if not (path / "transforms.json").is_file():
        generate_street(SynthStreetConfig(out=path, seed=seed, fov_deg=fov, cam_height=cam_h, num_cars=cars, num_street=1, num_bev=1,
                                          num_val_street=0, num_val_bev=0, width=200 * k, height=112 * k, progress=False,
                                          overwrite=True))
    return json.loads((path / "transforms.json").read_text())


street = work / "street"
meta = make_street(street, 1)
video_street = street if scale == 1 else work / f"street_x{scale}"
video_meta = meta if scale == 1 else make_street(video_street, scale)
capture = work / ("estimated" if scale == 1 else f"capture_x{scale}")
if not (capture / "transforms.json").is_file():
    video = br.write_video(work / ("drive.avi" if scale == 1 else f"drive_x{scale}.avi"),
                           [video_street / f["file_path"] for f in video_meta["frames"][:30]])
    br.process_capture(video, capture, 30, fov, cam_h)
est = capture if scale == 1 else br.training_view(capture, work / f"estimated_x{scale}", scale)
view = maskless_view(est)
cache = work / ("renders.pt" if scale == 1 else f"renders_x{scale}.pt")
if cache.is_file():
    r = torch.load(cache, weights_only=False)
else:
    reference = work / ("reference" if scale == 1 else f"reference_x{scale}")
    ensure_reference(est, reference, 1000, progress=False)
    r = render_views(view, reference, ["train"], progress=False)
    torch.save(r, cache)
train = parse_dataset(view, "train")
r.up, r.height = ground_plane(train, [])  # the plane as the code now fits it
em = {Path(f["file_path"]).name: f for f in json.loads((est / "transforms.json").read_text())["frames"]}


def mask_stats(opts: AutoOptions) -> tuple[dict, int]:
    """IoU / precision / recall per kind, pooled over the training frames; and the frames."""
    res = masks_from_renders(r, opts, log=lambda s: None)["train"]
    stats = {}
    for kind in ("sky", "ground", "transient"):
        i = u = p = t = 0
        for name, m in zip([q.name for q in train.image_filenames], res):
            f, tf = em[name], meta["frames"][br.frame_index(Path(name))]
            gt = load_mask(street / tf[f"{kind}_mask_path"])
            pred = resample_mask(getattr(m, kind), (f["fl_x"], f["fl_y"], f["cx"], f["cy"]),
                                 (meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"]), tuple(gt.shape))
            i, u, p, t = i + int((pred & gt).sum()), u + int((pred | gt).sum()), p + int(pred.sum()), t + int(gt.sum())
        stats[kind] = {"iou": i / max(u, 1), "precision": i / max(p, 1), "recall": i / max(t, 1)}
    return stats, len(res)


stats, n_train = mask_stats(AutoOptions())
# the same renders without the empty-ray ground rule (AutoOptions.ground_empty, 2026-11-25): what it changed
stats_off, _ = mask_stats(AutoOptions(ground_empty=False))
# the sky mask's holes filled (AutoOptions.sky_fill_holes, off by default, 2026-11-26)
stats_fill, _ = mask_stats(AutoOptions(sky_fill_holes=True))
cams = torch.stack([v["origin"] for v in r.views["train"]])
heights = ((cams @ r.up - r.height) / r.metres_to_world).tolist()
doc = {"scene": {"seed": seed, "fov_deg": fov, "cam_height": cam_h, "num_cars": cars, "frames": 30, "video_scale": scale},
       "registered": len(em), "train_views": n_train, "mask_iou": {k: v["iou"] for k, v in stats.items()}, "stats": stats,
       "without_ground_empty": {"mask_iou": {k: v["iou"] for k, v in stats_off.items()}, "stats": stats_off},
       "with_sky_fill_holes": {"mask_iou": {k: v["iou"] for k, v in stats_fill.items()}, "stats": stats_fill},
       "camera_heights_m": heights, "options": vars(AutoOptions()), "machine": machine_line(), "seconds": time.time() - t0}
atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
md = [f"# `--segmenter auto` on another street (seed {seed}, camera {cam_h} m, {fov:g} deg FOV, {cars} cars)", "",
      f"Machine: {machine_line()}. The 30-frame forward drive as a video ({200 * scale}x{112 * scale}"
      + (f", the reference and masks made from the capture's `images_{scale}`" if scale != 1 else "")
      + ") -> process video -> 1000-step mask-less reference "
      f"-> masks (default options); {len(em)}/30 frames registered, {n_train} training views (every 8th held out). "
      "Produced by `benchmarks/validation/auto_masks_scene.py`.", ""]


def table(st: dict) -> list[str]:
    return (["| kind | IoU | precision | recall |", "|---|---|---|---|"]
            + [f"| {k} | {v['iou']:.3f} | {v['precision']:.3f} | {v['recall']:.3f} |" for k, v in st.items()])


md += table(stats)
md += ["", "The same renders without the empty-ray ground rule (`--auto.ground-empty False`):", ""] + table(stats_off)
md += ["", "The same renders with the sky mask's holes filled (`--auto.sky-fill-holes`, off by default):", ""] + table(stats_fill)
md += ["", "Camera heights above the levelled plane (m): " + ", ".join(f"{h:.2f}" for h in heights)]
atomic_write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
print("\n".join(md))
