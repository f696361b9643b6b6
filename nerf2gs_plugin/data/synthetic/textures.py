"""Hashed value noise and the street's surface patterns, vectorised over hit points.

Every pattern is a pure function of the surface point (metres) and the scene seed, so the same
surface point has the same colour in every view: the scene is static apart from the cars.
Colours are display-space RGB in [0, 1].
"""

from __future__ import annotations

import torch
from torch import Tensor

_M31 = 0x7FFFFFFF


def hash01(seed: int, *coords: Tensor) -> Tensor:
    """Integer lattice coordinates (int64 tensors) -> float in [0, 1); a fixed function of the seed.

    A linear mix of the coordinates, then two xor-shift-multiply rounds; every intermediate stays
    below 2^62 (31-bit state times 31-bit constants), so int64 never overflows."""
    h = coords[0] * 73856093
    for i, c in enumerate(coords[1:]):
        h = h ^ (c * (19349663, 83492791, 50331653)[i % 3])
    h = (h ^ ((seed * 2654435761) & _M31)) & _M31
    h = (((h >> 15) ^ h) * 0x45D9F3B) & _M31
    h = (((h >> 13) ^ h) * 0x2C1B3C6D) & _M31
    return ((h >> 16) ^ h).bitwise_and_(0xFFFF).float().mul_(1.0 / 65536.0)


def _smooth(f: Tensor) -> Tensor:
    return f * f * (3.0 - 2.0 * f)


def noise2(x: Tensor, y: Tensor, seed: int) -> Tensor:
    """Smooth 2-D value noise in [0, 1] (bilinear over a unit lattice, smoothstep weights)."""
    ix, iy = torch.floor(x), torch.floor(y)
    fx, fy = _smooth(x - ix), _smooth(y - iy)
    ix, iy = ix.long(), iy.long()
    a = hash01(seed, ix, iy)
    b = hash01(seed, ix + 1, iy)
    c = hash01(seed, ix, iy + 1)
    d = hash01(seed, ix + 1, iy + 1)
    return torch.lerp(torch.lerp(a, b, fx), torch.lerp(c, d, fx), fy)


def noise3(p: Tensor, seed: int) -> Tensor:
    """Smooth 3-D value noise in [0, 1] for ``p [N, 3]``."""
    i = torch.floor(p)
    f = _smooth(p - i)
    i = i.long()
    out = torch.zeros(p.shape[0], dtype=p.dtype, device=p.device)
    for dx in (0, 1):
        wx = f[:, 0] if dx else 1 - f[:, 0]
        for dy in (0, 1):
            wy = f[:, 1] if dy else 1 - f[:, 1]
            for dz in (0, 1):
                wz = f[:, 2] if dz else 1 - f[:, 2]
                out = out + wx * wy * wz * hash01(seed, i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz)
    return out


def fbm2(x: Tensor, y: Tensor, seed: int, octaves: int = 3) -> Tensor:
    """Fractal sum of :func:`noise2` octaves, in [0, 1]."""
    out, amp, total = torch.zeros_like(x), 1.0, 0.0
    for o in range(octaves):
        s = 2.0**o
        out = out + amp * noise2(x * s, y * s, seed + 101 * o)
        total += amp
        amp *= 0.5
    return out / total


def _rgb(*v: float) -> Tensor:
    return torch.tensor(v, dtype=torch.float32)


def _in_band(v: Tensor, period: float, lo: float, hi: float) -> Tensor:
    r = torch.remainder(v, period)
    return (r >= lo) & (r < hi)


def road_colour(p: Tensor, seed: int, crosswalks: tuple[float, ...], road_half: float, street_half_len: float) -> Tensor:
    """Asphalt with a dashed centre line, edge lines, zebra crosswalks and stop lines; plain
    ground outside the street."""
    x, y = p[:, 0], p[:, 1]
    grain = 0.06 * (noise2(x * 1.3, y * 1.3, seed + 11) - 0.5) + 0.05 * (noise2(x * 9.0, y * 9.0, seed + 12) - 0.5)
    col = (_rgb(0.30, 0.30, 0.32) + grain[:, None]).clone()
    ay = y.abs()
    paint = (ay < 0.08) & _in_band(x, 6.0, 0.0, 3.0)
    paint |= (ay - (road_half - 0.3)).abs() < 0.08
    for cx in crosswalks:
        paint |= ((x - cx).abs() < 1.8) & (ay < road_half - 0.45) & _in_band(y + road_half, 0.9, 0.0, 0.45)
        paint |= ((x - (cx - 2.4)).abs() < 0.15) & (y < -0.2) & (y > -(road_half - 0.4))
        paint |= ((x - (cx + 2.4)).abs() < 0.15) & (y > 0.2) & (y < road_half - 0.4)
    centre = (ay < 0.08)[:, None]
    worn = (0.82 + 0.18 * noise2(x * 4.0, y * 4.0, seed + 13))[:, None]
    paint_col = torch.where(centre, _rgb(0.88, 0.76, 0.30), _rgb(0.90, 0.90, 0.88)) * worn
    col = torch.where(paint[:, None], paint_col, col)
    outside = (ay > road_half) | (x.abs() > street_half_len)
    lot = _rgb(0.36, 0.38, 0.33) + 0.08 * (noise2(x * 0.7, y * 0.7, seed + 14) - 0.5)[:, None]
    return torch.where(outside[:, None], lot, col).clamp(0, 1)


