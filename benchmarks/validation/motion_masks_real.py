"""The motion route on real dashcam frames labelled by hand: nuScenes CAM_FRONT frames (the
``image_2/`` folder of github:youngibby/nuscene, 1600x900 at 2 Hz; fetch it, nothing is downloaded
here), the bonnet cropped (rows 0-789) and resized to 480x237, frames FIRST..FIRST+N-1 as a video ->
``process video`` (64.6 deg FOV, camera 1.5 m up) -> 1000-step mask-less reference -> transient masks
without / with the motion route, scored against ``labels/nuscenes_moving.json`` (polygons drawn by eye
on the 480x237 crops: approximate outlines of the clearly moving objects; 'ignore' regions, objects
whose motion cannot be told, count neither way) on the labelled frames that
are training frames.

Usage: python benchmarks/validation/motion_masks_real.py NUSCENES_IMAGE_DIR WORK OUT_STEM [FIRST N]
(WORK keeps the crops, capture, reference and renders). Writes OUT_STEM.json's ``real`` entry (merged).
"""
import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np
import torch

torch.set_num_threads(1)
from nerf2gs_bench import real as br  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

CROP_ROWS, SIZE, FOV, CAM_H = 790, (480, 237), 64.6, 1.5
parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("src", type=Path, help="nuScenes image_2/ folder")
parser.add_argument("work", type=Path, help="work folder (crops, capture, reference, renders)")
parser.add_argument("out", type=Path, help="results stem (OUT.json's 'real' entry is merged)")
parser.add_argument("first", type=int, nargs="?", default=25)
parser.add_argument("n", type=int, nargs="?", default=30)
args = parser.parse_args()
src, work, out, first, n = args.src, args.work, args.out, args.first, args.n
labels = json.loads((Path(__file__).parent / "labels" / "nuscenes_moving.json").read_text())
crop = work / "crop"
crop.mkdir(parents=True, exist_ok=True)
files = []
for k in range(first, first + n):
    p = crop / f"{k:06d}.png"
    if not p.is_file():
        cv2.imwrite(str(p), cv2.resize(cv2.imread(str(src / f"{k:06d}.png"))[:CROP_ROWS], SIZE, interpolation=cv2.INTER_AREA))
    files.append(p)
capture = work / "estimated"
if not (capture / "transforms.json").is_file():
    br.process_capture(br.write_video(work / "drive.avi", files), capture, n, FOV, CAM_H)
from nerf2gs_plugin.data import parse_dataset  # noqa: E402
from nerf2gs_plugin.masks.auto import AutoOptions, masks_from_renders  # noqa: E402
from nerf2gs_plugin.masking.auto_masks import ground_plane, render_views  # noqa: E402
from nerf2gs_plugin.masking.mask_reference import ensure_reference  # noqa: E402
from nerf2gs_plugin.masks.maskless import maskless_view  # noqa: E402
from nerf2gs_plugin.masks.motion import MotionOptions, add_motion  # noqa: E402

view = maskless_view(capture)
cache = work / "renders.pt"
if cache.is_file():
    r = torch.load(cache, weights_only=False)
else:
    ensure_reference(capture, work / "reference", 1000, progress=False)
    r = render_views(view, work / "reference", ["train"], progress=False)
    torch.save(r, cache)
train = parse_dataset(view, "train")
r.up, r.height = ground_plane(train, [])
names = [q.name for q in train.image_filenames]
base = masks_from_renders(r, AutoOptions(), log=lambda s: None)
t0 = time.perf_counter()
motion = masks_from_renders(r, AutoOptions(), log=lambda s: None)
add_motion(r, motion, MotionOptions(enabled=True), log=print, progress=False)
seconds = round(time.perf_counter() - t0, 1)
rows, used = {}, []
for label, res in (("without_motion", base), ("with_motion", motion)):
    c = np.zeros(4, dtype=np.int64)
    for name, m in zip(names, res["train"]):
        key = f"{first + br.frame_index(Path(name)):06d}"  # frame_000004 is the 5th frame of the drive
        if key not in labels["frames"]:
            continue
        gt, ignore = np.zeros(SIZE[::-1], np.uint8), np.zeros(SIZE[::-1], np.uint8)
        for what, poly in labels["frames"][key].items():
            polys = poly if what == "ignore" else [poly]
            cv2.fillPoly(ignore if what == "ignore" else gt, [np.array(q, np.int32) for q in polys], 1)
        keep = ignore == 0  # an ignore region counts neither way
        pred = (cv2.resize(m.transient.numpy().astype(np.uint8), SIZE, interpolation=cv2.INTER_NEAREST) > 0) & keep
        gt = (gt > 0) & keep
        if label == "with_motion":
            cv2.imwrite(str(work / f"pred_{key}.png"), np.stack([gt * 255, pred * 255, ignore * 120], -1).astype(np.uint8))
        c += [int((pred & gt).sum()), int((pred | gt).sum()), int(pred.sum()), int(gt.sum())]
        used.append(key) if label == "with_motion" else None
    i, u, p, t = (int(x) for x in c)
    rows[label] = {"iou": round(i / max(u, 1), 4), "precision": round(i / max(p, 1), 4), "recall": round(i / max(t, 1), 4)}
doc = json.loads(out.with_suffix(".json").read_text()) if out.with_suffix(".json").is_file() else {"seeds": {}}
doc["real"] = {"capture": "nuScenes CAM_FRONT (github:youngibby/nuscene image_2/), frames "
               f"{first}-{first + n - 1}, bonnet cropped, {SIZE[0]}x{SIZE[1]}", "registered": len(names) and len(json.loads((capture / "transforms.json").read_text())["frames"]),
               "train_views": len(names), "labelled_frames": used, "labels": labels["how"], "motion_s": seconds, **rows}
atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
print(json.dumps(doc["real"], indent=1))
