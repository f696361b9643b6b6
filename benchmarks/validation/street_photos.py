"""A stand-in for a ~120-photo street capture: no public street set of that size is reachable from
this machine, so issue 18's SfM speed target (~120 photos at ~1200x900 within 10 minutes on 2 cores)
is measured on the forward pass of the synthetic street's drive: its first 120 of 240 training frames
(0.5 m apart over 60 m, one direction: the street's two passes look opposite ways and share no view),
rendered at 1200x900 with one sample per pixel, written as a folder of PNGs in capture order.

Usage: python benchmarks/validation/street_photos.py WORK [--down-and-back]
(--down-and-back: every other frame of both passes instead, 120 frames 1 m apart, the second pass
driving back facing the other way: the capture SfM joined at two scales, benchmarks/results/scale_check.md)
then:  python benchmarks/sfm_speed.py --images WORK/photos --work WORK/sfm --gt-transforms WORK/street/transforms.json \
           --fov-deg 80 --camera-height 3 --variant sequential --variant exhaustive --out benchmarks/results/sfm_speed_120
Produced the photos of benchmarks/results/sfm_speed_120.{json,md}.
"""
import argparse
from pathlib import Path

from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

N, W, H, FOV, CAM_H = 120, 1200, 900, 80.0, 3.0
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("work", type=Path)
ap.add_argument("--down-and-back", action="store_true", help="every second frame of a drive there and back")
args = ap.parse_args()
work = args.work
frames = range(0, 2 * N, 2) if args.down_and_back else range(N)
street, photos = work / "street", work / "photos"
if not (street / "transforms.json").is_file():
    generate_street(SynthStreetConfig(out=street, seed=11, width=W, height=H, num_train=2 * N, spp=1, num_street=1, num_bev=1,
                                      num_val_street=0, num_val_bev=0, fov_deg=FOV, cam_height=CAM_H, drive_half_len=30.0,
                                      progress=False, overwrite=True))
photos.mkdir(parents=True, exist_ok=True)
for i in frames:  # the forward pass (or both passes, every other frame)
    link = photos / f"train_{i:04d}.png"
    if not link.exists():
        link.symlink_to((street / "images" / link.name).resolve())
print(f"{N} photos of {W}x{H} in {photos}")
