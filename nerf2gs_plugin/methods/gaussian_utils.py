"""Helpers shared by the Gaussian-splatting methods: covariances, nearest-neighbour scale
initialisation, and the standard 3DGS PLY layout (write and read). SH and quaternion maths are in
:mod:`nerf2gs_plugin.utils.sh` and :mod:`nerf2gs_plugin.utils.quaternions`.

Conventions: quaternions are ``wxyz``; scales are stored as logs and opacities as logits by the
methods; SH coefficients are ``[N, K, 3]`` with ``K = (degree + 1) ** 2`` and the DC term first.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.data.ply import read_ply_vertices
from nerf2gs_plugin.errors import DataError
from nerf2gs_plugin.utils.io import atomic_write_bytes
from nerf2gs_plugin.utils.quaternions import quat_to_rotmat


def covariances(quats: Tensor, scales: Tensor) -> Tensor:
    """``R diag(s^2) R^T`` ``[N, 3, 3]`` from quats ``[N, 4]`` and linear scales ``[N, 3]``."""
    R = quat_to_rotmat(quats)  # normalises
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
    atomic_write_bytes(Path(path), header.encode("ascii") + data.tobytes())


def read_gaussian_ply(path: Union[str, Path]) -> dict[str, Tensor]:
    """Read a 3DGS PLY (the 3DGS vertex properties, any PLY encoding) -> ``means [N,3]``,
    ``log_scales [N,S]``, ``quats [N,4]``, ``opacity_logits [N]``, ``features_dc [N,3]``,
    ``features_rest [N,K-1,3]``."""
    data = read_ply_vertices(path)
    names, count = list(data), len(data["x"])

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
