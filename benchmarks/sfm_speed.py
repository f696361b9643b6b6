"""SfM time and pose accuracy of ``ns2gs-data process images`` under several matching settings.

    python benchmarks/sfm_speed.py --images DIR --work /tmp/sfm_speed [--gt-cameras DIR | --gt-transforms JSON] [--fov-deg F] \
        [--variant exhaustive --variant sequential ...] --out benchmarks/results/real_photos_sfm

Each variant runs the whole ``process images`` (fresh folder: features included) and records its
stage times, the registered count, the load average and, with ``--gt-cameras`` (Strecha-style
``<image>.camera`` files: K, distortion, R (camera-to-world, OpenCV axes), centre, size), the ATE
after a Sim(3) alignment (% of the trajectory) and the Sim(3) scale against the camera-height
scale. Results: ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

VARIANTS = {
    "exhaustive": ["--matching", "exhaustive"],
    "sequential": ["--matching", "sequential", "--loop-pairs", "0"],
    "sequential + loop pairs": ["--matching", "sequential", "--loop-pairs", "3"],
    "sequential + loop pairs, 2048 features": ["--matching", "sequential", "--loop-pairs", "3", "--max-features", "2048"],
}


def read_strecha(folder: Path, names: list[str]) -> np.ndarray:
    """OpenGL camera-to-world [N, 3, 4] of ``names`` from Strecha ``.camera`` files."""
    out = []
    for n in names:
        v = np.array((Path(folder) / f"{n}.camera").read_text().split(), dtype=np.float64)
        R, c = v[12:21].reshape(3, 3), v[21:24]
        out.append(np.concatenate([R @ np.diag([1.0, -1.0, -1.0]), c[:, None]], 1))
    return np.stack(out)


def run_variant(images: Path, work: Path, flags: list[str], fov_deg: float | None, camera_height: float, threads: int,
                metres_per_unit: float | None = None) -> dict:
    from nerf2gs_plugin.cli.data import main

    shutil.rmtree(work, ignore_errors=True)
    args = ["process", "images", str(images), "--out", str(work), "--camera-height", str(camera_height), "--no-progress",
            "--num-threads", str(threads), *flags] + (["--fov-deg", str(fov_deg)] if fov_deg else []) + (
        ["--metres-per-unit", str(metres_per_unit)] if metres_per_unit else [])
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    main(args)
    wall = time.perf_counter() - t0
    meta = json.loads((work / "transforms.json").read_text())
    pairs = work / "colmap" / "loop_pairs.txt"
    return {"flags": flags, "wall_seconds": round(wall, 1), "load_average_start": round(load0, 2), "load_average_end": round(os.getloadavg()[0], 2),
            "stage_seconds": json.loads((work / "colmap" / "stage_seconds.json").read_text()), "registered": meta["process"]["registered"], "frames": meta["process"]["frames"],
            "metres_per_unit": meta["metres_per_unit"], "scale_source": meta["process"]["scale_source"], "loop_pairs": len(pairs.read_text().splitlines()) if pairs.is_file() else 0,
            "poses": {Path(f["file_path"]).name: f["transform_matrix"] for f in meta["frames"]}}


def matched_pairs(work: Path) -> int:
    """Image pairs that went through matching (the COLMAP database of a finished variant)."""
    import pycolmap

    with pycolmap.Database.open(str(Path(work) / "colmap" / "database.db")) as d:
        return int(d.num_matched_image_pairs())


def read_transforms(path: Path, names: list[str]) -> np.ndarray:
    """OpenGL camera-to-world [N, 3, 4] of ``names`` from a nerfstudio ``transforms.json`` (matched by file name)."""
    frames = {Path(f["file_path"]).name: f["transform_matrix"] for f in json.loads(Path(path).read_text())["frames"]}
    missing = [n for n in names if n not in frames]
    if missing:
        raise SystemExit(f"{path}: no true pose for {len(missing)} registered photo(s), e.g. {missing[0]}")
    return np.stack([np.array(frames[n], dtype=np.float64)[:3] for n in names])


def pose_figures(row: dict, gt: Path) -> dict:
    """Against Strecha ``.camera`` files (a folder) or a ``transforms.json`` with the true poses."""
    from nerf2gs_plugin.eval.pose_eval import pose_errors

    names = sorted(row["poses"])
    est = np.array([np.array(row["poses"][n])[:3] for n in names])
    pe = pose_errors(est, read_transforms(gt, names) if Path(gt).is_file() else read_strecha(gt, names))
    return {"ate_percent": round(pe.ate_percent, 3), "ate_m": round(pe.ate_rmse, 3), "rotation_error_deg": round(pe.rotation_deg_mean, 3),
            "sim3_metres_per_unit": round(pe.scale, 4), "scale_error_percent": round(100.0 * (row["metres_per_unit"] / pe.scale - 1), 1),
            "scale_source": row["scale_source"]}


def markdown(doc: dict) -> str:
    from nerf2gs_bench.machine import machine_line

    lines = [f"# SfM time of `ns2gs-data process images` on {doc['photos']} photos ({doc['size']})", "",
             f"Machine: {machine_line(doc.get('machine'))}; `--num-threads {doc['threads']}`; other jobs were running "
             "(load average at the start and end of each run below).", "", doc.get("provenance", ""), "",
             "| variant | registered | pairs matched | features s | matching s | s per pair | mapping s | SfM s (features + matching + mapping) | process wall s | load | ATE % | rot deg |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in doc["variants"].items():
        s = r["stage_seconds"]
        sfm = s["features"] + s["matching"] + s["mapping"]
        p = r.get("pose", {})
        pairs = r.get("matched_pairs")
        per = f"{s['matching'] / pairs:.2f}" if pairs else "n/a"
        lines.append(f"| {name} | {r['registered']}/{r['frames']} | {pairs if pairs else 'n/a'} | {s['features']:.0f} | {s['matching']:.0f} | {per} | "
                     f"{s['mapping']:.0f} | {sfm:.0f} | {r['wall_seconds']:.0f} | {r['load_average_start']:.1f}-{r['load_average_end']:.1f} | "
                     f"{p.get('ate_percent', 'n/a')} | {p.get('rotation_error_deg', 'n/a')} |")
    lines += ["", "ATE: RMSE of the camera centres after a Sim(3) alignment onto the set's ground-truth cameras, % of the "
              "trajectory length; rot: mean rotation error after it. Matching and mapping use `--num-threads` threads; "
              "times are wall-clock on a shared machine, so the load column matters."]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=Path, required=True)
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True, help="results path without extension")
    ap.add_argument("--gt-cameras", type=Path, help="folder of Strecha .camera files")
    ap.add_argument("--gt-transforms", type=Path, help="or a transforms.json with the true poses (by file name)")
    ap.add_argument("--fov-deg", type=float)
    ap.add_argument("--camera-height", type=float, default=1.6)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--metres-per-unit", type=float, help="passed on (when the ground-plane scale is rejected)")
    ap.add_argument("--variant", action="append", choices=list(VARIANTS))
    ap.add_argument("--provenance", default="")
    ap.add_argument("--summarize-only", action="store_true", help="re-read finished variants' databases and rewrite OUT.md")
    a = ap.parse_args()
    from nerf2gs_bench.machine import machine_info
    from nerf2gs_plugin.utils.io import atomic_write_text

    out_json = a.out.with_suffix(".json")
    doc = json.loads(out_json.read_text()) if out_json.is_file() else {"variants": {}}
    from PIL import Image

    files = sorted(p for p in a.images.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    doc.update(photos=len(files), size="x".join(map(str, Image.open(files[0]).size)), threads=a.threads, provenance=a.provenance,
               machine=machine_info())
    if a.summarize_only:
        for name, row in doc["variants"].items():
            row["matched_pairs"] = matched_pairs(a.work / name.replace(" ", "_").replace(",", ""))
        atomic_write_text(out_json, json.dumps(doc, indent=1))
        atomic_write_text(a.out.with_suffix(".md"), markdown(doc))
        return
    for name in a.variant or list(VARIANTS):
        row = run_variant(a.images, a.work / name.replace(" ", "_").replace(",", ""), VARIANTS[name], a.fov_deg, a.camera_height, a.threads,
                          a.metres_per_unit)
        if a.gt_cameras or a.gt_transforms:
            row["pose"] = pose_figures(row, a.gt_cameras or a.gt_transforms)
        row.pop("poses")
        row["matched_pairs"] = matched_pairs(a.work / name.replace(" ", "_").replace(",", ""))
        doc["variants"][name] = row
        atomic_write_text(out_json, json.dumps(doc, indent=1))
        atomic_write_text(a.out.with_suffix(".md"), markdown(doc))
        print(name, json.dumps(row))


if __name__ == "__main__":
    main()
