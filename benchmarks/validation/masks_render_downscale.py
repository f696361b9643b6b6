"""``ns2gs-data masks --render-downscale``: masks from full-size renders vs every other pixel (same
reference, trained here when absent: STEPS steps on the mask-less view), IoU against the exact masks
when the dataset has them (synthetic streets) and the agreement of the two mask sets; default
AutoOptions, and with the motion route on. Numbers in docs/speed.md.
Usage: python benchmarks/validation/masks_render_downscale.py DATA REFERENCE_DIR STEPS OUT.json"""
import argparse, json, time, torch, torch.nn.functional as F
from pathlib import Path
from nerf2gs_plugin.masking.auto_masks import at_full_size, render_views
from nerf2gs_plugin.masking.mask_reference import ensure_reference
from nerf2gs_plugin.masks.auto import AutoOptions, masks_from_renders
from nerf2gs_plugin.masks.motion import MotionOptions, add_motion
from nerf2gs_plugin.masks.maskless import maskless_view
from nerf2gs_plugin.data.images import load_mask

torch.set_num_threads(1)
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("data", type=Path, help="dataset folder")
ap.add_argument("refdir", type=Path, help="the masks' reference folder (trained here when absent)")
ap.add_argument("steps", type=int, help="reference steps")
ap.add_argument("out", type=Path, help="results JSON")
args = ap.parse_args()
data, refdir, steps, out = args.data, args.refdir, args.steps, args.out
c0 = time.process_time()
ref = ensure_reference(data, refdir, steps, progress=False, log=lambda s: None)
print(f"reference: {time.process_time() - c0:.1f} CPU s", flush=True)
R = {}
for name, d in (("full", 1.0), ("half", 2.0)):
    c0 = time.process_time()
    R[name] = render_views(maskless_view(data), ref, ["train"], progress=False, render_downscale=d, log=lambda s: None)
    print(f"{name} renders: {time.process_time() - c0:.1f} CPU s, {len(R[name].views['train'])} views", flush=True)
exact = (data / "masks" / "sky").is_dir()
def up(m, shape):
    return m if tuple(m.shape) == tuple(shape) else F.interpolate(m.float()[None, None], size=shape, mode="nearest")[0, 0] > 0.5
doc = {"data": str(data), "reference_steps": steps}
for variant, motion in (("default", None), ("motion", MotionOptions(enabled=True))):
    masks = {}
    for name, r in R.items():
        res = {"train": masks_from_renders(r, AutoOptions(), log=lambda s: None)["train"]}
        if motion is not None:
            add_motion(at_full_size(r, res), res, motion, log=lambda s: None, progress=False)  # flow on the full-size frames
        masks[name] = res["train"]
    shape = tuple(R["full"].views["train"][0]["acc"].shape)
    row = {}
    for k in ("sky", "ground", "transient"):
        agree_i = agree_u = 0
        iou = {n: [0, 0] for n in masks}
        cover = {n: [0, 0] for n in masks}
        for j, v in enumerate(R["full"].views["train"]):
            a, b = getattr(masks["full"][j], k), up(getattr(masks["half"][j], k), shape)
            agree_i += int((a & b).sum()); agree_u += int((a | b).sum())
            for n, m in (("full", a), ("half", b)):
                cover[n][0] += int(m.sum()); cover[n][1] += m.numel()
            if exact:
                gt = load_mask(data / "masks" / k / (Path(v["name"]).stem + ".png")).bool()
                for n, m in (("full", a), ("half", b)):
                    m = up(m, tuple(gt.shape))
                    iou[n][0] += int((m & gt).sum()); iou[n][1] += int((m | gt).sum())
        row[k] = {"full_vs_half_iou": round(agree_i / max(1, agree_u), 4),
                  "coverage": {n: round(c[0] / max(1, c[1]), 4) for n, c in cover.items()}}
        if exact:
            row[k]["iou_vs_exact"] = {n: round(c[0] / max(1, c[1]), 4) for n, c in iou.items()}
    doc[variant] = row
    print(variant, json.dumps(row), flush=True)
out.write_text(json.dumps(doc, indent=1))
