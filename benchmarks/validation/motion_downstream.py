"""Downstream A/B of the motion route (``masks/motion.py``): do its masks remove the ghosts of movers
that ride with the camera, and what do they cost at street level?

On the synthetic street with movers (the motion bench's WORK folders of
``benchmarks/validation/motion_masks_scene.py``: its street, its ``process video`` capture and its
reference's cached renders), for each arm (masks without / with the motion route, everything else
equal, same seed):

  * masks: transient IoU / precision / recall over the training frames against the exact masks, and
    the CPU seconds of ``add_motion`` (getrusage, one thread);
  * a copy of the capture at 1/FACTOR per side with those masks (train split) -> StreetNeRF (STEPS,
    no warm start) -> Splatfacto ``--augment-from`` it (the NeRF views);
  * held-out frames (the parser's every 8th): PSNR over the static pixels (exact masks) and, in the exact
    mover pixels, PSNR / MAE against the street rendered without movers and cars (the background a
    static model should show there; gain fitted per channel on the static pixels): the ghost measure.
    ``mover_vs_photo``: PSNR in the same pixels against the photo (high: the model draws the mover).

Usage: python benchmarks/validation/motion_downstream.py WORK RUNS OUT_STEM [--steps N] [--factor F]
(RUNS keeps the arms' captures and runs; OUT_STEM.json gets this scene's rows merged, OUT_STEM.md is
written from the JSON). Produced benchmarks/results/motion_downstream.{json,md}.
"""
import argparse
import json
import resource
import shutil
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

torch.set_num_threads(1)
from nerf2gs_bench import real as br  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_bench.real_path_speed import Stages, _train, _trainer_config  # noqa: E402
from nerf2gs_plugin.data.images import load_image, load_mask  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

ARMS = ("without_motion", "with_motion", "with_motion_either")
EITHER = {"composite_loss": "either"}
"""The third arm: the route's masks and StreetNeRF, the target learning each composite pixel as painted or as
photographed (``--augment.composite-loss either``): do the ghosts come back?"""
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("work", type=Path, help="a motion bench WORK folder (street/, estimated/, renders.pt)")
ap.add_argument("runs", type=Path)
ap.add_argument("out_stem", type=Path)
ap.add_argument("--steps", type=int, default=600, help="StreetNeRF and Splatfacto steps")
ap.add_argument("--factor", type=int, default=2, help="training images at 1/FACTOR per side")
ap.add_argument("--arm", choices=(*ARMS, "both"), default="both", help="train one arm only (both: the first two)")
ap.add_argument("--train-seed", type=int, default=42, help="the trainings' seed (another one: the runs' own spread)")
ap.add_argument("--reuse", action="store_true", help="keep a StreetNeRF already trained in RUNS")
ap.add_argument("--md-only", action="store_true")
args = ap.parse_args()


def cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def counts(pred: torch.Tensor, gt: torch.Tensor) -> np.ndarray:
    return np.array([int((pred & gt).sum()), int((pred | gt).sum()), int(pred.sum()), int(gt.sum())])


def stats(c: np.ndarray) -> dict:
    i, u, p, t = (int(x) for x in c)
    return {"iou": round(i / max(u, 1), 4), "precision": round(i / max(p, 1), 4), "recall": round(i / max(t, 1), 4)}


def down(x: torch.Tensor, f: int) -> torch.Tensor:
    """[H, W] or [H, W, C] -> box-averaged at 1/f per side."""
    t = x.float()
    t = t[None, None] if t.dim() == 2 else t.permute(2, 0, 1)[None]
    t = F.avg_pool2d(t, f)[0]
    return t[0] if x.dim() == 2 else t.permute(1, 2, 0)


