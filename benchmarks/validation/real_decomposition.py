"""What separates the real bench's estimated column from its ground-truth one? Each ground-truth input
swapped, one at a time, into the other side, every run at the bench's settings (one seed).

Usage: python benchmarks/validation/real_decomposition.py RUNS OUT_STEM
RUNS: the runs folder of a finished ``ns2gs-bench real --video-scale 4`` (its ``real/`` holds the street,
the capture and the masks). Variants, each a dataset built under ``RUNS/real/decomposition/``:
- "estimated, true transient masks": the estimated capture with the true car masks;
- "estimated, true masks": the estimated capture with the true sky, ground and car masks;
- "true, video images": the ground-truth column trained on the capture's ``images_4`` (the video's frames);
- "true, capture's points": the bench's third column (``RUNS/real/gt_capture_points``: the ground-truth
  column with the capture's sparse points carried into the true frame); its runs are the bench's when they exist.
Produced benchmarks/results/real_decomposition.{json,md}.
"""
import argparse
import json
import shutil
from pathlib import Path

from nerf2gs_bench import real as br
from nerf2gs_bench.machine import machine_line
from nerf2gs_plugin.utils.io import atomic_write_text

SCALE = 4


def estimated_with_true_masks(real: Path, out: Path, kinds: tuple[str, ...]) -> Path:
    """A copy of the estimated dataset whose training masks of ``kinds`` are the street's (same pixel grid:
    the FOV is known and the capture's images_4 are the street's size)."""
    est = real / f"estimated_x{SCALE}"
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(est, out, symlinks=True)
    street = br.read_frames(real / "gt")["train"]
    for f in br.read_frames(est)["train"]:
        src = street[br.frame_index(f.image)]
        for k in kinds:
            shutil.copy(src.masks[k], out / "masks" / k / f"{Path(f.image).stem}.png")
    return out


def truth_with_video_images(real: Path, out: Path) -> Path:
    """The ground-truth dataset whose training images are the capture's images_4 of the same frames."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    for item in (real / "gt").iterdir():
        if item.name != "transforms.json":
            (out / item.name).symlink_to(item.resolve())
    meta = json.loads((real / "gt" / "transforms.json").read_text())
    for i, f in enumerate(meta["frames"]):
        stem = Path(f["file_path"]).stem
        for k in ("sky", "ground", "transient"):  # the frame's masks stay the street's
            f.setdefault(f"{k}_mask_path", str((real / "gt" / "masks" / k / f"{stem}.png").resolve()))
        f["file_path"] = str((real / f"capture_x{SCALE}" / f"images_{SCALE}" / f"frame_{i:06d}.jpg").resolve())
    atomic_write_text(out / "transforms.json", json.dumps(meta, indent=1))
    return out


def main(runs: Path, out_stem: Path) -> None:
    real = runs / "real"
    work = real / "decomposition"
    work.mkdir(exist_ok=True)
    variants = {
        "estimated, true transient masks": estimated_with_true_masks(real, work / "estimated_true_transient", ("transient",)),
        "estimated, true masks": estimated_with_true_masks(real, work / "estimated_true_masks", ("sky", "ground", "transient")),
        "true, video images": truth_with_video_images(real, work / "truth_video_images"),
        "true, capture's points": real / "gt_capture_points",
    }
    opts = br.RealBenchOptions()
    rows = {}
    for name, data in variants.items():
        res = br.run_plan_for(data, runs, opts, "real_decomposition", False)
        rows[name] = {label: {s: r["results"][s]["psnr"] for s in br.SPLITS} for label, r in res.items()}
        print(name, json.dumps(rows[name]), flush=True)
    doc = {"machine": machine_line(), "options": vars(opts), "rows": rows}
    atomic_write_text(out_stem.with_suffix(".json"), json.dumps(doc, indent=1))
    md = ["# What separates the real bench's estimated column from its ground truth", "",
          f"Machine: {doc['machine']}. `benchmarks/validation/real_decomposition.py`: one ground-truth input at a time swapped "
          "into the other side, the bench's settings (StreetNeRF 400 steps, Splatfacto 800, the default seed). Compare with "
          "`real.md`'s columns.", "", "| variant | run | PSNR street | PSNR bev_1 | PSNR bev_2 |", "|---|---|---|---|---|"]
    md += [f"| {name} | {label} | " + " | ".join(f"{r[s]:.2f}" for s in br.SPLITS) + " |" for name, res in rows.items() for label, r in res.items()]
    atomic_write_text(out_stem.with_suffix(".md"), "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", type=Path)
    ap.add_argument("out_stem", type=Path)
    args = ap.parse_args()
    main(args.runs, args.out_stem)
