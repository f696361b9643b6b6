"""Cameras: intrinsics + camera-to-world poses, ray generation, projection, bird's-eye poses.

Conventions (the same as nerfstudio):
  * ``camera_to_worlds`` is ``[N, 3, 4]`` in the OpenGL convention: x right, y up, the camera looks
    down -z.
  * Pixel ``(u, v)`` has its centre at ``(u + 0.5, v + 0.5)``; ``u`` runs along the width, ``v``
    along the height, ``v = 0`` is the top row.
  * Splatting rasterizers (gsplat and ours) take OpenCV view matrices (world-to-camera, x right,
    y down, looking down +z) and ``K`` matrices: :meth:`Cameras.viewmats` and :meth:`Cameras.Ks`.
  * ``distortion_params`` are OPENCV ``[k1, k2, p1, p2]``; zero means a pinhole.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Optional, Sequence, Union

import torch
from torch import Tensor

from nerf2gs_plugin.utils.lie import skew

# OpenGL <-> OpenCV camera axes: flip y and z.
_GL_TO_CV = torch.diag(torch.tensor([1.0, -1.0, -1.0]))


@dataclass
class RayBundle:
    """A batch of rays. ``pixel_radius`` is the cone radius at unit distance (for anti-aliasing)."""

    origins: Tensor  # [R, 3]
    directions: Tensor  # [R, 3], unit length
    pixel_radius: Tensor  # [R, 1]
    camera_indices: Tensor  # [R] long, index into the Cameras the rays came from

    def __len__(self) -> int:
        return self.origins.shape[0]

    def __getitem__(self, idx) -> "RayBundle":
        return RayBundle(*(getattr(self, f.name)[idx] for f in fields(self)))

    def to(self, device: Union[str, torch.device]) -> "RayBundle":
        return RayBundle(*(getattr(self, f.name).to(device) for f in fields(self)))


@dataclass
class Cameras:
    """A set of N pinhole (optionally OPENCV-distorted) cameras; index it like a tensor."""

    camera_to_worlds: Tensor  # [N, 3, 4] OpenGL convention
    fx: Tensor  # [N]
    fy: Tensor  # [N]
    cx: Tensor  # [N]
    cy: Tensor  # [N]
    width: Tensor  # [N] long
    height: Tensor  # [N] long
    distortion_params: Tensor = field(default=None)  # [N, 4] k1, k2, p1, p2

    def __post_init__(self) -> None:
        c2w = self.camera_to_worlds
        if c2w.ndim == 2:
            c2w = c2w[None]
        if c2w.shape[-2:] == (4, 4):
            c2w = c2w[..., :3, :]
        if c2w.shape[-2:] != (3, 4):
            raise ValueError(f"camera_to_worlds must be [N,3,4], got {tuple(self.camera_to_worlds.shape)}")
        self.camera_to_worlds = c2w.float()
        n = c2w.shape[0]

        def vec(x, dtype=torch.float32) -> Tensor:
            t = torch.as_tensor(x, dtype=dtype, device=c2w.device).reshape(-1)
            return t.expand(n).clone() if t.numel() == 1 else t

        self.fx, self.fy, self.cx, self.cy = (vec(v) for v in (self.fx, self.fy, self.cx, self.cy))
        self.width, self.height = vec(self.width, torch.long), vec(self.height, torch.long)
        if self.distortion_params is None:
            self.distortion_params = torch.zeros(n, 4, device=c2w.device)
        else:
            d = torch.as_tensor(self.distortion_params, dtype=torch.float32, device=c2w.device)
            self.distortion_params = d.reshape(1, 4).expand(n, 4).clone() if d.numel() == 4 else d.reshape(n, 4)

    # ----------------------------------------------------------------- container protocol
    def __len__(self) -> int:
        return self.camera_to_worlds.shape[0]

    def __getitem__(self, idx) -> "Cameras":
        if isinstance(idx, int):
            idx = slice(idx, idx + 1) if idx != -1 else slice(-1, None)
        return Cameras(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    def to(self, device: Union[str, torch.device]) -> "Cameras":
        return Cameras(**{f.name: getattr(self, f.name).to(device) for f in fields(self)})

    @property
    def device(self) -> torch.device:
        return self.camera_to_worlds.device

    @staticmethod
    def cat(cams: Sequence["Cameras"]) -> "Cameras":
        return Cameras(**{f.name: torch.cat([getattr(c, f.name) for c in cams]) for f in fields(Cameras)})

    def with_poses(self, camera_to_worlds: Tensor) -> "Cameras":
        """Same intrinsics, new poses (``[N, 3, 4]``)."""
        return replace(self, camera_to_worlds=camera_to_worlds)

    def scaled(self, factor: float) -> "Cameras":
        """Intrinsics for images resized by ``factor`` (e.g. 0.5 = half resolution)."""
        return replace(
            self,
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=self.cx * factor,
            cy=self.cy * factor,
            width=(self.width.float() * factor).round().long(),
            height=(self.height.float() * factor).round().long(),
        )

    def pixel_count(self) -> int:
        """Pixels in all these views together (what a densification budget read from the views counts)."""
        return int((self.width.long() * self.height.long()).sum())

    @property
    def is_distorted(self) -> bool:
        return bool((self.distortion_params.abs() > 0).any())

    # ----------------------------------------------------------------- matrices
    def Ks(self) -> Tensor:
        """Intrinsic matrices ``[N, 3, 3]``."""
        K = torch.zeros(len(self), 3, 3, device=self.device)
        K[:, 0, 0], K[:, 1, 1] = self.fx, self.fy
        K[:, 0, 2], K[:, 1, 2] = self.cx, self.cy
        K[:, 2, 2] = 1.0
        return K

    def camera_to_worlds_4x4(self) -> Tensor:
        bottom = torch.tensor([0.0, 0.0, 0.0, 1.0], device=self.device).expand(len(self), 1, 4)
        return torch.cat([self.camera_to_worlds, bottom], dim=1)

    def viewmats(self) -> Tensor:
        """OpenCV world-to-camera matrices ``[N, 4, 4]`` (what gsplat's ``rasterization`` takes)."""
        return opengl_c2w_to_opencv_w2c(self.camera_to_worlds)

    @property
    def centers(self) -> Tensor:
        return self.camera_to_worlds[:, :, 3]

    # ----------------------------------------------------------------- rays
    def pixel_grid(self, cam: int) -> Tensor:
        """All pixel coordinates ``[H*W, 2]`` (u, v) of camera ``cam``, row-major."""
        h, w = int(self.height[cam]), int(self.width[cam])
        v, u = torch.meshgrid(torch.arange(h, device=self.device), torch.arange(w, device=self.device), indexing="ij")
        return torch.stack([u.reshape(-1), v.reshape(-1)], dim=-1)

    def generate_rays(self, camera_indices: Tensor | int, coords: Optional[Tensor] = None) -> RayBundle:
        """Rays through pixel centres.

        Args:
            camera_indices: ``[R]`` camera index per ray, or one int for a whole image.
            coords: ``[R, 2]`` integer pixel coordinates (u, v); with an int camera and ``None``,
                every pixel of that camera in row-major order.
        """
        if isinstance(camera_indices, int):
            if coords is None:
                coords = self.pixel_grid(camera_indices)
            camera_indices = torch.full((coords.shape[0],), camera_indices, dtype=torch.long, device=self.device)
        assert coords is not None
        ci = camera_indices.to(self.device).long()
        uv = coords.to(self.device).float() + 0.5
        fx, fy, cx, cy = self.fx[ci], self.fy[ci], self.cx[ci], self.cy[ci]
        x = (uv[:, 0] - cx) / fx
        y = (uv[:, 1] - cy) / fy
        dist = self.distortion_params[ci]
        if bool((dist.abs() > 0).any()):
            x, y = undistort_normalized(x, y, dist)
        # camera frame is OpenGL: y up, looking down -z
        d_cam = torch.stack([x, -y, -torch.ones_like(x)], dim=-1)
        c2w = self.camera_to_worlds[ci]
        d_world = torch.einsum("rij,rj->ri", c2w[:, :, :3], d_cam)
        norm = d_world.norm(dim=-1, keepdim=True)
        directions = d_world / norm
        # cone radius at unit distance along the ray: pixel footprint / sqrt(3) scaled (mip-NeRF)
        pixel_radius = (2.0 / math.sqrt(12.0)) / (torch.sqrt(fx * fy)[:, None] * norm)
        return RayBundle(c2w[:, :, 3].clone(), directions, pixel_radius, ci)

    def project(self, points: Tensor, cam: int) -> tuple[Tensor, Tensor]:
        """Project world points ``[P, 3]`` into camera ``cam``.

        Returns pixel coordinates ``[P, 2]`` (continuous; pixel centre = integer + 0.5, with
        OPENCV distortion applied) and depth along the viewing axis ``[P]`` (positive in front).
        """
        w2c = self.viewmats()[cam]
        p = points @ w2c[:3, :3].T + w2c[:3, 3]
        z = p[:, 2]
        x, y = p[:, 0] / z, p[:, 1] / z
        dist = self.distortion_params[cam]
        if bool((dist.abs() > 0).any()):
            x, y = distort_normalized(x, y, dist[None].expand(x.shape[0], 4))
        u = self.fx[cam] * x + self.cx[cam]
        v = self.fy[cam] * y + self.cy[cam]
        return torch.stack([u, v], dim=-1), z


def opengl_c2w_to_opencv_w2c(c2w: Tensor) -> Tensor:
    """``[N, 3, 4]`` OpenGL camera-to-world -> ``[N, 4, 4]`` OpenCV world-to-camera."""
    n = c2w.shape[0]
    R = c2w[:, :, :3] @ _GL_TO_CV.to(c2w)
    t = c2w[:, :, 3]
    w2c = torch.zeros(n, 4, 4, dtype=c2w.dtype, device=c2w.device)
    w2c[:, :3, :3] = R.transpose(1, 2)
    w2c[:, :3, 3] = -torch.einsum("nji,nj->ni", R, t)
    w2c[:, 3, 3] = 1.0
    return w2c


def opencv_w2c_to_opengl_c2w(w2c: Tensor) -> Tensor:
    """``[N, 4, 4]`` (or ``[N, 3, 4]``) OpenCV world-to-camera -> ``[N, 3, 4]`` OpenGL camera-to-world."""
    R = w2c[:, :3, :3].transpose(1, 2)
    t = -torch.einsum("nij,nj->ni", R, w2c[:, :3, 3])
    return torch.cat([R @ _GL_TO_CV.to(w2c), t[:, :, None]], dim=-1)


def distort_normalized(x: Tensor, y: Tensor, dist: Tensor) -> tuple[Tensor, Tensor]:
    """Apply OPENCV radial-tangential distortion to normalized coordinates; ``dist`` is ``[R, 4]``."""
    k1, k2, p1, p2 = dist.unbind(-1)
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return xd, yd


def undistort_normalized(xd: Tensor, yd: Tensor, dist: Tensor, iters: int = 10) -> tuple[Tensor, Tensor]:
    """Invert :func:`distort_normalized` by fixed-point iteration (as OpenCV's undistortPoints)."""
    x, y = xd.clone(), yd.clone()
    k1, k2, p1, p2 = dist.unbind(-1)
    for _ in range(iters):
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x = (xd - dx) / radial
        y = (yd - dy) / radial
    return x, y


def look_at(eye: Tensor, target: Tensor, up: Tensor) -> Tensor:
    """OpenGL camera-to-world ``[N, 3, 4]`` at ``eye [N,3]`` looking at ``target [N,3]``."""
    fwd = torch.nn.functional.normalize(target - eye, dim=-1)
    right = torch.nn.functional.normalize(torch.cross(fwd, up.expand_as(fwd), dim=-1), dim=-1)
    cam_up = torch.cross(right, fwd, dim=-1)
    return torch.stack([right, cam_up, -fwd, eye], dim=-1)


def _per_view(x: "float | Tensor", like: Tensor) -> "float | Tensor":
    """A scalar as it is; a ``[N]`` tensor as a ``[N, 1]`` column on ``like``'s device and dtype."""
    return x.to(like)[:, None] if isinstance(x, Tensor) else x


def birds_eye_poses(camera_to_worlds: Tensor, up: Tensor, delta_h: "float | Tensor", theta_pitch_deg: "float | Tensor") -> Tensor:
    """The paper's additional views (Fig. 3): raise each camera by ``delta_h`` along ``up`` and pitch
    it down by ``theta_pitch`` degrees about its own right axis.

    ``camera_to_worlds`` is ``[N, 3, 4]`` OpenGL, ``up`` a unit ``[3]`` vector, ``delta_h`` in the
    units of the poses (convert metres with the dataparser's scale first); ``delta_h`` and
    ``theta_pitch_deg`` are one value for all views or a ``[N]`` tensor, one per view. Input views are
    assumed level (0 deg pitch, as a car-mounted camera); a tilted input keeps its tilt and adds
    ``theta_pitch``.
    """
    up = torch.nn.functional.normalize(up.to(camera_to_worlds), dim=0)
    R = camera_to_worlds[:, :, :3]
    t = camera_to_worlds[:, :, 3] + _per_view(delta_h, R) * up
    right = R[:, :, 0]
    a = torch.deg2rad(theta_pitch_deg.to(R)) if isinstance(theta_pitch_deg, Tensor) else math.radians(theta_pitch_deg)
    # Rodrigues rotation about each camera's right axis by -a (nose down in OpenGL: -z turns toward -up).
    Rr = _axis_angle(right, -a)
    R_new = Rr @ R
    return torch.cat([R_new, t[:, :, None]], dim=-1)


def birds_eye_poses_absolute(camera_to_worlds: Tensor, up: Tensor, delta_h: "float | Tensor", theta_pitch_deg: "float | Tensor") -> Tensor:
    """Bird's-eye views pitched ``theta_pitch`` below the HORIZON of the ground plane (normal ``up``),
    whatever the input camera's own tilt and roll: each camera's forward direction is projected on
    the ground plane, pitched down by ``theta_pitch``, and the view is levelled (no roll). For level
    input cameras (a car-mounted camera) this equals :func:`birds_eye_poses`; for walking photos
    pointing 9-24 deg up it is what "30 deg down" means."""
    up = torch.nn.functional.normalize(up.to(camera_to_worlds), dim=0)
    R = camera_to_worlds[:, :, :3]
    flat = flat_forward(camera_to_worlds, up)
    if isinstance(theta_pitch_deg, Tensor):
        a = torch.deg2rad(theta_pitch_deg.to(R))[:, None]
        f = torch.cos(a) * flat - torch.sin(a) * up
    else:
        a = math.radians(theta_pitch_deg)
        f = math.cos(a) * flat - math.sin(a) * up
    right = torch.nn.functional.normalize(torch.cross(f, up.expand_as(f), dim=-1), dim=-1)
    new_up = torch.cross(right, f, dim=-1)
    t = camera_to_worlds[:, :, 3] + _per_view(delta_h, R) * up
    return torch.stack([right, new_up, -f, t], dim=-1)


def flat_forward(camera_to_worlds: Tensor, up: Tensor) -> Tensor:
    """``[N, 3]`` each camera's viewing direction projected on the ground plane (``up``: its unit
    normal), unit length; a camera looking straight up or down has no horizontal forward: its own up
    axis instead."""
    R = camera_to_worlds[:, :, :3]
    fwd = -R[:, :, 2]
    flat = fwd - (fwd @ up)[:, None] * up
    cam_up = R[:, :, 1] - (R[:, :, 1] @ up)[:, None] * up
    weak = flat.norm(dim=-1, keepdim=True) < 1e-4
    return torch.nn.functional.normalize(torch.where(weak, cam_up, flat), dim=-1)


def ground_lateral(camera_to_worlds: Tensor, up: Tensor) -> Tensor:
    """``[N, 3]`` the ground plane's lateral axis at each camera: level, to the right of its heading,
    whatever the camera's own roll (a rolled camera's x axis leaves the plane; this one does not)."""
    up = torch.nn.functional.normalize(up.to(camera_to_worlds), dim=0)
    flat = flat_forward(camera_to_worlds, up)
    return torch.nn.functional.normalize(torch.cross(flat, up.expand_as(flat), dim=-1), dim=-1)


def raise_and_pitch(camera_to_worlds: Tensor, up: Tensor, delta_h_world: float | Tensor,
                    theta_pitch_deg: float | Tensor, pitch_mode: str = "relative") -> Tensor:
    """``[N, 3, 4]`` poses raised by ``delta_h_world`` along ``up`` and pitched down by ``theta_pitch_deg``
    (relative: about each camera's right axis; absolute: below the ground plane's horizon)."""
    poses = birds_eye_poses_absolute if pitch_mode == "absolute" else birds_eye_poses
    return poses(camera_to_worlds, up, delta_h_world, theta_pitch_deg)


def _axis_angle(axis: Tensor, angle: "float | Tensor") -> Tensor:
    """Rotation matrices ``[N, 3, 3]`` about unit axes ``[N, 3]`` by one angle or ``[N]`` angles (radians)."""
    axis = torch.nn.functional.normalize(axis, dim=-1)
    Kx = skew(axis).reshape(-1, 3, 3)
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device).expand_as(Kx)
    if isinstance(angle, Tensor):
        a = angle.to(axis)[:, None, None]
        return eye + torch.sin(a) * Kx + (1 - torch.cos(a)) * (Kx @ Kx)
    return eye + math.sin(angle) * Kx + (1 - math.cos(angle)) * (Kx @ Kx)