def masks_for_arms(work: Path, est: Path) -> tuple[dict, list[str], dict]:
    """Masks of the train frames without / with the motion route, their scores and the route's CPU s."""
    import nerf2gs_plugin.masks.auto as auto_mod
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.masking.auto_masks import ground_plane
    from nerf2gs_plugin.masks.auto import AutoOptions, masks_from_renders
    from nerf2gs_plugin.masks.maskless import maskless_view
    from nerf2gs_plugin.masks.motion import MotionOptions, add_motion

    sys.modules.setdefault("nerf2gs_plugin.data.masks.auto", auto_mod)  # renders cached before masks/ moved
    r = torch.load(work / "renders.pt", weights_only=False)
    train = parse_dataset(maskless_view(est), "train")
    r.up, r.height = ground_plane(train, [])
    names = [q.name for q in train.image_filenames]
    base = masks_from_renders(r, AutoOptions(), log=lambda s: None)
    with_motion = masks_from_renders(r, AutoOptions(), log=lambda s: None)
    c0 = cpu()
    add_motion(r, with_motion, MotionOptions(), log=lambda s: None, progress=False)
    seconds = cpu() - c0
    street = work / "street"
    rows = {arm: {"coverage": round(float(torch.stack([m.transient for m in res["train"]]).float().mean()), 4)}
            for arm, res in zip(ARMS, (base, with_motion))}
    rows["with_motion"]["motion_cpu_s"] = round(seconds, 1)
    rows["with_motion"]["motion_cpu_s_per_frame"] = round(seconds / len(names), 3)
    if not street.is_dir():  # a real capture: no exact masks
        return {"without_motion": base["train"], "with_motion": with_motion["train"]}, names, rows
    meta = json.loads((street / "transforms.json").read_text())
    for arm, res in zip(ARMS, (base, with_motion)):
        c = sum(counts(m.transient, load_mask(street / meta["frames"][br.frame_index(Path(n))]["transient_mask_path"]))
                for n, m in zip(names, res["train"]))
        rows[arm]["transient"] = stats(c)
    rows["with_motion_either"] = dict(rows["with_motion"])
    return {"without_motion": base["train"], "with_motion": with_motion["train"], "with_motion_either": with_motion["train"]}, names, rows


def arm_capture(est: Path, out: Path, f: int, names: list[str], masks: list) -> Path:
    """The capture at 1/f per side (box filter) with the arm's train masks."""
    from nerf2gs_plugin.masking.make_masks import _write

    shutil.rmtree(out, ignore_errors=True)
    (out / "images").mkdir(parents=True)
    meta = json.loads((est / "transforms.json").read_text())
    for fr in meta["frames"]:
        src = est / fr["file_path"]
        img = Image.open(src)
        w, h = img.size[0] // f, img.size[1] // f
        img.resize((w, h), Image.BOX).save(out / "images" / (src.stem + ".png"))
        fr["file_path"] = f"images/{src.stem}.png"
        for k in ("fl_x", "fl_y", "cx", "cy"):
            fr[k] = fr[k] / f
        fr["w"], fr["h"] = w, h
    shutil.copy(est / meta["ply_file_path"], out / meta["ply_file_path"])
    (out / "transforms.json").write_text(json.dumps(meta, indent=1))
    for n, m in zip(names, masks):
        _write(out, Path(n).with_suffix(".png"), {"sky": m.sky, "ground": m.ground, "transient": m.transient}, (w, h))
    return out


def backgrounds(street: Path, frames: list[int], size: tuple[int, int]) -> dict[int, torch.Tensor]:
    """The street's training frames rendered without movers and cars (the static scene)."""
    from nerf2gs_plugin.data.synthetic.layout import Boxes, build_layout, empty_boxes
    from nerf2gs_plugin.data.synthetic.movers import build_movers
    from nerf2gs_plugin.data.synthetic.raycast import Pinhole, ShadowMap, render_view

    meta = json.loads((street / "transforms.json").read_text())
    cfg = json.loads((street / "synth_stats.json").read_text())["config"]
    layout = build_layout(cfg["seed"], cfg["num_cars"])
    layout.static = Boxes.cat([layout.static, build_movers(layout).parked])
    shadows, intr = ShadowMap(layout), Pinhole.from_fov(*size, cfg["fov_deg"])
    return {i: render_view(layout, torch.tensor(meta["frames"][i]["transform_matrix"])[:3], intr, empty_boxes(), shadows,
                           cfg["spp"]).rgb for i in frames}