def sidewalk_colour(p: Tensor, n: Tensor, seed: int) -> Tensor:
    """Paving tiles (0.8 m grid, per-tile tone) on top; concrete kerb on the sides."""
    x, y = p[:, 0], p[:, 1]
    tx, ty = torch.floor(x / 0.8).long(), torch.floor(y / 0.8).long()
    tone = 0.9 + 0.2 * hash01(seed + 21, tx, ty)
    joint = _in_band(x, 0.8, 0.0, 0.05) | _in_band(y, 0.8, 0.0, 0.05)
    top = _rgb(0.64, 0.61, 0.56) * tone[:, None] * torch.where(joint, 0.72, 1.0)[:, None]
    kerb = _rgb(0.74, 0.73, 0.70) * (0.92 + 0.1 * noise2(x * 3.0, p[:, 2] * 3.0, seed + 22))[:, None]
    return torch.where((n[:, 2] > 0.5)[:, None], top, kerb).clamp(0, 1)


def facade_colour(p: Tensor, n: Tensor, base: Tensor, lo: Tensor, height: Tensor, bid: Tensor, seed: int) -> Tensor:
    """Walls with floors of framed windows (some lit), shop windows on the ground floor, a
    cornice line per floor and a darker parapet; roofs on top faces.

    ``base`` ``[N, 3]`` is the building's wall colour, ``lo`` its box minimum, ``height`` its roof
    height and ``bid`` its index (window lighting varies per building and window)."""
    z = p[:, 2]
    along_y = n[:, 0].abs() > 0.5  # a face looking along x: its horizontal coordinate is y
    u = torch.where(along_y, p[:, 1] - lo[:, 1], p[:, 0] - lo[:, 0])
    wall = base * (0.94 + 0.12 * noise2(u * 2.0, z * 2.0, seed + 31))[:, None]
    ground_floor = z < 3.4
    fz = z - 3.4
    # upper floors: 2.6 m bays, windows 1.1 x 1.6 m with 0.1 m frames
    ru, rz = torch.remainder(u, 2.6), torch.remainder(fz, 3.2)
    win_out = (ru > 0.65) & (ru < 1.95) & (rz > 0.6) & (rz < 2.4)
    win_in = (ru > 0.75) & (ru < 1.85) & (rz > 0.7) & (rz < 2.3)
    wid = hash01(seed + 32, bid, torch.floor(u / 2.6).long(), torch.floor(fz / 3.2).long())
    glass = _rgb(0.16, 0.20, 0.27) + 0.10 * (rz / 3.2)[:, None]  # sky reflection toward the top
    lit = (wid > 0.86)[:, None]
    glass = torch.where(lit, _rgb(0.86, 0.74, 0.45), glass + 0.08 * (wid[:, None] - 0.5))
    col = torch.where(win_in[:, None], glass, torch.where(win_out[:, None], _rgb(0.86, 0.85, 0.82), wall))
    col = torch.where((rz < 0.15)[:, None] & ~ground_floor[:, None], wall * 0.82, col)
    # ground floor: plinth with shop windows (5 m bays)
    rs = torch.remainder(u, 5.0)
    shop = (rs > 0.8) & (rs < 4.2) & (z > 0.5) & (z < 2.8)
    gf = torch.where(shop[:, None], _rgb(0.12, 0.15, 0.18) + 0.12 * (z / 2.8)[:, None], wall * 0.78)
    col = torch.where(ground_floor[:, None], gf, col)
    col = torch.where((z > height - 0.6)[:, None], wall * 0.7, col)
    roof = _rgb(0.33, 0.31, 0.30) * (0.85 + 0.3 * noise2(p[:, 0] * 0.8, p[:, 1] * 0.8, seed + 33))[:, None]
    return torch.where((n[:, 2] > 0.5)[:, None], roof, col).clamp(0, 1)


def crown_colour(p: Tensor, seed: int) -> Tensor:
    """Leafy tree crowns: two scales of 3-D noise over a green."""
    v = 0.55 * noise3(p * 2.2, seed + 41) + 0.45 * noise3(p * 6.0, seed + 42)
    return (_rgb(0.16, 0.36, 0.12) * (0.55 + 0.9 * v)[:, None]).clamp(0, 1)


def sky_colour(d: Tensor, sun: Tensor, seed: int) -> Tensor:
    """Horizon-to-zenith gradient, a sun glow and soft clouds, by ray direction ``d [N, 3]``."""
    dz = d[:, 2].clamp(min=0.0)
    t = dz.pow(0.6)[:, None]
    col = _rgb(0.80, 0.86, 0.93) * (1 - t) + _rgb(0.32, 0.52, 0.86) * t
    cs = (d @ sun).clamp(min=0.0)
    col = col + (0.5 * cs.pow(300.0) + 0.12 * cs.pow(8.0))[:, None] * _rgb(1.0, 0.9, 0.7)
    k = 1.0 / (dz + 0.12)
    c = fbm2(d[:, 0] * k * 1.5, d[:, 1] * k * 1.5, seed + 51, octaves=3)
    cover = ((c - 0.52) / 0.2).clamp(0, 1) * (1 - torch.exp(-dz * 10.0))
    col = torch.lerp(col, _rgb(0.95, 0.95, 0.97).expand_as(col), (0.85 * cover)[:, None])
    return col.clamp(0, 1)
