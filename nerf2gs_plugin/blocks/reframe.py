"""A splatting model's state from one run's normalised frame to another's (both of one dataset).

Each run normalises the data frame by its own train cameras (``x_n = s (R x + t)``,
``dataparser_transforms.json``), so a block run's Gaussians live in the block's frame. Moving
them to the merged run's frame: means through the data frame, log-scales by ``log(s_to / s_from)``,
orientations and the view-dependent colour (SH rest bands, and the sky background's SH) by the
rotation ``R_to R_from^T`` (:func:`nerf2gs_plugin.methods.gaussian_frame.rotate_sh_rest`).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from nerf2gs_plugin.data.normalize import DataparserTransform
from nerf2gs_plugin.methods.gaussian_frame import rotate_sh_rest
from nerf2gs_plugin.utils.quaternions import normalize_quats, quat_to_rotmat, rotmat_to_quat

PREFIX = "gauss."


def relative_rotation(src: DataparserTransform, dst: DataparserTransform) -> Tensor:
    """``[3, 3]`` rotation taking a direction of ``src``'s frame to ``dst``'s."""
    return dst.transform[:, :3].double() @ src.transform[:, :3].double().T


def means_to_data(means: Tensor, src: DataparserTransform) -> Tensor:
    return src.invert_points(means.double())


def reframe_state(state: dict[str, Tensor], src: DataparserTransform, dst: DataparserTransform) -> dict[str, Tensor]:
    """The model state with ``gauss.*`` (means, log scales, quats, SH rest) and the sky
    background's SH moved from ``src``'s frame to ``dst``'s; other entries unchanged."""
    out = dict(state)
    rot = relative_rotation(src, dst)
    means = state[PREFIX + "means"]
    out[PREFIX + "means"] = dst.apply_points(means_to_data(means, src)).to(means.dtype)
    if PREFIX + "scales" in state:
        out[PREFIX + "scales"] = state[PREFIX + "scales"] + math.log(dst.scale / src.scale)
    if PREFIX + "quats" in state:
        q = state[PREFIX + "quats"]
        out[PREFIX + "quats"] = rotmat_to_quat(rot.to(q) @ quat_to_rotmat(normalize_quats(q)))
    rest = state.get(PREFIX + "features_rest")
    if rest is not None and rest.shape[0] and rest.shape[1]:
        out[PREFIX + "features_rest"] = rotate_sh_rest(rest, rot.T.to(rest))  # d_src = rot^T d_dst
    sky = state.get("background.coeffs")
    if sky is not None and sky.shape[0] > 1:
        out["background.coeffs"] = torch.cat([sky[:1], rotate_sh_rest(sky[None, 1:], rot.T.to(sky))[0]])
    return out


def select(state: dict[str, Tensor], keep: Tensor) -> dict[str, Tensor]:
    """The state with only the primitives ``keep [N]`` (bool) in every ``gauss.*`` tensor."""
    return {k: (v[keep] if k.startswith(PREFIX) else v) for k, v in state.items()}
