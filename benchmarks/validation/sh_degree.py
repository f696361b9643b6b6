"""StreetNeRF's sh_degree re-checked on the validation views (val_street, val_bev), never the test views.

Usage: python benchmarks/validation/sh_degree.py DEGREE STEPS DATA OUT
(DATA: an `ns2gs-data synth-street` dataset of generator version >= 2; writes OUT/sh<DEGREE>-<STEPS>.json).
Produced benchmarks/results/sh_degree_val.{json,md} with DEGREE 0 and 3, STEPS 400.
"""
import argparse
import dataclasses, json, time
from pathlib import Path
import torch
torch.set_num_threads(1)
from nerf2gs_plugin.engine.config import apply_plain
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_bench.paper import step_overrides, _merge
from nerf2gs_plugin.registry import get_method
from nerf2gs_plugin.runs.load import load_run
from nerf2gs_plugin.eval.evaluate import evaluate_run

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
for name, kind in (("degree", int), ("steps", int), ("data", Path), ("out", Path)):
    ap.add_argument(name, type=kind)
args = ap.parse_args()
deg, steps, data, out_dir = args.degree, args.steps, args.data, args.out
ov = _merge(step_overrides("streetnerf", steps), {"pipeline": {"model": {"sh_degree": deg}}})
cfg = apply_plain(get_method("streetnerf").config, ov, where="sh")
cfg = dataclasses.replace(cfg, data=data, output_dir=out_dir / "runs", timestamp=f"sh{deg}-{steps}", progress=False)
t = time.time()
tr = Trainer(cfg); tr.setup(); tr.train()
run = load_run(cfg.get_run_dir(), device="cpu")
res = evaluate_run(run, ["val_street", "val_bev"], render_dir=None, lpips_model=None)
out = {"sh_degree": deg, "steps": steps, "seconds": time.time() - t, "results": res["results"]}
(out_dir / f"sh{deg}-{steps}.json").write_text(json.dumps(out, indent=1, default=str))
print(json.dumps({k: v.get("psnr") for k, v in res["results"].items()}))
