"""Exact ray casting of the street: every box and tree crown is rasterised into a depth buffer by
exact ray intersection restricted to the pixels its projection can cover (a Python loop over
~80 primitives, tensors over pixels), the ground plane is analytic, and hard sun shadows of the
static geometry come from an orthographic shadow map built the same way once per scene.

Each pixel is the mean of ``spp`` rays: sample 0 goes through the pixel centre (it alone decides
the depth and the sky/ground masks, so they agree with a pixel-centre ray of
:meth:`Cameras.generate_rays`), the others are a rotated-grid pattern for anti-aliasing; the
transient mask marks a pixel when ANY of its rays hits a car, so a composite that replaces masked
pixels leaves no car fringe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import torch
from torch import Tensor

from nerf2gs_plugin.data.synthetic import textures as tx
from nerf2gs_plugin.data.synthetic.layout import (
    BUILDING, CAR_BODY, CAR_CABIN, CAR_WHEELS, CROSSWALKS, CROWN, GROUND_MATERIALS, PARKED_CAR, POLE, ROAD, ROAD_HALF, SIDEWALK, SKY,
    STREET_HALF_LEN, TRANSIENT_MATERIALS, TRUNK, Boxes, Spheres, StreetLayout,
)

# sample 0 at the pixel centre, then a rotated 4-sample grid (offsets in pixels)
_OFFSETS = [(0.0, 0.0), (-0.3125, 0.1875), (0.1875, 0.3125), (0.3125, -0.1875), (-0.1875, -0.3125)]
_FAR = 400.0
_EPS = 1e-4
_NEAR = 0.05


@dataclass
class Pinhole:
    """Shared pinhole intrinsics (pixel centre at +0.5, as :class:`Cameras`)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @staticmethod
    def from_fov(width: int, height: int, fov_x_deg: float) -> "Pinhole":
        f = 0.5 * width / math.tan(math.radians(fov_x_deg) / 2)
        return Pinhole(f, f, width / 2.0, height / 2.0, width, height)


@dataclass
class View:
    """One rendered camera: ``rgb [H, W, 3]`` (before exposure), bool masks ``[H, W]``, z-depth
    ``[H, W]`` in metres (0 = sky), and the centre rays' hit points / materials ``[H*W, ...]``."""

    rgb: Tensor
    sky: Tensor
    ground: Tensor
    transient: Tensor
    depth: Tensor
    points: Tensor
    material: Tensor


@dataclass
class Hits:
    """Nearest hits of a grid of rays ``[..., H, W]``: distance (inf = none) and
    ``code = 3 * primitive + slab axis`` (boxes 0..B-1, spheres B..B+S-1; -3 = none)."""

    t: Tensor
    code: Tensor

    @property
    def prim(self) -> Tensor:
        return torch.div(self.code, 3, rounding_mode="floor")

    @property
    def axis(self) -> Tensor:
        return torch.remainder(self.code, 3)


def camera_rays(c2w: Tensor, intr: Pinhole, spp: int) -> Tensor:
    """Unit ray directions ``[spp, H, W, 3]`` of an OpenGL camera (y up, looking down -z)."""
    v, u = torch.meshgrid(torch.arange(intr.height, dtype=torch.float32), torch.arange(intr.width, dtype=torch.float32), indexing="ij")
    dirs = []
    for ou, ov in _OFFSETS[:spp]:
        x = (u + 0.5 + ou - intr.cx) / intr.fx
        y = (v + 0.5 + ov - intr.cy) / intr.fy
        d_cam = torch.stack([x, -y, -torch.ones_like(x)], dim=-1)
        dirs.append(torch.nn.functional.normalize(d_cam @ c2w[:, :3].T, dim=-1))
    return torch.stack(dirs)


