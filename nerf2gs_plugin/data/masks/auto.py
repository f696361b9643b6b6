"""``--segmenter auto``: masks derived from the capture itself through a first reference (no weights).

The reference (``reference.py``: a short StreetNeRF trained without masks) renders every frame;
``from_renders.py`` turns rgb / depth / accumulation and the photometric residual into masks. The
ground plane is the one StreetNeRF itself uses: normal = the dataset's up vector, height = the
densest height of the sparse points below the cameras (``ground_height_from_points``), else the
same estimate on the rendered surface points of the training views.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Optional

import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.data.masks import from_renders as fr
from nerf2gs_plugin.errors import CheckpointError, ConfigError


@dataclass
class AutoOptions:
    """Thresholds of ``--segmenter auto`` (metres where said; see ``from_renders.py``)."""

    sky_acc: float = 0.5
    """Sky: accumulation of the reference below this."""
    sky_far: float = 10.0
    """Sky also where the rendered depth is beyond this many scene-box half-sizes (what the reference
    pushed to the contraction boundary: a point there contracts to > 1.9 of 2)."""
    horizon_margin_deg: float = 2.0
    """Sky may reach this far below the ground plane's horizon."""
    ground_tol_m: float = 0.3
    """Ground: rendered surface within this many metres of the plane."""
    ground_normals: bool = False
    """Also require the rendered normal (from depth differences) within 30 deg of up."""
    transient_k: float = 4.0
    """Transient: residual above median + k * 1.4826 * MAD (all training views pooled)."""
    transient_k_low: float = 0.0
    """Hysteresis: regions above median + k_low * 1.4826 * MAD joined to the strong ones (0 or >= k:
    off). Off by default: with a 1000-step reference it cost 0.04 transient IoU and 0.04 ground IoU
    on both synthetic streets (false regions eat sky and ground)."""
    transient_floor: float = 0.04
    """... and above this absolute mean colour difference."""
    min_region_frac: float = 0.002
    """Transient regions smaller than this fraction of the image are dropped."""


@dataclass
class FrameMasks:
    sky: Tensor
    ground: Tensor
    transient: Tensor


def _ground_height(model, train_data, renders: Iterable[tuple[Tensor, Tensor]]) -> float:
    from nerf2gs_plugin.methods.streetnerf.model import ground_height_from_points

    up = train_data.up.float()
    if bool(getattr(model, "ground_known", torch.tensor(False))) and getattr(model, "ground_from_points", False):
        return float(model.ground_height)
    if train_data.points3D_xyz is not None:
        h = ground_height_from_points(train_data.points3D_xyz.float() @ up, train_data.cameras.centers.float() @ up)
        if h is not None:
            return h
    pts = torch.cat([p.reshape(-1, 3)[a.reshape(-1) > 0.5] for p, a in renders])
    h = ground_height_from_points(pts @ up, train_data.cameras.centers.float() @ up)
    if h is None:
        raise ConfigError("no ground plane found below the cameras (neither sparse points nor rendered surfaces)")
    return h


def check_reference_dataset(checkpoint: Path, image_filenames: list[Path]) -> None:
    from nerf2gs_plugin.engine.checkpoints import dataset_fingerprint, load_checkpoint

    ckpt = load_checkpoint(checkpoint, map_location="cpu")
    ours = dataset_fingerprint(image_filenames)
    if ckpt.get("dataset") not in (None, ours):
        raise CheckpointError(f"reference was trained on a different dataset (fingerprint {ckpt.get('dataset')} vs {ours})", checkpoint)


@dataclass
class Renders:
    """The reference's renders of every frame (reference resolution), keyed by split, plus the plane."""

    views: dict[str, list[dict[str, Tensor]]]
    up: Tensor
    height: float
    metres_to_world: float
    seconds: float
    box_extent: float = float("inf")  # half the scene box's largest side (world units)


