"""Helpers shared by the Gaussian-splatting methods: SH <-> RGB, SH basis, quaternions,
nearest-neighbour scale initialisation, and the standard 3DGS PLY layout (write and read).

Conventions: quaternions are ``wxyz``; scales are stored as logs and opacities as logits by the
methods; SH coefficients are ``[N, K, 3]`` with ``K = (degree + 1) ** 2`` and the DC term first.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional, Union

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.errors import DataError

SH_C0 = 0.28209479177387814
_SH_C1 = 0.4886025119029199
_SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
_SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
          -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def num_sh_bases(degree: int) -> int:
    return (degree + 1) ** 2


def rgb_to_sh(rgb: Tensor) -> Tensor:
    """Colour in [0, 1] -> DC coefficient (the rasterizer adds 0.5 back after evaluating SH)."""
    return (rgb - 0.5) / SH_C0


def sh_to_rgb(sh: Tensor) -> Tensor:
    return sh * SH_C0 + 0.5


def sh_basis(degree: int, dirs: Tensor) -> Tensor:
    """Real SH basis (the 3DGS sign convention) of unit directions ``[..., 3]`` -> ``[..., K]``."""
    x, y, z = dirs.unbind(-1)
    out = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        out += [-_SH_C1 * y, _SH_C1 * z, -_SH_C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [_SH_C2[0] * xy, _SH_C2[1] * yz, _SH_C2[2] * (2 * zz - xx - yy), _SH_C2[3] * xz, _SH_C2[4] * (xx - yy)]
    if degree >= 3:
        out += [
            _SH_C3[0] * y * (3 * xx - yy),
            _SH_C3[1] * xy * z,
            _SH_C3[2] * y * (4 * zz - xx - yy),
            _SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
            _SH_C3[4] * x * (4 * zz - xx - yy),
            _SH_C3[5] * z * (xx - yy),
            _SH_C3[6] * x * (xx - 3 * yy),
        ]
    if degree > 3:
        raise ValueError("SH degree > 3 is not supported")
    return torch.stack(out, dim=-1)


# ---------------------------------------------------------------------------------------- quaternions
def normalize_quats(q: Tensor) -> Tensor:
    return torch.nn.functional.normalize(q, dim=-1)


def random_quats(n: int, generator: Optional[torch.Generator] = None) -> Tensor:
    """Uniformly distributed unit quaternions ``[n, 4]`` (wxyz), Shoemake's method."""
    u, v, w = torch.rand(3, n, generator=generator)
    a, b = torch.sqrt(1 - u), torch.sqrt(u)
    return torch.stack([a * torch.sin(2 * math.pi * v), a * torch.cos(2 * math.pi * v),
                        b * torch.sin(2 * math.pi * w), b * torch.cos(2 * math.pi * w)], dim=-1)


def quat_to_rotmat(q: Tensor) -> Tensor:
    """``[..., 4]`` wxyz (any norm) -> rotation matrices ``[..., 3, 3]``."""
    w, x, y, z = normalize_quats(q).unbind(-1)
    R = torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1)
    return R.reshape(*q.shape[:-1], 3, 3)


def rotmat_to_quat(R: Tensor) -> Tensor:
    """Rotation matrices ``[..., 3, 3]`` -> unit quaternions ``[..., 4]`` wxyz (w >= 0)."""
    m = R
    t = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = torch.stack([
        torch.stack([1 + t, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        torch.stack([m[..., 2, 1] - m[..., 1, 2], 1 + 2 * m[..., 0, 0] - t, m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]], -1),
        torch.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 + 2 * m[..., 1, 1] - t, m[..., 1, 2] + m[..., 2, 1]], -1),
        torch.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1], 1 + 2 * m[..., 2, 2] - t], -1),
    ], dim=-2)  # [..., 4, 4]; row i is 4*q*q_i, best conditioned where q_i is largest
    diag = torch.stack([1 + t, 1 + 2 * m[..., 0, 0] - t, 1 + 2 * m[..., 1, 1] - t, 1 + 2 * m[..., 2, 2] - t], -1)
    best = diag.argmax(-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4)).squeeze(-2)
    q = normalize_quats(q)
    return torch.where(q[..., :1] < 0, -q, q)


def covariances(quats: Tensor, scales: Tensor) -> Tensor:
    """``R diag(s^2) R^T`` ``[N, 3, 3]`` from quats ``[N, 4]`` and linear scales ``[N, 3]``."""
    R = quat_to_rotmat(quats)
    M = R * scales[:, None, :]
    return M @ M.transpose(1, 2)


# ---------------------------------------------------------------------------------------- init
def knn_mean_distance(points: Tensor, k: int = 3, chunk: int = 512) -> Tensor:
    """Mean distance of each point ``[N, 3]`` to its ``k`` nearest neighbours ``[N]`` (3DGS scale
    initialisation). Chunked so memory stays ``chunk x N``."""
    n = points.shape[0]
    if n <= 1:
        return torch.full((n,), 0.01, device=points.device)
    k = min(k, n - 1)
    out = torch.empty(n, device=points.device)
    for s in range(0, n, chunk):
        d = torch.cdist(points[s : s + chunk], points)
        out[s : s + chunk] = d.topk(k + 1, dim=1, largest=False).values[:, 1:].mean(1)
    return out


