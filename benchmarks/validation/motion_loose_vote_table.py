"""One table of the motion route's hysteresis A/B (``--motion.loose-vote``), from the runs that made it:

  * the synthetic streets: ``motion_masks_scene.py SEED WORK OFF_STEM product --render-downscale 2`` and the
    same with ``--motion loose_vote=0.5`` into HALF_STEM (the masks stage's code, same references);
  * real captures: ``ns2gs-data masks CAPTURE --reference REF --motion.loose-vote V`` on a copy of the capture
    per arm, scored by ``moving_iou_hand_labels.py`` (one JSON per capture and arm).

Usage: python benchmarks/validation/motion_loose_vote_table.py OUT_STEM --synthetic OFF.json HALF.json
--real NAME OFF.json HALF.json [--real ...]. Writes OUT_STEM.{json,md}.
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.machine import machine_info
from nerf2gs_plugin.utils.io import atomic_write_text

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("out", type=Path)
ap.add_argument("--synthetic", nargs=2, type=Path, metavar=("OFF", "HALF"), required=True)
ap.add_argument("--real", nargs=3, action="append", default=[], metavar=("NAME", "OFF", "HALF"))
args = ap.parse_args()


def synthetic(path: Path) -> dict:
    doc = json.loads(path.read_text())
    return {f"seed {s}": {**row["product"]["2"]["settled"]["transient"], "motion": row["product"]["2"].get("motion", {})}
            for s, row in sorted(doc["seeds"].items())}


arms = {"off": {}, "half": {}}
for arm, path in zip(arms, args.synthetic):
    arms[arm].update(synthetic(path))
for name, *paths in args.real:
    for arm, path in zip(arms, paths):
        doc = json.loads(Path(path).read_text())
        arms[arm][name] = {k: doc["pooled"][k] for k in ("iou", "precision", "recall")} | {"frames": len(doc["pooled"]["frames"])}
doc = {"machine": machine_info(), "loose_vote": {"off": 1.0, "half": 0.5}, "transient": arms}
atomic_write_text(args.out.with_suffix(".json"), json.dumps(doc, indent=1))
cols = list(arms["off"])
lines = ["# The motion route's hysteresis (`--motion.loose-vote`), A/B through the masks stage", "",
         "Transient IoU (precision / recall) of the masks the stage writes (`--render-downscale 2`, second pass, neighbours "
         "agree; every other setting the default; the same first references in both arms). Synthetic streets: exact masks, "
         "all training frames. Real captures: hand labels on the labelled training frames (approximate polygons). "
         f"Machine: {doc['machine']['cpu']}, {doc['machine']['cores']} cores.", "",
         "| `loose_vote` | " + " | ".join(c + (f" ({arms['off'][c]['frames']} frames)" if "frames" in arms["off"][c] else "") for c in cols) + " |",
         "|---" * (len(cols) + 1) + "|"]
for arm, label in (("off", "1.0 (default)"), ("half", "0.5")):
    lines.append(f"| {label} | " + " | ".join(f"{arms[arm][c]['iou']:.3f} ({arms[arm][c]['precision']:.2f} / {arms[arm][c]['recall']:.2f})"
                                             for c in cols) + " |")
lines += ["", "See docs/masks-motion.md (\"Hysteresis\")."]
atomic_write_text(args.out.with_suffix(".md"), "\n".join(lines) + "\n")
print("\n".join(lines))
