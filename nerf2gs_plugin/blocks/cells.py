"""The grid of cells on the ground plane, in the source dataset's normalised frame (z up).

Ground coordinates ``(u, v)`` are the train cameras' positions projected on the plane and turned
onto their principal axis (``u`` along the street). The ``K`` columns along ``u`` hold equal
numbers of train cameras, and within each column the ``L`` rows along ``v`` do too (VastGaussian's
camera-count split, so every block gets a similar load). Outer cells reach to infinity, so every
point of the scene lies in exactly one cell (half-open ``[lo, hi)``). A block trains on the
cameras inside its cell grown by ``overlap`` times the cell's size on each side (the size of an
outer cell measured to the last camera).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

Interval = tuple[float, float]  # (lo, hi); -inf / inf for an open side


@dataclass
class Cell:
    name: str
    index: tuple[int, int]
    u: Interval
    v: Interval
    expanded_u: Interval
    expanded_v: Interval

    def to_json(self) -> dict:
        return {"name": self.name, "index": list(self.index), "cell": {"u": _iv_json(self.u), "v": _iv_json(self.v)},
                "expanded": {"u": _iv_json(self.expanded_u), "v": _iv_json(self.expanded_v)}}

    @staticmethod
    def from_json(d: dict) -> "Cell":
        return Cell(d["name"], tuple(d["index"]), _iv(d["cell"]["u"]), _iv(d["cell"]["v"]),
                    _iv(d["expanded"]["u"]), _iv(d["expanded"]["v"]))


def _iv_json(iv: Interval) -> list:
    return [None if math.isinf(x) else float(x) for x in iv]


def _iv(vals: list) -> Interval:
    lo, hi = vals
    return (-math.inf if lo is None else float(lo), math.inf if hi is None else float(hi))


def ground_axes(xy: Tensor) -> Tensor:
    """``[2, 2]`` rows ``(u, v)``: the principal axis of the points ``xy [N, 2]`` and its normal,
    signed so the larger component of ``u`` is positive (the same data gives the same axes)."""
    xy = xy.double()
    if len(xy) < 2:
        return torch.eye(2, dtype=torch.float64)
    c = xy - xy.mean(0)
    _, vecs = torch.linalg.eigh(c.T @ c)
    u = vecs[:, 1]
    if u[int(u.abs().argmax())] < 0:
        u = -u
    return torch.stack([u, torch.stack([-u[1], u[0]])])


def to_uv(xyz: Tensor, axes: Tensor) -> Tensor:
    """Points ``[N, 3]`` (normalised frame) -> ground coordinates ``[N, 2]``."""
    return xyz[:, :2].double() @ axes.to(torch.float64).T


def _edges(values: Tensor, n: int) -> list[float]:
    """``n + 1`` edges splitting ``values`` (non-empty) into ``n`` equal-count groups, outer edges infinite."""
    return [-math.inf, *(float(torch.quantile(values.double(), k / n)) for k in range(1, n)), math.inf]


def _expand(iv: Interval, lo_cam: float, hi_cam: float, overlap: float) -> Interval:
    lo = iv[0] if math.isfinite(iv[0]) else lo_cam
    hi = iv[1] if math.isfinite(iv[1]) else hi_cam
    grow = overlap * max(hi - lo, 0.0)
    return (iv[0] - grow if math.isfinite(iv[0]) else -math.inf, iv[1] + grow if math.isfinite(iv[1]) else math.inf)


def make_cells(uv: Tensor, k: int, l: int, overlap: float) -> list[Cell]:
    """``k x l`` cells over the train cameras' ground coordinates ``uv [N, 2]``."""
    u, v = uv[:, 0], uv[:, 1]
    u_edges = _edges(u, k)
    cells = []
    for i in range(k):
        ui = (u_edges[i], u_edges[i + 1])
        col = (u >= ui[0]) & (u < ui[1])
        v_edges = _edges(v[col] if bool(col.any()) else v, l)
        for j in range(l):
            vj = (v_edges[j], v_edges[j + 1])
            cells.append(Cell(f"block_{i}_{j}", (i, j), ui, vj,
                              _expand(ui, float(u.min()), float(u.max()), overlap),
                              _expand(vj, float(v.min()), float(v.max()), overlap)))
    return cells


def inside(uv: Tensor, u: Interval, v: Interval) -> Tensor:
    """``[N]`` bool: ``uv`` in ``[u0, u1) x [v0, v1)``."""
    return (uv[:, 0] >= u[0]) & (uv[:, 0] < u[1]) & (uv[:, 1] >= v[0]) & (uv[:, 1] < v[1])