def evaluate(run_dir: Path, street: Path, bg: dict, f: int) -> dict:
    """Held-out means; a real capture (no street) gets the whole-image PSNR only."""
    from nerf2gs_plugin.runs.load import load_run

    run = load_run(run_dir)
    dm = run.pipeline.datamanager
    outputs, _ = dm.eval_split("test")
    meta = json.loads((street / "transforms.json").read_text()) if street.is_dir() else None
    sums = {k: [] for k in ("psnr", "static_psnr", "ghost_psnr", "ghost_mae", "mover_vs_photo_psnr")}
    with torch.no_grad():
        for (camera, batch), name in zip(dm.eval_images("test"), outputs.image_filenames):
            i = br.frame_index(Path(name))
            pred, gt = run.model.render_camera(camera)["rgb"].clamp(0, 1).cpu(), batch["image"].cpu()
            if meta is None:
                sums["psnr"].append(-10 * np.log10(max(float(((pred - gt) ** 2).mean()), 1e-10)))
                continue
            mover = down(load_mask(street / meta["frames"][i]["transient_mask_path"]), f) > 0.5
            static = ~mover
            back = down(bg[i], f)
            gain = (gt[static] * back[static]).sum(0) / (back[static] ** 2).sum(0).clamp(min=1e-8)
            back = (back * gain).clamp(0, 1)
            mse = lambda a, b, m: float(((a[m] - b[m]) ** 2).mean())  # noqa: E731
            p = lambda v: -10 * np.log10(max(v, 1e-10))  # noqa: E731
            sums["psnr"].append(p(float(((pred - gt) ** 2).mean())))
            sums["static_psnr"].append(p(mse(pred, gt, static)))
            if mover.any():
                sums["ghost_psnr"].append(p(mse(pred, back, mover)))
                sums["ghost_mae"].append(float((pred[mover] - back[mover]).abs().mean()))
                sums["mover_vs_photo_psnr"].append(p(mse(pred, gt, mover)))
    return {k: round(float(np.mean(v)), 3) for k, v in sums.items() if v} | {"images": len(sums["psnr"])}


