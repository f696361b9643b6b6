"""Splatfacto (or 2DGS) variants on a processed photo capture at the real-photos bench's settings (StreetNeRF
600 steps, targets 1000, downscale 4), one line of JSON each (held-out PSNR per photo, primitives).

Usage: python benchmarks/validation/photo_variants.py DATA RUNS LABEL=JSON [...]
JSON: model overrides ({"strategy": {...}}), with "seed": N, "steps": N (the target's length, default 1000) and
"augment": {--augment.* overrides} at its top.
A label starting with 'aug:' trains with NeRF views (the bench's `--augment.delta-h 3 --augment.theta-pitch 30
--augment.every-n 2` unless "augment" says otherwise) from the StreetNeRF of the same runs folder; '2dgs:'
trains 2DGS. Made: benchmarks/results/castle_bev_geometry_val.* and castle_steps_capacity_val.* (through
run_table.py, rows benchmarks/validation/castle_bev_geometry_rows.json and castle_steps_capacity_rows.json).
"""
import argparse
import json
import sys
from pathlib import Path

from nerf2gs_bench.runner import BenchRunner
from nerf2gs_bench.paper import _merge
from nerf2gs_bench.real_photos import RealPhotosOptions, augment_overrides, run_overrides
from nerf2gs_bench.runs import RunSpec
from reference_length import show  # the same JSON line per run (this folder is the script's sys.path[0])


def main(data: Path, runs: Path, args: list[str]) -> None:
    opts = RealPhotosOptions(images=Path("."), streetnerf_steps=600, splatfacto_steps=1000, every_n=2)  # the bench run of castle-P30
    runner = BenchRunner(runs, log=lambda s: None)
    ref = None
    for arg in args:
        label, ov = arg.split("=", 1)
        ov = json.loads(ov)
        seed, aug_extra, steps = ov.pop("seed", None), ov.pop("augment", {}), ov.pop("steps", opts.splatfacto_steps)
        method = "2dgs" if label.startswith("2dgs:") else "splatfacto"
        o = run_overrides(opts, method, steps)
        o["pipeline"]["model"] = _merge(o["pipeline"].get("model", {}), ov)
        if seed is not None:
            o["seed"] = seed
        aug = label.startswith("aug:")
        if aug and ref is None:
            sn = runner.run(RunSpec("StreetNeRF", "streetnerf", run_overrides(opts, "streetnerf", opts.streetnerf_steps)), data)
            ref = (Path(sn.run_dir), sn.key)
            show("StreetNeRF", sn)
        spec = RunSpec(label, method, o, augment_from="StreetNeRF" if aug else None,
                       augment={**augment_overrides(opts), **aug_extra} if aug else {})
        show(label, runner.run(spec, data, reference=ref if aug else None))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    for name in ("data", "runs"):
        ap.add_argument(name, type=Path)
    ap.add_argument("args", nargs="+", help="LABEL=JSON", metavar="LABEL=JSON")
    main(**vars(ap.parse_args()))
