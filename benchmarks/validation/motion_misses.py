"""Where the masks stage's moving-object masks fall short on a synthetic street with movers: recall per kind
of mover (``nerf2gs_bench/mover_kinds.py``) and where the static pixels they mark lie (on the ground, beside a
mover), for the stage's masks as ``motion_masks_scene.py SEED WORK ... product`` makes them (same WORK: its
street, capture and first reference).

``--oracle-exclusion``: the second pass's reference is trained with only the first pass's pixels within
``ORACLE_PX`` of a true mover left out of its loss (the rest of the first pass, e.g. the road between the
camera and a car riding ahead, stays in it), and judges the same first-pass masks: what the best exclusion set
could buy.

Usage: python benchmarks/validation/motion_misses.py SEED WORK OUT_STEM [--render-downscale 2] [--frames 100]
[--oracle-exclusion] [--reuse-reference] [--motion KEY=VALUE ...]. Writes OUT_STEM.{json,md}.
"""
import argparse
import ast
import json
from contextlib import contextmanager, nullcontext
from pathlib import Path

import cv2
import numpy as np
import torch

from nerf2gs_bench import mover_kinds as mk
from nerf2gs_bench import real as br
from nerf2gs_bench.machine import machine_line
from nerf2gs_bench.motion_product import ensure_keyed_reference, product_masks
from nerf2gs_plugin.data.images import load_mask
from nerf2gs_plugin.masks.evaluate import resample_mask
from nerf2gs_plugin.masks.motion import MotionOptions
from nerf2gs_plugin.utils.io import atomic_write_text

LABELS = (("without_motion", "residual route alone"), ("first_pass", "+ motion route"), ("second_pass", "+ second pass"),
          ("settled", "+ neighbours agree (the stage's masks)"))
ORACLE_PX = 4
ONCOMING = "traffic, oncoming"


def scores(preds, gts) -> dict:
    """Pooled IoU, precision and recall of bool masks against the exact ones."""
    c = np.array([[int((p & g).sum()), int((p | g).sum()), int(p.sum()), int(g.sum())] for p, g in zip(preds, gts)]).sum(0)
    return {"iou": round(c[0] / max(c[1], 1), 4), "precision": round(c[0] / max(c[2], 1), 4), "recall": round(c[0] / max(c[3], 1), 4)}


