"""A splatting method at the quick scale, with or without the blending-weight prune, evaluated on
the validation views (val_street, val_bev), never the test views.

Usage: python benchmarks/validation/size_prune.py METHOD LABEL DATA OUT [FIELD=VALUE ...]
(FIELD: a dotted field of the model config, e.g. strategy.prune_weight_fraction=0.02; writes
OUT/<data name>-<METHOD>-<LABEL>.json with primitives, MB, FPS and the PSNR per split).
Produced the numbers of the blending-weight prune (issue 20, part 1) in the size branch's report.
"""
import argparse
import dataclasses, json, time
from pathlib import Path
import torch
torch.set_num_threads(1)
from nerf2gs_plugin.utils.config import apply_plain
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_bench.paper import _overrides
from nerf2gs_bench.size import model_overrides
from nerf2gs_plugin.registry import get_method
from nerf2gs_plugin.runs.load import load_run
from nerf2gs_plugin.eval.evaluate import evaluate_run

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("method")
ap.add_argument("label")
ap.add_argument("data", type=Path)
ap.add_argument("out", type=Path)
ap.add_argument("overrides", nargs="*", help="FIELD=VALUE of the model config")
args = ap.parse_args()
method, label, data, out_dir = args.method, args.label, args.data, args.out
extra = model_overrides(args.overrides)
cfg = apply_plain(get_method(method).config, _overrides("quick", method, extra), where="size_prune")
name = f"{data.name}-{method}-{label}"
cfg = dataclasses.replace(cfg, data=data, output_dir=out_dir / "runs", timestamp=name, progress=False)
t = time.time()
tr = Trainer(cfg)
tr.setup()
tr.train()
train_s = time.time() - t
run = load_run(cfg.get_run_dir(), device="cpu")
res = evaluate_run(run, ["val_street", "val_bev"], render_dir=None, lpips_model=None)
psnr = {k: v.get("psnr") for k, v in res["results"].items()}
out = {"method": method, "label": label, "data": str(data), "overrides": extra, "train_seconds": train_s,
       "primitives": res["size"]["primitives"], "megabytes": res["size"].get("checkpoint_megabytes", res["size"].get("megabytes")),
       "fps": res.get("fps"), "psnr": psnr, "mean_psnr": sum(psnr.values()) / len(psnr), "results": res["results"]}
(out_dir / f"{name}.json").write_text(json.dumps(out, indent=1, default=str))
print(json.dumps({k: out[k] for k in ("primitives", "megabytes", "mean_psnr", "psnr", "train_seconds")}))
