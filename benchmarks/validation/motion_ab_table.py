"""One table of an A/B of the motion route's options, from the runs that made it, one JSON per arm and capture:

  * the synthetic streets: ``motion_masks_scene.py SEED WORK STEM product --render-downscale 2 [--motion KEY=VALUE ...]``
    per arm (the masks stage's code, the same references);
  * real captures: ``ns2gs-data masks CAPTURE --reference REF [--motion.KEY VALUE ...]`` on a copy of the capture per
    arm, scored by ``moving_iou_hand_labels.py``.

Usage: python benchmarks/validation/motion_ab_table.py OUT_STEM --title TITLE --see SECTION --arms LABEL ...
--synthetic ARM1.json ARM2.json ... [--real NAME ARM1.json ARM2.json ...] (one JSON per arm, in the order of ``--arms``).
Writes OUT_STEM.{json,md}.
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.machine import machine_info
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig
from nerf2gs_plugin.utils.io import atomic_write_text

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("out", type=Path)
ap.add_argument("--title", required=True, help="the table's heading")
ap.add_argument("--see", required=True, help="the section of docs/masks-motion.md that discusses it")
ap.add_argument("--arms", nargs="+", required=True, help="a label per arm: the options it ran with")
ap.add_argument("--synthetic", nargs="+", type=Path, default=[])
ap.add_argument("--real", nargs="+", action="append", default=[], metavar="NAME JSON")
args = ap.parse_args()


STREET = SynthStreetConfig()


def street_name(seed: str, scene: dict) -> str:
    """The column of a street: its seed, and its frames' spacing where the drive has other than the generator's
    number of training views (half of them one way along the drive)."""
    views = scene.get("num_train", STREET.num_train)
    if views == STREET.num_train:
        return f"seed {seed}"
    return f"seed {seed}, {2 * STREET.drive_half_len / ((views + 1) // 2 - 1):.1f} m a frame"


def synthetic(path: Path) -> dict:
    doc = json.loads(path.read_text())
    return {street_name(s, row["scene"]): {**row["product"]["2"]["settled"]["transient"], "motion": row["product"]["2"].get("motion", {})}
            for s, row in sorted(doc["seeds"].items())}


arms: dict = {label: {} for label in args.arms}
for arm, path in zip(arms, args.synthetic):
    arms[arm].update(synthetic(path))
for name, *paths in args.real:
    for arm, path in zip(arms, paths):
        doc = json.loads(Path(path).read_text())
        arms[arm][name] = {k: doc["pooled"][k] for k in ("iou", "precision", "recall")} | {"frames": len(doc["pooled"]["frames"])}
doc = {"machine": machine_info(), "transient": arms}
atomic_write_text(args.out.with_suffix(".json"), json.dumps(doc, indent=1))
first = arms[args.arms[0]]
cols = list(first)
lines = [f"# {args.title}", "",
         "Transient IoU (precision / recall) of the masks the stage writes (`--render-downscale 2`, second pass, neighbours "
         "agree; every other setting the default; the same first references in every arm). Synthetic streets: exact masks, "
         "all training frames. " + ("Real captures: hand labels on the labelled training frames (approximate polygons). " if args.real else "") +
         f"Machine: {doc['machine']['cpu']}, {doc['machine']['cores']} cores.", "",
         "| arm | " + " | ".join(c + (f" ({first[c]['frames']} frames)" if "frames" in first[c] else "") for c in cols) + " |",
         "|---" * (len(cols) + 1) + "|"]
for arm in args.arms:
    lines.append(f"| {arm} | " + " | ".join(f"{arms[arm][c]['iou']:.3f} ({arms[arm][c]['precision']:.2f} / {arms[arm][c]['recall']:.2f})"
                                             for c in cols) + " |")
lines += ["", f"See docs/masks-motion.md (\"{args.see}\")."]
atomic_write_text(args.out.with_suffix(".md"), "\n".join(lines) + "\n")
print("\n".join(lines))