@contextmanager
def oracle_exclusion(truth: dict[str, torch.Tensor]):
    """The second pass's training masks (``masking/second_pass.masked_view``) cut to the pixels within
    ``ORACLE_PX`` of ``truth`` (stem -> exact mover mask on the capture's pixel grid)."""
    import nerf2gs_plugin.masking.second_pass as sp

    orig = sp.masked_view
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * ORACLE_PX + 1, 2 * ORACLE_PX + 1))

    def cut(view, transient):
        return orig(view, {s: m & torch.from_numpy(cv2.dilate(truth[s].numpy().astype(np.uint8), disc) > 0) for s, m in transient.items()})

    sp.masked_view = cut
    try:
        yield
    finally:
        sp.masked_view = orig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", type=int)
    ap.add_argument("work", type=Path, help="motion_masks_scene.py's WORK: street/, estimated/, reference/")
    ap.add_argument("out", type=Path, help="OUT_STEM")
    ap.add_argument("--render-downscale", type=int, default=2)
    ap.add_argument("--frames", type=int, default=100, help="the first FRAMES of the street's training views are the drive")
    ap.add_argument("--oracle-exclusion", action="store_true")
    ap.add_argument("--reuse-reference", action="store_true")
    ap.add_argument("--motion", nargs="+", default=[], metavar="KEY=VALUE", help="motion options other than the defaults (Python literals)")
    args = ap.parse_args()
    motion = MotionOptions(**{k: ast.literal_eval(v) for k, v in (kv.split("=", 1) for kv in args.motion)})
    street, capture, reference = args.work / "street", args.work / "estimated", args.work / "reference"
    if not (capture / "transforms.json").is_file():
        raise SystemExit(f"{capture}: no capture; run motion_masks_scene.py {args.seed} {args.work} ... product first")
    meta = json.loads((street / "transforms.json").read_text())
    em = {Path(f["file_path"]).name: f for f in json.loads((capture / "transforms.json").read_text())["frames"]}
    true_pin = (meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"])
    key = ensure_keyed_reference(capture, reference, args.reuse_reference)

    def truth_on(name: str, kind: str, hw: tuple[int, int]) -> torch.Tensor:
        f, tf = em[name], meta["frames"][br.frame_index(Path(name))]
        return resample_mask(load_mask(street / tf[f"{kind}_mask_path"]), true_pin, (f["fl_x"], f["fl_y"], f["cx"], f["cy"]), hw)

    names = sorted(n for n in em if br.frame_index(Path(n)) < args.frames)
    truth = {Path(n).stem: truth_on(n, "transient", (int(em[n]["h"]), int(em[n]["w"]))) for n in names}
    with oracle_exclusion(truth) if args.oracle_exclusion else nullcontext():
        res = product_masks(capture, reference, args.render_downscale, motion=motion)
    tfs = [meta["frames"][br.frame_index(Path(n))] for n in res["names"]]
    kinds = mk.kind_ids(args.seed, tfs, (*true_pin, meta["w"], meta["h"]))
    gts = [load_mask(street / tf["transient_mask_path"]) for tf in tfs]
    grounds = [load_mask(street / tf["ground_mask_path"]) for tf in tfs]
    rows = {}
    for label, _ in LABELS:
        preds = []
        for name, m, g in zip(res["names"], res[label], gts):
            f = em[name]
            preds.append(resample_mask(m.transient, (f["fl_x"], f["fl_y"], f["cx"], f["cy"]), true_pin, tuple(g.shape)))
        rows[label] = {**scores(preds, gts), "recall_by_kind": mk.recall_by_kind(preds, kinds), **mk.static_marked(preds, gts, grounds),
                       "without_oncoming": scores(*zip(*((p & ~k[ONCOMING], g & ~k[ONCOMING]) for p, g, k in zip(preds, gts, kinds))))}
        print(label, {k: rows[label][k] for k in ("iou", "precision", "recall", "static_marked_ground_share")}, flush=True)
    doc = {"seed": args.seed, "frames": args.frames, "train_views": len(res["names"]), "render_downscale": args.render_downscale,
           "oracle_exclusion": args.oracle_exclusion, "reference": key, "timings": res["timings"], "rows": rows,
           "options": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(motion).items()}, "machine": machine_line()}
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(doc, indent=1))
    md = [f"# Where the motion masks fall short: seed {args.seed} street, {args.frames} frames"
          + (" (second pass: oracle exclusion set)" if args.oracle_exclusion else ""), "",
          f"Machine: {doc['machine']}. `benchmarks/validation/motion_misses.py`; the masks stage's code (`--render-downscale "
          f"{args.render_downscale}`), {len(res['names'])} training views, exact masks and object ids of the street.", "",
          "| masks | IoU (P / R) | IoU without oncoming traffic (P / R) | " + " | ".join(f"recall: {k}" for k in mk.KINDS)
          + f" | static marked: on the ground / within {mk.NEAR_PX} px of a mover |", "|---|---|---|" + "---|" * (len(mk.KINDS) + 1)]
    for label, text in LABELS:
        r = rows[label]
        w = r["without_oncoming"]
        md.append(f"| {text} | {r['iou']:.3f} ({r['precision']:.2f} / {r['recall']:.2f}) | {w['iou']:.3f} ({w['precision']:.2f} / {w['recall']:.2f}) | "
                  + " | ".join(f"{r['recall_by_kind'][k]['recall']:.2f}" for k in mk.KINDS)
                  + f" | {r['static_marked_ground_share']:.2f} / {r['static_marked_near_share']:.2f} |")
    tot = sum(v["pixels"] for v in rows["settled"]["recall_by_kind"].values())
    md += ["", "Share of the mover pixels by kind: " + ", ".join(
        f"{k} {v['pixels'] / max(tot, 1):.2f}" for k, v in rows["settled"]["recall_by_kind"].items())
        + ". Without oncoming traffic: its pixels left out of the score (neither found nor marked)."]
    atomic_write_text(args.out.with_suffix(".md"), "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