def _corners(lo: Tensor, hi: Tensor) -> Tensor:
    """``[N, 8, 3]`` corners of boxes ``lo, hi [N, 3]``."""
    sel = torch.tensor([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=torch.bool)
    return torch.where(sel[None], hi[:, None], lo[:, None])


def _pixel_rects(corners: Tensor, c2w: Tensor, intr: Pinhole) -> list[Optional[tuple[int, int, int, int]]]:
    """Conservative pixel rectangle ``(r0, r1, c0, c1)`` each primitive (its bounding corners
    ``[N, 8, 3]``) can cover; the whole image when it crosses the camera plane; None when unseen."""
    cam = (corners - c2w[:, 3]) @ c2w[:, :3]  # OpenGL camera coordinates
    z = -cam[..., 2]
    zs = z.clamp(min=_NEAR)
    u = intr.fx * cam[..., 0] / zs + intr.cx
    v = intr.cy - intr.fy * cam[..., 1] / zs
    behind_all = (z <= _NEAR).all(1)
    crosses = (z <= _NEAR).any(1)
    rects: list[Optional[tuple[int, int, int, int]]] = []
    for i in range(corners.shape[0]):
        if bool(behind_all[i]):
            rects.append(None)
            continue
        if bool(crosses[i]):
            rects.append((0, intr.height, 0, intr.width))
            continue
        c0 = max(0, int(math.floor(float(u[i].min()))) - 1)
        c1 = min(intr.width, int(math.ceil(float(u[i].max()))) + 1)
        r0 = max(0, int(math.floor(float(v[i].min()))) - 1)
        r1 = min(intr.height, int(math.ceil(float(v[i].max()))) + 1)
        rects.append((r0, r1, c0, c1) if c1 > c0 and r1 > r0 else None)
    return rects


def _slab(o: Tensor, inv: Tensor, lo: Tensor, hi: Tensor) -> tuple[Tensor, Tensor]:
    """Entry distance (inf = miss) and entry axis of rays (origins ``o``, inverse directions
    ``inv [..., 3]``) into one box."""
    t1, t2 = (lo - o) * inv, (hi - o) * inv
    tnear, axis = torch.minimum(t1, t2).max(dim=-1)
    tfar = torch.maximum(t1, t2).min(dim=-1).values
    return torch.where((tfar >= tnear) & (tnear > _EPS), tnear, math.inf), axis


def _inverse(d: Tensor) -> Tensor:
    return 1.0 / torch.where(d.abs() < 1e-9, 1e-9, d)


def _sphere(o: Tensor, d: Tensor, c: Tensor, r: float) -> Tensor:
    oc = o - c
    b = (oc * d).sum(-1)
    disc = b * b - ((oc * oc).sum(-1) - r * r)
    t = -b - torch.sqrt(disc.clamp(min=0))
    return torch.where((disc > 0) & (t > _EPS), t, math.inf)


def _update(h: Hits, sl: tuple, t: Tensor, code: Tensor | int) -> None:
    """Keep the nearer hit; ``code`` = primitive * 3 + slab axis."""
    cur = h.t[sl]
    better = t < cur
    h.t[sl] = torch.where(better, t, cur)
    h.code[sl] = torch.where(better, code, h.code[sl])


def cast(o: Tensor, d: Tensor, boxes: Boxes, spheres: Spheres, rects: list) -> Hits:
    """Nearest box/sphere hit of rays ``d [S, H, W, 3]`` (origins ``o`` broadcastable), visiting
    only each primitive's pixel rectangle (``rects``: boxes then spheres)."""
    shape = d.shape[:-1]
    h = Hits(torch.full(shape, math.inf), torch.full(shape, -3, dtype=torch.long))
    inv = _inverse(d)
    B = len(boxes)
    for i, rect in enumerate(rects):
        if rect is None:
            continue
        sl = (slice(None), slice(rect[0], rect[1]), slice(rect[2], rect[3]))
        oo = o[sl] if o.dim() == d.dim() else o
        if i < B:
            t, axis = _slab(oo, inv[sl], boxes.lo[i], boxes.hi[i])
            _update(h, sl, t, axis + 3 * i)
        else:
            t = _sphere(oo, d[sl], spheres.centre[i - B], float(spheres.radius[i - B]))
            _update(h, sl, t, 3 * i)
    return h


def _prim_corners(boxes: Boxes, spheres: Spheres) -> Tensor:
    r = spheres.radius[:, None]
    return torch.cat([_corners(boxes.lo, boxes.hi), _corners(spheres.centre - r, spheres.centre + r)])


class ShadowMap:
    """Orthographic depth map of the static scene seen from the sun (texel ``texel`` metres):
    a point is in shadow when something lies between it and the sun."""

    def __init__(self, layout: StreetLayout, texel: float = 0.12) -> None:
        s = layout.sun
        e1 = torch.nn.functional.normalize(torch.linalg.cross(s, torch.tensor([0.0, 0.0, 1.0])), dim=0)
        e2 = torch.linalg.cross(s, e1)
        self.basis = torch.stack([e1, e2, s])  # rows: map a, map b, toward the sun
        corners = _prim_corners(layout.static, layout.crowns)
        ab = corners.reshape(-1, 3) @ self.basis.T
        self.lo = ab[:, :2].min(0).values - 1.0
        size = ab[:, :2].max(0).values + 1.0 - self.lo
        self.texel = texel
        self.W, self.H = int(math.ceil(float(size[0]) / texel)), int(math.ceil(float(size[1]) / texel))
        self.top = float(ab[:, 2].max()) + 1.0
        jj, ii = torch.meshgrid(torch.arange(self.H, dtype=torch.float32), torch.arange(self.W, dtype=torch.float32), indexing="ij")
        a = self.lo[0] + (ii + 0.5) * texel
        b = self.lo[1] + (jj + 0.5) * texel
        origins = (a[..., None] * e1 + b[..., None] * e2 + self.top * s)[None]  # [1, H, W, 3]
        dirs = (-s).expand(1, self.H, self.W, 3)
        rects = []
        for c in corners @ self.basis.T:
            c0 = max(0, int((float(c[:, 0].min()) - float(self.lo[0])) / texel) - 1)
            c1 = min(self.W, int((float(c[:, 0].max()) - float(self.lo[0])) / texel) + 2)
            r0 = max(0, int((float(c[:, 1].min()) - float(self.lo[1])) / texel) - 1)
            r1 = min(self.H, int((float(c[:, 1].max()) - float(self.lo[1])) / texel) + 2)
            rects.append((r0, r1, c0, c1))
        hits = cast(origins, dirs, layout.static, layout.crowns, rects)
        self.depth = (self.top - hits.t[0])  # along s; -inf where nothing

    def lit(self, p: Tensor, n: Tensor) -> Tensor:
        """1 where points ``p [N, 3]`` (normals ``n``) see the sun past the static scene, else 0."""
        ab = p @ self.basis.T
        ii = ((ab[:, 0] - self.lo[0]) / self.texel).long().clamp(0, self.W - 1)
        jj = ((ab[:, 1] - self.lo[1]) / self.texel).long().clamp(0, self.H - 1)
        occ = self.depth[jj, ii]
        ns = (n @ self.basis[2]).clamp(0.15, 1.0)
        bias = 0.03 + 1.5 * self.texel * torch.sqrt(1 - ns * ns) / ns
        return (ab[:, 2] >= occ - bias).float()


def _shade(p: Tensor, d: Tensor, mat: Tensor, n: Tensor, box: Tensor, layout: StreetLayout, boxes: Boxes, shadows: ShadowMap) -> Tensor:
    """Albedo by material times (skylight + sun * visibility), sky colour for misses."""
    seed = layout.seed
    R = p.shape[0]
    albedo = torch.zeros(R, 3)

    def fill(sel: Tensor, fn) -> None:
        idx = sel.nonzero()[:, 0]
        if len(idx):
            albedo[idx] = fn(idx)

    bi = box.clamp(min=0, max=len(boxes) - 1)
    fill(mat == ROAD, lambda i: tx.road_colour(p[i], seed, CROSSWALKS, ROAD_HALF, STREET_HALF_LEN))
    fill(mat == SIDEWALK, lambda i: tx.sidewalk_colour(p[i], n[i], seed))
    fill(mat == BUILDING, lambda i: tx.facade_colour(p[i], n[i], boxes.colour[bi[i]], boxes.lo[bi[i]], boxes.hi[bi[i], 2], boxes.ident[bi[i]], seed))
    fill(mat == CROWN, lambda i: tx.crown_colour(p[i], seed))
    plain = (mat == POLE) | (mat == TRUNK) | (mat == CAR_WHEELS)
    fill(plain, lambda i: boxes.colour[bi[i]] * (0.9 + 0.2 * tx.noise2(p[i, 0] * 5 + p[i, 1] * 5, p[i, 2] * 5, seed + 61))[:, None])
    fill((mat == CAR_BODY) | (mat == PARKED_CAR), lambda i: boxes.colour[bi[i]] * torch.where(p[i, 2] < 0.45, 0.55, 1.0)[:, None])
    fill(mat == CAR_CABIN, lambda i: torch.where((n[i, 2] > 0.5)[:, None], boxes.colour[bi[i]] * 2.0 - 0.2, boxes.colour[bi[i]]).clamp(0, 1))

    sun = layout.sun
    hit = mat != SKY
    lambert = (n @ sun).clamp(min=0.0)
    lit_idx = (hit & (lambert > 0)).nonzero()[:, 0]
    vis = torch.zeros(R)
    if len(lit_idx):
        vis[lit_idx] = shadows.lit(p[lit_idx], n[lit_idx])
    sky_light = 0.42 + 0.12 * n[:, 2].clamp(min=0)  # more skylight on up-facing surfaces
    shade = sky_light + 0.72 * lambert * vis
    rgb = albedo * shade[:, None] * torch.tensor([1.0, 0.99, 0.96])
    sky_idx = (~hit).nonzero()[:, 0]
    if len(sky_idx):
        rgb[sky_idx] = tx.sky_colour(d[sky_idx], sun, seed)
    return rgb.clamp(0, 1)


def render_view(layout: StreetLayout, c2w: Tensor, intr: Pinhole, cars: Boxes, shadows: ShadowMap, spp: int = 5) -> View:
    """Ray-cast one camera (``c2w [3, 4]`` OpenGL, metres) over the static street plus ``cars``."""
    spp = max(1, min(spp, len(_OFFSETS)))
    c2w = c2w.float()
    origin = c2w[:, 3]
    dirs = camera_rays(c2w, intr, spp)  # [S, H, W, 3]
    boxes = Boxes.cat([layout.static, cars])
    rects = _pixel_rects(_prim_corners(boxes, layout.crowns), c2w, intr)
    h = cast(origin, dirs, boxes, layout.crowns, rects)
    d = dirs.reshape(-1, 3)
    t, prim, axis = h.t.reshape(-1), h.prim.reshape(-1), h.axis.reshape(-1)
    R, B = d.shape[0], len(boxes)
    tp = torch.where(d[:, 2] < -1e-6, -origin[2] / d[:, 2].clamp(max=-1e-6), torch.full((R,), math.inf))
    plane = (tp < _FAR) & (tp < t)
    t = torch.where(plane, tp, t)
    is_box = ~plane & (prim >= 0) & (prim < B)
    is_sph = ~plane & (prim >= B)
    mat = torch.full((R,), SKY, dtype=torch.long)
    mat = torch.where(plane, torch.full_like(mat, ROAD), mat)
    mat = torch.where(is_box, boxes.material[prim.clamp(0, B - 1)], mat)
    mat = torch.where(is_sph, torch.full_like(mat, CROWN), mat)
    p = origin + torch.where(torch.isfinite(t), t, torch.zeros_like(t))[:, None] * d
    n = torch.zeros(R, 3)
    n.scatter_(1, axis[:, None], -torch.sign(d.gather(1, axis[:, None])))
    n = torch.where(is_box[:, None], n, torch.tensor([0.0, 0.0, 1.0]).expand(R, 3))
    if len(layout.crowns.radius):
        sn = torch.nn.functional.normalize(p - layout.crowns.centre[(prim - B).clamp(0, len(layout.crowns.radius) - 1)], dim=-1)
        n = torch.where(is_sph[:, None], sn, n)
    rgb = _shade(p, d, mat, n, torch.where(is_box, prim, -1), layout, boxes, shadows)
    H, W, P = intr.height, intr.width, intr.height * intr.width
    rgb = rgb.reshape(spp, P, 3).mean(0).reshape(H, W, 3)
    mat = mat.reshape(spp, P)
    m0, t0, p0 = mat[0], t.reshape(spp, P)[0], p.reshape(spp, P, 3)[0]
    sky = m0 == SKY
    depth = torch.where(sky, torch.zeros_like(t0), t0 * (dirs[0].reshape(P, 3) @ -c2w[:, 2]))
    transient = torch.isin(mat, torch.tensor(TRANSIENT_MATERIALS)).any(0)
    ground = torch.isin(m0, torch.tensor(GROUND_MATERIALS))
    return View(rgb, sky.reshape(H, W), ground.reshape(H, W), transient.reshape(H, W), depth.reshape(H, W), p0, m0)


def centre_hits(layout: StreetLayout, c2w: Tensor, intr: Pinhole, cars: Boxes) -> tuple[Tensor, Tensor]:
    """What :func:`render_view`'s pixel-centre rays hit: the distance along each unit ray ``[H, W]``
    (inf: sky) and the object ``[H, W]`` long: a box's index in ``Boxes.cat([layout.static, cars])``,
    ``len(boxes) + s`` for tree crown ``s``, -1 the ground plane, -2 the sky."""
    c2w = c2w.float()
    origin = c2w[:, 3]
    dirs = camera_rays(c2w, intr, 1)
    boxes = Boxes.cat([layout.static, cars])
    h = cast(origin, dirs, boxes, layout.crowns, _pixel_rects(_prim_corners(boxes, layout.crowns), c2w, intr))
    d, t, prim = dirs[0], h.t[0], h.prim[0]
    tp = torch.where(d[..., 2] < -1e-6, -origin[2] / d[..., 2].clamp(max=-1e-6), torch.full_like(t, math.inf))
    plane = (tp < _FAR) & (tp < t)
    obj = torch.where(plane, -1, torch.where(prim >= 0, prim, -2))
    return torch.where(plane, tp, torch.where(obj == -2, math.inf, t)), obj
