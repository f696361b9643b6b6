"""A/B interleaved in one process: the --augment-from bird's-eye renders (every-n N) of a StreetNeRF run, one view at a time
(torch's threads, before) vs side by side in forked workers (now); CPU s, wall s, renders compared.
Usage: python benchmarks/validation/augment_render_workers_ab.py DATA RUN_COPY N (RUN_COPY: a copy of the run: its augment_cache is removed)."""
import argparse, shutil, time, torch
from pathlib import Path
from nerf2gs_plugin.augment.config import AugmentConfig
from nerf2gs_plugin.augment.datamanager import render_augmented_views
from nerf2gs_plugin.augment.reference import load_reference
from nerf2gs_plugin.data.fingerprint import dataset_fingerprint
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.utils.parallel import cpu_seconds
ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("data", type=Path, help="the dataset")
ap.add_argument("run", type=Path, help="a copy of the StreetNeRF run (its augment_cache is removed)")
ap.add_argument("every", type=int, help="bird's-eye every-n")
args = ap.parse_args()
data, run, every = args.data, args.run, args.every
dm = FullImageDataManagerConfig().setup(data=data, device="cpu")
ref = load_reference(run, dm, "cpu")
td = dm.train_data
print("torch threads", torch.get_num_threads(), "workers", ref.render_workers, flush=True)
cfg = AugmentConfig(composites=False, every_n=every, use_cache=False, seed_points=0.0)
res = {}
for rep, workers in enumerate((1, 2, 2, 1)):
    shutil.rmtree(run / "augment_cache", ignore_errors=True)
    c0, w0 = cpu_seconds(), time.perf_counter()
    v = render_augmented_views(dm.train_images, td, ref.render, ref.key, dataset_fingerprint(td.image_filenames), ref.cache_root,
                               cfg, None, td.scene_box, ref.depth_along, None, ref.render_pixels, workers)
    cpu, wall = cpu_seconds() - c0, time.perf_counter() - w0
    imgs = torch.stack([v.extra.image(i) for i in range(len(v.extra))])
    res.setdefault(workers, []).append((cpu, wall, imgs))
    print(f"workers {workers}: {len(v.extra)} views, CPU {cpu:.1f} s, wall {wall:.1f} s, load {open('/proc/loadavg').read().split()[0]}", flush=True)
a, b = res[1][0][2], res[2][0][2]
print("max abs rgb diff (8-bit PNGs)", float((a - b).abs().max()))
