"""Two more cues tried on the masks stage's moving-object masks, scored against exact masks (synthetic streets) or
hand labels (real captures). No default is changed by them; docs/masks-motion.md tells what they gave.

* ``sweep``: photo-consistency with every static depth a pixel may have. Frame ``j`` is sampled along frame
  ``i``'s epipolar line at parallaxes from -8 to 160 pixels (1-pixel steps), the 5x5 mean grey difference kept per
  parallax; a pixel is "explained" by a pair where its best cost over the feasible parallaxes (not beyond the
  ground-plane bound, ``rel`` / ``floor_px`` as the route's) is under ``max(tau, k x the frame's median)``.
  Gates: the masks less the pixels every pair of each side explains (then holes filled, small regions dropped),
  or the regions whose share of explained pixels is under ``r``; and the other way, the textured pixels no
  feasible parallax explains in any pair of either side added to the masks.
* ``contact``: objects stand on the road, so the road below a region's object is not the object: in each column a
  region's pixels more than ``margin`` rows below the lowest "evidence" pixel of it (over ``smooth`` columns)
  dropped. Evidence: the true mover pixels (a bound: the best such a cut could do), or textured pixels that the
  ground plane's warp explains in no pair of either side.

Usage:
  python benchmarks/validation/motion_static_cues.py cache-synthetic SEED WORK STASH   (WORK: motion_masks_scene.py's)
  python benchmarks/validation/motion_static_cues.py cache-real ROOT STASH --labels NAME ... [--frame-offset 1] [--crop-rows R]
      (ROOT: capture/ and masks-reference/ of a real path capture, e.g. real_path_speed's make_capture + process)
  python benchmarks/validation/motion_static_cues.py score STASH OUT_STEM [--every 3]
  python benchmarks/validation/motion_static_cues.py ab OUT_STEM LABEL=STASH ...   (each stage's scores per arm)
(the cache commands take --motion KEY=VALUE ...: the route's options, e.g. sweep_grey=6)
STASH keeps the frames the route saw and the stage's masks (torch.save); OUT_STEM.{json,md} get the scores.
"""
import argparse
import ast
import json
from pathlib import Path

import cv2
import numpy as np
import torch

import nerf2gs_plugin.masks.motion as mm
from nerf2gs_plugin.masks.static_sweep import textured, unexplained
from nerf2gs_bench.machine import machine_line
from nerf2gs_plugin.utils.io import atomic_write_text

STAGES = ("without_motion", "first_pass", "second_pass", "settled")


def cache(capture: Path, reference: Path, truth_of, out: Path, motion: dict) -> None:
    """The masks stage's code on ``capture`` (``motion_product.product_masks``, renders at 1/2) with the frames the
    motion route built kept; ``truth_of(name, mask) -> (truth, leave-out) or None``."""
    from nerf2gs_bench.motion_product import ensure_keyed_reference, product_masks

    ensure_keyed_reference(capture, reference, True)
    stash: dict = {}
    orig = mm.frames_from_renders

    def keep(views, sky, up, height, clamp=True, workers=None):
        frames = orig(views, sky, up, height, clamp, workers)
        if "frames" not in stash:  # the first pass's; the second pass reuses them
            stash["frames"] = [dict(image=f.image, dist=f.dist, c2w=f.c2w, intr=f.intr, bound=f.bound, residual=f.residual, name=v["name"]) for f, v in zip(frames, views)]
            stash["up"], stash["height"] = up, height
        return frames

    mm.frames_from_renders = keep
    try:
        res = product_masks(capture, reference, 2, motion=mm.MotionOptions(**motion))
    finally:
        mm.frames_from_renders = orig
    stash["names"] = res["names"]
    for k in STAGES:
        stash[k] = [m.transient for m in res[k]]
    pairs = [truth_of(n, m.transient) for n, m in zip(res["names"], res["settled"])]
    stash["truth"] = [p[0] if p else None for p in pairs]
    stash["leave"] = [p[1] if p else None for p in pairs]
    torch.save(stash, out)


