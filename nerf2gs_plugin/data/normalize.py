"""Scene normalisation shared by every parser: orient, centre and scale the TRAIN cameras into a
unit box (as nerfstudio's ``auto_orient_and_center_poses`` + ``auto_scale_poses``), apply the same
transform to every split and to the points, and record it with the metric scale.

Normalised world = ``scale * (transform @ [x_orig; 1])`` with ``transform`` a rigid ``[3, 4]``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Optional, Union

import torch
from torch import Tensor

from nerf2gs_plugin.errors import DataError

FORMAT = "nerf2gs-dataparser-transforms/1"
Orientation = Literal["up", "none"]
Center = Literal["poses", "none"]


@dataclass
class NormalizeOptions:
    """How to map the data frame into the normalised world (the same for all parsers)."""

    orientation: Orientation = "up"
    """"up": rotate the up vector (the data's declared ``up``, else the mean camera up axis) onto +z;
    "none": keep the data's axes."""
    center: Center = "poses"
    """"poses": move the mean TRAIN camera position to the origin; "none": keep the origin."""
    auto_scale: bool = True
    """Scale so the largest |coordinate| of a TRAIN camera position is ``scale_factor``."""
    scale_factor: float = 1.0
    """Extra scale (with ``auto_scale``: the target max |coordinate|; without: the scale itself)."""
    scene_scale: float = 1.0
    """The scene box is at least ``[-scene_scale, scene_scale]^3`` (grown to hold the points)."""


@dataclass
class DataparserTransform:
    transform: Tensor = field(default_factory=lambda: torch.eye(4)[:3])  # [3, 4], rigid
    scale: float = 1.0
    up: Tensor = field(default_factory=lambda: torch.tensor([0.0, 0.0, 1.0]))  # [3], normalised world
    metres_per_unit: float = 1.0  # metres per unit of the ORIGINAL frame
    scene_box: Tensor = field(default_factory=lambda: torch.tensor([[-1.0] * 3, [1.0] * 3]))  # [2, 3]

    def apply_poses(self, c2w: Tensor) -> Tensor:
        """Original ``[N, 3, 4]`` camera-to-world -> normalised world (rotation stays orthonormal)."""
        R, t = self.transform[:, :3].to(c2w), self.transform[:, 3].to(c2w)
        rot = R @ c2w[:, :, :3]
        pos = self.scale * (c2w[:, :, 3] @ R.T + t)
        return torch.cat([rot, pos[:, :, None]], dim=-1)

    def apply_points(self, xyz: Tensor) -> Tensor:
        """Original ``[P, 3]`` -> normalised world."""
        R, t = self.transform[:, :3].to(xyz), self.transform[:, 3].to(xyz)
        return self.scale * (xyz @ R.T + t)

    def invert_points(self, xyz: Tensor) -> Tensor:
        """Normalised world ``[P, 3]`` -> original frame."""
        R, t = self.transform[:, :3].to(xyz), self.transform[:, 3].to(xyz)
        return (xyz / self.scale - t) @ R


def rotation_between(a: Tensor, b: Tensor) -> Tensor:
    """The smallest rotation ``[3, 3]`` taking unit vector ``a`` to unit vector ``b``."""
    a = torch.nn.functional.normalize(a.double(), dim=0)
    b = torch.nn.functional.normalize(b.double(), dim=0)
    v = torch.linalg.cross(a, b)
    c = float(torch.dot(a, b))
    if c < -1 + 1e-9:  # opposite: rotate by pi about any axis orthogonal to a
        axis = torch.linalg.cross(a, torch.tensor([1.0, 0.0, 0.0], dtype=a.dtype))
        if axis.norm() < 1e-6:
            axis = torch.linalg.cross(a, torch.tensor([0.0, 1.0, 0.0], dtype=a.dtype))
        axis = axis / axis.norm()
        return (2 * torch.outer(axis, axis) - torch.eye(3, dtype=a.dtype)).float()
    K = torch.tensor([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]], dtype=a.dtype)
    return (torch.eye(3, dtype=a.dtype) + K + K @ K / (1 + c)).float()


