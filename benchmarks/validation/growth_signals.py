"""Could a quick Splatfacto run read from itself when to stop densifying? At every refinement: the
Gaussian count, the PSNR of a fixed subset of the training views (every 6th), the count carrying 90% of
the training views' blending weight, and how often a Gaussian is visible per step; beside them the
validation PSNR (val_street, val_bev: analysis only, nothing is chosen on it here).

Usage: python benchmarks/validation/growth_signals.py DATA OUT LABEL [FIELD=VALUE ...]
(FIELD: a dotted field of Splatfacto's model config, as benchmarks/validation/size_prune.py).
Writes OUT/<LABEL>.json (one record per refinement, then the final primitives and validation PSNR) and
OUT/<LABEL>.md (the same as a table); the run itself goes to a temporary folder.
Produced benchmarks/results/growth_signals/ (issue 20, point 1: none of the signals levels off while
the Gaussians grow, README "Model size").
"""
import argparse
import dataclasses
import json
import shutil
import tempfile
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.engine.trainer import Trainer  # noqa: E402
from nerf2gs_bench.paper import _overrides  # noqa: E402
from nerf2gs_bench.size import model_overrides  # noqa: E402
from nerf2gs_plugin.methods.splatfacto import strategy as S  # noqa: E402
from nerf2gs_plugin.registry import get_method  # noqa: E402
from nerf2gs_plugin.utils.config import apply_plain  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("data", type=Path)
ap.add_argument("out", type=Path)
ap.add_argument("label")
ap.add_argument("overrides", nargs="*", help="FIELD=VALUE of the model config")
args = ap.parse_args()
data, out, label = args.data, args.out, args.label
extra = model_overrides(args.overrides)
cfg = apply_plain(get_method("splatfacto").config, _overrides("quick", "splatfacto", extra), where="growth_signals")
cfg = dataclasses.replace(cfg, data=data, output_dir=Path(tempfile.mkdtemp()), timestamp=f"{data.name}-{label}", progress=False)
trainer = Trainer(cfg)
trainer.setup()
model = trainer.pipeline.model
train = trainer.pipeline.datamanager.train_images
val = {s: trainer.pipeline.datamanager.eval_split(s)[1] for s in ("val_street", "val_bev")}


@torch.no_grad()
def mean_psnr(images, idx) -> float:
    vals = []
    for i in idx:
        rgb = model.render_camera(images.cameras[i:i + 1])["rgb"]
        vals.append(float(-10 * torch.log10(((rgb - images.image(i).to(rgb)) ** 2).mean())))
    return sum(vals) / len(vals)


records = []
refine = S.DefaultStrategy.refine
last = {"step": 0}  # the statistics are reset at every refinement step (densifying or not)


def logged_refine(self, step, params, optimizers):
    visible = float(self.count.mean()) if self.count is not None else float("nan")  # since the last reset
    counts = refine(self, step, params, optimizers)
    c = self.cfg
    if step >= c.warmup_length and step % c.refine_every == 0 and step > 0:
        since, last["step"] = step - last["step"], step
        was = model.training
        model.eval()
        weights = model.training_blend_weights()
        records.append({"step": step, "gaussians": int(params["means"].shape[0]),
                        "carry_90pct_weight": int((~S.light_mask(weights, 0.1)).sum()) if weights is not None else None,
                        "visible_per_step": visible / since,
                        "train_subset_psnr": mean_psnr(train, range(0, len(train), 6)),
                        **{s: mean_psnr(v, range(len(v))) for s, v in val.items()}, **counts})
        model.train(was)
    return counts


S.DefaultStrategy.refine = logged_refine
trainer.train()
model.eval()
final = {"primitives": model.num_primitives(), **{s: mean_psnr(v, range(len(v))) for s, v in val.items()}}
final["val_mean"] = (final["val_street"] + final["val_bev"]) / 2
doc = {"data": str(data), "label": label, "overrides": extra, "refinements": records, "final": final}
out.mkdir(parents=True, exist_ok=True)
atomic_write_text(out / f"{label}.json", json.dumps(doc, indent=1))
shutil.rmtree(cfg.output_dir, ignore_errors=True)
f = lambda v, fmt: "-" if v is None else fmt.format(v)  # noqa: E731
md = [f"# Growth signals of a quick Splatfacto run: {label}", "", f"Data: `{data}`; overrides: `{json.dumps(extra)}`. At every "
      "refinement: Gaussians, the count carrying 90% of the training views' blending weight, visible Gaussians per step "
      "(mean over the Gaussians since the last refinement), PSNR of every 6th training view, validation PSNR.", "",
      "| step | Gaussians | carry 90% of the weight | visible per step | train subset PSNR | val_street | val_bev | cloned | split | pruned |",
      "|---|---|---|---|---|---|---|---|---|---|"]
md += [f"| {r['step']} | {r['gaussians']} | {f(r['carry_90pct_weight'], '{}')} | {f(r['visible_per_step'], '{:.3f}')} | "
       f"{r['train_subset_psnr']:.2f} | {r['val_street']:.2f} | {r['val_bev']:.2f} | {r['cloned']} | {r['split']} | {r['pruned']} |"
       for r in records]
md += ["", f"Final: {final['primitives']} Gaussians, val_street {final['val_street']:.2f}, val_bev {final['val_bev']:.2f}, "
       f"mean {final['val_mean']:.2f} dB."]
atomic_write_text(out / f"{label}.md", "\n".join(md) + "\n")
print(json.dumps(final))
