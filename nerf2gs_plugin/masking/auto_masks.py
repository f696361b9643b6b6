"""``--segmenter auto``, the part that loads a run: the mask-less reference renders every frame,
the ground plane is fitted, and ``masks/auto.py`` turns the renders into masks.

The ground plane is ``data/ground.py``'s RANSAC fit (the one ``ns2gs-data process`` uses for the
metric scale) on the sparse points in the reference's normalised world, else on the rendered
surface points of the training views.
"""

from __future__ import annotations

import json
import shutil
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Callable, Iterable, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.masks import from_renders as fr
from nerf2gs_plugin.masks.auto import AutoOptions, FrameMasks, Renders, masks_from_renders
from nerf2gs_plugin.errors import CheckpointError, ConfigError
from nerf2gs_plugin.utils.parallel import cpu_seconds, render_ahead
from nerf2gs_plugin.utils.resize import area_resize

MAX_PLANE_POINTS = 50_000  # RANSAC on a random subset of the rendered surface points


def ground_plane(train_data, rendered: Iterable[tuple[Tensor, Tensor]]) -> tuple[Tensor, float]:
    """``(up, height)`` of the ground plane ``{x : x . up = height}`` in the normalised world:
    the RANSAC plane of the sparse points below the cameras, else of the rendered surface points
    (``(points [H, W, 3], acc [H, W])`` per training view, accumulation > 0.5), made upright with the
    cameras' horizontal axes and path, else levelled with the path (``data/road_plane.py``)."""
    from nerf2gs_plugin.data.ground import MAX_TILT_DEG, fit_ground_plane
    from nerf2gs_plugin.data.road_plane import level_plane

    centres = train_data.cameras.centers.double().numpy()
    cam_up = train_data.up.double().numpy()
    plane = None
    if train_data.points3D_xyz is not None and len(train_data.points3D_xyz):
        # None also for planes steeper than data.ground.MAX_TILT_DEG (roof lines): try the rendered surfaces
        plane = fit_ground_plane(train_data.points3D_xyz.double().numpy(), centres, cam_up)
    used_sparse = plane is not None
    if plane is None:
        pts = [p.reshape(-1, 3)[a.reshape(-1) > 0.5] for p, a in rendered]
        pts = torch.cat(pts) if pts else torch.zeros(0, 3)
        if len(pts) > MAX_PLANE_POINTS:
            pts = pts[torch.randperm(len(pts), generator=torch.Generator().manual_seed(0))[:MAX_PLANE_POINTS]]
        plane = fit_ground_plane(pts.double().numpy(), centres, cam_up)
    if plane is None:
        raise ConfigError(f"no ground plane found below the cameras within {MAX_TILT_DEG:.0f} deg of their up "
                          "(neither the sparse points nor the rendered surfaces give one)")
    fitted_on = train_data.points3D_xyz.double().numpy() if used_sparse else pts.double().numpy()
    cam_right = train_data.cameras.camera_to_worlds[:, :3, 0].double().numpy()
    normal, offset = level_plane(plane.normal, plane.offset, fitted_on, centres, cam_right=cam_right)
    return torch.from_numpy(normal).float(), -float(offset)


def check_reference_dataset(checkpoint: Path, image_filenames: list[Path]) -> None:
    from nerf2gs_plugin.data.fingerprint import dataset_fingerprint
    from nerf2gs_plugin.engine.checkpoints import load_checkpoint

    ckpt = load_checkpoint(checkpoint, map_location="cpu")
    ours = dataset_fingerprint(image_filenames)
    if ckpt.get("dataset") not in (None, ours):
        raise CheckpointError(f"reference was trained on a different dataset (fingerprint {ckpt.get('dataset')} vs {ours})", checkpoint)


