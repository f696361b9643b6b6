"""How far the motion route's decision logic (``masks/motion.py``) goes with the EXACT optical flow:
on the synthetic street with movers (``synth-street --movers``, the 30-frame forward drive at 400x224,
as ``motion_masks_scene.py``'s ``gt`` path: true poses, the static scene's true depth, the movers'
pixels at infinity bounded by the ground plane), the route's DIS flow is replaced by a lookup of the
exact flow (``data/synthetic/scene_flow.py``: each pixel's 3D point moved with its object to the
neighbour's time and projected into the neighbour; hidden and out-of-frame pixels invalid), and by
that flow smoothed across motion boundaries (a box filter of the flow left after the static warp,
what DIS measures, over the valid pixels: how DIS's spill arises). Transient IoU / precision / recall
pooled over the frames after each step: the votes (opened), the regions, grabCut's outline (the
oracle path has no reference render, so no residual gate). Per-object recall and where the static
pixels marked lie, for the final masks.

Usage: python benchmarks/validation/motion_exact_flow.py WORK OUT [--seeds 0 3]
(WORK/s<seed>/street: the street, generated there when missing; OUT: a JSON of the rows, and the
markdown table printed).
"""
import argparse
import json
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import torch

torch.set_num_threads(1)
from nerf2gs_plugin.data.images import load_image, load_mask  # noqa: E402
from nerf2gs_bench import mover_kinds as mk  # noqa: E402
from nerf2gs_plugin.data.synthetic.layout import Boxes, build_layout  # noqa: E402
from nerf2gs_plugin.data.synthetic.movers import build_movers, frame_boxes  # noqa: E402
from nerf2gs_plugin.data.synthetic.raycast import Pinhole  # noqa: E402
from nerf2gs_plugin.data.synthetic.scene_flow import exact_flow, trace_frame  # noqa: E402
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street  # noqa: E402
from nerf2gs_plugin.masks import from_renders as fr  # noqa: E402
from nerf2gs_plugin.masks import motion as mo  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

FRAMES, SIZE = 30, (400, 224)