def synthetic_truth(seed: int, work: Path):
    from nerf2gs_bench import real as br
    from nerf2gs_plugin.data.images import load_mask
    from nerf2gs_plugin.masks.evaluate import resample_mask

    meta = json.loads((work / "street" / "transforms.json").read_text())
    em = {Path(f["file_path"]).name: f for f in json.loads((work / "estimated" / "transforms.json").read_text())["frames"]}

    def truth_of(name, mask):
        f, tf = em[name], meta["frames"][br.frame_index(Path(name))]
        t = resample_mask(load_mask(work / "street" / tf["transient_mask_path"]), (meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"]),
                          (f["fl_x"], f["fl_y"], f["cx"], f["cy"]), tuple(mask.shape))
        return t.numpy(), np.zeros(t.shape, bool)
    return truth_of


def labels_truth(names: list[str], offset: int, crop_rows):
    from nerf2gs_bench.hand_labels import frame_key, frame_masks, merged_labels

    labels = merged_labels(names)
    width = len(next(iter(labels["frames"])))

    def truth_of(name, mask):
        key = frame_key(Path(name).stem)
        key = None if key is None else f"{int(key) + offset:0{width}d}"
        if key not in labels["frames"]:
            return None
        moving, leave = frame_masks(labels["frames"][key], labels, (mask.shape[1], mask.shape[0]), crop_rows)
        return np.asarray(moving, bool), np.asarray(leave, bool)
    return truth_of


class Frame:
    def __init__(self, d: dict):
        self.__dict__.update(d)
        if getattr(self, "dist", None) is None:  # stashes made before the prior was kept
            self.dist = torch.full(self.image.shape[:2], float("inf"))
        self.residual = getattr(self, "residual", None)


def bound_parallax(fi, fj, rays, p_inf, u):
    if fi.bound is None:
        return torch.zeros(fi.dist.shape)
    rb, ok = mm.rigid_flow(fi.c2w, fi.intr, fi.bound, fj.c2w, fj.intr, rays)
    return torch.where(ok, mm.along(rb, p_inf, u), torch.zeros(fi.dist.shape))


def sweep_pair(fi, fj, gi, gj, opts: mm.MotionOptions, smin=-8.0, smax=160.0) -> dict:
    """Best 5x5 grey cost over the feasible parallaxes along the epipolar line, the worst over all, validity."""
    h, w = gi.shape
    rays = mm.ray_directions(fi.c2w, fi.intr, h, w)
    p_inf, u, line_ok = mm.epipolar_line(fi, fj, rays)
    s_b = bound_parallax(fi, fj, rays, p_inf, u)
    lim = (s_b - torch.clamp(opts.rel * s_b, min=opts.floor_px)).numpy()
    p_inf, u = p_inf.numpy(), u.numpy()
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    bx, by = xs + p_inf[..., 0], ys + p_inf[..., 1]
    best, worst = np.full((h, w), np.inf, np.float32), np.zeros((h, w), np.float32)
    for s in np.arange(smin, smax + 1e-6, 1.0, dtype=np.float32):
        mx, my = bx + s * u[..., 0], by + s * u[..., 1]
        inside = cv2.blur(((mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)).astype(np.float32), (5, 5)) > 0.999
        c = np.where(inside, cv2.blur(np.abs(gi.astype(np.float32) - cv2.remap(gj, mx, my, cv2.INTER_LINEAR)), (5, 5)), np.inf)
        best = np.where(s >= lim, np.minimum(best, c), best)
        worst = np.where(inside, np.maximum(worst, c), worst)
    return {"best": best, "worst": worst, "ok": line_ok.numpy() & np.isfinite(best)}


def plane_pair(fi, fj, gi, gj) -> dict:
    """5x5 grey cost of frame ``j`` warped onto ``i`` by the ground plane (below the horizon)."""
    rays = mm.ray_directions(fi.c2w, fi.intr, *gi.shape)
    flow, ok = mm.rigid_flow(fi.c2w, fi.intr, fi.bound, fj.c2w, fj.intr, rays)
    wj, inside = mm.warp(gj, flow.numpy())
    c = cv2.blur(np.abs(gi.astype(np.float32) - wj.astype(np.float32)), (5, 5))
    return {"best": c, "worst": c, "ok": ok.numpy() & inside & np.isfinite(fi.bound.numpy())}


def product_sweep(frames, greys, i: int, stride: int, opts: mm.MotionOptions, grey_min: float, rel: float) -> np.ndarray:
    """``masks/static_sweep.unexplained`` in every valid pair of each side, opened (what the route's vote keeps of it)."""
    pairs = []
    fi = frames[i]
    rays = mm.ray_directions(fi.c2w, fi.intr, *fi.dist.shape)
    for o in opts.neighbours:
        j = i + o * stride
        if not 0 <= j < len(frames):
            continue
        p_inf, u, ok = mm.epipolar_line(fi, frames[j], rays)
        s_b = bound_parallax(fi, frames[j], rays, p_inf, u)
        lowest = s_b - torch.clamp(opts.rel * s_b, min=opts.floor_px)
        rig, _ = mm.rigid_flow(fi.c2w, fi.intr, torch.minimum(fi.dist, fi.bound), frames[j].c2w, frames[j].intr, rays)
        wj, inside = mm.warp(greys[j], rig.numpy())
        warped = [np.where(inside, wj, greys[i]), mm.warp(greys[j], mm.rigid_flow(fi.c2w, fi.intr, fi.bound, frames[j].c2w, frames[j].intr, rays)[0].numpy())[0]]
        m = unexplained(greys[i], greys[j], p_inf, u, lowest, warped, grey_min, rel, opts.sweep_texture, opts.sweep_reach, opts.sweep_scale)
        pairs.append((o, {"ok": ok.numpy(), "m": (m & ok).numpy()}))
    got = per_side(pairs, lambda p: p["m"])
    return cv2.morphologyEx(got.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)) > 0


