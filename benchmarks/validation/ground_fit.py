"""The ground-plane fit (``data/ground.py``) on processed captures with known true cameras: the
plane's angle to the true up, that of the up ``process`` writes (the cameras' upright direction
where it agrees with the plane, ``data/road_plane.upright_normal``), and the camera-height scale
against the Sim(3) scale.

Why: on castle-P30 the fit once returned a plane 39 deg off the true up and a scale 87% too small
(each RANSAC hypothesis's inlier band grew with its own camera height, and the refit was not held
to the tilt limit); this records what the current fit gives on the same sparse points, and on the
real-capture bench's synthetic drive as a second scene.

Usage: python benchmarks/validation/ground_fit.py OUT_STEM NAME:DATA:TRUE:CAMERA_HEIGHT ...
with DATA a processed capture (transforms.json + sparse_pc.ply) and TRUE either a folder of
Strecha ``.camera`` files (true up: -z) or a dataset whose transforms.json holds the true cameras
(frames named ``frame_<index>``; true up: its ``up``). Produced benchmarks/results/ground_fit.{json,md}
through the plan benchmarks/plans/ground_fit.yaml (castle-P30 and the real-capture bench's drive).
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sfm_speed import read_strecha  # noqa: E402

from nerf2gs_plugin.data.ground import MAX_TILT_DEG, estimate_metric_scale, fit_ground_plane  # noqa: E402
from nerf2gs_plugin.data.ply import read_ply_points  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_plugin.eval.pose_eval import pose_errors  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))))


def true_cameras(true: Path, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """True OpenGL c2w of ``names`` and the true up, from Strecha files or a dataset's transforms.json."""
    if (true / "transforms.json").is_file():
        meta = json.loads((true / "transforms.json").read_text())
        by_index = {int(Path(f["file_path"]).stem.rsplit("_", 1)[-1]): f for f in meta["frames"]}
        c2w = np.array([by_index[int(Path(n).stem.rsplit("_", 1)[-1])]["transform_matrix"] for n in names])[:, :3]
        return c2w, np.asarray(meta.get("up", [0, 0, 1]), dtype=np.float64)
    return read_strecha(true, names), np.array([0.0, 0.0, -1.0])


def measure(data: Path, true: Path, camera_height: float) -> dict:
    meta = json.loads((data / "transforms.json").read_text())
    c2w = np.array([f["transform_matrix"] for f in meta["frames"]], dtype=np.float64)[:, :3]
    names = [Path(f["file_path"]).name for f in meta["frames"]]
    xyz, _ = read_ply_points(data / "sparse_pc.ply")
    cam_up = c2w[:, :, 1].mean(0)
    true_c2w, true_up = true_cameras(true, names)
    pe = pose_errors(c2w, true_c2w)
    up_here = pe.sim3.R.T @ (true_up / np.linalg.norm(true_up))  # the true up in the capture's frame
    plane = fit_ground_plane(xyz, c2w[:, :, 3], cam_up)
    row = {"data": str(data), "points": int(len(xyz)), "cameras": int(len(c2w)), "camera_height_m": camera_height,
           "sim3_metres_per_unit": pe.scale, "cameras_up_to_true_up_deg": angle(cam_up, up_here), "plane": None}
    if plane is not None:
        mpu = camera_height / plane.median_camera_height
        row["plane"] = {"to_true_up_deg": angle(plane.normal, up_here), "to_cameras_up_deg": angle(plane.normal, cam_up),
                        "metres_per_unit": mpu, "scale_error_percent": 100.0 * (mpu / pe.scale - 1.0),
                        "inliers": plane.inliers, "candidates": plane.candidates}
        # the up `process` writes: the cameras' upright direction where it agrees with the plane
        row["up_to_true_up_deg"] = angle(estimate_metric_scale(xyz, c2w[:, :, 3], cam_up, camera_height, cam_right=c2w[:, :, 0]).up, up_here)
    return row


def markdown(doc: dict) -> str:
    lines = ["# The ground-plane fit on captures with true cameras (`data/ground.py`)", "", f"Machine: {doc['machine']}", "",
             __doc__.split("Usage:")[0].strip(), "", f"Tilt limit (`MAX_TILT_DEG`): {doc['max_tilt_deg']:.0f} deg.", "",
             "| capture | points | plane to true up, deg | cameras' up to true up, deg | process's up (upright) to true up, deg | metres per unit | Sim(3) metres per unit | scale error % |",
             "|---|---|---|---|---|---|---|---|"]
    for name, r in doc["captures"].items():
        p = r["plane"]
        if p is None:
            lines.append(f"| {name} | {r['points']} | no plane | {r['cameras_up_to_true_up_deg']:.1f} | | | {r['sim3_metres_per_unit']:.3f} | |")
            continue
        lines.append(f"| {name} | {r['points']} | {p['to_true_up_deg']:.1f} | {r['cameras_up_to_true_up_deg']:.1f} | {r['up_to_true_up_deg']:.1f} | "
                     f"{p['metres_per_unit']:.3f} | {r['sim3_metres_per_unit']:.3f} | {p['scale_error_percent']:+.1f} |")
    lines += ["", "The scale error also holds the error of the assumed camera height (`camera_height_m` in the JSON)."]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_stem", type=Path)
    ap.add_argument("captures", nargs="+", help="NAME:DATA:TRUE:CAMERA_HEIGHT")
    args = ap.parse_args()
    out = args.out_stem
    doc = {"machine": machine_line(), "max_tilt_deg": MAX_TILT_DEG, "captures": {}}
    for arg in args.captures:
        name, data, true, height = arg.split(":")
        doc["captures"][name] = measure(Path(data), Path(true), float(height))
    atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
    atomic_write_text(out.with_suffix(".md"), markdown(doc))
    print(markdown(doc))


if __name__ == "__main__":
    main()
