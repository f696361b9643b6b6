"""The motion route on real dashcam frames labelled by hand, two captures (fetch them, nothing is
downloaded here):

  * ``nuscenes``: CAM_FRONT frames (the ``image_2/`` folder of github:youngibby/nuscene, 1600x900 at
    2 Hz), the bonnet cropped (rows 0-789) and resized to 480x237, 64.6 deg FOV, camera 1.5 m up;
  * ``kitti``: the KITTI excerpt of github:rahulagrawal048/kitti-odometry (``kitti/0001-0133.png``,
    800x240; its frames 1.2 camera heights apart by its SfM: not consecutive 10 Hz frames), 81 deg FOV, camera 1.65 m up.

Frames FIRST..FIRST+N-1 as a video -> ``process video`` -> 1000-step mask-less reference -> transient
masks without / with the motion route, scored against ``labels/<capture>_moving.json`` (polygons drawn
by eye on the frames at the size given there: approximate outlines of the clearly moving objects;
'ignore' regions, objects whose motion cannot be told, count neither way) on the labelled frames that
are training frames.

``--product D ...``: instead, the masks stage's code at each render_downscale D
(``nerf2gs_bench/motion_product.py``, as ``ns2gs-data masks`` runs it, with the second pass; rows without
motion, before the second pass and after it), into the entry's ``product``.

Usage: python benchmarks/validation/motion_masks_real.py IMAGE_DIR WORK OUT_STEM [FIRST N] [--capture kitti]
[--product D ...] [--reuse-reference]
(WORK keeps the crops, capture, reference and renders). Writes OUT_STEM.json's ``real`` entry (nuScenes)
or ``real_<capture>`` (merged).
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

CAPTURES = {  # crop rows (None: all), size, FOV (deg), camera height (m), file name digits, results key
    "nuscenes": (790, (480, 237), 64.6, 1.5, 6, "real"),
    "kitti": (None, (800, 240), 81.0, 1.65, 4, "real_kitti"),
}
parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("src", type=Path, help="nuScenes image_2/ folder")
parser.add_argument("work", type=Path, help="work folder (crops, capture, reference, renders)")
parser.add_argument("out", type=Path, help="results stem (OUT.json's 'real' entry is merged)")
parser.add_argument("first", type=int, nargs="?", default=25)
parser.add_argument("n", type=int, nargs="?", default=30)
parser.add_argument("--capture", choices=sorted(CAPTURES), default="nuscenes")
parser.add_argument("--product", type=int, nargs="+", metavar="D", help="the masks stage at render_downscale D (ns2gs-data masks: 2)")
parser.add_argument("--reuse-reference", action="store_true", help="--product: keep a reference trained by other model code (recorded as stale)")
args = parser.parse_args()
src, work, out, first, n = args.src, args.work, args.out, args.first, args.n
CROP_ROWS, SIZE, FOV, CAM_H, DIGITS, KEY = CAPTURES[args.capture]
labels = json.loads((Path(__file__).parent / "labels" / f"{args.capture}_moving.json").read_text())
crop = work / "crop"
crop.mkdir(parents=True, exist_ok=True)
files = []
for k in range(first, first + n):
    p = crop / f"{k:0{DIGITS}d}.png"
    if not p.is_file():
        cv2.imwrite(str(p), cv2.resize(cv2.imread(str(src / f"{k:0{DIGITS}d}.png"))[:CROP_ROWS], SIZE, interpolation=cv2.INTER_AREA))
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



def score(names: list, masks: list, save_preds: bool = False) -> tuple[dict, list]:
    """IoU / precision / recall of ``masks``' transients on the labelled training frames, and those frames."""
    c, used = np.zeros(4, dtype=np.int64), []
    for name, m in zip(names, masks):
        key = f"{first + br.frame_index(Path(name)):0{DIGITS}d}"  # frame_000004 is the 5th frame of the drive
        if key not in labels["frames"]:
            continue
        gt, ignore = np.zeros(SIZE[::-1], np.uint8), np.zeros(SIZE[::-1], np.uint8)
        for what, poly in labels["frames"][key].items():
            polys = poly if what == "ignore" else [poly]
            cv2.fillPoly(ignore if what == "ignore" else gt, [np.array(q, np.int32) for q in polys], 1)
        keep = ignore == 0  # an ignore region counts neither way
        pred = (cv2.resize(m.transient.numpy().astype(np.uint8), SIZE, interpolation=cv2.INTER_NEAREST) > 0) & keep
        gt = (gt > 0) & keep
        if save_preds:
            cv2.imwrite(str(work / f"pred_{key}.png"), np.stack([gt * 255, pred * 255, ignore * 120], -1).astype(np.uint8))
        c += [int((pred & gt).sum()), int((pred | gt).sum()), int(pred.sum()), int(gt.sum())]
        used.append(key)
    i, u, p, t = (int(x) for x in c)
    return {"iou": round(i / max(u, 1), 4), "precision": round(i / max(p, 1), 4), "recall": round(i / max(t, 1), 4)}, used


def merge(entry: dict) -> None:
    """``entry`` into OUT_STEM.json's entry for this capture (read just before: other runs write the file too)."""
    doc = json.loads(out.with_suffix(".json").read_text()) if out.with_suffix(".json").is_file() else {"seeds": {}}
    doc[KEY] = {**doc.get(KEY, {}), **entry}
    atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
    print(json.dumps(doc[KEY], indent=1))


if args.product:
    from nerf2gs_bench.motion_product import ensure_keyed_reference, product_masks  # noqa: E402

    ref_key = ensure_keyed_reference(capture, work / "reference", args.reuse_reference)
    prod = {}
    for d in args.product:
        res = product_masks(capture, work / "reference", d)
        prod[str(d)] = {label: score(res["names"], res[label])[0] for label in ("without_motion", "first_pass", "second_pass", "settled")}
        prod[str(d)].update(timings=res["timings"], reference=ref_key, train_views=len(res["names"]))
        print("product", d, prod[str(d)], flush=True)
    prev = json.loads(out.with_suffix(".json").read_text()).get(KEY, {}) if out.with_suffix(".json").is_file() else {}
    merge({"product": {**prev.get("product", {}), **prod}})
    raise SystemExit(0)
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
add_motion(r, motion, MotionOptions(), log=print, progress=False)
seconds = round(time.perf_counter() - t0, 1)
LEVERS = {  # the route's defaults changed one at a time
    "no residual gate": {"residual_rel": 0.0}, "no outlines": {"outline": False}, "carry test on (0.5)": {"carry": 0.5},
    "none of the three (the route before them)": {"residual_rel": 0.0, "outline": False}}
variants = []
for label, kw in LEVERS.items():
    variants.append((label, masks_from_renders(r, AutoOptions(), log=lambda s: None)))
    add_motion(r, variants[-1][1], MotionOptions(**kw), log=lambda s: None, progress=False)
rows, used = {}, []
for label, res in (("without_motion", base), ("with_motion", motion), *variants):
    rows[label], frames_used = score(names, res["train"], save_preds=label == "with_motion")
    used = frames_used if label == "with_motion" else used
merge({"capture": f"{labels['source']}; frames {first}-{first + n - 1}", "size": list(SIZE), "registered": len(names) and len(json.loads((capture / "transforms.json").read_text())["frames"]),
       "train_views": len(names), "labelled_frames": used, "labels": labels["how"], "motion_s": seconds,
       "without_motion": rows["without_motion"], "with_motion": rows["with_motion"], "levers": {k: rows[k] for k in LEVERS}})