def decimated(camera, d: int) -> tuple[object, Tensor]:
    """Every ``d``-th pixel of ``camera`` (one camera) per side, the middle one of each d x d block:
    ``(a camera whose pixels are exactly those, bool [H, W] of them)``."""
    h, w = int(camera.height[0]), int(camera.width[0])
    rows, cols = torch.arange(h // d) * d + d // 2, torch.arange(w // d) * d + d // 2
    pixels = torch.zeros(h, w, dtype=torch.bool)
    pixels[rows[:, None], cols[None, :]] = True
    # full pixel k*d + d//2 has its centre at u = k*d + d//2 + 0.5, the decimated pixel k at k + 0.5
    shift = d // 2 + 0.5 - d / 2
    small = replace(camera.scaled(1.0 / d), cx=(camera.cx - shift) / d, cy=(camera.cy - shift) / d,
                    width=torch.full_like(camera.width, w // d), height=torch.full_like(camera.height, h // d))
    return small, pixels


def _render(model, cam, d: int) -> tuple[object, dict[str, Tensor], Optional[Tensor]]:
    """One frame at 1/d per side: ``(the camera of the rendered pixels, the render, which pixels of the
    frame or None)``. Rays of the full-size camera at every d-th pixel keep its footprint: renders
    of a smaller camera have d times wider cones, which an anti-aliased field blurs (far facades
    then read as empty, i.e. sky)."""
    import inspect

    if d == 1:
        return cam, model.render_camera(cam), None
    if "pixels" not in inspect.signature(model.render_camera).parameters:
        small = cam.scaled(1.0 / d)
        return small, model.render_camera(small), None
    small, pixels = decimated(cam, d)
    out = model.render_camera(cam, pixels=pixels)
    hh, ww = int(small.height[0]), int(small.width[0])
    return small, {k: v[pixels].reshape(hh, ww, -1) for k, v in out.items()}, pixels


def _intrinsics(cam) -> Tensor:
    return torch.stack([cam.fx[0], cam.fy[0], cam.cx[0], cam.cy[0]]).cpu()


def upsample(x: Tensor, step: int, size: tuple[int, int], smooth: bool = False) -> Tensor:
    """``[h, w, ...]`` values at every ``step``-th pixel per side (the middle of each step x step block,
    :func:`decimated`) -> ``[H, W, ...]`` at every pixel: each block takes its sample (nearest: the
    same blocks as ``make_masks``' nearest upsampling), or, with ``smooth``, the samples are
    interpolated linearly between their true positions (clamped at the border)."""
    h, w = size
    if not smooth:
        rows, cols = (torch.arange(h) // step).clamp(max=x.shape[0] - 1), (torch.arange(w) // step).clamp(max=x.shape[1] - 1)
        return x[rows][:, cols]

    def axis(n: int, m: int) -> tuple[Tensor, Tensor, Tensor]:
        pos = ((torch.arange(n, dtype=torch.float64) - step // 2) / step).clamp(0, m - 1)
        lo = pos.floor().long()
        return lo, (lo + 1).clamp(max=m - 1), (pos - lo).to(x.dtype)

    (r0, r1, fr_), (c0, c1, fc) = axis(h, x.shape[0]), axis(w, x.shape[1])
    shape = (-1, 1) + (1,) * (x.dim() - 2)
    fr_, fc = fr_.reshape(shape), fc.reshape((1, -1) + (1,) * (x.dim() - 2))
    top = x[r0][:, c0] * (1 - fc) + x[r0][:, c1] * fc
    bottom = x[r1][:, c0] * (1 - fc) + x[r1][:, c1] * fc
    return top * (1 - fr_) + bottom * fr_


def at_full_size(renders: Renders, result: dict[str, list[FrameMasks]]) -> Renders:
    """The motion route's inputs at the frames' full size where the reference rendered every d-th
    pixel (``render_views(render_downscale=d)``): the full-size image and camera, the depth taken
    per block from its sample (nearest: a depth edge stays an edge, no surface in between), the
    render interpolated (the residual against it); ``result``'s masks upsampled in place to that
    size (as they would be written). Views rendered at every pixel are returned as they are."""
    views: dict[str, list[dict[str, Tensor]]] = {}
    for s, vs in renders.views.items():
        views[s] = []
        for i, v in enumerate(vs):
            if "full_image" not in v:
                views[s].append(v)
                continue
            size, step = tuple(v["full_image"].shape[:2]), int(v["step"])
            views[s].append({"image": v["full_image"], "intr": v["full_intr"], "c2w": v["c2w"], "name": v["name"],
                             "depth": upsample(v["depth"], step, size), "rgb": upsample(v["rgb"], step, size, smooth=True)})
            m = result[s][i]
            for kind in ("sky", "ground", "transient"):
                setattr(m, kind, upsample(getattr(m, kind), step, size))
    return replace(renders, views=views)


def render_views(view: Path, reference: Path, splits: list[str], log: Callable[[str], None] = print, progress: bool = True,
                 render_downscale: int = 1) -> Renders:
    """Render every frame of ``splits`` with the reference at every ``render_downscale``-th pixel per
    side of the reference's image size. ``view``: the dataset (its mask-less view) the reference was
    trained on."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.data.images import load_image
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.progress import make_progress
    from nerf2gs_plugin.utils.model_output import check_finite

    with warnings.catch_warnings():  # a reference without masks: its "no sky masks" warnings are intended
        warnings.filterwarnings("ignore", message="StreetNeRF: the dataset has no .* masks")
        run = load_run(reference, device="cpu", data=view)
    model = run.model
    if not hasattr(model, "render_camera"):
        raise CheckpointError(f"method '{run.config.method_name}' cannot render cameras", run.checkpoint)
    train = run.pipeline.datamanager.train_data
    check_reference_dataset(run.checkpoint, train.image_filenames)
    parser = run.config.pipeline.datamanager.dataparser
    data = {s: train if s == "train" else parse_dataset(view, s, downscale=parser.downscale, cache_dir=parser.cache_dir)
            for s in splits}
    t0, c0 = time.perf_counter(), cpu_seconds()  # with the render workers'
    views: dict[str, list[dict[str, Tensor]]] = {s: [] for s in splits}
    total = sum(len(d) for d in data.values())
    frames = [(s, i) for s, d in data.items() for i in range(len(d))]
    with make_progress(progress) as prog, torch.no_grad():
        task = prog.add_task("masks: render", total=total, stats="")
        # views rendered side by side (utils/parallel.py) while this loop takes each one apart
        rendered = render_ahead(lambda si: _render(model, data[si[0]].cameras[si[1] : si[1] + 1], int(render_downscale)), frames)
        for (s, i), (cam, out, pixels) in zip(frames, rendered):
            d = data[s]
            for key in ("rgb", "accumulation"):  # masks are never made from a NaN render
                check_finite(out[key], run.checkpoint, f"reference render '{key}' of {s} view {i}")
            rays = cam.generate_rays(0)
            h, w = int(cam.height[0]), int(cam.width[0])
            img = load_image(d.image_filenames[i])
            full = {}
            if pixels is not None and tuple(img.shape[:2]) == tuple(pixels.shape):
                # the motion route measures flow on the whole frame: small movers vanish at half size
                full = {"full_image": img, "full_intr": _intrinsics(d.cameras[i : i + 1]), "step": int(render_downscale)}
                img = img[pixels].reshape(h, w, -1)  # the same pixels as the render
            img = area_resize(img, (h, w))
            views[s].append({"rgb": out["rgb"].cpu(), "depth": out["depth"][..., 0].cpu(), "acc": out["accumulation"][..., 0].cpu(),
                             "dirs": rays.directions.reshape(h, w, 3).cpu(), "origin": rays.origins[0].cpu(), "image": img,
                             "c2w": cam.camera_to_worlds[0].cpu(), "intr": _intrinsics(cam), "name": d.image_filenames[i].name, **full})
            prog.advance(task)
    seconds, cpu = time.perf_counter() - t0, cpu_seconds() - c0
    log(f"masks: rendered {total} views in {seconds:.1f} s")
    pts = ((fr.surface_points(r["origin"], r["dirs"], r["depth"]), r["acc"]) for r in views.get("train", []))
    up, height = ground_plane(train, pts)
    box = train.scene_box.float()
    extent = float((box[1] - box[0]).max()) / 2
    return Renders(views, up, height, train.metres_to_world(1.0), seconds, extent, cpu)


def auto_masks(view: Path, reference: Path, splits: list[str], opts: AutoOptions,
               log: Callable[[str], None] = print, progress: bool = True, motion=None, render_downscale: int = 1,
               stats: Optional[dict] = None, keep_second_pass: bool = False) -> dict[str, list[FrameMasks]]:
    """:func:`render_views` then :func:`masks_for_renders`; ``stats`` receives ``render_seconds`` and
    ``render_cpu_seconds`` (and the second pass's seconds and, with ``keep_second_pass``, its kept run)."""
    renders = render_views(view, reference, splits, log, progress, render_downscale)
    if stats is not None:
        stats["render_seconds"], stats["render_cpu_seconds"] = round(renders.seconds, 1), round(renders.cpu_seconds, 1)
    return masks_for_renders(view, reference, renders, opts, log, progress, motion, stats, render_downscale,
                             keep_second_pass=keep_second_pass)


def masks_for_renders(view: Path, reference: Path, renders: Renders, opts: AutoOptions, log: Callable[[str], None] = print,
                      progress: bool = True, motion=None, stats: Optional[dict] = None, render_downscale: int = 1,
                      first_pass: Optional[Callable[[dict[str, list[FrameMasks]]], None]] = None,
                      before_settle: Optional[Callable[[dict[str, list[FrameMasks]]], None]] = None,
                      keep_second_pass: bool = False) -> dict[str, list[FrameMasks]]:
    """:func:`~nerf2gs_plugin.masks.auto.masks_from_renders` on ``reference``'s renders of ``view``, plus
    what moves against the static scene's flow (``motion``: :class:`~nerf2gs_plugin.masks.motion.MotionOptions`)
    and its second pass (``render_downscale``: that of ``renders``), then the neighbours' check
    (``masks/motion.settle_transients``); ``first_pass`` and ``before_settle`` (benchmarks) see the masks
    before the second pass and before that check. ``keep_second_pass``: the second pass's run stays beside the
    reference (an earlier one there goes whether or not a second pass runs now)."""
    result = masks_from_renders(renders, opts, log)
    if motion is not None:
        from nerf2gs_plugin.masks.motion import add_motion, is_sequence, settle_transients

        meta = json.loads((Path(view) / "transforms.json").read_text())
        full = at_full_size(renders, result)
        kept: dict = {}
        moved = add_motion(full, result, motion, log, progress, sequence=is_sequence(meta), kept=kept)
        if first_pass is not None:
            first_pass(result)
        from nerf2gs_plugin.masking.second_pass import kept_run_dir, second_pass

        if keep_second_pass:
            shutil.rmtree(kept_run_dir(reference), ignore_errors=True)  # another run's: not what these masks came from
        if moved and motion.second_pass_steps > 0:
            took = second_pass(view, reference, full, result, motion.second_pass_steps, motion.second_pass_margin, log, progress,
                               render_step=max(1, int(render_downscale)), keep=keep_second_pass)
            if stats is not None:
                stats.update(took)
        if moved:
            if before_settle is not None:
                before_settle(result)
            settle_transients(full, result, kept, motion, log, progress)
    return result