def logit(p: Union[float, Tensor]) -> Tensor:
    p = torch.as_tensor(p, dtype=torch.float32)
    return torch.log(p / (1 - p))


# ---------------------------------------------------------------------------------------- PLY
def write_gaussian_ply(
    path: Union[str, Path],
    means: Tensor,
    log_scales: Tensor,
    quats: Tensor,
    opacity_logits: Tensor,
    features_dc: Tensor,
    features_rest: Optional[Tensor] = None,
    comments: tuple[str, ...] = (),
) -> None:
    """The standard 3DGS PLY (what the original code, SuperSplat and most viewers read).

    Args: means ``[N,3]``, log_scales ``[N,3]`` (2DGS passes a very small value, a "zero" scale,
    for its third axis), quats ``[N,4]`` wxyz, opacity_logits ``[N]``, features_dc ``[N,3]``
    SH DC, features_rest ``[N,K-1,3]`` (written channel-major as ``f_rest_*``, as 3DGS does);
    ``comments``: one-line ``comment`` header entries (e.g. the coordinate frame).
    """
    n = means.shape[0]
    cols: list[tuple[str, Tensor]] = [("x", means[:, 0]), ("y", means[:, 1]), ("z", means[:, 2])]
    zeros = torch.zeros(n, device=means.device)
    cols += [("nx", zeros), ("ny", zeros), ("nz", zeros)]
    cols += [(f"f_dc_{i}", features_dc[:, i]) for i in range(3)]
    if features_rest is not None and features_rest.shape[1] > 0:
        rest = features_rest.transpose(1, 2).reshape(n, -1)  # [N, 3*(K-1)] channel-major
        cols += [(f"f_rest_{i}", rest[:, i]) for i in range(rest.shape[1])]
    cols.append(("opacity", opacity_logits.reshape(n)))
    cols += [(f"scale_{i}", log_scales[:, i]) for i in range(log_scales.shape[1])]
    cols += [(f"rot_{i}", quats[:, i]) for i in range(4)]
    data = np.empty(n, dtype=[(name, "<f4") for name, _ in cols])
    for name, col in cols:
        data[name] = col.detach().float().cpu().numpy()
    header = "ply\nformat binary_little_endian 1.0\n" + "".join(f"comment {c}\n" for c in comments)
    header += f"element vertex {n}\n" + "".join(f"property float {name}\n" for name, _ in cols) + "end_header\n"
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(data.tobytes())
    tmp.replace(path)


def read_gaussian_ply(path: Union[str, Path]) -> dict[str, Tensor]:
    """Read a 3DGS PLY (binary little endian, float properties) -> ``means [N,3]``,
    ``log_scales [N,S]``, ``quats [N,4]``, ``opacity_logits [N]``, ``features_dc [N,3]``,
    ``features_rest [N,K-1,3]``."""
    path = Path(path)
    if not path.is_file():
        raise DataError("PLY file does not exist", path)
    raw = path.read_bytes()
    end = raw.find(b"end_header\n")
    if not raw.startswith(b"ply") or end < 0:
        raise DataError("not a PLY file", path)
    names, count, fmt = [], 0, None
    for line in raw[:end].decode("ascii", errors="replace").splitlines():
        tok = line.split()
        if tok[:1] == ["format"]:
            fmt = tok[1]
        elif tok[:2] == ["element", "vertex"]:
            count = int(tok[2])
        elif tok[:1] == ["property"]:
            if tok[1] not in ("float", "float32"):
                raise DataError(f"unsupported property type {tok[1]} (3DGS PLYs are float)", path)
            names.append(tok[2])
    if fmt != "binary_little_endian":
        raise DataError(f"unsupported PLY format {fmt}", path)
    body = raw[end + len(b"end_header\n"):]
    dtype = np.dtype([(n, "<f4") for n in names])
    if len(body) < count * dtype.itemsize:
        raise DataError("PLY file is truncated", path)
    data = np.frombuffer(body, dtype=dtype, count=count)

    def stack(prefix: str) -> Tensor:
        cols = sorted((n for n in names if n.startswith(prefix)), key=lambda s: int(s[len(prefix):]))
        return torch.from_numpy(np.stack([data[c] for c in cols], axis=-1).astype(np.float32)) if cols else torch.zeros(count, 0)

    for required in ("x", "y", "z", "opacity", "f_dc_0", "rot_0", "scale_0"):
        if required not in names:
            raise DataError(f"PLY lacks the 3DGS property '{required}'", path)
    rest = stack("f_rest_")
    return {
        "means": torch.from_numpy(np.stack([data["x"], data["y"], data["z"]], -1).astype(np.float32)),
        "log_scales": stack("scale_"),
        "quats": stack("rot_"),
        "opacity_logits": torch.from_numpy(data["opacity"].astype(np.float32)),
        "features_dc": stack("f_dc_"),
        "features_rest": rest.reshape(count, 3, -1).transpose(1, 2).contiguous(),
    }