def compute_transform(
    train_c2w: Tensor,
    options: NormalizeOptions,
    declared_up: Optional[Tensor] = None,
    metres_per_unit: float = 1.0,
    points: Optional[Tensor] = None,
) -> DataparserTransform:
    """The normalisation, from the TRAIN cameras ``[N, 3, 4]`` (OpenGL) only, so every split and
    every run on the same data agree. ``points`` (original frame) only grow the scene box."""
    c2w = train_c2w.double()
    if declared_up is not None:
        up = torch.as_tensor(declared_up, dtype=torch.float64).reshape(3)
    else:
        up = c2w[:, :, 1].mean(0)  # OpenGL camera y axis = camera up
    if up.norm() < 1e-8:
        up = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    up = up / up.norm()
    R = rotation_between(up, torch.tensor([0.0, 0.0, 1.0])).double() if options.orientation == "up" else torch.eye(3, dtype=torch.float64)
    centre = c2w[:, :, 3].mean(0) if options.center == "poses" else torch.zeros(3, dtype=torch.float64)
    t = -(R @ centre)
    pos = c2w[:, :, 3] @ R.T + t
    scale = float(options.scale_factor)
    if options.auto_scale:
        extent = float(pos.abs().max()) if len(pos) else 0.0
        scale = options.scale_factor / extent if extent > 1e-8 else options.scale_factor
    tf = DataparserTransform(torch.cat([R, t[:, None]], dim=1).float(), scale, (R @ up).float(), float(metres_per_unit))
    lo = torch.full((3,), -float(options.scene_scale))
    hi = -lo
    if points is not None and len(points) > 0:
        p = tf.apply_points(points.float())
        q = torch.quantile(p[torch.randperm(len(p), generator=torch.Generator().manual_seed(0))[:100000]], torch.tensor([0.01, 0.99]), dim=0)
        pad = 0.1 * (q[1] - q[0])
        lo, hi = torch.minimum(lo, q[0] - pad), torch.maximum(hi, q[1] + pad)
    cams = tf.apply_poses(train_c2w.float())[:, :, 3]
    if len(cams):
        lo, hi = torch.minimum(lo, cams.min(0).values), torch.maximum(hi, cams.max(0).values)
    tf.scene_box = torch.stack([lo, hi])
    return tf


def check_rigid(m: Tensor, where: str, path: Path, tol: float = 1e-2) -> None:
    """A camera pose must be finite, its rotation orthonormal with det +1 (else DataError)."""
    if not bool(torch.isfinite(m).all()):
        raise DataError(f"{where}: transform has non-finite values", path)
    R = m[:3, :3].double()
    err = float((R.T @ R - torch.eye(3, dtype=torch.float64)).abs().max())
    det = float(torch.linalg.det(R))
    if err > tol or abs(det - 1.0) > tol:
        raise DataError(f"{where}: transform is not rigid (|R^T R - I| = {err:.3g}, det R = {det:.3g})", path)
    if m.shape[0] == 4 and float((m[3] - torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=m.dtype)).abs().max()) > 1e-6:
        raise DataError(f"{where}: bottom row of the 4x4 transform is not [0, 0, 0, 1]", path)


def orthonormalize(R: Tensor) -> Tensor:
    """Nearest rotation (SVD) to a nearly-orthonormal ``[..., 3, 3]``: cleans float noise in files."""
    U, _, Vh = torch.linalg.svd(R.double())
    return (U @ Vh).to(R.dtype)


# ---------------------------------------------------------------------------- dataparser_transforms.json
def save_dataparser_transform(path: Union[str, Path], outputs) -> None:
    """Write ``dataparser_transforms.json`` (nerfstudio's ``transform``/``scale`` + our fields) for a
    :class:`DataparserOutputs` or a :class:`DataparserTransform`."""
    if hasattr(outputs, "dataparser_transform"):
        tf = DataparserTransform(outputs.dataparser_transform, outputs.dataparser_scale, outputs.up, outputs.metres_per_unit, outputs.scene_box)
    else:
        tf = outputs
    data = {
        "format": FORMAT,
        "transform": [[float(v) for v in row] for row in tf.transform.tolist()],
        "scale": float(tf.scale),
        "metres_per_unit": float(tf.metres_per_unit),
        "up": [float(v) for v in tf.up.tolist()],
        "scene_box": [[float(v) for v in row] for row in tf.scene_box.tolist()],
        "metres_per_world_unit": float(tf.metres_per_unit / tf.scale),
    }
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2))
    tmp.replace(path)


def load_dataparser_transform(path: Union[str, Path]) -> DataparserTransform:
    """Read ``dataparser_transforms.json`` (ours or nerfstudio's: missing fields take defaults)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        tf = torch.tensor(data["transform"], dtype=torch.float32)
        if tf.shape == (4, 4):
            tf = tf[:3]
        if tf.shape != (3, 4):
            raise ValueError(f"transform has shape {tuple(tf.shape)}, expected 3x4")
        scale = float(data.get("scale", 1.0))
        if not math.isfinite(scale) or scale <= 0:
            raise ValueError(f"scale must be positive, got {scale}")
        return DataparserTransform(
            tf,
            scale,
            torch.tensor(data.get("up", [0.0, 0.0, 1.0]), dtype=torch.float32),
            float(data.get("metres_per_unit", 1.0)),
            torch.tensor(data.get("scene_box", [[-1.0] * 3, [1.0] * 3]), dtype=torch.float32),
        )
    except FileNotFoundError:
        raise DataError("dataparser transform file does not exist", path) from None
    except (ValueError, KeyError, TypeError) as e:
        raise DataError(f"malformed dataparser transform ({type(e).__name__}: {e})", path) from None
