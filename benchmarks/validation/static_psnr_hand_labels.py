"""Static PSNR of held-out frames against hand labels, beside the masks stage's estimate.

``ns2gs-eval`` scores static pixels outside ``masks/transient/<image>.png``; for held-out frames those are
the masks stage's own estimate (``ns2gs-data masks --splits test``), whose misses count the movers as
static. This script scores the same runs on a view of the capture whose held-out frames carry hand-drawn
labels instead (``labels/<name>.json``, in the source frames' pixels: 'moving' and 'ignore' polygons and the
'ego' polygon all leave the score). The capture's frames must be the labels' source frames
(``frame_000031.jpg`` <-> key ``000031``), their first ``--crop-rows`` rows kept and resized: the real path's
capture (``ns2gs-bench real-path-speed --capture nuscenes [--crop-bottom F]``).

Usage: python benchmarks/validation/static_psnr_hand_labels.py CAPTURE OUT_STEM RUN [RUN ...]
[--labels nuscenes_moving_heldout] [--crop-rows 810] [--estimated CAPTURE_WITH_ALL_MASKS]
Writes OUT_STEM.{json,md}: per run, PSNR over all pixels, static PSNR on the estimated masks and on the
hand labels (held-out frames that have both), Gaussians.
"""
import argparse
import json
import tempfile
from pathlib import Path

from nerf2gs_bench.hand_labels import labelled_view, load_labels
from nerf2gs_plugin.utils.io import atomic_write_text


def evaluate(run: Path, data: Path | None) -> dict:
    from nerf2gs_plugin.eval.evaluate import evaluate_run
    from nerf2gs_plugin.runs.load import load_run

    loaded = load_run(run, device="cpu", data=data)
    doc = evaluate_run(loaded, ["test"])
    res = doc["results"]["test"]
    return {"psnr": res["psnr"], "static_psnr": res["static_psnr"], "static_psnr_images": res["static_psnr_images"],
            "primitives": doc["size"].get("primitives")}


def _static(r: dict) -> str:
    """Static PSNR and the images it is over (n/a where no held-out frame has a mask)."""
    return "n/a" if r["static_psnr"] is None else f"{r['static_psnr']:.2f} ({r['static_psnr_images']})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--labels", default="nuscenes_moving_heldout")
    ap.add_argument("--crop-rows", type=int, help="the source rows the capture's frames keep (a bonnet cut off: "
                    "real-path-speed --crop-bottom); default: all")
    ap.add_argument("--estimated", type=Path, help="the same capture with the masks stage's masks of every frame "
                    "(ns2gs-data masks over all splits); default: CAPTURE's own masks")
    args = ap.parse_args()
    labels = load_labels(args.labels)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        view = Path(tmp) / args.capture.name
        stems = labelled_view(args.capture, labels, view, args.crop_rows)
        for run in args.runs:
            rows[run.name] = {"estimated": evaluate(run, args.estimated), "hand": evaluate(run, view)}
            print(run.name, json.dumps(rows[run.name]))
    from nerf2gs_bench.machine import machine_info, machine_line

    doc = {"machine": machine_info(), "capture": str(args.capture), "crop_rows": args.crop_rows, "estimated": str(args.estimated or args.capture), "labels": args.labels, "labelled_frames": stems, "runs": rows}
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(doc, indent=1))
    lines = [f"# Static PSNR of held-out frames: estimated masks vs hand labels ({args.labels})", "",
             f"Machine: {machine_line(doc['machine'])}. Capture {args.capture.resolve().parent.name} (its source frames' first "
             f"{args.crop_rows or 'all'} rows); labelled held-out frames: {', '.join(stems)}. Hand labels: the moving "
             "objects, the undecided ones and the bonnet leave the score. Estimated: the masks stage's transient masks of "
             f"{'every frame (' + args.estimated.name + ')' if args.estimated else 'the capture'}.", "",
             "| run | PSNR (all) | static, estimated masks | static, hand labels | primitives |", "|---|---|---|---|---|"]
    for name, r in rows.items():
        e, h = r["estimated"], r["hand"]
        lines.append(f"| {name} | {e['psnr']:.2f} | {_static(e)} | {_static(h)} | {e['primitives']} |")
    atomic_write_text(args.out.with_suffix(".md"), "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
