"""How stable is ``ns2gs-data process video`` on the real-capture bench's drive? The same processing
(known FOV, one thread, as ``ns2gs-bench real``) on two renders of the street's forward drive and with
other matching options, each scored against the true cameras (ATE after Sim(3), rotation error).

Why: the bench's capture figures (ATE 0.31%, 1.4 deg) come from one video; a second render of the
same drive (the generator run with fewer eval views: same cameras, images a few grey levels apart) is
a second video of the same kind, and exhaustive matching is what ``--matching auto`` picks for small unordered sets.

Usage: python benchmarks/validation/sfm_fragility.py OUT_STEM WORK [VIDEO_SCALE [BENCH_RUNS]]
(WORK gets the second street and every processed capture; the bench's own video is read from
BENCH_RUNS/real, default benchmarks/runs). VIDEO_SCALE (default 1): both drives rendered at that multiple of
the street's 200x112, as ``ns2gs-bench real --video-scale`` makes its video. Produced
benchmarks/results/sfm_fragility.{json,md} (VIDEO_SCALE 1) and sfm_fragility_video4.{json,md} (4).
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from nerf2gs_plugin.data.process.frames import extract_video_frames  # noqa: E402
from nerf2gs_plugin.data.process.pipeline import ProcessOptions, run_process  # noqa: E402
from nerf2gs_plugin.data.process.sfm import SfmOptions  # noqa: E402
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street  # noqa: E402
from nerf2gs_bench.real import c2w_array, frame_index, read_frames, write_video  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_plugin.eval.pose_eval import capture_report  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

FRAMES, FOV, HEIGHT = 30, 80.0, 3.0
VARIANTS = {"sequential (bench)": {}, "sequential, overlap 5": {"overlap": 5}, "sequential, overlap 20": {"overlap": 20},
            "exhaustive": {"matching": "exhaustive"}}


def second_drive(work: Path, scale: int = 1) -> tuple[Path, Path]:
    tag = "" if scale == 1 else f"_x{scale}"
    street = work / f"street_fewer_eval{tag}"
    if not (street / "transforms.json").is_file():
        base = SynthStreetConfig()
        generate_street(SynthStreetConfig(out=street, num_street=1, num_bev=1, num_val_street=0, num_val_bev=0, progress=False,
                                          width=base.width * scale, height=base.height * scale, overwrite=True))
    frames = read_frames(street)["train"][:FRAMES]
    return street, write_video(work / f"drive_fewer_eval{tag}.avi", [f.image for f in frames])


def score(street: Path, video: Path, out: Path, sfm: dict) -> dict:
    opts = ProcessOptions(out=out, camera_height=HEIGHT, fov_deg=FOV, progress=False,
                          sfm=SfmOptions(refine_intrinsics=False, num_threads=1, **sfm))
    rep = run_process(lambda d, progress: extract_video_frames(video, d, None, FRAMES, 0.0, opts.max_size, progress=progress),
                      opts, is_video=True)
    true = read_frames(street)["train"][:FRAMES]
    est = read_frames(out)["train"]
    idx = [frame_index(f.image) for f in est]
    meta = json.loads((out / "transforms.json").read_text())
    r = capture_report(c2w_array(est), c2w_array(true)[idx], float(meta["metres_per_unit"]), np.asarray(meta["up"]),
                       np.asarray([0.0, 0.0, 1.0]), rep.registered, FRAMES)
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_stem", type=Path)
    ap.add_argument("work", type=Path)
    ap.add_argument("video_scale", type=int, nargs="?", default=1)
    ap.add_argument("bench_runs", type=Path, nargs="?", default=Path("benchmarks/runs"))
    args = ap.parse_args()
    out_stem, work, scale, bench = args.out_stem, args.work, args.video_scale, args.bench_runs / "real"
    work.mkdir(parents=True, exist_ok=True)
    tag = "" if scale == 1 else f"_x{scale}"
    drives = {"bench video": (bench / f"street{tag}", bench / f"drive{tag}.avi"), "second render": second_drive(work, scale)}
    rows = []
    for drive, (street, video) in drives.items():
        for name, sfm in VARIANTS.items():
            out = work / f"{drive.replace(' ', '_')}{tag}-{name.replace(' ', '_').replace(',', '').replace('(', '').replace(')', '')}"
            rows.append({"drive": drive, "variant": name, **score(street, video, out, sfm)})
            print(rows[-1], flush=True)
    doc = {"machine": machine_line(), "frames": FRAMES, "video_scale": scale, "fov_deg": FOV, "camera_height": HEIGHT, "rows": rows}
    atomic_write_text(out_stem.with_suffix(".json"), json.dumps(doc, indent=1))
    lines = ["# SfM of the real-capture bench's drive, on two renders and with other matching", "",
             f"Machine: {doc['machine']}", "",
             f"`ns2gs-data process video` as `ns2gs-bench real` runs it ({FRAMES} frames, {200 * scale}x{112 * scale}, `--fov-deg {FOV:g} "
             f"--camera-height {HEIGHT:g} --no-refine-intrinsics`, one thread), scored against the true cameras. "
             "\"second render\": the same generator with fewer eval views: the same cameras, images that differ by a few grey "
             "levels on average (render noise, the cars), so another video of the same drive.",
             "", "| drive | matching | registered | ATE % | rotation error deg | scale error % | up error deg |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['drive']} | {r['variant']} | {r['registered_fraction']:.2f} | {r['ate_percent']:.2f} | "
                     f"{r['rotation_error_deg']:.2f} | {r['scale_error_percent']:+.1f} | {r['up_error_deg']:.2f} |")
    atomic_write_text(out_stem.with_suffix(".md"), "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
