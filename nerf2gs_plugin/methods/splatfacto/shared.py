"""Pieces every splatting method here shares: the settings of :class:`SplatModelConfig`, the
background (sky) model, the image loss (``(1-l) L1 + l (1-SSIM)`` weighted by the batch weight,
optional transient masking, sky alpha loss) and camera helpers."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import torch
from torch import Tensor, nn

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.engine.model import ModelConfig
from nerf2gs_plugin.utils.image_metrics import ssim, ssim_map
from nerf2gs_plugin.utils.sh import num_sh_bases, sh_basis, sh_rotation

BackgroundMode = Literal["sky", "random", "learned", "black", "white"]


@dataclass
class SplatModelConfig(ModelConfig):
    """The settings every splatting model here has (Splatfacto, 2DGS, Scaffold-GS): initial points,
    image loss, background, rasterizer. Same flags for each (--pipeline.model.NAME)."""

    num_random: int = 5000
    """Random primitives in the scene box when the dataset has no sparse points (nerfstudio: 50000)."""
    ssim_lambda: float = 0.2
    """Weight of the (1 - SSIM) term of the image loss (the rest is L1)."""
    background: BackgroundMode = "sky"
    """sky: learned view-direction background; random: random colour per step; learned; black; white."""
    sky_sh_degree: int = 3
    """SH degree of the sky background's view-direction colour."""
    sky_alpha_weight: float = 0.05
    """Push accumulation to 0 on sky-mask pixels (when the dataset has sky masks)."""
    mask_transients: bool = False
    """Ignore transient-mask pixels in the loss (the baseline-with-masks variant)."""
    rasterize_mode: Literal["classic", "antialiased"] = "classic"
    """classic (3DGS) or antialiased (Mip-Splatting's opacity compensation)."""
    backend: str = "auto"
    """Rasterizer: auto (gsplat on CUDA, else our C++ kernel, else torch), cpu, torch or gsplat."""
    near_plane: float = 0.01
    """Gaussians nearer to the camera than this are not drawn."""
    far_plane: float = 1e10
    """Gaussians farther than this are not drawn."""


def camera_directions(camera: Cameras) -> Tensor:
    """Unit world ray directions ``[H, W, 3]`` of a one-camera :class:`Cameras`."""
    h, w = int(camera.height[0]), int(camera.width[0])
    return camera.generate_rays(0).directions.reshape(h, w, 3)


class Background(nn.Module):
    """What shows where the Gaussians leave transmittance.

    * ``sky`` (default): a learned environment colour as a function of the view direction
      (degree-``sh_degree`` SH through a sigmoid), so sky pixels are explained without Gaussians
      and do not seed floaters.
    * ``random``: a random colour per training step (Gaussians must be opaque to be seen; black at eval).
    * ``learned``: one learned colour; ``black`` / ``white``: fixed.
    """

    def __init__(self, mode: BackgroundMode = "sky", sh_degree: int = 3) -> None:
        super().__init__()
        self.mode = mode
        self.sh_degree = sh_degree
        self._bases: dict[tuple, Tensor] = {}  # camera-frame SH bases by intrinsics (see _camera_basis)
        if mode == "sky":
            coeffs = torch.zeros(num_sh_bases(sh_degree), 3)
            self.coeffs = nn.Parameter(coeffs)
        elif mode == "learned":
            self.color = nn.Parameter(torch.zeros(3))

    def parameters_list(self) -> list[nn.Parameter]:
        return list(self.parameters())

    def _sky_logits(self, camera: Cameras) -> Tensor:
        """``basis(world directions) @ coeffs`` ``[H, W, 3]``. The SH basis of the camera-frame directions
        depends only on the intrinsics and is kept; the camera's rotation turns the coefficients instead
        (a 16 x 16 map): the same values to float rounding, without a basis per pixel every step."""
        c2w = camera.camera_to_worlds[0]
        rot = c2w[:, :3]
        eye = torch.eye(3, dtype=rot.dtype, device=rot.device)
        if c2w.requires_grad or not torch.allclose(rot.T @ rot, eye, atol=1e-5):
            return sh_basis(self.sh_degree, camera_directions(camera)) @ self.coeffs
        turn = sh_rotation(self.sh_degree, rot).to(self.coeffs)
        basis = self._camera_basis(camera)  # [K, H, W]
        # [3, K] @ [K, H*W], read back as [H, W, 3]: a GEMM with three output columns over a long
        # [H*W, K] operand runs several times slower, forward and backward, on CPU BLAS
        return ((turn @ self.coeffs).T @ basis.flatten(1)).T.reshape(*basis.shape[1:], -1)

    def _camera_basis(self, camera: Cameras) -> Tensor:
        """SH basis ``[K, H, W]`` (contiguous) of the camera-frame ray directions of a one-camera ``camera``, per intrinsics."""
        key = (int(camera.height[0]), int(camera.width[0]), str(camera.device),
               *(float(v) for v in (camera.fx[0], camera.fy[0], camera.cx[0], camera.cy[0])),
               *(float(v) for v in camera.distortion_params[0]))
        cache = self._bases
        if key not in cache:
            if len(cache) >= 8:  # a few image sizes at most in one run; never grow without bound
                cache.clear()
            pose = torch.eye(4, device=camera.device)[None, :3]
            basis = sh_basis(self.sh_degree, camera_directions(camera.with_poses(pose))).to(self.coeffs.dtype)
            cache[key] = basis.permute(2, 0, 1).contiguous()
        return cache[key]

    def forward(self, camera: Cameras, training: bool) -> Tensor:
        """Background ``[H, W, 3]`` or ``[3]`` (broadcastable) on the camera's device."""
        dev = camera.device
        if self.mode == "sky":
            return torch.sigmoid(self._sky_logits(camera))
        if self.mode == "learned":
            return torch.sigmoid(self.color)
        if self.mode == "random":
            return torch.rand(3, device=dev) if training else torch.zeros(3, device=dev)
        if self.mode == "white":
            return torch.ones(3, device=dev)
        return torch.zeros(3, device=dev)


