"""How well the reference knows each pixel it rendered for the target (``--augment.confidence``).

A reference's render is trustworthy where its training cameras saw the surface it shows, and a
guess elsewhere (rooftops and facade tops from above, the road behind a parked car that never
moved). ``visibility`` confidence measures exactly that, with the reference's own depth:

  1. every pixel of a rendered view is lifted to the surface point ``X`` its depth says it shows;
  2. ``X`` is projected into every training camera; that camera *observed* ``X`` when ``X`` falls
     inside its image, in front of it, on a pixel that is neither sky nor transient in its masks,
     and the reference's depth rendered at that training view (interpolated in inverse depth)
     agrees with ``X``'s depth there within ``rel_tol`` (otherwise something nearer hid ``X``: a
     facade in front of a rooftop);
  3. confidence = ``min(observations / full_views, 1)`` x the render's accumulation.

So a surface no training view saw gets ~0 and one seen by ``full_views`` views or more gets ~1.
``consistency`` also asks whether what the reference shows is what those cameras recorded: each
observation counts ``exp(-(d / color_tol)^2)``, ``d`` the mean absolute RGB difference between the
reference's pixel and the real image at the point's projection, so a surface the reference renders
softer or in other colours than every real view recorded it (a blurred facade seen again from above)
weighs little, and the target keeps its own street-view evidence there.
``unseen`` turns visibility around for the views from above: they should teach the target only what the
input views do not show (rooftops, the road away from the path), since where the photos see a surface
they teach it themselves and the reference's softer colour there only competes with them. A pixel's
weight falls from 1 (no input view observed its point) to ``seen_weight`` at ``full_views`` observations.
``footprint`` asks how finely, not how often: the street cameras see the road, but at a grazing angle, where
one of their pixels covers a long strip that a view from above resolves. A pixel's footprint on the surface
it shows is ``distance / (focal * |cos(angle between the ray and the surface normal)|)`` (the normal from
the reference's depth); the weight is a smooth ramp of ``best input footprint / the view's own footprint``
over the input views that observe the point: 0 up to ratio 1 (a photo sees it at least as finely), 1 from
``footprint_ratio`` on and where no input view observed it.
The cost is one projection of every rendered pixel into every training camera (``P x N`` work, a
Python loop over the N cameras only), plus one reference render per training view for its depth.
"""

from __future__ import annotations

from typing import Iterator, Literal, Optional, Sequence

import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras

DepthAlong = Literal["z", "ray"]
"""What a model's ``depth`` output measures: camera-space z (splatting) or distance along the ray (NeRFs)."""


def _view_cosines(camera: Cameras) -> tuple[Tensor, Tensor]:
    """Unit world ray directions ``[H*W, 3]`` of one camera and the cosine of each with its viewing axis ``[H*W]``."""
    rays = camera.generate_rays(0)
    forward = -camera.camera_to_worlds[0, :, 2]  # OpenGL cameras look down -z
    return rays.directions, (rays.directions @ forward).clamp_min(1e-6)


def depth_to_z(depth: Tensor, camera: Cameras, along: DepthAlong) -> Tensor:
    """A rendered depth ``[H, W, 1]`` of one camera as camera-space z ``[H, W]``."""
    d = depth[..., 0].float()
    if along == "z":
        return d
    _, cos = _view_cosines(camera)
    return d * cos.reshape(d.shape).to(d)


def lift(depth: Tensor, camera: Cameras, along: DepthAlong) -> Tensor:
    """World points ``[H*W, 3]`` that the pixels of one camera's rendered ``depth`` ``[H, W, 1]`` show."""
    directions, cos = _view_cosines(camera)
    t = depth.reshape(-1).float().to(directions)
    if along == "z":
        t = t / cos
    return camera.camera_to_worlds[0, :, 3] + directions * t[:, None]


