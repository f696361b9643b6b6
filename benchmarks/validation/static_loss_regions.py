"""Where a run loses against another on the static pixels of held-out frames labelled by hand: the squared
error split by region, the masks stage's false alarms (static by the hand labels, moving by the capture's own
transient masks) against the rest, and the bottom third of the frame against the top two thirds.

Usage: python benchmarks/validation/static_loss_regions.py CAPTURE BASE RUN [RUN ...] [--labels nuscenes_moving_heldout]
[--crop-rows 747] (CAPTURE: the runs' dataset, its held-out frames with masks/transient/ from ``ns2gs-data masks``
and hand labels; BASE: the run the others are compared with). Prints one line per region.
"""
import argparse
from pathlib import Path

import cv2
import numpy as np
import torch

from nerf2gs_bench.hand_labels import frame_key, frame_masks, load_labels
from nerf2gs_plugin.runs.load import load_run


def errors(run_dir: Path) -> list[np.ndarray]:
    """Per held-out image, in the split's order: the mean squared RGB error ``[H, W]`` of the run's render."""
    run = load_run(run_dir, device="cpu")
    dm, model = run.pipeline.datamanager, run.model
    model.eval()
    with torch.no_grad():
        return [((model.render_camera(camera)["rgb"] - batch["image"][..., :3]) ** 2).mean(-1).numpy()
                for camera, batch in dm.eval_images("test")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--labels", default="nuscenes_moving_heldout")
    ap.add_argument("--crop-rows", type=int)
    args = ap.parse_args()
    labels = load_labels(args.labels)
    from nerf2gs_plugin.data import dataparser_config

    stems = [f.image.stem for f in dataparser_config(args.capture).raw_frames()["test"]]
    errs = {r.name: errors(r) for r in args.runs}
    acc: dict[str, dict[str, list[float]]] = {}
    for k, stem in enumerate(stems):
        if frame_key(stem) not in labels["frames"]:
            continue
        h, w = errs[args.runs[0].name][k].shape
        moving, leave_out = frame_masks(labels["frames"][frame_key(stem)], labels, (w, h), args.crop_rows)
        hand = moving | leave_out
        est = cv2.resize(cv2.imread(str(args.capture / "masks" / "transient" / f"{stem}.png"), 0), (w, h),
                         interpolation=cv2.INTER_NEAREST) > 127
        top = np.arange(h)[:, None].repeat(w, 1) < 2 * h // 3
        for region, m in {"false alarms (static, marked moving)": ~hand & est, "the other static pixels": ~hand & ~est,
                          "static, top two thirds": ~hand & top, "static, bottom third": ~hand & ~top}.items():
            a = acc.setdefault(region, {n: [0.0, 0] for n in errs})
            for n in errs:
                a[n][0] += float(errs[n][k][m].sum())
                a[n][1] += int(m.sum())
    base = args.runs[0].name
    n_static = sum(acc[r][base][1] for r in ("false alarms (static, marked moving)", "the other static pixels"))
    for region, a in acc.items():
        psnr = {n: -10 * np.log10(v[0] / max(v[1], 1)) for n, v in a.items()}
        extra = {n: a[n][0] - a[base][0] for n in a if n != base}
        print(f"{region}: {a[base][1] / n_static:.1%} of the static pixels; PSNR " + ", ".join(f"{n} {p:.2f}" for n, p in psnr.items())
              + "; squared error over " + base + ": " + ", ".join(f"{n} {e:+.0f}" for n, e in extra.items()))


if __name__ == "__main__":
    main()