def render_views(view: Path, reference: Path, splits: list[str], log: Callable[[str], None] = print, progress: bool = True) -> Renders:
    """Render every frame of ``splits`` with the reference. ``view``: the dataset (its mask-less
    view) the reference was trained on."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.data.images import load_image
    from nerf2gs_plugin.engine.reference import load_run
    from nerf2gs_plugin.progress import make_progress

    run = load_run(reference, device="cpu", data=view)
    model = run.model
    if not hasattr(model, "render_camera"):
        raise CheckpointError(f"method '{run.config.method_name}' cannot render cameras", run.checkpoint)
    train = run.pipeline.datamanager.train_data
    check_reference_dataset(run.checkpoint, train.image_filenames)
    downscale = float(getattr(run.config.pipeline.datamanager, "downscale", 1.0))
    data = {s: (train if s == "train" else parse_dataset(view, s, downscale=downscale)) for s in splits}
    t0 = time.perf_counter()
    views: dict[str, list[dict[str, Tensor]]] = {s: [] for s in splits}
    total = sum(len(d) for d in data.values())
    with make_progress(progress) as prog:
        task = prog.add_task("masks: render", total=total, stats="")
        for s, d in data.items():
            for i in range(len(d)):
                cam = d.cameras[i : i + 1]
                out = model.render_camera(cam)
                rays = cam.generate_rays(0)
                h, w = int(cam.height[0]), int(cam.width[0])
                img = load_image(d.image_filenames[i])
                if tuple(img.shape[:2]) != (h, w):
                    img = F.interpolate(img.permute(2, 0, 1)[None], size=(h, w), mode="area")[0].permute(1, 2, 0)
                views[s].append({"rgb": out["rgb"].cpu(), "depth": out["depth"][..., 0].cpu(), "acc": out["accumulation"][..., 0].cpu(),
                                 "dirs": rays.directions.reshape(h, w, 3).cpu(), "origin": rays.origins[0].cpu(), "image": img})
                prog.advance(task)
    seconds = time.perf_counter() - t0
    log(f"masks: rendered {total} views in {seconds:.1f} s")
    pts = ((fr.surface_points(r["origin"], r["dirs"], r["depth"]), r["acc"]) for r in views.get("train", []))
    height = _ground_height(model, train, pts)
    box = train.scene_box.float()
    extent = float((box[1] - box[0]).max()) / 2
    return Renders(views, train.up.float(), height, train.metres_to_world(1.0), seconds, extent)


def masks_from_renders(r: Renders, opts: AutoOptions, log: Callable[[str], None] = print) -> dict[str, list[FrameMasks]]:
    """Sky / ground / transient per frame (reference resolution), keyed by split, in parser order."""
    up, tol = r.up, r.metres_to_world * opts.ground_tol_m
    sky_res = {}
    for s, rs in r.views.items():
        for i, v in enumerate(rs):
            sky = fr.sky_from_render(v["acc"], v["dirs"], up, opts.sky_acc, opts.horizon_margin_deg,
                                     depth=v["depth"], far=opts.sky_far * r.box_extent)
            fitted = fr.fit_colour(v["rgb"], v["image"])
            sky_res[s, i] = (sky, fr.residual_map(v["image"], fitted))
    base = "train" if "train" in r.views else next(iter(r.views))
    pool = torch.cat([sky_res[base, i][1][~sky_res[base, i][0]] for i in range(len(r.views[base]))])
    thr = fr.robust_threshold(pool, opts.transient_k, opts.transient_floor)
    low = fr.robust_threshold(pool, opts.transient_k_low, opts.transient_floor / 2) if 0 < opts.transient_k_low < opts.transient_k else None
    log(f"masks: ground plane at height {r.height:.4f} (world units), tolerance {tol:.4f}; transient residual threshold {thr:.3f}" + (f" (regions grown to {low:.3f})" if low else ""))
    result: dict[str, list[FrameMasks]] = {}
    for s, rs in r.views.items():
        result[s] = []
        for i, v in enumerate(rs):
            sky, res = sky_res[s, i]
            h, w = v["acc"].shape
            trans = fr.transient_from_residual(res, thr, max(4, int(opts.min_region_frac * h * w)), low=low)
            normals = fr.normals_from_points(fr.surface_points(v["origin"], v["dirs"], v["depth"])) if opts.ground_normals else None
            ground = fr.ground_from_render(v["origin"], v["dirs"], v["depth"], v["acc"], up, r.height, tol, normals=normals)
            result[s].append(FrameMasks(sky & ~trans, ground & ~trans & ~sky, trans))
    return result


def auto_masks(view: Path, reference: Path, splits: list[str], opts: AutoOptions,
               log: Callable[[str], None] = print, progress: bool = True) -> dict[str, list[FrameMasks]]:
    """:func:`render_views` then :func:`masks_from_renders`."""
    return masks_from_renders(render_views(view, reference, splits, log, progress), opts, log)
