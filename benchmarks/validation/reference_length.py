"""StreetNeRF trained for other lengths on a processed photo capture (the real-photos bench's settings
otherwise), and Splatfacto + NeRF views from each: does a longer reference give the target more?

Usage: python benchmarks/validation/reference_length.py DATA RUNS LABEL=JSON [LABEL=JSON ...]
JSON: {"steps": N, "model": {StreetNeRF model overrides}, "aug": true, "target_steps": N (default 1000)}. One line of JSON per run (held-out
PSNR per photo, primitives). Made: benchmarks/results/reference_length_val.* (through run_table.py, rows
benchmarks/validation/reference_length_rows.json), on castle-P30's validation photos.
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.runner import BenchRunner, failure_reason
from nerf2gs_bench.real_photos import RealPhotosOptions, augment_overrides, run_overrides
from nerf2gs_bench.runs import RunSpec


def show(label: str, out) -> None:
    r = out.result if isinstance(out.result, dict) else {}
    test = (r.get("results") or {}).get("test", {})
    print(json.dumps({"label": label, "run": str(out.run_dir), "error": failure_reason(out), "psnr": test.get("psnr"),
                      "per_image": test.get("psnr_per_image"), "primitives": (r.get("size") or {}).get("primitives")}), flush=True)


def main(data: Path, runs: Path, args: list[str]) -> None:
    opts = RealPhotosOptions(images=Path("."), streetnerf_steps=600, splatfacto_steps=1000, every_n=2)  # the bench run of castle-P30
    runner = BenchRunner(runs, log=lambda s: None)
    for arg in args:
        label, ov = arg.split("=", 1)
        ov = json.loads(ov)
        o = run_overrides(opts, "streetnerf", ov.get("steps", opts.streetnerf_steps))
        o["pipeline"].setdefault("model", {}).update(ov.get("model", {}))
        sn = runner.run(RunSpec(label, "streetnerf", o), data)
        show(label, sn)
        if ov.get("aug"):
            spec = RunSpec("aug:" + label, "splatfacto", run_overrides(opts, "splatfacto", ov.get("target_steps", opts.splatfacto_steps)),
                           augment_from=label,
                           augment=augment_overrides(opts))
            show("aug:" + label, runner.run(spec, data, reference=(Path(sn.run_dir), sn.key)))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    for name in ("data", "runs"):
        ap.add_argument(name, type=Path)
    ap.add_argument("args", nargs="+", help="LABEL=JSON", metavar="LABEL=JSON")
    main(**vars(ap.parse_args()))
