"""Fewer samples per ray at inference, interleaved A/B in one process: CPU s per view and PSNR vs today's
render, on bird's-eye views of the augmentation (AugmentConfig defaults) and training views.
The first variant is the reference of the PSNR column. Numbers in docs/speed.md.
Usage: python benchmarks/validation/render_samples_ab.py RUN NBEV NTRAIN REPS "48,24,24;48,24,16;32,16,16"
(proposal samples..., fine samples per variant)"""
import argparse, dataclasses, time, torch
from nerf2gs_plugin.runs.load import load_run
from nerf2gs_plugin.augment.config import AugmentConfig
from nerf2gs_plugin.augment.views import additional_views

torch.set_num_threads(1)
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("run", help="a StreetNeRF run folder")
ap.add_argument("nbev", type=int, help="bird's-eye views to render")
ap.add_argument("ntrain", type=int, help="training views to render")
ap.add_argument("reps", type=int, help="interleaved repetitions (best kept)")
ap.add_argument("variants", help='"proposal...,fine;..." one variant per ;')
args = ap.parse_args()
run = load_run(args.run, device="cpu")
model = run.model
td = run.pipeline.datamanager.train_data
nbev, ntrain, reps = args.nbev, args.ntrain, args.reps
variants = [tuple(int(x) for x in v.split(",")) for v in args.variants.split(";")]
views = additional_views(td.cameras, td, AugmentConfig())
bev = views.cameras
cams = [bev[int(i)] for i in torch.linspace(0, len(bev) - 1, nbev).round().long()] + \
       [td.cameras[int(i):int(i) + 1] for i in torch.linspace(0, len(td.cameras) - 1, ntrain).round().long()]
kind = ["bev"] * nbev + ["train"] * ntrain
base = model.config
print(f"{len(bev)} bird's-eye views, size {int(bev.width[0])}x{int(bev.height[0])}; base samples {base.num_proposal_samples} / {base.num_nerf_samples}", flush=True)
def setup(v):
    model.config = dataclasses.replace(base, num_proposal_samples=tuple(v[:-1]), num_nerf_samples=v[-1])
setup(variants[0]); model.render_camera(cams[0])
cpu = {v: [] for v in variants}; outs = {}
for rep in range(reps):
    order = variants if rep % 2 == 0 else variants[::-1]
    for v in order:
        setup(v)
        c0 = time.process_time()
        outs[v] = [model.render_camera(c) for c in cams]
        cpu[v].append(time.process_time() - c0)
ref = outs[variants[0]]
def psnr(a, b):
    return float(10 * torch.log10(1 / ((a - b) ** 2).mean().clamp_min(1e-20)))
for v in variants:
    c = min(cpu[v]) / len(cams)
    rows = {}
    for k in ("bev", "train"):
        idx = [i for i, kk in enumerate(kind) if kk == k]
        if idx:
            mse = sum(float(((outs[v][i]["rgb"] - ref[i]["rgb"]) ** 2).mean()) for i in idx) / len(idx)
            rows[k] = round(float(10 * torch.log10(torch.tensor(1 / max(mse, 1e-20)))), 1)
    mx = max(float((o["rgb"] - r["rgb"]).abs().max()) for o, r in zip(outs[v], ref))
    dacc = max(float((o["accumulation"] - r["accumulation"]).abs().mean()) for o, r in zip(outs[v], ref))
    print(f"{v}: {c:.2f} CPU s/view (x{min(cpu[variants[0]]) / min(cpu[v]):.2f}); PSNR vs {variants[0]}: {rows}; max|d rgb| {mx:.3f}; mean|d acc| {dacc:.1e}; all {[round(x, 1) for x in cpu[v]]}", flush=True)