def street_frames(street: Path) -> tuple[dict, list[mo.MotionFrame], list[torch.Tensor]]:
    """The drive's frames on the true poses and the static scene's true depth (``motion_masks_scene.run_gt``)."""
    meta = json.loads((street / "transforms.json").read_text())
    intr = (meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"])
    frames, gts = [], []
    for f in meta["frames"][:FRAMES]:
        c2w = torch.tensor(f["transform_matrix"])[:3]
        z = torch.from_numpy(np.load(street / f["depth_file_path"])).float()
        cos = (mo.ray_directions(c2w, intr, *z.shape) @ -c2w[:, 2].double()).float()
        trans = load_mask(street / f["transient_mask_path"])
        dist = torch.where((z > 0) & ~trans, z / cos, torch.full_like(z, float("inf")))
        bound = mo.static_distance(torch.full_like(dist, float("inf")), c2w, intr, torch.tensor([0.0, 0, 1]), 0.0)
        frames.append(mo.MotionFrame(load_image(street / f["file_path"]), torch.minimum(dist, bound), c2w, intr, bound))
        gts.append(trans)
    return meta, frames, gts


def exact_flows(seed: int, meta: dict, neighbours: tuple[int, ...]) -> tuple[dict, list, int]:
    """(i, j) -> (exact flow, valid) for the drive's pairs; the frames' traces; the static box count."""
    layout = build_layout(seed)
    movers = build_movers(layout)
    layout.static = Boxes.cat([layout.static, movers.parked])
    intr = Pinhole(meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"], meta["w"], meta["h"])
    hits = []
    for f in meta["frames"][:FRAMES]:
        c2w = torch.tensor(f["transform_matrix"], dtype=torch.float32)[:3]
        hits.append(trace_frame(layout, c2w, intr, frame_boxes(layout, movers, float(f["time"]), c2w)))
    flows = {(i, i + o): exact_flow(layout, intr, hits[i], hits[i + o]) for i in range(FRAMES) for o in neighbours if 0 <= i + o < FRAMES}
    return flows, hits, len(layout.static)


def box_blur(resid: torch.Tensor, valid: torch.Tensor, px: int) -> torch.Tensor:
    """``resid`` averaged over the valid pixels of a ``px`` box (normalised convolution)."""
    m = valid.numpy().astype(np.float32)
    num = cv2.blur(resid.numpy() * m[..., None], (px, px))
    den = cv2.blur(m, (px, px))[..., None]
    return torch.from_numpy(np.where(den > 1e-6, num / np.maximum(den, 1e-6), 0.0).astype(np.float32))


@contextmanager
def flow_lookup(frames: list, flows: dict, variant: str):
    """``optical_flow`` answers with the chosen flow for the pair ``pair_moving`` is judging (the
    flow left after the static warp: obs = rigid + it = the looked-up flow)."""
    if variant == "dis":
        yield
        return
    index = {id(f): k for k, f in enumerate(frames)}
    box = int(variant.split("blur")[1]) if "blur" in variant else 0
    orig_pair, orig_flow, ctx = mo.pair_moving, mo.optical_flow, {}

    def pair(fi, fj, gi, gj, opts, rays=None):
        flow, valid = flows[(index[id(fi)], index[id(fj)])]
        rig, _ = mo.rigid_flow(fi.c2w, fi.intr, fi.dist, fj.c2w, fj.intr, rays)
        keep = torch.isfinite(fi.dist) if variant == "exact, occlusion ignored" else valid
        resid = torch.where(keep[..., None], flow - rig, torch.zeros_like(rig))
        ctx["resid"] = box_blur(resid, valid, box) if box else resid
        moving, ok, obs, static = orig_pair(fi, fj, gi, gj, opts, rays)
        return moving, ok if variant == "exact, occlusion ignored" else ok & valid, obs, static

    mo.pair_moving, mo.optical_flow = pair, lambda a, b: ctx["resid"].numpy()
    try:
        yield
    finally:
        mo.pair_moving, mo.optical_flow = orig_pair, orig_flow


def counts(preds: list, gts: list) -> dict:
    k = np.zeros(4)
    for p, g in zip(preds, gts):
        k += [int((p & g).sum()), int((p | g).sum()), int(p.sum()), int(g.sum())]
    i, u, pp, t = k
    return {"iou": round(i / max(u, 1), 4), "precision": round(i / max(pp, 1), 4), "recall": round(i / max(t, 1), 4)}


def run_stages(frames: list, opts: mo.MotionOptions) -> dict:
    """``motion_masks`` (``carry`` off) step by step: the votes, the regions, grabCut's outline."""
    greys = [mo.grey(f.image) for f in frames]
    out: dict = {"votes": [], "regions": [], "outline": []}
    for i, f in enumerate(frames):
        frac = mo.frame_votes(frames, i, opts, greys)[0]
        seeds = fr.opening(frac >= opts.vote, 1) & mo.residual_gate(f, opts.residual_rel)
        regions = mo.grow_regions(seeds, f.image, opts)
        h, w = regions.shape
        o = fr.clean_regions(mo.outline(regions, f.image, opts.outline_ring), max(4, int(opts.min_region_frac * h * w)),
                             close_px=max(1, round(0.01 * min(h, w))))
        out["votes"].append(seeds), out["regions"].append(regions), out["outline"].append(o)
    return out


def breakdown(preds: list, gts: list, hits: list, n_static: int, cars: list) -> dict:
    """Recall per kind of mover (``nerf2gs_bench/mover_kinds.py``) and the share of the static pixels
    marked within ``mover_kinds.NEAR_PX`` of a mover."""
    kinds = [mk.kinds_of_hits(h.obj, len(h.moving), n_static, cars) for h in hits]
    return {"recall_by_kind": mk.recall_by_kind(preds, kinds), **mk.static_marked(preds, gts)}


VARIANTS = ("dis", "exact", "exact, occlusion ignored", "exact, blur9", "exact, blur17")
OPTION_ROWS = {"default": {}, "photo_grey 0": {"photo_grey": 0.0}, "one_sided_grey 0": {"one_sided_grey": 0.0},
               "ref_close_rel 0.3": {"ref_close_rel": 0.3}}  # the last: the static depth behind a mover is the oracle's road


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("work", type=Path, help="WORK/s<seed>/street holds (or gets) the street")
    ap.add_argument("out", type=Path, help="JSON of the rows")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 3])
    args = ap.parse_args()
    rows: dict = {}
    for seed in args.seeds:
        street = args.work / f"s{seed}" / "street"
        if not (street / "transforms.json").is_file():
            generate_street(SynthStreetConfig(out=street, seed=seed, movers=True, width=SIZE[0], height=SIZE[1], num_street=1, num_bev=1,
                                              num_val_street=0, num_val_bev=0, progress=False, overwrite=True))
        meta, frames, gts = street_frames(street)
        opts = mo.MotionOptions()
        flows, hits, n_static = exact_flows(seed, meta, opts.neighbours)
        cars = build_layout(seed).cars
        for variant in VARIANTS:
            for label, kw in OPTION_ROWS.items():
                if label != "default" and variant not in ("exact", "dis"):
                    continue
                o = mo.MotionOptions(**kw)
                with flow_lookup(frames, flows, variant):
                    st = run_stages(frames, o)
                row = {k: counts(v, gts) for k, v in st.items()}
                row.update(breakdown(st["outline"], gts, hits, n_static, cars))
                rows.setdefault(str(seed), {})[f"{variant}, {label}"] = row
                print(seed, variant, label, json.dumps(row), flush=True)
        atomic_write_text(args.out, json.dumps(rows, indent=1))
    print("| flow | seed | votes IoU (P / R) | + regions | + outline |\n|---|---|---|---|---|")
    for seed, rs in rows.items():
        for name, r in rs.items():
            cells = " | ".join(f"{r[k]['iou']:.3f} ({r[k]['precision']:.2f} / {r[k]['recall']:.2f})" for k in ("votes", "regions", "outline"))
            print(f"| {name} | {seed} | {cells} |")


if __name__ == "__main__":
    main()
