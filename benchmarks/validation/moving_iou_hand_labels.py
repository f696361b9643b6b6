"""Moving-object IoU of a capture's masks (``ns2gs-data masks``) against hand labels, per frame and pooled.

The labelled training frames of CAPTURE (the masks stage marks those) are scored against the moving objects
of the named label files (``labels/<name>.json``; where two label a frame the first named wins); 'ignore'
regions and the bonnet count neither way. The capture's frames must be the labels' source frames (trailing
digits of the name: ``frame_000031.jpg`` <-> ``000031``), their first ``--crop-rows`` source rows kept and resized.

``--complete-hit H [H ...]`` adds a bound: the IoU had every labelled object that the masks cover by more than
the share H been marked whole (what completing the objects the masks find could give; nothing new found).

Usage: python benchmarks/validation/moving_iou_hand_labels.py CAPTURE OUT_STEM --labels NAME [NAME ...]
[--crop-rows 747] [--frame-offset 1] [--complete-hit 0.05 0.2]. Writes OUT_STEM.{json,md}.
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.hand_labels import completion_bound, frame_key, merged_labels, moving_scores
from nerf2gs_plugin.utils.io import atomic_write_text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--labels", nargs="+", required=True)
    ap.add_argument("--crop-rows", type=int, help="the source rows the capture's frames keep (a bonnet cut off); default: all")
    ap.add_argument("--frame-offset", type=int, default=0, help="label key = the frame's number + this (a video's frame_000075 "
                    "is source frame 0076 of a folder numbered from 1: 1)")
    ap.add_argument("--complete-hit", type=float, nargs="*", default=[],
                    help="also the IoU had every labelled object the masks cover by more than this share been marked whole")
    args = ap.parse_args()
    labels = merged_labels(args.labels)
    width = len(next(iter(labels["frames"])))

    def key_of(stem: str) -> str | None:
        key = frame_key(stem)
        return None if key is None else f"{int(key) + args.frame_offset:0{width}d}"

    pooled = moving_scores(args.capture, labels, args.crop_rows, key_of)
    if pooled is None:
        raise SystemExit(f"{args.capture}: no labelled training frame with a transient mask")
    per_frame = pooled.pop("per_frame")
    bounds = {str(h): completion_bound(args.capture, labels, args.crop_rows, key_of, h) for h in args.complete_hit}
    from nerf2gs_bench.machine import machine_info

    doc = {"machine": machine_info(), "capture": str(args.capture), "labels": args.labels, "crop_rows": args.crop_rows,
           "pooled": pooled, "per_frame": per_frame, "completion_bound": bounds}
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(doc, indent=1))
    lines = [f"# Moving-object IoU against hand labels ({', '.join(args.labels)})", "",
             f"Capture {args.capture.resolve().parent.name}/{args.capture.name} (its source frames' first {args.crop_rows or 'all'} "
             "rows); its masks stage's transient masks on the labelled training frames. 'ignore' regions and the bonnet "
             "count neither way.", "", "| frame | IoU | precision | recall |", "|---|---|---|---|"]
    for stem, s in per_frame.items():
        lines.append(f"| {stem} | {s['iou']:.3f} | {s['precision']:.2f} | {s['recall']:.2f} |")
    lines.append(f"| **pooled** | **{pooled['iou']:.3f}** | {pooled['precision']:.2f} | {pooled['recall']:.2f} |")
    for h, b in bounds.items():
        lines.append(f"\nEvery labelled object the masks cover by more than {float(h):.0%} marked whole: IoU {b['iou']:.3f} "
                     f"(precision {b['precision']:.2f}, recall {b['recall']:.2f}).")
    atomic_write_text(args.out.with_suffix(".md"), "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