def per_side(pairs: list[tuple[int, dict]], test) -> np.ndarray:
    """Pixels where ``test(pair, threshold)`` holds in every valid pair of each side that has one (both sides
    where both have valid pairs)."""
    out = None
    for side in (-1, 1):
        ps = [p for off, p in pairs if np.sign(off) == side]
        if not ps:
            continue
        every, any_valid = np.ones(ps[0]["ok"].shape, bool), np.zeros(ps[0]["ok"].shape, bool)
        for p in ps:
            every &= test(p) | ~p["ok"]
            any_valid |= p["ok"]
        out = (every & any_valid) if out is None else (out & every & any_valid)
    return out if out is not None else np.zeros((1, 1), bool)


def threshold(p: dict, tau: float, k: float) -> float:
    return max(tau, k * float(np.median(p["best"][p["ok"]]))) if p["ok"].any() else tau


def regions(m: np.ndarray) -> tuple[int, np.ndarray]:
    n, lab = cv2.connectedComponents(m.astype(np.uint8), connectivity=8)
    return n, lab


def cleaned(m: np.ndarray, min_frac: float = 0.002) -> np.ndarray:
    pad = np.pad(m.astype(np.uint8), 1)
    cv2.floodFill(pad, np.zeros((pad.shape[0] + 2, pad.shape[1] + 2), np.uint8), (0, 0), 2)
    m = m | (pad[1:-1, 1:-1] == 0)  # holes filled
    n, lab = regions(m)
    sizes = np.bincount(lab.ravel(), minlength=n)
    return (sizes >= min_frac * m.size)[lab] & m


def region_share_below(m: np.ndarray, e: np.ndarray, r: float) -> np.ndarray:
    n, lab = regions(m)
    share = np.bincount(lab.ravel(), e.ravel().astype(float), n) / np.maximum(np.bincount(lab.ravel(), minlength=n), 1)
    return (share < r)[lab] & m


