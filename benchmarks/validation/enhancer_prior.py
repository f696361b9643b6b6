"""The built-in enhancer with and without a prior pre-trained on generated streets
(``ns2gs-enhance pretrain``), measured alone on a reference's renders of the VALIDATION views
(val_street, val_bev; never the test views) of a street the prior was not pre-trained on:

* ``own``: the bench's enhancer, trained from the identity on the capture's own pairs (today's rows);
* ``prior``: the pre-trained prior as it is (no fine-tuning on the capture);
* ``prior + fine-tune``: the bench's enhancer settings started from the prior (``train --init``).

Usage: python benchmarks/validation/enhancer_prior.py REFERENCE_RUN DATA OUT_DIR PRIOR_ONNX [SCALE]
(PRIOR_ONNX's weights are the ``.pt`` beside it. Writes OUT_DIR/{own,finetune}/enhancer.onnx (+ report)
and OUT_DIR/enhancer_prior.{json,md}; a model already there with its report is evaluated again, not retrained.)
"""
import argparse
import dataclasses
import json
import time
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.cli.enhance import evaluate_enhancer  # noqa: E402
from nerf2gs_bench.enhancer import bench_enhancer_config  # noqa: E402
from nerf2gs_plugin.enhancer.train import report_path, train_enhancer  # noqa: E402
from nerf2gs_bench.runner import write_bench_files  # noqa: E402

SPLITS = ("val_street", "val_bev")
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
for name in ("reference_run", "data", "out_dir", "prior_onnx"):
    ap.add_argument(name, type=Path)
ap.add_argument("scale", nargs="?", default="quick")
args = ap.parse_args()
reference, data, out_dir, prior, scale = args.reference_run, args.data, args.out_dir, args.prior_onnx, args.scale
prior_info = json.loads(report_path(prior).read_text())
results, t0 = {}, time.time()
for name, init in (("own", None), ("prior", "as is"), ("prior + fine-tune", prior.with_suffix(".pt"))):
    t = time.time()
    if init == "as is":
        model, selected = prior, None
    else:
        model = out_dir / ("own" if init is None else "finetune") / "enhancer.onnx"
        if not (model.is_file() and report_path(model).is_file()):
            cfg = dataclasses.replace(bench_enhancer_config(data, model, scale), reference=(reference,), init=init, threads=1)
            for line in train_enhancer(cfg).summary_lines():
                print(f"[{name}] {line}", flush=True)
        selected = json.loads(report_path(model).read_text())["selected_step"]
    ev = evaluate_enhancer(f"onnx:{model}", data, reference, SPLITS)
    results[name] = {"model": str(model), "selected_step": selected, "seconds": time.time() - t, "splits": ev["splits"]}
    print(name, json.dumps(ev["splits"]), flush=True)

rows = ["| enhancer | split | PSNR before -> after | d PSNR | LPIPS before -> after | d LPIPS |", "|---|---|---|---|---|---|"]
for name, r in results.items():
    for s in SPLITS:
        v = r["splits"][s]
        rows.append(f"| {name} | {s} | {v['psnr_before']:.2f} -> {v['psnr_after']:.2f} | {v['psnr_after'] - v['psnr_before']:+.2f} | "
                    f"{v['lpips_before']:.3f} -> {v['lpips_after']:.3f} | {v['lpips_after'] - v['lpips_before']:+.3f} |")
seeds = prior_info["config"]["seeds"]
md = (f"`python benchmarks/validation/enhancer_prior.py {reference} {data} OUT {prior} {scale}`: each enhancer applied alone to "
      f"the reference's renders of the validation views (before = the render, after = enhanced; against the true images). "
      f"The prior was pre-trained on generated streets with seeds {', '.join(map(str, seeds))} (not this one).\n\n" + "\n".join(rows) + "\n")
write_bench_files(out_dir, "enhancer_prior", "The built-in enhancer with a prior pre-trained on generated streets",
                  {"reference": str(reference), "data": str(data), "scale": scale, "prior": str(prior), "prior_seeds": seeds,
                   "splits": list(SPLITS), "date": time.strftime("%Y-%m-%d"), "seconds": time.time() - t0, "results": results}, md)
print(md)