def run_scene() -> dict:
    work, runs = args.work.resolve(), args.runs.resolve()
    est = runs / "estimated"
    if not (est / "transforms.json").is_file():
        shutil.copytree(work / "estimated", est, ignore=shutil.ignore_patterns("images_*", "colmap", ".ns2gs*"))
    masks, names, rows = masks_for_arms(work, est)
    print("masks", rows, flush=True)
    street = work / "street"
    every = [Path(fr["file_path"]).name for fr in json.loads((est / "transforms.json").read_text())["frames"]]
    held = sorted(br.frame_index(Path(n)) for n in every if n not in names)
    size = tuple(int(v) for v in load_image(est / json.loads((est / "transforms.json").read_text())["frames"][0]["file_path"]).shape[1::-1])
    bg = backgrounds(street, held, size) if street.is_dir() else {}
    for arm in ARMS[:2] if args.arm == "both" else (args.arm,):
        stages, sn = Stages(), runs / arm / "streetnerf"
        if arm == "with_motion_either":  # the same masks and StreetNeRF as with_motion
            sn = runs / "with_motion" / "streetnerf"
        if (args.reuse or arm == "with_motion_either") and any((sn / "checkpoints").glob("*.ckpt")):  # an interrupted run's StreetNeRF
            data = sn.parent / "capture"
        else:
            data = arm_capture(est, runs / arm / "capture", args.factor, names, masks[arm])
            sn = _train(stages, "StreetNeRF", _trainer_config("streetnerf", data, sn, args.steps, seed=args.train_seed))
        rows[arm]["streetnerf"] = evaluate(sn, street, bg, args.factor)
        if street.is_dir():
            changes = EITHER if arm == "with_motion_either" else None
            gs = _train(stages, "Splatfacto + NeRF views", _trainer_config("splatfacto", data, runs / arm / "splatfacto-nerf-views", args.steps,
                                                                           changes, augment_from=sn, seed=args.train_seed),
                        setup_part="NeRF views: renders")
            rows[arm]["splatfacto_nerf_views"] = evaluate(gs, street, bg, args.factor)
        rows[arm]["cpu_s"] = {k: v["cpu_s"] for k, v in stages.rows.items()}
        print(arm, rows[arm], flush=True)
    seed = json.loads((street / "synth_stats.json").read_text())["config"]["seed"] if street.is_dir() else None
    return {"work": str(work), "seed": seed, "size": [size[0] // args.factor, size[1] // args.factor],
            "train_frames": len(names), "held_out": held, "steps": args.steps, "train_seed": args.train_seed, **rows}


def write_md(doc: dict, stem: Path) -> None:
    md = ["# Motion masks downstream: ghosts and street-level cost", "",
          f"Machine: {doc['machine']}. Produced by `benchmarks/validation/motion_downstream.py`. The synthetic street with "
          "movers (a car and a cyclist ahead at the drive's speed, pedestrians, parked cars), its 30-frame drive through "
          "`process video` and a 1000-step mask-less reference (the motion bench's), masks without / with the motion "
          "route; each arm's capture at half size trains StreetNeRF and Splatfacto + NeRF views (same seed, same steps). "
          "Held-out frames: every 8th. `static`: PSNR over the exact static pixels. `ghost`: PSNR / MAE in the exact "
          "mover pixels against the street rendered without movers (higher PSNR, lower MAE: fewer ghosts). `mover vs photo`: "
          "PSNR there against the photo (high: the model draws the mover).", "",
          "| scene | arm | transient IoU (P / R) | motion CPU s | model | PSNR | static PSNR | ghost PSNR | ghost MAE | mover vs photo |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for key, sc in sorted(doc["scenes"].items()):
        for arm in ARMS:
            a = sc.get(arm, {})
            t = a.get("transient")
            iou = f"{t['iou']:.3f} ({t['precision']:.2f} / {t['recall']:.2f})" if t else ""
            secs = f"{a['motion_cpu_s']:.1f}" if "motion_cpu_s" in a else ""
            for model, label in (("streetnerf", "StreetNeRF"), ("splatfacto_nerf_views", "Splatfacto + NeRF views")):
                e = a.get(model)
                if e:
                    cells = [f"{e[k]:{fmt}}" if k in e else "" for k, fmt in
                             (("psnr", ".2f"), ("static_psnr", ".2f"), ("ghost_psnr", ".2f"), ("ghost_mae", ".3f"), ("mover_vs_photo_psnr", ".2f"))]
                    md.append(f"| {key} | {arm.replace('_', ' ')} | {iou} | {secs} | {label} | " + " | ".join(cells) + " |")
    md.append("")
    md.append(doc.get("notes", ""))
    atomic_write_text(stem.with_suffix(".md"), "\n".join(md) + "\n")


stem = args.out_stem
doc = json.loads(stem.with_suffix(".json").read_text()) if stem.with_suffix(".json").is_file() else {"scenes": {}}
if not args.md_only:
    row = run_scene()
    doc = json.loads(stem.with_suffix(".json").read_text()) if stem.with_suffix(".json").is_file() else {"scenes": {}}
    key = args.work.name + (f", training seed {args.train_seed}" if args.train_seed != 42 else "") + (f", {args.steps} steps" if args.steps != 600 else "")
    scene = doc["scenes"].setdefault(key, {})
    for k, v in row.items():  # an arm trained by an earlier run keeps its rows
        if isinstance(v, dict) and isinstance(scene.get(k), dict):
            scene[k].update(v)
        else:
            scene[k] = v
    doc["machine"] = machine_line()
    atomic_write_text(stem.with_suffix(".json"), json.dumps(doc, indent=1))
write_md(doc, stem)
print(stem.with_suffix(".md").read_text())
