"""``ns2gs-data masks --render-downscale 2`` with the motion route: masks from full-size renders vs
every other pixel, the motion route on half-size frames (as before) vs on the full-size frames with the
half-size renders upsampled (``masking/auto_masks.at_full_size``).

Reads a work folder of ``motion_masks_scene.py`` (synthetic street with movers: exact masks) or
``motion_masks_real.py`` (hand labels): its ``estimated`` capture and the cached full-size renders
``renders.pt``. The renders at every other pixel are those very pixels of the full-size renders (the
same rays with the same footprint: ``decimated``), so nothing is rendered here.

Usage: python benchmarks/validation/motion_render_downscale.py WORK (--street | --labels kitti|nuscenes FIRST) OUT.json
"""
import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import torch

torch.set_num_threads(1)
import nerf2gs_plugin.masks.auto as auto_mod  # noqa: E402

sys.modules.setdefault("nerf2gs_plugin.data.masks.auto", auto_mod)  # renders cached before masks/ moved
from nerf2gs_bench import real as br  # noqa: E402
from nerf2gs_plugin.data import parse_dataset  # noqa: E402
from nerf2gs_plugin.data.images import load_mask  # noqa: E402
from nerf2gs_plugin.masking.auto_masks import at_full_size, ground_plane, upsample  # noqa: E402
from nerf2gs_plugin.masks.auto import AutoOptions, Renders, masks_from_renders  # noqa: E402
from nerf2gs_plugin.masks.evaluate import resample_mask  # noqa: E402
from nerf2gs_plugin.masks.maskless import maskless_view  # noqa: E402
from nerf2gs_plugin.masks.motion import MotionOptions, add_motion  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("work", type=Path)
ap.add_argument("out", type=Path)
ap.add_argument("--street", action="store_true", help="score against WORK/street's exact masks")
ap.add_argument("--labels", nargs=2, metavar=("CAPTURE", "FIRST"), help="score against labels/CAPTURE_moving.json")
ap.add_argument("--step", type=int, default=2)
args = ap.parse_args()
work, d = args.work, args.step
full = torch.load(work / "renders.pt", weights_only=False)
view = maskless_view(work / "estimated")
train = parse_dataset(view, "train")
full.up, full.height = ground_plane(train, [])


def decimate(r: Renders) -> Renders:
    """What ``render_views(render_downscale=d)`` returns: the full render's pixels at every d-th pixel."""
    views = []
    for v in r.views["train"]:
        h, w = v["acc"].shape
        rows, cols = torch.arange(h // d) * d + d // 2, torch.arange(w // d) * d + d // 2
        fx, fy, cx, cy = (float(x) for x in v["intr"])
        shift = d // 2 + 0.5 - d / 2
        small = {k: v[k][rows][:, cols] for k in ("rgb", "depth", "acc", "dirs", "image")}
        views.append({**small, "origin": v["origin"], "c2w": v["c2w"], "name": v["name"],
                      "intr": torch.tensor([fx / d, fy / d, (cx - shift) / d, (cy - shift) / d]),
                      "full_image": v["image"], "full_intr": v["intr"], "step": d})
    return Renders({"train": views}, r.up, r.height, r.metres_to_world, 0.0, r.box_extent)


half = decimate(full)
names = [v["name"] for v in full.views["train"]]
shape = tuple(full.views["train"][0]["acc"].shape)
if args.street:
    street = work / "street"
    meta = json.loads((street / "transforms.json").read_text())
    em = {Path(f["file_path"]).name: f for f in json.loads((work / "estimated" / "transforms.json").read_text())["frames"]}
else:
    capture, first = args.labels[0], int(args.labels[1])
    labels = json.loads((Path(__file__).parent / "labels" / f"{capture}_moving.json").read_text())
    size = tuple(labels.get("size") or (shape[1], shape[0]))


def score(masks: list, kind: str) -> dict:
    c = np.zeros(4, dtype=np.int64)
    for name, m in zip(names, masks):
        pred = getattr(m, kind)
        if tuple(pred.shape) != shape:
            pred = upsample(pred, d, shape)  # as make_masks writes them
        if args.street:
            f, tf = em[name], meta["frames"][br.frame_index(Path(name))]
            gt = load_mask(street / tf[f"{kind}_mask_path"])
            pred = resample_mask(pred, (f["fl_x"], f["fl_y"], f["cx"], f["cy"]), (meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"]), tuple(gt.shape))
            keep = torch.ones_like(gt)
        else:
            key = f"{first + br.frame_index(Path(name)):04d}" if capture == "kitti" else f"{first + br.frame_index(Path(name)):06d}"
            if key not in labels["frames"]:
                continue
            g, ign = np.zeros(size[::-1], np.uint8), np.zeros(size[::-1], np.uint8)
            for what, poly in labels["frames"][key].items():
                polys = poly if what == "ignore" else [poly]
                cv2.fillPoly(ign if what == "ignore" else g, [np.array(q, np.int32) for q in polys], 1)
            keep = torch.from_numpy(ign == 0)
            gt = torch.from_numpy(g > 0) & keep
            pred = torch.from_numpy(cv2.resize(pred.numpy().astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0) & keep
        c += [int((pred & gt).sum()), int((pred | gt).sum()), int(pred.sum()), int(gt.sum())]
    i, u, p, t = (int(x) for x in c)
    return {"iou": round(i / max(u, 1), 4), "precision": round(i / max(p, 1), 4), "recall": round(i / max(t, 1), 4)}


rows = {}
for label, r, full_size in (("full renders", full, False), ("every other pixel, motion on half-size frames", half, False),
                            ("every other pixel, motion on full-size frames", half, True)):
    c0 = time.process_time()
    res = masks_from_renders(r, AutoOptions(), log=lambda s: None)
    add_motion(at_full_size(r, res) if full_size else r, res, MotionOptions(), log=lambda s: None, progress=False)
    cpu = round(time.process_time() - c0, 1)
    kinds = ("sky", "ground", "transient") if args.street else ("transient",)
    rows[label] = {**{k: score(res["train"], k) for k in kinds}, "maths_cpu_s": cpu}
    print(label, json.dumps(rows[label]), flush=True)
doc = json.loads(args.out.read_text()) if args.out.is_file() else {}
doc[work.name] = {"views": len(names), "size": list(shape[::-1]), "step": d, "rows": rows}
atomic_write_text(args.out, json.dumps(doc, indent=1))