def image_loss(
    outputs: dict[str, Tensor],
    batch: dict[str, Any],
    ssim_lambda: float,
    mask_transients: bool = False,
    sky_alpha_weight: float = 0.0,
    sky_background: Tensor | None = None,
) -> dict[str, Tensor]:
    """The 3DGS photometric loss, times ``batch["weight"]``.

    With ``mask_transients`` the transient-mask pixels of the prediction are replaced by the
    (constant) target, so they contribute neither L1 nor SSIM gradient. With a sky mask and
    ``sky_alpha_weight > 0`` the accumulation on sky pixels is pushed to 0 (the background
    explains them). With ``sky_background`` (the random background of a step) the target's sky
    pixels become that colour, i.e. the sky is treated as transparent (nerfstudio's alpha images).
    """
    pred, gt = outputs["rgb"], batch["image"].to(outputs["rgb"])
    photo = batch.get("photo")
    if photo is not None:  # a composite's pixel is learnt as photographed unless the paint is clearly nearer
        photo, margin = photo.to(pred), float(batch.get("photo_margin", 0.0))
        nearer = ((pred - photo).abs().mean(-1, keepdim=True) < (pred - gt).abs().mean(-1, keepdim=True) + margin).detach()
        gt = torch.where(nearer, photo, gt)
    if sky_background is not None and batch.get("sky_mask") is not None:  # after the choice: the sky stays transparent
        gt = torch.where(batch["sky_mask"].to(pred.device), sky_background.to(gt).expand_as(gt), gt)
    weight = torch.as_tensor(batch.get("weight", 1.0), dtype=pred.dtype, device=pred.device)
    if mask_transients and batch.get("transient_mask") is not None:
        m = batch["transient_mask"].to(pred.device)
        pred = torch.where(m, gt, pred)
    conf = batch.get("confidence")
    if conf is None:
        l1 = (pred - gt).abs().mean()
        loss = (1 - ssim_lambda) * l1
        if ssim_lambda > 0:
            loss = loss + ssim_lambda * (1 - ssim(pred, gt))
    else:
        loss = confidence_weighted_loss(pred, gt, conf.to(pred), ssim_lambda)
    out = {"main_loss": weight * loss}
    sky = batch.get("sky_mask")
    if sky_alpha_weight > 0 and sky is not None and "accumulation" in outputs:
        sky = sky.to(pred.device)
        if bool(sky.any()):
            acc = outputs["accumulation"]
            out["sky_alpha_loss"] = weight * sky_alpha_weight * acc[sky].mean()
    return out


def confidence_weighted_loss(pred: Tensor, gt: Tensor, confidence: Tensor, ssim_lambda: float) -> Tensor:
    """``(1-l) L1 + l (1-SSIM)`` with each pixel's terms times its ``confidence`` ``[H, W, 1]`` (a reference
    render's pixels weigh as much as the reference knows them; all ones gives the plain loss). SSIM
    is per pixel over the valid region, so the confidence is cropped to it."""
    loss = (1 - ssim_lambda) * ((pred - gt).abs() * confidence).mean()
    if ssim_lambda > 0:
        smap = ssim_map(pred, gt)  # [1, 3, H - win + 1, W - win + 1]
        top, left = (pred.shape[0] - smap.shape[2]) // 2, (pred.shape[1] - smap.shape[3]) // 2
        c = confidence[top : top + smap.shape[2], left : left + smap.shape[3]].permute(2, 0, 1)[None]
        loss = loss + ssim_lambda * ((1 - smap) * c).mean()
    return loss


def composite(rgb: Tensor, alpha: Tensor, background: Tensor) -> Tensor:
    """``rgb`` was rendered on black: add the background where transmittance remains."""
    return rgb + (1.0 - alpha) * background

