"""``process``'s capture check on finished captures: the largest jump of the camera's height above its road
along each capture, the largest jump of its path (ordered captures: sequential matching), and, where the true poses are known, the pose error of the whole capture and of
each stretch on either side of the split it found (a wrong join: each stretch right, the whole wrong).

Usage: python benchmarks/validation/scale_check.py OUT LABEL=DATA[:GT_TRANSFORMS] [LABEL=DATA[:GT] ...]
(DATA: a folder written by ``ns2gs-data process``; GT_TRANSFORMS: a transforms.json with the true
poses of the same image names). Writes OUT.json and OUT.md.
Produced benchmarks/results/scale_check.{json,md}.
"""
import argparse
import json
from pathlib import Path

import numpy as np
import pycolmap

from nerf2gs_plugin.data.process import export
from nerf2gs_plugin.data.process.capture_check import check_reconstruction
from nerf2gs_plugin.data.process.scale_check import MAX_HEIGHT_JUMP, MAX_STEP_JUMP, MAX_STEP_JUMP_PHOTOS, local_camera_heights
from nerf2gs_bench.machine import machine_info, machine_line
from nerf2gs_plugin.eval.pose_eval import pose_errors
from nerf2gs_plugin.utils.io import atomic_write_text

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("out", type=Path)
ap.add_argument("captures", nargs="+", help="LABEL=DATA[:GT_TRANSFORMS]")
args = ap.parse_args()
out = args.out
rows = []
for arg in args.captures:
    label, rest = arg.split("=", 1)
    data, _, gt = rest.partition(":")
    data = Path(data)
    rec = pycolmap.Reconstruction(str(data / "sparse" / "0"))
    names, c2w, _ = model_arrays.camera_arrays(rec)
    meta = json.loads((data / "transforms.json").read_text())
    up = np.asarray(meta["up"])
    heights = local_camera_heights(c2w[:, :3, 3], model_arrays.observed_points(rec, names), up)
    check = check_reconstruction(rec, names, c2w, up, ordered=meta["process"]["source"] == "video" or meta["process"]["matching"] == "sequential")
    line = check.pop("line")
    row = {"label": label, "data": str(data), "matching": meta["process"]["matching"], **check,
           "height_ratio_percentiles_5_50_95": [float(v) for v in np.nanpercentile(heights / np.nanmedian(heights), [5, 50, 95])]}
    if gt:
        true = {Path(f["file_path"]).name: np.asarray(f["transform_matrix"])[:3] for f in json.loads(Path(gt).read_text())["frames"]}
        T = np.stack([true[n] for n in names])
        k = (check["path_jump"]["index"] + 1 if check["path_jump"] and not check["path_jump"]["consistent"]
             else check["split"]) or len(names)
        parts = {"whole": slice(None), "before split": slice(0, k), "from split": slice(k, None)}
        row["ate_percent"] = {p: float(pose_errors(c2w[s], T[s]).ate_percent) for p, s in parts.items() if len(names[s]) >= 3}
        row["sim3_scale"] = {p: float(pose_errors(c2w[s], T[s]).scale) for p, s in parts.items() if len(names[s]) >= 3}
        row["scale_error_percent"] = 100.0 * (float(meta["metres_per_unit"]) / row["sim3_scale"]["whole"] - 1.0)
    rows.append(row)
    print(label, line, sep="\n  ", flush=True)

doc = {"machine": machine_info(), "max_height_ratio": MAX_HEIGHT_JUMP, "max_step_ratio": MAX_STEP_JUMP,
       "max_step_ratio_photos": MAX_STEP_JUMP_PHOTOS, "rows": rows}
md = ["# Scale check of `ns2gs-data process`: one scale along the capture?", "",
      f"Machine: {machine_line(doc['machine'])}", "",
      "Each camera's height above the road it sees (90th percentile of the drops to the sparse points it observes "
      "below it, SfM units); the change point of their logs along the capture (least absolute deviations from each "
      f"stretch's median); flagged when the two stretches' medians differ by more than {MAX_HEIGHT_JUMP:g}x. The path: "
      "the largest step between consecutive frames (name order) over the median of the 5 steps on each side, flagged "
      f"above {MAX_STEP_JUMP:g}x for a video or sequentially matched photos, above {MAX_STEP_JUMP_PHOTOS:g}x for a photo set matched "
      "exhaustively. ATE (% of the trajectory) after a Sim(3) to the true poses, for the "
      "whole capture and each stretch (split at the path jump when flagged, else at the height split); the metric scale "
      "`process` set from the camera height against the whole capture's Sim(3) scale.", "",
      "| capture | matching | frames | height ratio | height split at | path jump (steps) | jump between | flagged | height / median (5th, 50th, 95th pct) | ATE % whole / before / from split | Sim(3) scale before / from split | metric scale error % |",
      "|---|---|---|---|---|---|---|---|---|---|---|---|"]
for r in rows:
    ate, sc = r.get("ate_percent", {}), r.get("sim3_scale", {})
    f = lambda d, k, fmt: fmt.format(d[k]) if k in d else "n/a"  # noqa: E731
    pj = r["path_jump"]
    jump = f"{pj['ratio']:.2f}x (of {pj['max_ratio']:g}x)"
    md.append(f"| {r['label']} | {r['matching']} | {r['frames']} | {r['ratio']:.2f} | {r['first_name'] or '-'} | "
              f"{jump} | "
              f"{' / '.join(pj['names'])} | {'no' if r['consistent'] else '**yes**'} | "
              f"{', '.join(f'{v:.2f}' for v in r['height_ratio_percentiles_5_50_95'])} | "
              f"{f(ate, 'whole', '{:.3f}')} / {f(ate, 'before split', '{:.3f}')} / {f(ate, 'from split', '{:.3f}')} | "
              f"{f(sc, 'before split', '{:.4g}')} / {f(sc, 'from split', '{:.4g}')} | {f(r, 'scale_error_percent', '{:+.1f}')} |")
atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
atomic_write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
print("\n".join(md))
