"""Which kind of mover each pixel of a synthetic street's frame shows (``synth-street --movers``), for the
motion benches' per-kind recall, and where the static pixels that a mask marks lie.

Kinds, by the object a pixel-centre ray hits (``data/synthetic/scene_flow.trace_frame``; the drive goes
toward +x): the street's cars driving the drive's way and toward it, the lead car and the cyclist that
ride ahead at the drive's speed, the pedestrians crossing.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch import Tensor

KINDS = ("traffic, same way", "traffic, oncoming", "lead car", "cyclist", "pedestrians")
NEAR_PX = 24
"""A static pixel "beside a mover": within this many pixels of one (the spill of DIS's flow)."""


def kind_ids(seed: int, frames: list[dict], intr: tuple[float, float, float, float, int, int]) -> list[dict[str, Tensor]]:
    """Per frame of ``frames`` (``transforms.json`` entries of the street of ``seed``: true poses and
    times), kind -> bool ``[H, W]`` of the pixels showing a mover of that kind; ``intr``: fx, fy, cx, cy,
    width, height."""
    from nerf2gs_plugin.data.synthetic.layout import Boxes, build_layout
    from nerf2gs_plugin.data.synthetic.movers import build_movers, frame_boxes
    from nerf2gs_plugin.data.synthetic.raycast import Pinhole
    from nerf2gs_plugin.data.synthetic.scene_flow import trace_frame

    layout = build_layout(seed)
    movers = build_movers(layout)
    layout.static = Boxes.cat([layout.static, movers.parked])
    out = []
    for f in frames:
        c2w = torch.tensor(f["transform_matrix"], dtype=torch.float32)[:3]
        hits = trace_frame(layout, c2w, Pinhole(*intr), frame_boxes(layout, movers, float(f["time"]), c2w))
        out.append(kinds_of_hits(hits.obj, len(hits.moving), len(layout.static), layout.cars))
    return out


def kinds_of_hits(obj: Tensor, n_moving: int, n_static: int, cars: list) -> dict[str, Tensor]:
    """Kind -> bool ``[H, W]`` from a frame's object ids ``obj`` (``raycast.centre_hits``: moving box ``k`` is
    ``n_static + k``; ``n_moving`` boxes move) and the street's ``cars``."""
    return {k: sum(((obj >= n_static + lo) & (obj < n_static + min(hi, n_moving)) for lo, hi in s), torch.zeros_like(obj, dtype=torch.bool)) > 0
            for k, s in kind_spans(cars).items()}


def kind_spans(cars: list) -> dict[str, list[tuple[int, int]]]:
    """Kind -> ranges of moving-box indices (``movers.frame_boxes``' order: three boxes a car of ``cars``,
    then the lead car's three, the cyclist's three, the pedestrians')."""
    n = len(cars)
    return {"traffic, same way": [(3 * c, 3 * c + 3) for c, car in enumerate(cars) if car.direction > 0],
            "traffic, oncoming": [(3 * c, 3 * c + 3) for c, car in enumerate(cars) if car.direction < 0],
            "lead car": [(3 * n, 3 * n + 3)], "cyclist": [(3 * n + 3, 3 * n + 6)], "pedestrians": [(3 * n + 6, 10 ** 6)]}


def recall_by_kind(preds: list[Tensor], kinds: list[dict[str, Tensor]]) -> dict[str, dict]:
    """Kind -> ``{"pixels", "recall"}`` pooled over the frames (``preds``: bool masks on the same grid)."""
    rec = {}
    for name in KINDS:
        tot = sum(int(k[name].sum()) for k in kinds)
        hit = sum(int((p & k[name]).sum()) for p, k in zip(preds, kinds))
        rec[name] = {"pixels": tot, "recall": round(hit / max(tot, 1), 4)}
    return rec


def static_marked(preds: list[Tensor], gts: list[Tensor], grounds: list[Tensor] | None = None) -> dict:
    """The static pixels ``preds`` mark (not in ``gts``): how many, the share within :data:`NEAR_PX` of a
    mover, and (with ``grounds``, the exact ground masks) the share on the ground."""
    fp = near = on_ground = 0
    for k, (p, g) in enumerate(zip(preds, gts)):
        d = cv2.distanceTransform((~g).numpy().astype(np.uint8), cv2.DIST_L2, 5)
        f = (p & ~g).numpy()
        fp, near = fp + int(f.sum()), near + int((f & (d <= NEAR_PX)).sum())
        if grounds is not None:
            on_ground += int((f & grounds[k].numpy()).sum())
    out = {"static_marked": fp, "static_marked_near_share": round(near / max(fp, 1), 4)}
    if grounds is not None:
        out["static_marked_ground_share"] = round(on_ground / max(fp, 1), 4)
    return out