def contact_cut(m: np.ndarray, ev: np.ndarray, margin: int, smooth: int, min_ev: int = 5) -> np.ndarray:
    from numpy.lib.stride_tricks import sliding_window_view

    n, lab = regions(m)
    out, h = m.copy(), m.shape[0]
    rows = np.arange(h)[:, None]
    for r in range(1, n):
        reg = lab == r
        e = reg & ev
        if e.sum() < min_ev:
            continue
        low = np.where(e.any(0), h - 1 - np.argmax(e[::-1], axis=0), -1).astype(float)
        have, cols = np.where(low >= 0)[0], np.where(reg.any(0))[0]
        low[cols] = np.where(low[cols] < 0, low[have[np.abs(have[None, :] - cols[:, None]).argmin(1)]], low[cols])
        lowest = np.max(sliding_window_view(np.pad(low, smooth // 2, mode="edge"), smooth), axis=1)
        out &= ~(reg & (rows > lowest[None, :] + margin))
    return out


def score(stash: dict, keys: list[int], preds: list[np.ndarray]) -> dict:
    c = np.zeros(4)
    for k, p in zip(keys, preds):
        t, keep = stash["truth"][k], ~stash["leave"][k]
        p, t = p & keep, t & keep
        c += [(p & t).sum(), (p | t).sum(), p.sum(), t.sum()]
    return {"iou": round(c[0] / max(c[1], 1), 4), "precision": round(c[0] / max(c[2], 1), 3), "recall": round(c[0] / max(c[3], 1), 3)}


def run_score(stash_path: Path, out: Path, every: int) -> None:
    stash = torch.load(stash_path, weights_only=False)
    stash["truth"] = [None if t is None else np.asarray(t, bool) for t in stash["truth"]]
    stash["leave"] = [None if t is None else (np.zeros(t.shape, bool) if lv is None else np.asarray(lv, bool))
                      for t, lv in zip(stash["truth"], stash.get("leave") or [None] * len(stash["truth"]))]
    frames = sorted((Frame(d) for d in stash["frames"]), key=lambda f: f.name)
    pos = {f.name: i for i, f in enumerate(frames)}
    greys = [mm.grey(f.image) for f in frames]
    opts = mm.MotionOptions()
    stride = mm.neighbour_stride(frames, stash["up"], stash["height"], opts)
    keys = [k for k, t in enumerate(stash["truth"]) if t is not None][::every]
    rows: dict = {"stride": stride, "frames_scored": len(keys)}
    base = {st: [np.asarray(stash[st][k], bool) for k in keys] for st in STAGES}
    for st in STAGES:
        rows[st] = score(stash, keys, base[st])
    sweeps, planes, tex = {}, {}, {}
    for k in keys:
        i = pos[stash["names"][k]]
        nbrs = [o * stride for o in opts.neighbours if 0 <= i + o * stride < len(frames)]
        sweeps[k] = [(o, sweep_pair(frames[i], frames[i + o], greys[i], greys[i + o], opts)) for o in nbrs]
        planes[k] = [(o, plane_pair(frames[i], frames[i + o], greys[i], greys[i + o])) for o in nbrs]
        tex[k] = textured(greys[i], opts.sweep_texture)
    settled = base["settled"]
    for tau in (6, 10, 15):
        for kmed in (2.0, 3.0):
            expl = [per_side(sweeps[k], lambda p: p["best"] < threshold(p, tau, kmed)) for k in keys]
            rows[f"sweep: explained pixels dropped, tau {tau} k {kmed}"] = score(stash, keys, [cleaned(m & ~e) for m, e in zip(settled, expl)])
            rows[f"sweep: regions under 0.8 explained kept, tau {tau} k {kmed}"] = score(stash, keys, [region_share_below(m, e, 0.8) for m, e in zip(settled, expl)])
            new = [cv2.morphologyEx((per_side(sweeps[k], lambda p: p["best"] > threshold(p, tau, kmed)) & tex[k]).astype(np.uint8),
                                    cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)) > 0 for k in keys]
            rows[f"sweep: unexplained textured pixels added, tau {tau} k {kmed}"] = score(stash, keys, [cleaned(m | n) for m, n in zip(settled, new)])
            gated = [n & mm.residual_gate(frames[pos[stash["names"][k]]], opts.residual_rel).numpy() for n, k in zip(new, keys)]
            rows[f"sweep: ... and differing from the reference's render, tau {tau} k {kmed}"] = score(stash, keys, [cleaned(m | n) for m, n in zip(settled, gated)])
            rows[f"sweep: ... and touching a region, tau {tau} k {kmed}"] = score(stash, keys, [cleaned(mm.touching(torch.from_numpy(m), torch.from_numpy(n)).numpy()) for m, n in zip(settled, gated)])
    for tau in (6, 10):
        for kmed in (2.0, 3.0):
            new = [product_sweep(frames, greys, pos[stash["names"][k]], stride, opts, tau, kmed) for k in keys]
            rows[f"static_sweep.unexplained (the route's test), textured pixels no pair explains added, grey {tau} rel {kmed}"] = score(
                stash, keys, [cleaned(m | n) for m, n in zip(settled, new)])
    plane_ev = [per_side(planes[k], lambda p: p["best"] > threshold(p, 10, 3.0)) & tex[k] for k in keys]
    for margin in (2, 6):
        for smooth in (7, 21):
            rows[f"contact cut, exact evidence, margin {margin} smooth {smooth}"] = score(
                stash, keys, [contact_cut(m, stash["truth"][k], margin, smooth) for m, k in zip(settled, keys)])
            rows[f"contact cut, ground-plane evidence, margin {margin} smooth {smooth}"] = score(
                stash, keys, [contact_cut(m, e, margin, smooth) for m, e in zip(settled, plane_ev)])
    doc = {"stash": str(stash_path), "machine": machine_line(), "rows": rows}
    atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
    md = [f"# Static-hypothesis cues on the masks stage's masks ({stash_path.name})", "",
          f"Machine: {doc['machine']}. `benchmarks/validation/motion_static_cues.py score`; {len(keys)} frames scored, "
          f"neighbours {stride} frame(s) apart.", "", "| masks | IoU | precision | recall |", "|---|---|---|---|"]
    md += [f"| {name} | {r['iou']:.3f} | {r['precision']:.2f} | {r['recall']:.2f} |" for name, r in rows.items() if isinstance(r, dict)]
    atomic_write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
    print("\n".join(md))


def run_ab(arms: list[str], out: Path) -> None:
    """Each stage's pooled scores per arm (``LABEL=STASH``: the cache commands' stashes, e.g. without and with a
    route option, on the same capture and reference)."""
    rows = {}
    for arm in arms:
        label, path = arm.split("=", 1)
        stash = torch.load(path, weights_only=False)
        keys = [k for k, t in enumerate(stash["truth"]) if t is not None]
        stash["truth"] = [None if t is None else np.asarray(t, bool) for t in stash["truth"]]
        stash["leave"] = [None if t is None else (np.zeros(t.shape, bool) if lv is None else np.asarray(lv, bool))
                          for t, lv in zip(stash["truth"], stash.get("leave") or [None] * len(stash["truth"]))]
        rows[label] = {st: score(stash, keys, [np.asarray(stash[st][k], bool) for k in keys]) for st in STAGES}
        rows[label]["frames_scored"] = len(keys)
    doc = {"machine": machine_line(), "arms": {a.split("=", 1)[0]: a.split("=", 1)[1] for a in arms}, "rows": rows}
    atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
    md = [f"# The masks stage's moving-object masks, arm by arm ({out.name})", "", f"Machine: {doc['machine']}. "
          "`benchmarks/validation/motion_static_cues.py ab`; transient IoU (precision / recall) pooled over the scored frames.", "",
          "| arm | frames | " + " | ".join(STAGES) + " |", "|---|---|" + "---|" * len(STAGES)]
    for label, r in rows.items():
        md.append(f"| {label} | {r['frames_scored']} | " + " | ".join(f"{r[st]['iou']:.3f} ({r[st]['precision']:.2f} / {r[st]['recall']:.2f})" for st in STAGES) + " |")
    atomic_write_text(out.with_suffix(".md"), "\n".join(md) + "\n")
    print("\n".join(md))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("cache-synthetic")
    a.add_argument("seed", type=int), a.add_argument("work", type=Path), a.add_argument("stash", type=Path)
    b = sub.add_parser("cache-real")
    b.add_argument("root", type=Path), b.add_argument("stash", type=Path)
    b.add_argument("--labels", nargs="+", required=True), b.add_argument("--frame-offset", type=int, default=0), b.add_argument("--crop-rows", type=int)
    for p in (a, b):
        p.add_argument("--motion", nargs="*", default=[], metavar="KEY=VALUE", help="motion options other than the defaults")
    c = sub.add_parser("score")
    c.add_argument("stash", type=Path), c.add_argument("out", type=Path), c.add_argument("--every", type=int, default=1)
    d = sub.add_parser("ab")
    d.add_argument("out", type=Path), d.add_argument("arms", nargs="+", metavar="LABEL=STASH")
    args = ap.parse_args()
    motion = {k: ast.literal_eval(v) for k, v in (kv.split("=", 1) for kv in getattr(args, "motion", []))}
    if args.cmd == "cache-synthetic":
        cache(args.work / "estimated", args.work / "reference", synthetic_truth(args.seed, args.work), args.stash, motion)
    elif args.cmd == "cache-real":
        cache(args.root / "capture", args.root / "masks-reference", labels_truth(args.labels, args.frame_offset, args.crop_rows), args.stash, motion)
    elif args.cmd == "ab":
        run_ab(args.arms, args.out)
    else:
        run_score(args.stash, args.out, args.every)


if __name__ == "__main__":
    main()
