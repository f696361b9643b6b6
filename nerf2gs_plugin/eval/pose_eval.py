"""Pose accuracy of an estimated trajectory against the true one: Sim(3) alignment and ATE.

Why: SfM poses live in an arbitrary similarity frame, so they are compared only after the best
Sim(3) (Umeyama 1991) maps them onto the truth; ATE is then the RMS position error, reported as a
percentage of the true trajectory length so captures of any size compare.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class Sim3:
    """``x -> s * R @ x + t``."""

    s: float
    R: np.ndarray  # [3, 3]
    t: np.ndarray  # [3]

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Points ``[N, 3]``."""
        return self.s * np.asarray(x, dtype=np.float64) @ self.R.T + self.t

    def inverse(self) -> "Sim3":
        """``y -> R^T (y - t) / s``."""
        Rt = self.R.T
        return Sim3(1.0 / self.s, Rt, -(Rt @ self.t) / self.s)

    def apply_poses(self, c2w: np.ndarray) -> np.ndarray:
        """Camera-to-world ``[N, 3, 4]``: rotations turned by R, centres mapped."""
        c2w = np.asarray(c2w, dtype=np.float64)
        out = np.empty_like(c2w)
        out[:, :, :3] = self.R @ c2w[:, :, :3]
        out[:, :, 3] = self.apply(c2w[:, :, 3])
        return out


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> Sim3:
    """The least-squares similarity taking ``src [N, 3]`` onto ``dst [N, 3]`` (N >= 3, not collinear
    for a unique rotation)."""
    src, dst = np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 3:
        raise ValueError(f"umeyama needs two [N>=3, 3] arrays, got {src.shape} and {dst.shape}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    var_s = (xs**2).sum() / len(src)
    s = float(np.trace(np.diag(D) @ S) / var_s) if with_scale and var_s > 0 else 1.0
    return Sim3(s, R, mu_d - s * R @ mu_s)


def trajectory_length(centres: np.ndarray) -> float:
    """Sum of the distances between consecutive camera centres ``[N, 3]`` (in order)."""
    c = np.asarray(centres, dtype=np.float64)
    return float(np.linalg.norm(np.diff(c, axis=0), axis=1).sum()) if len(c) > 1 else 0.0


@dataclass
class PoseErrors:
    ate_rmse: float  # in the true frame's units
    ate_percent: float  # of the true trajectory length
    rotation_deg_mean: float  # mean angle between aligned and true camera rotations
    scale: float  # the similarity's scale (true units per estimated unit)
    sim3: Sim3


def align_poses(est_c2w: np.ndarray, true_c2w: np.ndarray) -> Sim3:
    """Sim(3) from estimated to true cameras ``[N, 3, 4]``. Centres alone leave the rotation about a
    straight drive free, so each camera also contributes two points along its axes (at a tenth of
    the trajectory length): a straight dashcam drive aligns by its orientations too."""
    est, true = np.asarray(est_c2w, dtype=np.float64), np.asarray(true_c2w, dtype=np.float64)
    s0 = umeyama(est[:, :, 3], true[:, :, 3]).s
    arm = max(trajectory_length(true[:, :, 3]) / 10.0, 1e-6)
    src = np.concatenate([est[:, :, 3]] + [est[:, :, 3] + (arm / s0) * est[:, :, k] for k in (1, 2)])
    dst = np.concatenate([true[:, :, 3]] + [true[:, :, 3] + arm * true[:, :, k] for k in (1, 2)])
    return umeyama(src, dst)


def pose_errors(est_c2w: np.ndarray, true_c2w: np.ndarray) -> PoseErrors:
    """ATE after Sim(3) alignment (:func:`align_poses`) of estimated to true cameras (same order, ``[N, 3, 4]``)."""
    est, true = np.asarray(est_c2w, dtype=np.float64), np.asarray(true_c2w, dtype=np.float64)
    sim = align_poses(est, true)
    aligned = sim.apply_poses(est)
    err = np.linalg.norm(aligned[:, :, 3] - true[:, :, 3], axis=1)
    rmse = float(np.sqrt((err**2).mean()))
    length = trajectory_length(true[:, :, 3])
    rot = float(np.mean([rotation_angle_deg(a, t) for a, t in zip(aligned[:, :, :3], true[:, :, :3])]))
    return PoseErrors(rmse, 100.0 * rmse / length if length > 0 else float("nan"), rot, sim.s, sim)


def _nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation closest to ``M [3, 3]`` (Frobenius): the chordal mean of summed rotations."""
    U, _, Vt = np.linalg.svd(M)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ D @ Vt


@dataclass
class LocalAlignment:
    """Maps cameras from the true frame into an estimated one by the training cameras around each.

    Why: one Sim(3) leaves each camera with the SfM's slowly drifting orientation error; an eval camera
    mapped by it looks a few degrees off where the models, fitted to the estimated training cameras,
    expect it, and that alone costs PSNR (the real bench's ``real_rotation_check.md``) whatever the
    models learnt. Here each camera gets the
    rotation and offset that carry its true neighbours onto their estimated selves (Gaussian weights
    over the distance to the training centres beyond the nearest, ``sigma`` in true units), the scale
    stays the global one. It reads only training cameras, never an eval image or a model, so every
    method is scored at the same cameras; equal frames give the identity."""

    est: np.ndarray  # [N, 3, 4] training cameras in the estimated frame
    true: np.ndarray  # [N, 3, 4] the same cameras in the true frame
    sigma: float  # neighbourhood width, true units
    global_sim: Sim3  # the one estimated -> true Sim(3) (:func:`align_poses`): the capture figures' alignment

    @classmethod
    def fit(cls, est_c2w: np.ndarray, true_c2w: np.ndarray, sigma: Optional[float] = None) -> "LocalAlignment":
        """``sigma`` defaults to twice the median spacing of consecutive true camera centres."""
        est, true = np.asarray(est_c2w, dtype=np.float64), np.asarray(true_c2w, dtype=np.float64)
        if sigma is None:
            steps = np.linalg.norm(np.diff(true[:, :, 3], axis=0), axis=1)
            sigma = 2.0 * float(np.median(steps)) if len(steps) else 1.0
        return cls(est, true, max(float(sigma), 1e-9), align_poses(est, true))

    @property
    def scale(self) -> float:
        """Estimated units per true unit (the global Sim(3)'s: the local maps keep it)."""
        return 1.0 / self.global_sim.s

    def weights(self, centre: np.ndarray, skip: Optional[int] = None) -> np.ndarray:
        d = np.linalg.norm(self.true[:, :, 3] - np.asarray(centre, dtype=np.float64), axis=1)
        if skip is not None:
            d[skip] = np.inf
        w = np.exp(-0.5 * ((d - d[np.isfinite(d)].min()) / self.sigma) ** 2)
        return w / w.sum()

    def map_pose(self, c2w_true: np.ndarray, skip: Optional[int] = None) -> np.ndarray:
        """One camera ``[3, 4]`` from the true into the estimated frame (``skip``: leave that
        training camera out, for the leave-one-out figure)."""
        c2w_true = np.asarray(c2w_true, dtype=np.float64)
        w = self.weights(c2w_true[:, 3], skip)
        Rc = _nearest_rotation(np.einsum("n,nij,nkj->ik", w, self.est[:, :, :3], self.true[:, :, :3]))
        t = (w[:, None] * (self.est[:, :, 3] - self.scale * self.true[:, :, 3] @ Rc.T)).sum(0)
        out = np.empty((3, 4))
        out[:, :3] = Rc @ c2w_true[:, :3]
        out[:, 3] = self.scale * Rc @ c2w_true[:, 3] + t
        return out

    def apply_poses(self, c2w_true: np.ndarray) -> np.ndarray:
        """Cameras ``[N, 3, 4]`` from the true into the estimated frame."""
        return np.stack([self.map_pose(m) for m in np.asarray(c2w_true, dtype=np.float64)]) if len(c2w_true) else np.zeros((0, 3, 4))

    def leave_one_out_rotation_deg(self) -> float:
        """Mean angle by which each training camera, mapped from its neighbours alone, misses its
        estimated self: what the mapping of a held-out camera is expected to miss by."""
        errs = [rotation_angle_deg(self.map_pose(self.true[i], skip=i)[:, :3], self.est[i, :, :3]) for i in range(len(self.true))]
        return float(np.mean(errs)) if len(self.true) > 1 else float("nan")


def rotation_angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    """The angle between two rotations ``[3, 3]`` (from the chord ``|A - B| = 2 sqrt(2) sin(angle / 2)``:
    exact near zero, where the trace's arccos is not)."""
    chord = np.linalg.norm(np.asarray(A, dtype=np.float64) - np.asarray(B, dtype=np.float64))
    return float(np.degrees(2.0 * np.arcsin(min(chord / (2.0 * np.sqrt(2.0)), 1.0))))


def vector_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle between two vectors ``[3]`` as ``atan2(|a x b|, a . b)``: exact near zero, where
    ``arccos`` of a dot product loses half the digits (1e-6 deg of float64 noise)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), float(a @ b))))


def capture_report(est_c2w: np.ndarray, true_c2w: np.ndarray, est_metres_per_unit: float, est_up: np.ndarray,
                   true_up: np.ndarray, registered: int, total: int) -> dict:
    """The figures ``ns2gs-bench real`` reports for a processed capture against its true cameras
    (true frame in metres): registered fraction, ATE (% of trajectory), rotation error, the error of
    the camera-height scale against the Sim(3) scale, and the angle between estimated and true up."""
    pe = pose_errors(est_c2w, true_c2w)
    up = pe.sim3.R @ (np.asarray(est_up, dtype=np.float64) / np.linalg.norm(est_up))
    tu = np.asarray(true_up, dtype=np.float64) / np.linalg.norm(true_up)
    return {
        "registered_fraction": registered / max(total, 1),
        "ate_percent": pe.ate_percent,
        "ate_m": pe.ate_rmse,
        "rotation_error_deg": pe.rotation_deg_mean,
        "scale_error_percent": 100.0 * (est_metres_per_unit / pe.scale - 1.0),
        "up_error_deg": vector_angle_deg(up, tu),
    }