def _sample(image: Tensor, uv: Tensor, w: int, h: int) -> Tensor:
    """Bilinear samples ``[P, C]`` of an ``[H, W, C]`` image at continuous pixel positions ``uv`` ``[P, 2]``."""
    grid = torch.stack([2.0 * uv[:, 0] / w - 1.0, 2.0 * uv[:, 1] / h - 1.0], -1).to(image)
    out = F.grid_sample(image.permute(2, 0, 1)[None].float(), grid[None, None], mode="bilinear", padding_mode="border", align_corners=False)
    return out[0, :, 0].T


def _inverse_depth_at(depth_z: Tensor, uv: Tensor, w: int, h: int) -> Tensor:
    """The depth ``[P]`` at continuous pixel positions ``uv`` ``[P, 2]``, interpolated bilinearly in
    inverse depth (exact on planes: a road seen at a grazing angle changes depth by several percent
    a row); across an occlusion edge it matches neither side, so no view is credited there."""
    inv = 1.0 / depth_z.clamp_min(1e-6)
    return 1.0 / _sample(inv[..., None], uv, w, h)[:, 0].clamp_min(1e-12)


def _observations(points: Tensor, cameras: Cameras, depths_z: Sequence[Tensor],
                  blind: Optional[Sequence[Optional[Tensor]]], rel_tol: float) -> Iterator[tuple[int, Tensor, Tensor]]:
    """Per camera ``i``: ``(i, seen [P] bool, uv [P, 2])``: which ``points`` it observed (see
    :func:`observation_counts`) and where they project."""
    finite = torch.isfinite(points).all(-1)
    pts = torch.where(finite[:, None], points, torch.zeros_like(points))
    for i in range(len(cameras)):
        uv, z = cameras.project(pts, i)
        h, w = depths_z[i].shape
        u, v = uv[:, 0].floor().long(), uv[:, 1].floor().long()
        inside = finite & (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        uc, vc = u.clamp(0, w - 1), v.clamp(0, h - 1)
        d = _inverse_depth_at(depths_z[i].to(points), uv, w, h)
        seen = inside & ((z - d).abs() <= rel_tol * d.abs())
        if blind is not None and blind[i] is not None:
            seen &= ~blind[i].to(points.device)[vc, uc]
        yield i, seen, uv


def observation_counts(points: Tensor, cameras: Cameras, depths_z: Sequence[Tensor],
                       blind: Optional[Sequence[Optional[Tensor]]] = None, rel_tol: float = 0.05,
                       colors: Optional[Tensor] = None, images: Optional[Sequence[Tensor]] = None,
                       color_tol: float = 0.1) -> Tensor:
    """How many of ``cameras`` observed each world point (with ``colors`` and ``images``, each
    observation weighted by how well the point's colour agrees with that camera's image).

    Args:
        points: ``[P, 3]`` world points (non-finite ones are observed by none).
        cameras: the N training cameras.
        depths_z: per camera its rendered camera-space z ``[H, W]`` (the occlusion test).
        blind: per camera an optional ``[H, W]`` bool of pixels that observe no surface (sky, transients).
        rel_tol: a projection observes the point when ``|z - depth| <= rel_tol * depth`` at its pixel.
        colors: ``[P, 3]`` the colour the reference gives each point; ``images``: per camera its real
            ``[H, W, 3]`` image; an observation then counts ``exp(-(mean |colour diff| / color_tol)^2)``.

    Returns:
        ``[P]`` float counts.
    """
    counts = torch.zeros(points.shape[0], device=points.device)
    for i, seen, uv in _observations(points, cameras, depths_z, blind, rel_tol):
        if colors is not None and images is not None:
            h, w = depths_z[i].shape
            diff = (colors.to(points) - _sample(images[i].to(points), uv, w, h)).abs().mean(-1)
            counts += seen.float() * torch.exp(-((diff / color_tol) ** 2))
        else:
            counts += seen.float()
    return counts


def visibility_confidence(depth: Tensor, camera: Cameras, along: DepthAlong, train_cameras: Cameras,
                          train_depths_z: Sequence[Tensor], train_blind: Optional[Sequence[Optional[Tensor]]] = None,
                          accumulation: Optional[Tensor] = None, full_views: int = 3, rel_tol: float = 0.05,
                          rgb: Optional[Tensor] = None, train_images: Optional[Sequence[Tensor]] = None,
                          color_tol: float = 0.1) -> Tensor:
    """Per-pixel confidence ``[H, W, 1]`` in [0, 1] of one rendered view (see the module docstring).

    ``depth``, ``accumulation`` ``[H, W, 1]`` and ``rgb`` ``[H, W, 3]`` are the reference's render at
    ``camera`` (one camera); with ``rgb`` and ``train_images`` the observations are colour-weighted
    (``consistency``).
    """
    h, w = depth.shape[:2]
    colors = rgb.reshape(-1, 3) if rgb is not None and train_images is not None else None
    counts = observation_counts(lift(depth, camera, along), train_cameras, train_depths_z, train_blind, rel_tol,
                                colors, train_images if colors is not None else None, color_tol)
    conf = (counts / max(int(full_views), 1)).clamp(max=1.0).reshape(h, w, 1)
    if accumulation is not None:
        conf = conf * accumulation.float().clamp(0.0, 1.0).to(conf)
    return conf


def unseen_weight(depth: Tensor, camera: Cameras, along: DepthAlong, train_cameras: Cameras,
                  train_depths_z: Sequence[Tensor], train_blind: Optional[Sequence[Optional[Tensor]]] = None,
                  full_views: int = 3, rel_tol: float = 0.05, seen_weight: float = 0.0) -> Tensor:
    """Per-pixel loss weight ``[H, W, 1]`` of one rendered view (``unseen``, see the module docstring):
    ``1 - (1 - seen_weight) * min(observations / full_views, 1)``. The accumulation does not enter: a
    pixel the reference renders empty shows nothing the input views could teach either."""
    seen = visibility_confidence(depth, camera, along, train_cameras, train_depths_z, train_blind,
                                 full_views=full_views, rel_tol=rel_tol)
    return 1.0 - (1.0 - float(seen_weight)) * seen


MIN_COS = 0.02
"""A ray more grazing than this (about 89 deg from the normal) counts at this angle: the footprint stays finite."""


def surface_normals(points: Tensor) -> Tensor:
    """Unit normals ``[H, W, 3]`` of the surface that a view's lifted points ``[H, W, 3]`` show. Along each
    image axis the smaller of the forward and backward differences is taken, so a pixel next to a depth
    edge takes its tangent from its own side; non-finite where a point or both neighbours are."""
    def tangent(dim: int) -> Tensor:
        diff = points.diff(dim=dim)
        first, last = diff.narrow(dim, 0, 1), diff.narrow(dim, diff.shape[dim] - 1, 1)
        fwd, bwd = torch.cat([diff, last], dim), torch.cat([first, diff], dim)
        nf, nb = fwd.norm(dim=-1, keepdim=True), bwd.norm(dim=-1, keepdim=True)
        return torch.where((nf <= nb) | ~torch.isfinite(nb), fwd, bwd)

    n = torch.cross(tangent(1), tangent(0), dim=-1)
    return n / n.norm(dim=-1, keepdim=True)


def footprint(points: Tensor, normals: Tensor, center: Tensor, focal: Tensor | float) -> Tensor:
    """``[P]``: how long a strip of the surface at ``points`` ``[P, 3]`` (unit ``normals`` ``[P, 3]``) one
    pixel of a camera at ``center`` ``[3]`` with ``focal`` (pixels) covers: ``distance / (focal * |cos|)``."""
    ray = points - center.to(points)
    dist = ray.norm(dim=-1).clamp_min(1e-9)
    cos = ((ray / dist[:, None]) * normals).sum(-1).abs().nan_to_num(1.0).clamp_min(MIN_COS)
    return dist / (focal * cos)


def relative_footprint(depth: Tensor, camera: Cameras, along: DepthAlong, train_cameras: Cameras,
                    train_depths_z: Sequence[Tensor], train_blind: Optional[Sequence[Optional[Tensor]]] = None,
                    rel_tol: float = 0.05) -> Tensor:
    """``[H, W]``: per pixel of one rendered view, the finest footprint among the input views that observe its
    point over the view's own (below 1: a photo sees it more finely); inf where no input view observed it."""
    h, w = depth.shape[:2]
    pts = lift(depth, camera, along)
    normals = surface_normals(pts.reshape(h, w, 3)).reshape(-1, 3)
    focal = lambda cams, i: torch.sqrt(cams.fx[i] * cams.fy[i]).to(pts)  # noqa: E731
    own = footprint(pts, normals, camera.centers[0], focal(camera, 0))
    best = torch.full_like(own, float("inf"))
    for i, seen, _ in _observations(pts, train_cameras, train_depths_z, train_blind, rel_tol):
        best = torch.where(seen, torch.minimum(best, footprint(pts, normals, train_cameras.centers[i], focal(train_cameras, i))), best)
    return (best / own).reshape(h, w)


def footprint_weight(depth: Tensor, camera: Cameras, along: DepthAlong, train_cameras: Cameras,
                     train_depths_z: Sequence[Tensor], train_blind: Optional[Sequence[Optional[Tensor]]] = None,
                     rel_tol: float = 0.05, footprint_ratio: float = 2.0) -> Tensor:
    """Per-pixel loss weight ``[H, W, 1]`` of one rendered view (``footprint``, see the module docstring):
    a smoothstep of ``(ratio - 1) / (footprint_ratio - 1)``, ``ratio`` as :func:`relative_footprint` gives it."""
    if footprint_ratio <= 1.0:
        raise ValueError(f"footprint_ratio must be > 1 (got {footprint_ratio})")
    ratio = relative_footprint(depth, camera, along, train_cameras, train_depths_z, train_blind, rel_tol)
    t = ((ratio - 1.0) / (float(footprint_ratio) - 1.0)).nan_to_num(1.0).clamp(0.0, 1.0)
    return (t * t * (3.0 - 2.0 * t))[..., None]


def inside_box(points: Tensor, box: Optional[Tensor]) -> Tensor:
    """Bool ``[N]``: points ``[N, 3]`` inside the scene box ``[2, 3]`` (all True without a box)."""
    if box is None:
        return torch.ones(len(points), dtype=torch.bool, device=points.device)
    box = box.to(points)
    return ((points >= box[0]) & (points <= box[1])).all(-1)


SKY_ACCUMULATION = 0.5
"""A reference pixel with less accumulation than this shows sky (the masks stage's rule)."""


def inside_box_weight(depth: Tensor, accumulation: Optional[Tensor], camera: Cameras, along: DepthAlong,
                      box: Optional[Tensor]) -> Tensor:
    """``[H, W, 1]``: 1 where a reference render at ``camera`` shows a surface inside the scene ``box``
    ``[2, 3]`` (the pixel's depth lifted to the point it shows), 0 where that point lies outside the box
    or the pixel shows sky (``accumulation`` < :data:`SKY_ACCUMULATION`); no box: only the sky is 0."""
    h, w = depth.shape[:2]
    keep = torch.ones(h * w, dtype=torch.bool, device=depth.device)
    if box is not None:
        pts = lift(depth, camera, along).to(depth.device)
        keep &= torch.isfinite(pts).all(-1) & inside_box(pts, box)
    if accumulation is not None:
        keep &= accumulation.reshape(-1).to(depth.device) >= SKY_ACCUMULATION
    return keep.reshape(h, w, 1).float()
